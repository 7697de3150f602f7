//! What a live source streamed, in the recording format's CSV layouts: `telemetry.csv`
//! (the measured poses the pipeline saw) and `truth.csv` (the simulator's truth, for
//! evaluation only). The `file` column says `live` because no image file exists.

use super::rows::{telemetry_record, truth_record};
use super::{
    RecordingError, TelemetryRow, TruthRow, TELEMETRY_FILE, TELEMETRY_HEADER, TRUTH_FILE,
    TRUTH_HEADER,
};
use std::fs::File;
use std::path::{Path, PathBuf};

pub struct StreamLog {
    dir: PathBuf,
    telemetry: csv::Writer<File>,
    truth: csv::Writer<File>,
}

fn err(path: &Path, e: impl std::fmt::Display) -> RecordingError {
    RecordingError::Write {
        path: path.into(),
        message: e.to_string(),
    }
}

impl StreamLog {
    /// Creates `dir` (if needed) with the two CSV files and their headers.
    pub fn create(dir: &Path) -> Result<Self, RecordingError> {
        std::fs::create_dir_all(dir).map_err(|e| RecordingError::io(dir, e))?;
        let open = |name: &str, header: &[&str]| -> Result<csv::Writer<File>, RecordingError> {
            let path = dir.join(name);
            let mut w = csv::Writer::from_path(&path).map_err(|e| err(&path, e))?;
            w.write_record(header).map_err(|e| err(&path, e))?;
            Ok(w)
        };
        Ok(Self {
            dir: dir.to_path_buf(),
            telemetry: open(TELEMETRY_FILE, &TELEMETRY_HEADER)?,
            truth: open(TRUTH_FILE, &TRUTH_HEADER)?,
        })
    }

    /// Opens the two files of `dir` to add rows after what a previous (killed)
    /// acquisition wrote; creates them with their headers when they are not there.
    pub fn reopen(dir: &Path) -> Result<Self, RecordingError> {
        if !dir.join(TELEMETRY_FILE).is_file() || !dir.join(TRUTH_FILE).is_file() {
            return Self::create(dir);
        }
        let open = |name: &str| -> Result<csv::Writer<File>, RecordingError> {
            let path = dir.join(name);
            let file = std::fs::OpenOptions::new()
                .append(true)
                .open(&path)
                .map_err(|e| RecordingError::io(&path, e))?;
            Ok(csv::Writer::from_writer(file))
        };
        Ok(Self {
            dir: dir.to_path_buf(),
            telemetry: open(TELEMETRY_FILE)?,
            truth: open(TRUTH_FILE)?,
        })
    }

    /// Writes what is buffered (after every pair: a killed acquisition loses no row of
    /// a pair it sent).
    pub fn flush(&mut self) -> Result<(), RecordingError> {
        self.telemetry
            .flush()
            .map_err(|e| err(&self.dir.join(TELEMETRY_FILE), e))?;
        self.truth
            .flush()
            .map_err(|e| err(&self.dir.join(TRUTH_FILE), e))
    }

    pub fn append(
        &mut self,
        telemetry: &TelemetryRow,
        truth: &TruthRow,
    ) -> Result<(), RecordingError> {
        self.telemetry
            .write_record(telemetry_record(telemetry, false))
            .map_err(|e| err(&self.dir.join(TELEMETRY_FILE), e))?;
        self.truth
            .write_record(truth_record(truth, false))
            .map_err(|e| err(&self.dir.join(TRUTH_FILE), e))
    }

    /// Flushes both files.
    pub fn finish(mut self) -> Result<(), RecordingError> {
        self.flush()
    }
}
