//! Small state files a service leaves so that its restarted successor resumes where it
//! was (issue #13): acquisition's stream position, geolocation's filter, matching's
//! keyframe rings. Each file is written whole to a temporary name and renamed over the
//! old one (rename is atomic on one file system), so a reader sees the previous state
//! or the new one, never half of either, whenever the writer is killed.
//!
//! Layout: the magic `DGCK`, a little-endian u32 format version, a u32 kind tag (which
//! state this is), then the state in `postcard`. A file of another version, kind or
//! shape is an error the caller logs and counts before starting from nothing; it is
//! never trusted. The state directory is owner-only (0700), like the shared memory.

use serde::de::DeserializeOwned;
use serde::Serialize;
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 4] = b"DGCK";
/// Bumped whenever a checkpointed type changes shape (2: the geolocation checkpoint
/// holds the other vehicles' tracks; 3: geolocation's and matching's hold the stream
/// segment; 4: each track holds the persistent part of its error; 5: the tracks' colours
/// and the deleted tracks remembered for re-identification; 6: each track's own noise
/// scale; 7: each track's altitude reference; 8: a track's motion on trial).
pub const VERSION: u32 = 8;
const HEADER: usize = 12;

#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not a dualgeo checkpoint of this kind and version ({detail})")]
    Format { path: PathBuf, detail: String },
}

/// Creates `dir` owner-only (0700) if it does not exist.
pub fn create_dir(dir: &Path) -> Result<(), CheckpointError> {
    use std::os::unix::fs::DirBuilderExt;
    match std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(dir)
    {
        Ok(()) => Ok(()),
        Err(source) => Err(CheckpointError::Io {
            path: dir.to_path_buf(),
            source,
        }),
    }
}

/// The bytes of a checkpoint of `kind` holding `state`.
pub fn encode<T: Serialize>(kind: u32, state: &T) -> Result<Vec<u8>, postcard::Error> {
    let mut bytes = Vec::with_capacity(256);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&VERSION.to_le_bytes());
    bytes.extend_from_slice(&kind.to_le_bytes());
    postcard::to_io(state, &mut bytes)?;
    Ok(bytes)
}

/// The state in `bytes`, checked against the magic, the version and `kind`.
pub fn decode<T: DeserializeOwned>(kind: u32, bytes: &[u8]) -> Result<T, String> {
    if bytes.len() < HEADER || &bytes[..4] != MAGIC {
        return Err("no DGCK header".into());
    }
    let word = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    if word(4) != VERSION {
        return Err(format!("version {} (this build reads {VERSION})", word(4)));
    }
    if word(8) != kind {
        return Err(format!("kind {} (expected {kind})", word(8)));
    }
    let (state, rest) =
        postcard::take_from_bytes::<T>(&bytes[HEADER..]).map_err(|e| e.to_string())?;
    if !rest.is_empty() {
        return Err(format!("{} trailing bytes", rest.len()));
    }
    Ok(state)
}

/// Writes `state` to `path` atomically (temporary file, then rename), mode 0600.
pub fn write<T: Serialize>(path: &Path, kind: u32, state: &T) -> Result<(), CheckpointError> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let bytes = encode(kind, state).map_err(|e| CheckpointError::Format {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })?;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let io = |source| CheckpointError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(&tmp)
        .map_err(io)?;
    file.write_all(&bytes).map_err(io)?;
    drop(file);
    std::fs::rename(&tmp, path).map_err(io)
}

/// The state at `path`: `Ok(None)` when there is no file (a first start).
pub fn read<T: DeserializeOwned>(path: &Path, kind: u32) -> Result<Option<T>, CheckpointError> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => {
            return Err(CheckpointError::Io {
                path: path.to_path_buf(),
                source,
            })
        }
    };
    decode(kind, &bytes)
        .map(Some)
        .map_err(|detail| CheckpointError::Format {
            path: path.to_path_buf(),
            detail,
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct State {
        seq: u64,
        values: Vec<f64>,
    }

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("dualgeo-ckpt-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        create_dir(&d).unwrap();
        d
    }

    #[test]
    fn round_trip_is_owner_only_and_atomic() {
        use std::os::unix::fs::PermissionsExt;
        let d = dir("rt");
        let path = d.join("s.ckpt");
        assert!(read::<State>(&path, 7).unwrap().is_none());
        let s = State {
            seq: 42,
            values: vec![1.5, -2.0],
        };
        write(&path, 7, &s).unwrap();
        assert_eq!(read::<State>(&path, 7).unwrap(), Some(s));
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&path), 0o600);
        assert_eq!(mode(&d), 0o700);
        assert!(!d.join("s.ckpt.tmp").exists());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn wrong_kind_version_or_bytes_is_refused() {
        let d = dir("bad");
        let path = d.join("s.ckpt");
        write(
            &path,
            7,
            &State {
                seq: 1,
                values: vec![],
            },
        )
        .unwrap();
        let e = read::<State>(&path, 8).unwrap_err().to_string();
        assert!(e.contains("kind 7"), "{e}");
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[4] = 99;
        assert!(decode::<State>(7, &bytes)
            .unwrap_err()
            .contains("version 99"));
        assert!(decode::<State>(7, b"DGCK").is_err());
        assert!(decode::<State>(7, b"").is_err());
        let mut long = encode(
            7,
            &State {
                seq: 1,
                values: vec![],
            },
        )
        .unwrap();
        long.push(0);
        assert!(decode::<State>(7, &long).unwrap_err().contains("trailing"));
        let mut short = encode(
            7,
            &State {
                seq: 1,
                values: vec![2.0],
            },
        )
        .unwrap();
        short.pop();
        assert!(decode::<State>(7, &short).is_err());
        std::fs::remove_dir_all(&d).unwrap();
    }
}
