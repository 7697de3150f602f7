//! Recording format, version 1 (`docs/recording-format.md`): a reader that validates
//! strictly and a writer whose output reads back identically.

mod error;
mod image_file;
mod image_header;
mod meta;
mod reader;
pub(crate) mod rows;
mod stream_log;
mod targets_truth;
mod writer;

pub use error::{CsvPlace, RecordingError};
pub use image_file::{decode_bytes_into, decode_image, decode_image_into};
pub use image_header::declared_size;
pub use meta::{
    CameraMeta, CameraMount, MountAngles, Origin, RecordingMeta, UavMeta, UavPair, FORMAT_NAME,
    FORMAT_VERSION,
};
pub use reader::{camera_pose, Recording, StereoPair};
pub use rows::{
    parse_telemetry, parse_truth, read_telemetry, read_truth, TelemetryRow, TruthRow,
    TELEMETRY_HEADER, TRUTH_HEADER,
};
pub use stream_log::StreamLog;
pub use targets_truth::{
    parse_targets_truth, read_targets_truth, TargetTruthRow, TargetsTruthWriter,
    TRUTH_TARGETS_HEADER,
};
pub use writer::{ImageEncoding, RecordingWriter, TruthSample};

pub const META_FILE: &str = "recording.toml";
pub const TELEMETRY_FILE: &str = "telemetry.csv";
pub const TRUTH_FILE: &str = "truth.csv";
/// Every moving vehicle's truth (optional, for multi-target evaluation; the
/// simulator writes it for a scene with moving traffic, `dualgeo score` reads it).
pub const TRUTH_TARGETS_FILE: &str = "truth_targets.csv";
