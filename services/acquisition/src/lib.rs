//! # acquisition
//!
//! Frame sources for the pipeline: the recording reader/writer (docs/recording-format.md)
//! and the simulator land with issue #3, the service binary with issue #5. Until then
//! this crate holds only what they will share.

#[cfg(test)]
mod tests {
    use opencv::core as cv;
    use opencv::prelude::*;

    #[test]
    fn opencv_png_codec_round_trips() {
        let img =
            cv::Mat::new_rows_cols_with_default(8, 12, cv::CV_8UC1, cv::Scalar::all(77.0)).unwrap();
        let mut buf = cv::Vector::<u8>::new();
        assert!(opencv::imgcodecs::imencode_def(".png", &img, &mut buf).unwrap());
        let back = opencv::imgcodecs::imdecode(&buf, opencv::imgcodecs::IMREAD_UNCHANGED).unwrap();
        assert_eq!((back.rows(), back.cols()), (8, 12));
        assert_eq!(*back.at_2d::<u8>(3, 5).unwrap(), 77);
    }
}
