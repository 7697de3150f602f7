//! `telemetry.csv` and `truth.csv`: row types, strict parsing (every error names the
//! file, line and column) and writing (floats in Rust's shortest round-trip form, so a
//! recording written and read back is identical).

use super::error::CsvPlace;
use super::RecordingError;
use shared_types::conventions::Uav;
use shared_types::messages::{MountSample, PoseSample};
use std::io::Read;
use std::path::Path;

pub const TELEMETRY_HEADER: [&str; 10] = [
    "uav",
    "frame",
    "file",
    "t_s",
    "x_m",
    "y_m",
    "z_m",
    "yaw_deg",
    "pitch_deg",
    "roll_deg",
];

pub const TRUTH_HEADER: [&str; 14] = [
    "uav",
    "frame",
    "t_s",
    "x_m",
    "y_m",
    "z_m",
    "yaw_deg",
    "pitch_deg",
    "roll_deg",
    "target_x_m",
    "target_y_m",
    "target_z_m",
    "target_u_px",
    "target_v_px",
];

/// Version 2: the headers with the three gimbal columns after the others, for a
/// recording where a UAV has `mount = "gimbal"`.
pub const TELEMETRY_GIMBAL_HEADER: [&str; 13] = with_gimbal_columns(TELEMETRY_HEADER);
pub const TRUTH_GIMBAL_HEADER: [&str; 17] = with_gimbal_columns(TRUTH_HEADER);

/// `header` followed by the gimbal columns (`M` must be `N` + 3: checked when compiled).
const fn with_gimbal_columns<const N: usize, const M: usize>(
    header: [&'static str; N],
) -> [&'static str; M] {
    let mut out = [""; M];
    let mut i = 0;
    while i < N {
        out[i] = header[i];
        i += 1;
    }
    out[N] = "gimbal_yaw_deg";
    out[N + 1] = "gimbal_pitch_deg";
    out[N + 2] = "gimbal_roll_deg";
    assert!(M == N + 3);
    out
}

/// One row of telemetry.csv: the measured state of one image.
#[derive(Debug, Clone, PartialEq)]
pub struct TelemetryRow {
    pub uav: Uav,
    pub frame: u64,
    /// Image path relative to the recording.
    pub file: String,
    pub t_s: f64,
    /// Measured position and attitude of the body (ENU metres, degrees).
    pub pose: PoseSample,
    /// Version 2, `mount = "gimbal"`: the gimbal's measured angles relative to the body
    /// (yaw, pitch, roll in degrees); `None` for other mounts.
    pub gimbal: Option<[f64; 3]>,
}

/// One row of truth.csv: the true state of one image and the true target.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthRow {
    pub uav: Uav,
    pub frame: u64,
    pub t_s: f64,
    pub pose: PoseSample,
    /// The target point (centre of the vehicle's top face), ENU metres.
    pub target: [f64; 3],
    /// Its true pixel in this image; `None` when outside the image.
    pub target_px: Option<[f64; 2]>,
    /// The true gimbal angles (degrees), for `mount = "gimbal"`.
    pub gimbal: Option<[f64; 3]>,
}

/// Reads one CSV row at a time with its place, for error messages.
pub(super) struct Fields<'a> {
    record: &'a csv::StringRecord,
    path: &'a Path,
    pub(super) line: u64,
    header: &'static [&'static str],
}

impl Fields<'_> {
    fn place(&self, column: usize) -> CsvPlace {
        CsvPlace {
            path: self.path.to_path_buf(),
            line: self.line,
            column: column + 1,
            column_name: self.header[column],
        }
    }

    pub(super) fn error(&self, column: usize, message: impl Into<String>) -> RecordingError {
        RecordingError::Csv {
            place: self.place(column),
            message: message.into(),
        }
    }

    pub(super) fn text(&self, column: usize) -> &str {
        self.record.get(column).unwrap_or("")
    }

    pub(super) fn uav(&self, column: usize) -> Result<Uav, RecordingError> {
        match self.text(column) {
            "left" => Ok(Uav::Left),
            "right" => Ok(Uav::Right),
            other => Err(self.error(
                column,
                format!("unknown uav \"{other}\" (expected left or right)"),
            )),
        }
    }

    pub(super) fn frame(&self, column: usize) -> Result<u64, RecordingError> {
        self.text(column).parse().map_err(|_| {
            self.error(
                column,
                format!(
                    "\"{}\" is not a frame index (0, 1, 2, …)",
                    self.text(column)
                ),
            )
        })
    }

    pub(super) fn number(&self, column: usize) -> Result<f64, RecordingError> {
        let text = self.text(column);
        let v: f64 = text
            .parse()
            .map_err(|_| self.error(column, format!("\"{text}\" is not a number")))?;
        if !v.is_finite() {
            return Err(self.error(column, format!("{text} is not finite")));
        }
        Ok(v)
    }

    pub(super) fn optional_number(&self, column: usize) -> Result<Option<f64>, RecordingError> {
        if self.text(column).is_empty() {
            Ok(None)
        } else {
            self.number(column).map(Some)
        }
    }

    /// The three gimbal columns from `first`, if the file has them: all three numbers
    /// or all three empty.
    fn gimbal(&self, first: usize) -> Result<Option<[f64; 3]>, RecordingError> {
        if self.header.len() < first + 3 {
            return Ok(None);
        }
        let v = [
            self.optional_number(first)?,
            self.optional_number(first + 1)?,
            self.optional_number(first + 2)?,
        ];
        match v {
            [Some(y), Some(p), Some(r)] => Ok(Some([y, p, r])),
            [None, None, None] => Ok(None),
            _ => {
                let empty = v.iter().position(Option::is_none).unwrap_or(0);
                Err(self.error(
                    first + empty,
                    "the three gimbal angles must all be given or all be empty",
                ))
            }
        }
    }

    fn pose(&self, first: usize) -> Result<PoseSample, RecordingError> {
        Ok(PoseSample {
            x_m: self.number(first)?,
            y_m: self.number(first + 1)?,
            z_m: self.number(first + 2)?,
            yaw_deg: self.number(first + 3)?,
            pitch_deg: self.number(first + 4)?,
            roll_deg: self.number(first + 5)?,
            mount: MountSample::default(),
        })
    }
}

