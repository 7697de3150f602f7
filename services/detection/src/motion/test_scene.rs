//! Synthetic frames for the motion detector's tests: a blurred random texture (the
//! ground), moved as a camera would see it, with boxes (vehicles) drawn over it.

use opencv::core as cv;
use opencv::prelude::*;

/// A `width` × `height` BGR texture of grey values 60–186, blurred (σ 1.2 px).
pub fn ground(width: i32, height: i32, seed: u64) -> cv::Mat {
    let mut rng = seed;
    let mut img =
        cv::Mat::new_rows_cols_with_default(height, width, cv::CV_8UC3, 0.into()).unwrap();
    for y in 0..height {
        for x in 0..width {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let v = 60 + (rng >> 58) as u8 * 2;
            *img.at_2d_mut::<cv::Vec3b>(y, x).unwrap() = cv::Vec3b::from([v, v, v]);
        }
    }
    let mut blurred = cv::Mat::default();
    opencv::imgproc::gaussian_blur_def(&img, &mut blurred, cv::Size::new(5, 5), 1.2).unwrap();
    blurred
}

/// `img` moved by (`dx`, `dy`) pixels (its border reflected in).
pub fn shifted(img: &cv::Mat, dx: f64, dy: f64) -> cv::Mat {
    let m = cv::Mat::from_slice_2d(&[[1.0f64, 0.0, dx], [0.0, 1.0, dy]]).unwrap();
    let mut out = cv::Mat::default();
    opencv::imgproc::warp_affine(
        img,
        &mut out,
        &m,
        img.size().unwrap(),
        opencv::imgproc::INTER_LINEAR,
        cv::BORDER_REFLECT,
        cv::Scalar::default(),
    )
    .unwrap();
    out
}

/// A filled box of colour `bgr` over `img`.
pub fn draw_box(img: &mut cv::Mat, rect: cv::Rect, bgr: [f64; 3]) {
    opencv::imgproc::rectangle(
        img,
        rect,
        cv::Scalar::new(bgr[0], bgr[1], bgr[2], 0.0),
        -1,
        opencv::imgproc::LINE_8,
        0,
    )
    .unwrap();
}
