//! `truth_targets.csv` (optional): every moving vehicle in every image, for scoring
//! several targets. Written by the simulator, read by the scorer (`dualgeo score`);
//! estimators never read it. Row order: per UAV, frames never go back; within one
//! image each `target_id` at most once.

use super::rows::{open_csv, parse_csv};
use super::{RecordingError, TRUTH_TARGETS_FILE};
use shared_types::conventions::Uav;
use std::collections::HashSet;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

pub const TRUTH_TARGETS_HEADER: [&str; 9] = [
    "uav",
    "frame",
    "t_s",
    "target_id",
    "target_x_m",
    "target_y_m",
    "target_z_m",
    "target_u_px",
    "target_v_px",
];

/// One vehicle in one image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetTruthRow {
    pub uav: Uav,
    pub frame: u64,
    pub t_s: f64,
    /// Stable over the recording; 0 is truth.csv's target.
    pub target_id: u32,
    /// The centre of the vehicle's top face, ENU metres.
    pub target: [f64; 3],
    /// Its projection into the image; `None` outside it or hidden.
    pub target_px: Option<[f64; 2]>,
}

/// Rows of a `truth_targets.csv`.
pub fn read_targets_truth(path: &Path) -> Result<Vec<TargetTruthRow>, RecordingError> {
    parse_targets_truth(open_csv(path)?, path)
}

/// Rows of a `truth_targets.csv` read from `input`, errors naming `path`.
pub fn parse_targets_truth(
    input: impl Read,
    path: &Path,
) -> Result<Vec<TargetTruthRow>, RecordingError> {
    let mut last_frame: [Option<u64>; 2] = [None; 2];
    let mut ids_in_frame: HashSet<(Uav, u64, u32)> = HashSet::new();
    parse_csv(input, path, &[&TRUTH_TARGETS_HEADER], |f| {
        let uav = f.uav(0)?;
        let frame = f.frame(1)?;
        if last_frame[uav.index()].is_some_and(|last| frame < last) {
            return Err(f.error(1, format!("{} frame {frame} goes back", uav.name())));
        }
        last_frame[uav.index()] = Some(frame);
        let t_s = f.number(2)?;
        let target_id: u32 = f.text(3).parse().map_err(|_| {
            f.error(
                3,
                format!("\"{}\" is not a target id (0, 1, 2, …)", f.text(3)),
            )
        })?;
        if !ids_in_frame.insert((uav, frame, target_id)) {
            return Err(f.error(
                3,
                format!("target {target_id} twice in {} frame {frame}", uav.name()),
            ));
        }
        let target = [f.number(4)?, f.number(5)?, f.number(6)?];
        let target_px = match (f.optional_number(7)?, f.optional_number(8)?) {
            (Some(u), Some(v)) => Some([u, v]),
            (None, None) => None,
            _ => {
                return Err(f.error(
                    7,
                    "target_u_px and target_v_px must both be given or both be empty",
                ))
            }
        };
        Ok(TargetTruthRow {
            uav,
            frame,
            t_s,
            target_id,
            target,
            target_px,
        })
    })
}

/// Writes a recording's `truth_targets.csv` (floats in Rust's shortest round-trip
/// form, as the other files).
pub struct TargetsTruthWriter {
    path: PathBuf,
    w: csv::Writer<File>,
}

impl TargetsTruthWriter {
    /// Creates `truth_targets.csv` in the recording folder `root`.
    pub fn create(root: &Path) -> Result<Self, RecordingError> {
        let path = root.join(TRUTH_TARGETS_FILE);
        let err = |e: csv::Error| RecordingError::Write {
            path: path.clone(),
            message: e.to_string(),
        };
        let mut w = csv::Writer::from_path(&path).map_err(err)?;
        w.write_record(TRUTH_TARGETS_HEADER).map_err(err)?;
        Ok(Self { path, w })
    }

