//! Errors of the recording reader and writer. Each names the file, and for CSV the line
//! and column, so a user can fix their conversion script.

use std::path::PathBuf;
use thiserror::Error;

/// Where in a CSV file a problem is: 1-based line and the column's name and number.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CsvPlace {
    pub path: PathBuf,
    pub line: u64,
    /// 1-based column number and header name; 0 and "" when the whole line is at fault.
    pub column: usize,
    pub column_name: &'static str,
}

impl std::fmt::Display for CsvPlace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.path.display())?;
        if self.line > 0 {
            write!(f, " line {}", self.line)?;
        }
        if self.column > 0 {
            write!(f, ", column {} ({})", self.column, self.column_name)?;
        }
        Ok(())
    }
}

#[derive(Debug, Error)]
pub enum RecordingError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: required file is missing")]
    MissingFile { path: PathBuf },
    #[error("{path}: unexpected file in the recording (not listed in telemetry.csv / not part of format v1)")]
    ExtraFile { path: PathBuf },
    #[error("{path}: {message}")]
    Metadata { path: PathBuf, message: String },
    #[error("{place}: {message}")]
    Csv { place: CsvPlace, message: String },
    #[error(
        "{path}: image is {got_width}x{got_height}, recording.toml says {want_width}x{want_height}"
    )]
    ImageSize {
        path: PathBuf,
        want_width: u32,
        want_height: u32,
        got_width: u32,
        got_height: u32,
    },
    #[error("{path}: unreadable image: {reason}")]
    ImageUnreadable { path: PathBuf, reason: String },
    #[error("{path}: {message}")]
    Write { path: PathBuf, message: String },
}

impl RecordingError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        RecordingError::Io {
            path: path.into(),
            source,
        }
    }
}
