//! Lens distortion honoured end to end (issue #12): `suite_wide_lens` renders a strong
//! barrel lens (k1 = −0.25, 1280×720, 80°) into the pixels; `suite_wide_pinhole` is the
//! same scene through a pinhole. The chain, told the lens, must locate the target as
//! often and as accurately as on the pinhole twin (within 10 %), and told nothing
//! (the old behaviour) must do clearly worse: the control that shows the test can fail.
//! No navigation noise (the Table 1 protocol): the difference is the lens alone.
//! Truth is read by the test only.

#[path = "support/render.rs"]
mod render;

use acquisition::sim::{Presets, Simulator};
use detection::{ColourBlobConfig, ColourBlobDetector};
use geolocation::{EstimatorConfig, EstimatorMethod, NoiseModel};
use matching::{ChainOutcome, MatchingConfig, VisionChain};
use nalgebra::Point3;
use shared_types::lens::Distortion;

/// Located pairs, pairs tried, and the median 3-D error of the paper's filtered
/// estimate, over every 3rd pair of the first 14 s, after 6 s of warm-up.
fn run(preset: &str, tell_the_lens: bool) -> (usize, usize, f64) {
    let mut config = Presets::builtin().get(preset).unwrap();
    config.duration_s = 14.0;
    config.noise = shared_types::nav_noise::NavNoise::NONE;
    config.bias = shared_types::nav_noise::BiasModel::NONE;
    let mut sim = Simulator::new(config).unwrap();
    let lens = if tell_the_lens {
        sim.distortion()
    } else {
        Distortion::NONE
    };
    let mut detector = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
    let estimator = EstimatorConfig {
        noise_left: NoiseModel::isotropic(0.05, 0.05, 1.0),
        noise_right: NoiseModel::isotropic(0.05, 0.05, 1.0),
        method: EstimatorMethod::Paper,
        ..EstimatorConfig::default()
    };
    let mut chain = VisionChain::new(MatchingConfig::default(), estimator).unwrap();
    let mut images = render::blank_pair(&sim);
    let (mut tried, mut errors) = (0, Vec::new());
    let mut k = 0u64;
    while let Some(step) = sim.step() {
        k += 1;
        if !k.is_multiple_of(3) {
            continue;
        }
        let inputs = render::inputs(&mut sim, &step, &mut images, &mut detector, true, lens);
        let result = chain.process(&inputs[0], &inputs[1]).unwrap();
        if step.frames[0].t_s < 6.0 {
            continue;
        }
        tried += 1;
        if let ChainOutcome::Located(located) = result.outcome {
            if let Ok(f) = located.filtered {
                let target = Point3::from(step.frames[0].target);
                errors.push((f.estimate.position - target).norm());
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    let median = errors
        .get(errors.len() / 2)
        .copied()
        .unwrap_or(f64::INFINITY);
    (errors.len(), tried, median)
}

#[test]
fn a_distorted_camera_locates_like_its_pinhole_twin() {
    // The three flights are independent: flown side by side on the cores.
    let [(pin_n, pin_tried, pin_err), (lens_n, lens_tried, lens_err), (raw_n, _, raw_err)] =
        std::thread::scope(|s| {
            [
                ("suite_wide_pinhole", true),
                ("suite_wide_lens", true),
                ("suite_wide_lens", false),
            ]
            .map(|(preset, tell)| s.spawn(move || run(preset, tell)))
            .map(|h| h.join().expect("flight thread"))
        });
    eprintln!(
        "pinhole: {pin_n}/{pin_tried} located, median error {pin_err:.3} m; \
         distorted, undistorted by matching: {lens_n}/{lens_tried}, {lens_err:.3} m; \
         distorted, lens ignored: {raw_n}/{lens_tried}, {raw_err:.3} m"
    );
    assert!(
        pin_n * 10 >= pin_tried * 8,
        "pinhole twin located {pin_n}/{pin_tried}"
    );
    assert!(
        lens_n * 10 >= pin_n * 9,
        "distorted located {lens_n} vs pinhole {pin_n}"
    );
    // Within 10 %, or within 2 cm where both are a few centimetres.
    assert!(
        lens_err <= pin_err * 1.1 || lens_err <= pin_err + 0.02,
        "distorted median error {lens_err} m vs pinhole {pin_err} m"
    );
    // The control: ignoring the lens loses geolocations or accuracy.
    assert!(
        raw_n * 10 < lens_n * 9 || raw_err > 2.0 * lens_err,
        "ignoring the lens did not hurt: {raw_n} located, {raw_err} m"
    );
}
