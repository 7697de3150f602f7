//! Reading one image of a recording: PNG or JPEG, 8-bit grey or BGR, of the size
//! recording.toml gives. Truncated files are caught by their missing end marker
//! (libjpeg would otherwise pad a truncated JPEG with grey and call it a success).

use super::RecordingError;
use opencv::core as cv;
use opencv::prelude::*;
use std::path::Path;

const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
const PNG_IEND: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xae, 0x42, 0x60, 0x82];

fn unreadable(path: &Path, reason: impl Into<String>) -> RecordingError {
    RecordingError::ImageUnreadable {
        path: path.into(),
        reason: reason.into(),
    }
}

/// Checks the container's start and end markers.
fn check_container(path: &Path, bytes: &[u8]) -> Result<(), RecordingError> {
    if bytes.starts_with(&PNG_SIGNATURE) {
        if !bytes.ends_with(&PNG_IEND) {
            return Err(unreadable(path, "truncated PNG (no IEND chunk at the end)"));
        }
        return Ok(());
    }
    if bytes.starts_with(&[0xff, 0xd8]) {
        // Allow padding after the end-of-image marker, as some encoders write it.
        let end = bytes.iter().rposition(|&b| b != 0).unwrap_or(0);
        if end < 1 || bytes[end - 1..=end] != [0xff, 0xd9] {
            return Err(unreadable(path, "truncated JPEG (no end-of-image marker)"));
        }
        return Ok(());
    }
    Err(unreadable(path, "neither PNG nor JPEG"))
}

/// Reads and decodes an image file, checking format, depth, channels and size.
pub fn decode_image(path: &Path, width: u32, height: u32) -> Result<cv::Mat, RecordingError> {
    let bytes = std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => RecordingError::MissingFile { path: path.into() },
        _ => RecordingError::io(path, e),
    })?;
    check_container(path, &bytes)?;
    let buf = cv::Vector::<u8>::from_slice(&bytes);
    let mat = opencv::imgcodecs::imdecode(&buf, opencv::imgcodecs::IMREAD_UNCHANGED)
        .map_err(|e| unreadable(path, e.message))?;
    if mat.empty() {
        return Err(unreadable(
            path,
            "the decoder could not read it (corrupt data)",
        ));
    }
    if mat.depth() != cv::CV_8U || !(mat.channels() == 1 || mat.channels() == 3) {
        return Err(unreadable(
            path,
            format!(
                "must be 8-bit grey or BGR, got depth {} with {} channels",
                mat.depth(),
                mat.channels()
            ),
        ));
    }
    let (got_width, got_height) = (mat.cols() as u32, mat.rows() as u32);
    if (got_width, got_height) != (width, height) {
        return Err(RecordingError::ImageSize {
            path: path.into(),
            want_width: width,
            want_height: height,
            got_width,
            got_height,
        });
    }
    Ok(mat)
}