    pub fn write(&mut self, row: &TargetTruthRow) -> Result<(), RecordingError> {
        let finite = row.t_s.is_finite()
            && row.target.iter().all(|v| v.is_finite())
            && row
                .target_px
                .is_none_or(|p| p.iter().all(|v| v.is_finite()));
        if !finite {
            return Err(RecordingError::Write {
                path: self.path.clone(),
                message: format!("target {} is not finite", row.target_id),
            });
        }
        let (u, v) = row
            .target_px
            .map_or((String::new(), String::new()), |[u, v]| {
                (u.to_string(), v.to_string())
            });
        let record = [
            row.uav.name().to_string(),
            row.frame.to_string(),
            row.t_s.to_string(),
            row.target_id.to_string(),
            row.target[0].to_string(),
            row.target[1].to_string(),
            row.target[2].to_string(),
            u,
            v,
        ];
        self.w
            .write_record(&record)
            .map_err(|e| RecordingError::Write {
                path: self.path.clone(),
                message: e.to_string(),
            })
    }

    /// Flushes the file. Dropping the writer without `finish` may lose rows.
    pub fn finish(mut self) -> Result<(), RecordingError> {
        self.w
            .flush()
            .map_err(|e| RecordingError::io(&self.path, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Vec<TargetTruthRow>, RecordingError> {
        parse_targets_truth(text.as_bytes(), Path::new("truth_targets.csv"))
    }

    const HEADER: &str =
        "uav,frame,t_s,target_id,target_x_m,target_y_m,target_z_m,target_u_px,target_v_px\n";

    #[test]
    fn the_format_example_reads() {
        let rows = parse(&format!(
            "{HEADER}left,0,0.000000,0,12.40,-3.10,13.50,322.1,241.7\nleft,0,0.000000,1,30.02,-2.95,13.50,,\n"
        ))
        .unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].target_px, Some([322.1, 241.7]));
        assert_eq!(rows[1].target_id, 1);
        assert_eq!(rows[1].target_px, None);
    }

    #[test]
    fn what_is_written_reads_back_identically() {
        let dir = tempfile::tempdir().unwrap();
        let rows = [
            TargetTruthRow {
                uav: Uav::Left,
                frame: 0,
                t_s: 0.0,
                target_id: 0,
                target: [1.0 / 3.0, -2.5, 13.5],
                target_px: Some([320.125, 0.1]),
            },
            TargetTruthRow {
                uav: Uav::Right,
                frame: 0,
                t_s: 0.0,
                target_id: 4,
                target: [30.0, 1e-9, 13.5],
                target_px: None,
            },
        ];
        let mut w = TargetsTruthWriter::create(dir.path()).unwrap();
        for r in &rows {
            w.write(r).unwrap();
        }
        w.finish().unwrap();
        let back = read_targets_truth(&dir.path().join(TRUTH_TARGETS_FILE)).unwrap();
        assert_eq!(back, rows);
    }

    #[test]
    fn bad_rows_are_refused_with_their_place() {
        let cases = [
            ("left,0,0,0,1,2,3,4,\n", "both be given"),
            ("left,0,0,-1,1,2,3,,\n", "not a target id"),
            ("left,0,0,1,1,2,3,,\nleft,0,0,1,1,2,3,,\n", "twice"),
            ("left,1,0,1,1,2,3,,\nleft,0,0,2,1,2,3,,\n", "goes back"),
            ("up,0,0,1,1,2,3,,\n", "unknown uav"),
            ("left,0,0,1,nan,2,3,,\n", "not finite"),
        ];
        for (rows, expected) in cases {
            let e = parse(&format!("{HEADER}{rows}")).unwrap_err().to_string();
            assert!(e.contains(expected), "{rows}: {e}");
            assert!(e.contains("truth_targets.csv"), "{e}");
        }
        let e = parse("uav,frame\n").unwrap_err().to_string();
        assert!(e.contains("header"), "{e}");
    }
}
