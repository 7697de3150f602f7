//! # detection
//!
//! The `Detector` trait, the classical and ONNX (OpenCV DNN) detectors and the detection
//! service land with issues #4 and #5. Until then this crate only checks that the OpenCV
//! modules it needs are linked.

use opencv::core as cv;

/// The OpenCV version the crate was built against (e.g. "4.6.0").
pub fn opencv_version() -> String {
    format!(
        "{}.{}.{}",
        cv::CV_VERSION_MAJOR,
        cv::CV_VERSION_MINOR,
        cv::CV_VERSION_REVISION
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn built_against_opencv_4() {
        assert!(super::opencv_version().starts_with("4."));
    }
}
