//! Where a stream was (issue #13): acquisition checkpoints its position before it sends
//! each pair, so a restarted acquisition goes on with the next pair instead of the
//! first. Written before the send: if the process dies between the two, that pair is
//! skipped (lost, never sent twice), so sequence numbers and stream times stay strictly
//! increasing across a restart.

use serde::{Deserialize, Serialize};
use shared_types::checkpoint::{self, CheckpointError};
use std::path::Path;

const KIND: u32 = 1;

/// The stream position after the pair `next_seq − 1`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct StreamPosition {
    /// Sequence number of the next pair.
    pub next_seq: u64,
    /// Pairs the source has handed out since its last rewind (simulator steps, or the
    /// index of the next recorded pair).
    pub consumed: u64,
    /// Loops completed (`--loop`).
    pub loops: u64,
    /// Stream time bookkeeping of the loop: offset added to the source's clock, the
    /// first pair's source time in this loop, the last pair's source time.
    pub t_offset: f64,
    pub t_first: Option<f64>,
    pub last_t: f64,
}

impl StreamPosition {
    pub fn save(&self, path: &Path) -> Result<(), CheckpointError> {
        checkpoint::write(path, KIND, self)
    }

    /// The saved position, `None` on a first start; refused when a value is not finite.
    pub fn load(path: &Path) -> Result<Option<Self>, CheckpointError> {
        let p: Option<Self> = checkpoint::read(path, KIND)?;
        p.map(|p| {
            p.checked().map_err(|detail| CheckpointError::Format {
                path: path.to_path_buf(),
                detail,
            })
        })
        .transpose()
    }

    /// A checkpoint file's bytes decoded and checked (what `load` does after reading).
    pub fn decode(bytes: &[u8]) -> Result<Self, String> {
        checkpoint::decode::<Self>(KIND, bytes)?.checked()
    }

    fn checked(self) -> Result<Self, String> {
        if self.t_offset.is_finite()
            && self.last_t.is_finite()
            && self.t_first.is_none_or(f64::is_finite)
        {
            Ok(self)
        } else {
            Err("a stream time is not finite".into())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_round_trip_and_non_finite_ones_are_refused() {
        let dir = std::env::temp_dir().join(format!("dualgeo-resume-{}", std::process::id()));
        checkpoint::create_dir(&dir).unwrap();
        let path = dir.join("acquisition.ckpt");
        assert_eq!(StreamPosition::load(&path).unwrap(), None);
        let p = StreamPosition {
            next_seq: 120,
            consumed: 40,
            loops: 2,
            t_offset: 8.0,
            t_first: Some(0.0),
            last_t: 1.3,
        };
        p.save(&path).unwrap();
        assert_eq!(StreamPosition::load(&path).unwrap(), Some(p));
        StreamPosition {
            t_offset: f64::NAN,
            ..p
        }
        .save(&path)
        .unwrap();
        assert!(StreamPosition::load(&path).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