pub(super) fn open_csv(path: &Path) -> Result<std::io::BufReader<std::fs::File>, RecordingError> {
    let file = std::fs::File::open(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => RecordingError::MissingFile { path: path.into() },
        _ => RecordingError::io(path, e),
    })?;
    Ok(std::io::BufReader::new(file))
}

/// Reads CSV from `input` (errors name `path`), checks that its header is one of
/// `headers` and hands each data row to `row` with its line.
pub(super) fn parse_csv<T>(
    input: impl Read,
    path: &Path,
    headers: &[&'static [&'static str]],
    mut row: impl FnMut(&Fields) -> Result<T, RecordingError>,
) -> Result<Vec<T>, RecordingError> {
    let mut header: &'static [&'static str] = headers[0];
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(input);
    let whole_line = |line: u64, message: String| RecordingError::Csv {
        place: CsvPlace {
            path: path.into(),
            line,
            column: 0,
            column_name: "",
        },
        message,
    };
    let mut out = Vec::new();
    let mut record = csv::StringRecord::new();
    let mut first = true;
    loop {
        let more = reader.read_record(&mut record).map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            whole_line(line, format!("not valid CSV: {e}"))
        })?;
        if !more {
            break;
        }
        let line = record.position().map_or(0, |p| p.line());
        if first {
            first = false;
            match headers.iter().find(|h| record.iter().eq(h.iter().copied())) {
                Some(h) => header = h,
                None => {
                    let expected: Vec<String> = headers.iter().map(|h| h.join(",")).collect();
                    return Err(whole_line(
                        line,
                        format!(
                            "bad or missing header: expected \"{}\"",
                            expected.join("\" or \"")
                        ),
                    ));
                }
            }
            continue;
        }
        if record.len() != header.len() {
            return Err(whole_line(
                line,
                format!("{} fields, the header has {}", record.len(), header.len()),
            ));
        }
        out.push(row(&Fields {
            record: &record,
            path,
            line,
            header,
        })?);
    }
    if first {
        return Err(whole_line(1, "empty file: bad or missing header".into()));
    }
    Ok(out)
}

/// Each UAV's rows must start at frame 0 and increase in `frame` and `t_s`.
struct Monotonic {
    last: [Option<(u64, f64)>; 2],
}

impl Monotonic {
    fn new() -> Self {
        Self { last: [None; 2] }
    }

    fn check(
        &mut self,
        f: &Fields,
        uav: Uav,
        frame: u64,
        t_s: f64,
        frame_col: usize,
        t_col: usize,
    ) -> Result<(), RecordingError> {
        match self.last[uav.index()] {
            None if frame != 0 => {
                return Err(f.error(
                    frame_col,
                    format!("the first {} frame must be 0, got {frame}", uav.name()),
                ))
            }
            Some((last_frame, _)) if frame <= last_frame => {
                return Err(f.error(
                    frame_col,
                    format!(
                        "{} frame {frame} does not increase (previous {last_frame})",
                        uav.name()
                    ),
                ))
            }
            Some((_, last_t)) if t_s <= last_t => {
                return Err(f.error(
                    t_col,
                    format!(
                        "{} timestamp {t_s} does not increase (previous {last_t})",
                        uav.name()
                    ),
                ))
            }
            _ => {}
        }
        self.last[uav.index()] = Some((frame, t_s));
        Ok(())
    }
}

