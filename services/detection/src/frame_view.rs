//! An OpenCV `Mat` header over a frame's pixels where they already are (a shared-memory
//! sample): no copy. Rows must be packed (stride = width × bytes per pixel), which is how
//! acquisition writes them.

use crate::DetectError;
use opencv::core as cv;
use shared_types::messages::{FrameHeader, PixelFormat};
use std::marker::PhantomData;

/// A `Mat` header over borrowed bytes. It only derefs to `&Mat` (never `&mut`), and it
/// cannot outlive the bytes, so OpenCV can only read them.
pub struct FrameMat<'a> {
    mat: cv::Mat,
    _pixels: PhantomData<&'a [u8]>,
}

impl std::ops::Deref for FrameMat<'_> {
    type Target = cv::Mat;
    fn deref(&self) -> &cv::Mat {
        &self.mat
    }
}

/// A read-only `Mat` borrowing `payload`, described by `header`.
pub fn frame_mat<'a>(header: &FrameHeader, payload: &'a [u8]) -> Result<FrameMat<'a>, DetectError> {
    let bad = |why: String| DetectError::BadFrameLayout(why);
    let format = PixelFormat::from_code(header.pixel_format)
        .ok_or_else(|| bad(format!("unknown pixel format {}", header.pixel_format)))?;
    let expected = header
        .payload_len()
        .ok_or_else(|| bad(format!("inconsistent header {header:?}")))?;
    if header.stride != header.width * format.bytes_per_pixel() {
        return Err(bad(format!(
            "rows must be packed: stride {} for width {}",
            header.stride, header.width
        )));
    }
    if payload.len() < expected {
        return Err(bad(format!(
            "payload {} bytes, header says {expected}",
            payload.len()
        )));
    }
    let (rows, cols) = (header.height as i32, header.width as i32);
    let typ = match format {
        PixelFormat::Bgr8 => cv::CV_8UC3,
        PixelFormat::Gray8 => cv::CV_8UC1,
    };
    // SAFETY: `payload` holds `expected` = stride × height bytes (checked above); the
    // Mat does not own them, and `FrameMat` ties its lifetime to the borrow and only
    // exposes `&Mat`, so nothing writes through the pointer.
    let mat = unsafe {
        cv::Mat::new_rows_cols_with_data_unsafe(
            rows,
            cols,
            typ,
            payload.as_ptr().cast_mut().cast(),
            header.stride as usize,
        )
    }?;
    Ok(FrameMat {
        mat,
        _pixels: PhantomData,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use opencv::prelude::*;

    #[test]
    fn mat_points_at_the_payload_without_copying() {
        let header = FrameHeader {
            width: 4,
            height: 2,
            stride: 12,
            pixel_format: PixelFormat::Bgr8 as u32,
            ..Default::default()
        };
        let payload: Vec<u8> = (0..24).collect();
        let mat = frame_mat(&header, &payload).unwrap();
        assert_eq!(mat.data(), payload.as_ptr());
        assert_eq!(
            *mat.at_2d::<cv::Vec3b>(1, 1).unwrap(),
            cv::Vec3b::from([15, 16, 17])
        );
        let short = &payload[..20];
        assert!(frame_mat(&header, short).is_err());
        let padded = FrameHeader {
            stride: 16,
            ..header
        };
        assert!(frame_mat(&padded, &payload).is_err());
    }
}
