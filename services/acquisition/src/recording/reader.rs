//! Opening a recording: every structural rule of format v1 is checked here, before a
//! single frame is used. Images are decoded on demand ([`Recording::read_image`]).

use super::error::CsvPlace;
use super::image_file::decode_image;
use super::meta::CameraMount;
use super::rows::{read_telemetry, read_truth, TelemetryRow, TruthRow};
use super::{
    RecordingError, RecordingMeta, META_FILE, TELEMETRY_FILE, TRUTH_FILE, TRUTH_TARGETS_FILE,
};
use opencv::core as cv;
use shared_types::conventions::{Mount, Uav};
use shared_types::messages::PoseSample;
use std::collections::{BTreeSet, HashMap};
use std::path::{Component, Path, PathBuf};

/// A validated recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    pub root: PathBuf,
    pub meta: RecordingMeta,
    /// Rows of telemetry.csv in file order.
    pub telemetry: Vec<TelemetryRow>,
    /// Rows of truth.csv aligned with `telemetry` (same index), when truth.csv exists.
    pub truth: Option<Vec<TruthRow>>,
}

/// A left and a right image taken within half a frame period of each other.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StereoPair {
    /// Indices into [`Recording::telemetry`].
    pub left: usize,
    pub right: usize,
}

impl Recording {
    /// Opens and validates the recording in `root`.
    pub fn open(root: impl AsRef<Path>) -> Result<Self, RecordingError> {
        let root = root.as_ref().to_path_buf();
        if !root.is_dir() {
            return Err(RecordingError::MissingFile { path: root });
        }
        let meta = RecordingMeta::read(&root.join(META_FILE))?;
        let telemetry_path = root.join(TELEMETRY_FILE);
        let rows = read_telemetry(&telemetry_path)?;
        if ![Uav::Left, Uav::Right]
            .iter()
            .all(|u| rows.iter().any(|(_, r)| r.uav == *u))
        {
            return Err(RecordingError::Csv {
                place: CsvPlace {
                    path: telemetry_path,
                    line: rows.len() as u64 + 1,
                    column: 0,
                    column_name: "",
                },
                message: "needs at least one image of each UAV".into(),
            });
        }
        check_image_files(&root, &meta, &telemetry_path, &rows)?;
        check_gimbal_angles(&meta, &telemetry_path, &rows)?;
        check_no_extra_top_level(&root, &meta)?;
        let truth_path = root.join(TRUTH_FILE);
        let truth = if truth_path.exists() {
            Some(align_truth(&truth_path, &telemetry_path, &rows)?)
        } else {
            None
        };
        Ok(Self {
            root,
            meta,
            telemetry: rows.into_iter().map(|(_, r)| r).collect(),
            truth,
        })
    }

    /// The camera's measured pose at telemetry row `index`: the body's position, and
    /// its attitude turned into the equivalent nadir camera's for a tilted or
    /// gimballed camera (`Mount::equivalent_nadir_attitude`; the yaw bias carries over).
    /// The row's own pose for a nadir camera.
    pub fn camera_pose(&self, index: usize) -> PoseSample {
        let row = &self.telemetry[index];
        camera_pose(&self.meta, row.uav, row.pose, row.gimbal)
    }

    /// Decodes the image of telemetry row `index` (8-bit grey or BGR).
    pub fn read_image(&self, index: usize) -> Result<cv::Mat, RecordingError> {
        let row = &self.telemetry[index];
        let camera = &self.meta.uav(row.uav).camera;
        decode_image(&self.root.join(&row.file), camera.width, camera.height)
    }

    /// Stereo pairs by time: a left and a right image whose `t_s` differ by less than
    /// half a frame period, in time order. Each image is in at most one pair.
    pub fn pairs(&self) -> Vec<StereoPair> {
        let half_period = 0.5 / self.meta.frame_rate_hz;
        let of = |uav: Uav| -> Vec<usize> {
            (0..self.telemetry.len())
                .filter(|&i| self.telemetry[i].uav == uav)
                .collect()
        };
        let (left, right) = (of(Uav::Left), of(Uav::Right));
        let (mut i, mut j) = (0, 0);
        let mut pairs = Vec::new();
        while i < left.len() && j < right.len() {
            let (tl, tr) = (self.telemetry[left[i]].t_s, self.telemetry[right[j]].t_s);
            if (tl - tr).abs() < half_period {
                pairs.push(StereoPair {
                    left: left[i],
                    right: right[j],
                });
                i += 1;
                j += 1;
            } else if tl < tr {
                i += 1;
            } else {
                j += 1;
            }
        }
        pairs
    }
}

/// A camera's pose from its body's `pose` and, for a gimbal, the gimbal's angles
/// (degrees) of the same image.
pub fn camera_pose(
    meta: &RecordingMeta,
    uav: Uav,
    pose: PoseSample,
    gimbal: Option<[f64; 3]>,
) -> PoseSample {
    let mount = match (meta.mount(uav), gimbal) {
        (CameraMount::Nadir, _) => return pose,
        (CameraMount::Fixed(m), _) => m,
        (CameraMount::Gimbal, Some([y, p, r])) => Mount::from_degrees(y, p, r),
        // Refused by `Recording::open`: a gimbal row without angles.
        (CameraMount::Gimbal, None) => Mount::NADIR,
    };
    pose.on_mount(mount)
}

fn csv_error(
    path: &Path,
    line: u64,
    column: usize,
    column_name: &'static str,
    message: String,
) -> RecordingError {
    RecordingError::Csv {
        place: CsvPlace {
            path: path.into(),
            line,
            column,
            column_name,
        },
        message,
    }
}