/// Rows of telemetry.csv with their line numbers.
pub fn read_telemetry(path: &Path) -> Result<Vec<(u64, TelemetryRow)>, RecordingError> {
    parse_telemetry(open_csv(path)?, path)
}

/// Rows of telemetry.csv read from `input`, errors naming `path` (the fuzz targets'
/// entry point: no file needed).
pub fn parse_telemetry(
    input: impl Read,
    path: &Path,
) -> Result<Vec<(u64, TelemetryRow)>, RecordingError> {
    let mut order = Monotonic::new();
    let headers: [&'static [&'static str]; 2] = [&TELEMETRY_HEADER, &TELEMETRY_GIMBAL_HEADER];
    parse_csv(input, path, &headers, |f| {
        let uav = f.uav(0)?;
        let frame = f.frame(1)?;
        let file = f.text(2).to_string();
        if file.is_empty() {
            return Err(f.error(2, "empty image path"));
        }
        let t_s = f.number(3)?;
        let pose = f.pose(4)?;
        let gimbal = f.gimbal(10)?;
        order.check(f, uav, frame, t_s, 1, 3)?;
        Ok((
            f.line,
            TelemetryRow {
                uav,
                frame,
                file,
                t_s,
                pose,
                gimbal,
            },
        ))
    })
}

/// Rows of truth.csv with their line numbers.
pub fn read_truth(path: &Path) -> Result<Vec<(u64, TruthRow)>, RecordingError> {
    parse_truth(open_csv(path)?, path)
}

/// Rows of truth.csv read from `input`, errors naming `path`.
pub fn parse_truth(input: impl Read, path: &Path) -> Result<Vec<(u64, TruthRow)>, RecordingError> {
    let mut order = Monotonic::new();
    let headers: [&'static [&'static str]; 2] = [&TRUTH_HEADER, &TRUTH_GIMBAL_HEADER];
    parse_csv(input, path, &headers, |f| {
        let uav = f.uav(0)?;
        let frame = f.frame(1)?;
        let t_s = f.number(2)?;
        let pose = f.pose(3)?;
        order.check(f, uav, frame, t_s, 1, 2)?;
        let target = [f.number(9)?, f.number(10)?, f.number(11)?];
        let target_px = match (f.optional_number(12)?, f.optional_number(13)?) {
            (Some(u), Some(v)) => Some([u, v]),
            (None, None) => None,
            (Some(_), None) => {
                return Err(f.error(13, "target_v_px is empty but target_u_px is not"))
            }
            (None, Some(_)) => {
                return Err(f.error(12, "target_u_px is empty but target_v_px is not"))
            }
        };
        let gimbal = f.gimbal(14)?;
        Ok((
            f.line,
            TruthRow {
                uav,
                frame,
                t_s,
                pose,
                target,
                target_px,
                gimbal,
            },
        ))
    })
}

fn pose_fields(p: &PoseSample) -> [String; 6] {
    [p.x_m, p.y_m, p.z_m, p.yaw_deg, p.pitch_deg, p.roll_deg].map(|v| v.to_string())
}

/// The gimbal columns of a row of a file that has them (empty for a UAV without a
/// gimbal).
fn gimbal_fields(gimbal: Option<[f64; 3]>) -> [String; 3] {
    gimbal.map_or_else(Default::default, |g| g.map(|v| v.to_string()))
}

/// A telemetry.csv record; `gimbal_columns` when the file has them.
pub(crate) fn telemetry_record(row: &TelemetryRow, gimbal_columns: bool) -> Vec<String> {
    let mut r = vec![
        row.uav.name().to_string(),
        row.frame.to_string(),
        row.file.clone(),
        row.t_s.to_string(),
    ];
    r.extend(pose_fields(&row.pose));
    if gimbal_columns {
        r.extend(gimbal_fields(row.gimbal));
    }
    r
}

/// A truth.csv record; `gimbal_columns` when the file has them.
pub(crate) fn truth_record(row: &TruthRow, gimbal_columns: bool) -> Vec<String> {
    let mut r = vec![
        row.uav.name().to_string(),
        row.frame.to_string(),
        row.t_s.to_string(),
    ];
    r.extend(pose_fields(&row.pose));
    r.extend(row.target.iter().map(|v| v.to_string()));
    match row.target_px {
        Some([u, v]) => r.extend([u.to_string(), v.to_string()]),
        None => r.extend([String::new(), String::new()]),
    }
    if gimbal_columns {
        r.extend(gimbal_fields(row.gimbal));
    }
    r
}

/// The headers of telemetry.csv and truth.csv, with or without the gimbal columns.
pub fn headers(gimbal_columns: bool) -> (&'static [&'static str], &'static [&'static str]) {
    if gimbal_columns {
        (&TELEMETRY_GIMBAL_HEADER, &TRUTH_GIMBAL_HEADER)
    } else {
        (&TELEMETRY_HEADER, &TRUTH_HEADER)
    }
}
