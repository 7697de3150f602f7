//! # matching
//!
//! Keyframe ring buffer, ORB features, fundamental matrices and epipolar transfer
//! (paper Section 2.3, eq. 24–28) land with issue #4. Until then this crate only checks
//! that the OpenCV feature module runs.

#[cfg(test)]
mod tests {
    use opencv::core as cv;
    use opencv::prelude::*;

    #[test]
    fn orb_finds_features_on_scattered_rectangles() {
        let mut img =
            cv::Mat::new_rows_cols_with_default(240, 320, cv::CV_8UC1, cv::Scalar::all(90.0))
                .unwrap();
        // Rectangles at fixed pseudo-random places: each gives four L-corners for FAST.
        let mut state = 12345u32;
        let mut next = |m: u32| {
            state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            (state >> 16) % m
        };
        for _ in 0..40 {
            let (x, y, w, h) = (next(280), next(200), 8 + next(24), 8 + next(24));
            let shade = cv::Scalar::all(if next(2) == 0 { 20.0 } else { 230.0 });
            let rect = cv::Rect::new(x as i32, y as i32, w as i32, h as i32);
            opencv::imgproc::rectangle(&mut img, rect, shade, -1, opencv::imgproc::LINE_8, 0)
                .unwrap();
        }
        let mut orb = opencv::features2d::ORB::create_def().unwrap();
        let mut kps = cv::Vector::<cv::KeyPoint>::new();
        let mut desc = cv::Mat::default();
        orb.detect_and_compute_def(&img, &cv::no_array(), &mut kps, &mut desc)
            .unwrap();
        assert!(kps.len() > 10, "{} keypoints", kps.len());
    }
}