/// Version 2: a UAV with `mount = "gimbal"` has its angles on every row, any other
/// UAV none (a file whose gimbal columns are all empty is read as one without them).
fn check_gimbal_angles(
    meta: &RecordingMeta,
    path: &Path,
    rows: &[(u64, TelemetryRow)],
) -> Result<(), RecordingError> {
    for (line, row) in rows {
        let gimbal = meta.mount(row.uav) == CameraMount::Gimbal;
        if gimbal != row.gimbal.is_some() {
            return Err(csv_error(
                path,
                *line,
                11,
                "gimbal_yaw_deg",
                if gimbal {
                    format!(
                        "{} has mount = \"gimbal\": its gimbal angles are empty",
                        row.uav.name()
                    )
                } else {
                    format!(
                        "{} has no gimbal: its gimbal angles must be empty",
                        row.uav.name()
                    )
                },
            ));
        }
    }
    Ok(())
}

/// Every image path is inside its UAV's folder and exists; no folder holds other files.
fn check_image_files(
    root: &Path,
    meta: &RecordingMeta,
    telemetry_path: &Path,
    rows: &[(u64, TelemetryRow)],
) -> Result<(), RecordingError> {
    let mut listed: BTreeSet<PathBuf> = BTreeSet::new();
    for (line, row) in rows {
        let folder = &meta.uav(row.uav).frames;
        let rel = Path::new(&row.file);
        let inside = rel.starts_with(folder)
            && rel.components().count() == 2
            && rel.components().all(|c| matches!(c, Component::Normal(_)));
        if !inside {
            return Err(csv_error(
                telemetry_path,
                *line,
                3,
                "file",
                format!(
                    "\"{}\" must be an image directly inside the {} UAV's folder \"{folder}/\"",
                    row.file,
                    row.uav.name()
                ),
            ));
        }
        let ext = rel
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if !matches!(ext.as_deref(), Some("png" | "jpg" | "jpeg")) {
            return Err(csv_error(
                telemetry_path,
                *line,
                3,
                "file",
                format!("\"{}\" is not a .png, .jpg or .jpeg file", row.file),
            ));
        }
        let path = root.join(rel);
        if !path.is_file() {
            return Err(RecordingError::MissingFile { path });
        }
        if !listed.insert(path) {
            return Err(csv_error(
                telemetry_path,
                *line,
                3,
                "file",
                format!("\"{}\" is listed twice", row.file),
            ));
        }
    }
    for uav in [Uav::Left, Uav::Right] {
        let folder = root.join(&meta.uav(uav).frames);
        let entries = std::fs::read_dir(&folder).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => RecordingError::MissingFile {
                path: folder.clone(),
            },
            _ => RecordingError::io(&folder, e),
        })?;
        let mut extra = Vec::new();
        for entry in entries {
            let path = entry.map_err(|e| RecordingError::io(&folder, e))?.path();
            if !listed.contains(&path) {
                extra.push(path);
            }
        }
        if let Some(path) = extra.into_iter().min() {
            return Err(RecordingError::ExtraFile { path });
        }
    }
    Ok(())
}

fn check_no_extra_top_level(root: &Path, meta: &RecordingMeta) -> Result<(), RecordingError> {
    let allowed: BTreeSet<&str> = [
        META_FILE,
        TELEMETRY_FILE,
        TRUTH_FILE,
        TRUTH_TARGETS_FILE,
        &meta.uav.left.frames,
        &meta.uav.right.frames,
    ]
    .into_iter()
    .collect();
    let mut extra = Vec::new();
    for entry in std::fs::read_dir(root).map_err(|e| RecordingError::io(root, e))? {
        let entry = entry.map_err(|e| RecordingError::io(root, e))?;
        let name = entry.file_name();
        if !name.to_str().is_some_and(|n| allowed.contains(n)) {
            extra.push(entry.path());
        }
    }
    match extra.into_iter().min() {
        Some(path) => Err(RecordingError::ExtraFile { path }),
        None => Ok(()),
    }
}

/// truth.csv must have exactly one row per telemetry row (same uav, frame and t_s).
fn align_truth(
    truth_path: &Path,
    telemetry_path: &Path,
    rows: &[(u64, TelemetryRow)],
) -> Result<Vec<TruthRow>, RecordingError> {
    let mut by_key: HashMap<(Uav, u64), (u64, TruthRow)> = HashMap::new();
    for (line, row) in read_truth(truth_path)? {
        by_key.insert((row.uav, row.frame), (line, row));
    }
    let mut aligned = Vec::with_capacity(rows.len());
    for (line, row) in rows {
        let Some((truth_line, truth)) = by_key.remove(&(row.uav, row.frame)) else {
            return Err(csv_error(
                truth_path,
                0,
                0,
                "",
                format!(
                    "no row for {} frame {} (telemetry.csv line {line})",
                    row.uav.name(),
                    row.frame
                ),
            ));
        };
        if truth.t_s != row.t_s {
            return Err(csv_error(
                truth_path,
                truth_line,
                3,
                "t_s",
                format!(
                    "t_s {} differs from telemetry.csv line {line} ({})",
                    truth.t_s, row.t_s
                ),
            ));
        }
        aligned.push(truth);
    }
    if let Some((line, row)) = by_key.into_values().min_by_key(|(line, _)| *line) {
        return Err(csv_error(
            truth_path,
            line,
            0,
            "",
            format!(
                "{} frame {} is not in {}",
                row.uav.name(),
                row.frame,
                telemetry_path.display()
            ),
        ));
    }
    Ok(aligned)
}
