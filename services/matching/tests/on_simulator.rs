//! The chain on rendered frames of the `table1` scenario (no navigation noise).
//! Truth is read by the test only.

use acquisition::sim::{Presets, SimFrame, Simulator};
use detection::{ColourBlobConfig, ColourBlobDetector, Detector};
use geolocation::EstimatorConfig;
use matching::{ChainOutcome, FrameInput, MatchingConfig, VisionChain};
use nalgebra::Point3;
use opencv::core as cv;
use opencv::prelude::*;
use std::collections::HashMap;

#[test]
fn epipolar_transfer_lands_on_the_current_target_in_past_images() {
    let config = Presets::builtin().get("table1").unwrap();
    let (w, h) = (config.camera.width as i32, config.camera.height as i32);
    let mut sim = Simulator::new(config.clone()).unwrap();
    let mut detector = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
    let mut chain =
        VisionChain::new(MatchingConfig::default(), EstimatorConfig::default()).unwrap();
    let mut images = [
        cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0)).unwrap(),
        cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0)).unwrap(),
    ];
    let mut history: HashMap<(usize, u64), SimFrame> = HashMap::new();
    let (mut errors, mut located, mut position_errors, mut true_f_errors) =
        (Vec::new(), 0, Vec::new(), Vec::new());
    let mut k = 0u64;
    while let Some(step) = sim.step() {
        k += 1;
        if !k.is_multiple_of(4) || k > 480 {
            continue;
        }
        {
            let [l, r] = &mut images;
            sim.render_pair(
                &step,
                l.data_bytes_mut().unwrap(),
                r.data_bytes_mut().unwrap(),
                3 * w as usize,
            );
        }
        let mut inputs = Vec::new();
        for (frame, image) in step.frames.iter().zip(&images) {
            history.insert((frame.uav.index(), frame.seq), *frame);
            inputs.push(FrameInput {
                seq: frame.seq,
                t_s: frame.t_s,
                pose: frame.measured,
                image,
                detection: detector.detect(image).unwrap().map(|d| d.centre),
                intrinsics: sim.intrinsics(),
                distortion: sim.distortion(),
                width: w as u32,
                height: h as u32,
            });
        }
        let result = chain.process(&inputs[0], &inputs[1]).unwrap();
        if let ChainOutcome::Located(located_target) = result.outcome {
            let matching::Located { past, filtered, .. } = *located_target;
            located += 1;
            let target = Point3::from(step.frames[0].target);
            for m in past {
                let then = history[&(m.uav.index(), m.seq)];
                let truth = then.view.project(&target).unwrap();
                let e = ((m.pixel[0] - truth[0]).powi(2) + (m.pixel[1] - truth[1]).powi(2)).sqrt();
                // The transfer through the *true* F's isolates the method from F estimation.
                let det = [inputs[0].detection.unwrap(), inputs[1].detection.unwrap()];
                let (fl, fr) = (
                    step.frames[0].view.fundamental_to(&then.view).unwrap(),
                    step.frames[1].view.fundamental_to(&then.view).unwrap(),
                );
                let loose = MatchingConfig {
                    min_line_angle_deg: 0.0,
                    border_px: -1e9,
                    ..Default::default()
                };
                let bounds = matching::epipolar::ImageBounds {
                    intrinsics: &sim.intrinsics(),
                    distortion: &shared_types::lens::Distortion::NONE,
                    width: 640,
                    height: 480,
                };
                if let Ok(p) =
                    matching::epipolar::transfer_point(&fl, det[0], &fr, det[1], &bounds, &loose)
                {
                    true_f_errors
                        .push(((p[0] - truth[0]).powi(2) + (p[1] - truth[1]).powi(2)).sqrt());
                }
                errors.push(e);
            }
            if let Ok(f) = filtered {
                position_errors.push((f.estimate.position - target).norm());
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    position_errors.sort_by(f64::total_cmp);
    true_f_errors.sort_by(f64::total_cmp);
    let true_f_median = true_f_errors[true_f_errors.len() / 2];
    let median = errors[errors.len() / 2];
    eprintln!(
        "{located} geolocations, {} past points: transfer error median {median:.3} px (through the true F: {true_f_median:.3} px), p90 {:.3} px; 3-D error median {:.3} m",
        errors.len(),
        errors[errors.len() * 9 / 10],
        position_errors[position_errors.len() / 2]
    );
    assert!(located >= 60, "only {located} geolocations");
    // The method itself is exact: through the true F's the point lands on the truth.
    assert!(
        true_f_median < 0.5,
        "transfer through the true F: median {true_f_median} px"
    );
    // Issue #4's target: a median of 1.5 px with the estimated F's. Measured 0.48 px
    // with the default `ground_plane` F and guided matching (docs/matching.md); the
    // 5-point E measured 4.2 px here.
    assert!(median <= 1.5, "median transfer error {median} px");
}
