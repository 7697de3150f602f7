//! The motion detector on rendered flights, scored against the simulator's truth pixel
//! (read here, by the test, never by the detector).

use acquisition::sim::{Presets, Simulator};
use detection::motion::{MotionConfig, MotionDetector};
use opencv::core as cv;
use opencv::prelude::*;

struct Score {
    looked: usize,
    hits: usize,
    wrong: usize,
    errors: Vec<f64>,
}

/// Runs the motion detector on both cameras of `preset` for `seconds`; with
/// `designate`, the test plays the operator and points at the target when the detector
/// first looks.
fn run(preset: &str, seconds: f64, designate: bool) -> Score {
    let mut config = Presets::builtin().get(preset).unwrap();
    config.duration_s = seconds;
    let (w, h) = (config.camera.width as i32, config.camera.height as i32);
    let mut sim = Simulator::new(config).unwrap();
    let mut detector = MotionDetector::new(MotionConfig::default()).unwrap();
    let warm_up = 2 * MotionConfig::default().short_gap_frames as usize;
    let blank = || cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0));
    let mut frames = [blank().unwrap(), blank().unwrap()];
    let mut score = Score {
        looked: 0,
        hits: 0,
        wrong: 0,
        errors: Vec::new(),
    };
    let mut k = 0;
    while let Some(step) = sim.step() {
        let [l, r] = &mut frames;
        sim.render_pair(
            &step,
            l.data_bytes_mut().unwrap(),
            r.data_bytes_mut().unwrap(),
            3 * w as usize,
        );
        for (camera, image) in frames.iter().enumerate() {
            let truth = step.frames[camera].target_px;
            if designate && k == warm_up {
                detector.designate(camera, truth.unwrap());
            }
            let found = detector.detect(camera, image, None).unwrap();
            if k < warm_up {
                continue;
            }
            score.looked += 1;
            match (found, truth) {
                (Some(d), Some(t)) if (d.centre[0] - t[0]).hypot(d.centre[1] - t[1]) <= 8.0 => {
                    score.hits += 1;
                    score
                        .errors
                        .push((d.centre[0] - t[0]).hypot(d.centre[1] - t[1]));
                }
                (Some(_), _) => score.wrong += 1,
                (None, _) => {}
            }
        }
        k += 1;
    }
    score.errors.sort_by(f64::total_cmp);
    score
}

#[test]
fn a_silver_car_is_followed_past_parked_cars_of_its_colour() {
    // Two parked silver cars at the kerb ahead, a blue car and a white one moving.
    let s = run("silver_parked", 8.0, true);
    let recall = s.hits as f64 / s.looked as f64;
    let wrong = s.wrong as f64 / s.looked as f64;
    let median = s.errors[s.errors.len() / 2];
    eprintln!("silver_parked: recall {recall:.3}, wrong {wrong:.3}, median error {median:.2} px");
    assert!(recall >= 0.85, "recall {recall}");
    // Measured 3.2 %: above the 1 % the detector aims for (docs/matching.md).
    assert!(wrong <= 0.05, "wrong {wrong}");
    assert!(median <= 2.0, "median centre error {median} px");
}

#[test]
fn without_a_designation_a_camera_pointing_at_the_target_acquires_it() {
    // The tracking gimbal keeps the red car near the centre; traffic moves around it.
    let s = run("gimbal", 6.0, false);
    let recall = s.hits as f64 / s.looked as f64;
    let wrong = s.wrong as f64 / s.looked as f64;
    eprintln!("gimbal: recall {recall:.3}, wrong {wrong:.3}");
    assert!(recall >= 0.75, "recall {recall}");
    assert!(wrong <= 0.06, "wrong {wrong}");
}
