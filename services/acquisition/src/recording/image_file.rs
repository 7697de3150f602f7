//! Reading one image of a recording: PNG or JPEG, 8-bit grey or BGR, of the size
//! recording.toml gives. Truncated files are caught by their missing end marker
//! (libjpeg would otherwise pad a truncated JPEG with grey and call it a success), and a
//! header declaring another size is refused before the decoder allocates anything
//! ([`super::image_header`]).

use super::RecordingError;
use opencv::core as cv;
use opencv::prelude::*;
use std::path::Path;

use super::image_header::PNG_SIGNATURE;
const PNG_IEND: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xae, 0x42, 0x60, 0x82];

fn unreadable(path: &Path, reason: impl Into<String>) -> RecordingError {
    RecordingError::ImageUnreadable {
        path: path.into(),
        reason: reason.into(),
    }
}

/// Checks the container's start and end markers and the size its header declares.
fn check_container(
    path: &Path,
    bytes: &[u8],
    width: u32,
    height: u32,
) -> Result<(), RecordingError> {
    check_markers(path, bytes)?;
    let got = super::image_header::declared_size(bytes).map_err(|e| unreadable(path, e))?;
    same_size(path, got, (width, height))
}

/// An image of `got` size where recording.toml says `want`.
fn same_size(path: &Path, got: (u32, u32), want: (u32, u32)) -> Result<(), RecordingError> {
    if got == want {
        return Ok(());
    }
    Err(RecordingError::ImageSize {
        path: path.into(),
        want_width: want.0,
        want_height: want.1,
        got_width: got.0,
        got_height: got.1,
    })
}

/// Checks the container's start and end markers.
fn check_markers(path: &Path, bytes: &[u8]) -> Result<(), RecordingError> {
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

/// The decoded image must have the size recording.toml gives.
fn check_size(
    path: &Path,
    mat: &impl MatTraitConst,
    width: u32,
    height: u32,
) -> Result<(), RecordingError> {
    same_size(
        path,
        (mat.cols() as u32, mat.rows() as u32),
        (width, height),
    )
}

fn read_file(path: &Path) -> Result<Vec<u8>, RecordingError> {
    std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => RecordingError::MissingFile { path: path.into() },
        _ => RecordingError::io(path, e),
    })
}

/// Reads and decodes an image file as 8-bit BGR straight into `dst` (packed rows,
/// `width × height × 3` bytes: a loaned shared-memory sample), without an intermediate
/// image. Grey images are expanded to BGR. Checks the container and the size.
pub fn decode_image_into(
    path: &Path,
    width: u32,
    height: u32,
    dst: &mut [u8],
) -> Result<(), RecordingError> {
    decode_bytes_into(&read_file(path)?, path, width, height, dst)
}

/// [`decode_image_into`] of a file's bytes already in memory (errors name `path`).
pub fn decode_bytes_into(
    bytes: &[u8],
    path: &Path,
    width: u32,
    height: u32,
    dst: &mut [u8],
) -> Result<(), RecordingError> {
    check_container(path, bytes, width, height)?;
    let expected = width as usize * height as usize * 3;
    if dst.len() != expected {
        return Err(unreadable(
            path,
            format!(
                "destination holds {} bytes, a BGR frame needs {expected}",
                dst.len()
            ),
        ));
    }
    let dst_ptr = dst.as_ptr();
    let mut mat =
        cv::Mat::new_rows_cols_with_bytes_mut::<cv::Vec3b>(height as i32, width as i32, dst)
            .map_err(|e| unreadable(path, e.message))?;
    let buf = cv::Vector::<u8>::from_slice(bytes);
    opencv::imgcodecs::imdecode_to(&buf, opencv::imgcodecs::IMREAD_COLOR, &mut mat)
        .map_err(|e| unreadable(path, e.message))?;
    if mat.empty() {
        return Err(unreadable(
            path,
            "the decoder could not read it (corrupt data)",
        ));
    }
    check_size(path, &mat, width, height)?;
    // Same size and type: OpenCV wrote into our buffer (any other size would have made
    // it allocate its own, which `check_size` has ruled out).
    if mat.data() != dst_ptr {
        return Err(unreadable(
            path,
            "the decoder did not write into the frame buffer",
        ));
    }
    Ok(())
}

/// Reads and decodes an image file, checking format, depth, channels and size.
pub fn decode_image(path: &Path, width: u32, height: u32) -> Result<cv::Mat, RecordingError> {
    let bytes = read_file(path)?;
    check_container(path, &bytes, width, height)?;
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
    check_size(path, &mat, width, height)?;
    Ok(mat)
}

#[cfg(test)]
mod decode_into_tests {
    use super::*;

    fn png(width: i32, height: i32) -> Vec<u8> {
        let mut m =
            cv::Mat::new_rows_cols_with_default(height, width, cv::CV_8UC3, cv::Scalar::all(0.0))
                .unwrap();
        for (i, b) in m.data_bytes_mut().unwrap().iter_mut().enumerate() {
            *b = (i % 251) as u8;
        }
        let mut out = cv::Vector::<u8>::new();
        opencv::imgcodecs::imencode_def(".png", &m, &mut out).unwrap();
        out.to_vec()
    }

    #[test]
    fn decodes_in_place_and_rejects_a_wrong_size() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        std::fs::write(&path, png(8, 4)).unwrap();
        let mut dst = vec![0u8; 8 * 4 * 3];
        decode_image_into(&path, 8, 4, &mut dst).unwrap();
        assert!(dst.iter().enumerate().all(|(i, &b)| b == (i % 251) as u8));

        std::fs::write(&path, png(6, 4)).unwrap();
        let e = decode_image_into(&path, 8, 4, &mut dst).unwrap_err();
        assert!(
            matches!(e, RecordingError::ImageSize { got_width: 6, .. }),
            "{e}"
        );

        let mut bytes = png(8, 4);
        bytes.truncate(bytes.len() - 20);
        std::fs::write(&path, bytes).unwrap();
        let e = decode_image_into(&path, 8, 4, &mut dst)
            .unwrap_err()
            .to_string();
        assert!(e.contains("a.png") && e.contains("truncated"), "{e}");
    }
}
