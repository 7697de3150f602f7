//! The classical detector on the `default` scenario, scored against truth.csv's pixel
//! (truth is read here, by the test, never by the detector).

use acquisition::sim::{Presets, Simulator};
use detection::{ColourBlobConfig, ColourBlobDetector, Detector};
use opencv::core as cv;
use opencv::prelude::*;

#[test]
fn detects_the_vehicle_on_the_default_scenario() {
    let config = Presets::builtin().get("default").unwrap();
    let (w, h) = (config.camera.width as i32, config.camera.height as i32);
    let mut sim = Simulator::new(config).unwrap();
    let mut detector = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
    let mut left =
        cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0)).unwrap();
    let mut right = left.clone();
    let (mut frames, mut found, mut errors) = (0usize, 0usize, Vec::new());
    let mut k = 0;
    while let Some(step) = sim.step() {
        k += 1;
        if k % 4 != 0 {
            continue;
        }
        sim.render_pair(
            &step,
            left.data_bytes_mut().unwrap(),
            right.data_bytes_mut().unwrap(),
            3 * w as usize,
        );
        for (frame, image) in step.frames.iter().zip([&left, &right]) {
            let Some(truth) = frame.target_px else {
                continue;
            };
            frames += 1;
            if let Some(d) = detector.detect(image).unwrap() {
                found += 1;
                errors.push(
                    ((d.centre[0] - truth[0]).powi(2) + (d.centre[1] - truth[1]).powi(2)).sqrt(),
                );
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    let rate = found as f64 / frames as f64;
    let median = errors[errors.len() / 2];
    let p95 = errors[errors.len() * 95 / 100];
    eprintln!("detection rate {:.2}% of {frames} frames; centre error median {median:.3} px, p95 {p95:.3} px, max {:.3} px", 100.0 * rate, errors[errors.len() - 1]);
    assert!(frames >= 500);
    assert!(rate >= 0.99, "detection rate {rate}");
    assert!(median <= 1.5, "median centre error {median} px");
}
