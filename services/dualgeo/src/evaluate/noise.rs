//! The noise passes: each scenario's navigation noise and yaw biases applied to the
//! vision pass's matched sets, then the paper's method, the joint estimator and
//! one-shot on them.
//!
//! An image's measured pose is a function of (scenario seed, UAV, frame) only, so a
//! keyframe used by many geolocations carries the same error in all of them, as in
//! flight. Measured = true + N(0, σ) per axis; yaw also + the bias of eq. (34) (or
//! the scenario's constant bias), exactly as the simulator does. The estimator is told
//! the scenario's σ's (its Q of eq. 8), with σ_px = 1.

use super::vision::{ImageRef, Record};
use acquisition::sim::SimConfig;
use geolocation::evaluation::ErrorStats;
use geolocation::{
    geolocate_configured, geolocate_filtered, one_shot, EstimatorConfig, EstimatorMethod,
    NoiseModel, Observation,
};
use nalgebra::Vector2;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use shared_types::conventions::wrap_angle;
use shared_types::messages::PoseSample;

/// Errors of one method over one scenario (estimate − truth).
#[derive(Debug, Default, Clone)]
pub struct MethodErrors {
    pub xyz: [Vec<f64>; 3],
    pub distance: Vec<f64>,
    /// Degrees (estimate − truth, wrapped).
    pub bias: [Vec<f64>; 2],
    pub rejected: usize,
}

impl MethodErrors {
    fn push(
        &mut self,
        p: nalgebra::Point3<f64>,
        truth: nalgebra::Point3<f64>,
        bias: Option<([f64; 2], [f64; 2])>,
    ) {
        let d = p - truth;
        (0..3).for_each(|i| self.xyz[i].push(d[i]));
        self.distance.push(d.norm());
        if let Some((est, tru)) = bias {
            for i in 0..2 {
                self.bias[i].push(wrap_angle(est[i] - tru[i]).to_degrees());
            }
        }
    }

    pub fn stats_xyz(&self) -> [ErrorStats; 4] {
        [
            ErrorStats::from_errors(&self.xyz[0]),
            ErrorStats::from_errors(&self.xyz[1]),
            ErrorStats::from_errors(&self.xyz[2]),
            ErrorStats::from_errors(&self.distance),
        ]
    }

    pub fn stats_bias(&self) -> [ErrorStats; 2] {
        [
            ErrorStats::from_errors(&self.bias[0]),
            ErrorStats::from_errors(&self.bias[1]),
        ]
    }
}

/// Everything one scenario gives, for one N.
#[derive(Debug, Default, Clone)]
pub struct ScenarioResult {
    pub paper: MethodErrors,
    pub joint: MethodErrors,
    pub one_shot: MethodErrors,
    /// Table 4: k → (|δψ_L|, |δψ_R|, |z|) errors after k iterations (paper's method).
    pub by_iterations: Vec<(usize, MethodErrors)>,
}

pub const TABLE4_K: [usize; 8] = [1, 2, 3, 4, 8, 12, 16, 20];

fn measured(config: &SimConfig, image: &ImageRef) -> (PoseSample, f64) {
    let seed = config.seed
        ^ (image.seq.wrapping_mul(0x9E37_79B9_7F4A_7C15))
        ^ ((image.uav.index() as u64 + 1) << 56);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut draw = |sigma: f64| {
        if sigma > 0.0 {
            Normal::new(0.0, sigma)
                .map(|n| n.sample(&mut rng))
                .unwrap_or(0.0)
        } else {
            0.0
        }
    };
    let n = &config.noise;
    let p = &image.true_pose;
    let bias = config.bias.at(image.t_s)[image.uav.index()];
    let pose = PoseSample {
        x_m: p.x_m + draw(n.sigma_position_m[0]),
        y_m: p.y_m + draw(n.sigma_position_m[1]),
        z_m: p.z_m + draw(n.sigma_position_m[2]),
        yaw_deg: p.yaw_deg + bias.to_degrees() + draw(n.sigma_attitude_deg[0]),
        pitch_deg: p.pitch_deg + draw(n.sigma_attitude_deg[1]),
        roll_deg: p.roll_deg + draw(n.sigma_attitude_deg[2]),
    };
    (pose, bias)
}

fn observation(config: &SimConfig, image: &ImageRef) -> (Observation, f64) {
    let (pose, bias) = measured(config, image);
    (
        Observation {
            uav: image.uav,
            position: pose.position(),
            attitude: pose.attitude(),
            pixel: Vector2::new(image.pixel[0], image.pixel[1]),
            intrinsics: image.intrinsics,
        },
        bias,
    )
}

/// The estimator configuration matching a scenario's noise (σ's floored at tiny
/// values so that Q stays invertible when an axis has no noise).
pub fn estimator_for(config: &SimConfig) -> EstimatorConfig {
    let n = &config.noise;
    let pos = n
        .sigma_position_m
        .iter()
        .copied()
        .fold(0.0, f64::max)
        .max(0.05);
    let att = n
        .sigma_attitude_deg
        .iter()
        .copied()
        .fold(0.0, f64::max)
        .max(0.05);
    let model = NoiseModel::isotropic(pos, att, 1.0);
    EstimatorConfig {
        noise_left: model,
        noise_right: model,
        ..EstimatorConfig::default()
    }
}

pub fn run(config: &SimConfig, records: &[Record], with_iterations: bool) -> ScenarioResult {
    let estimator = estimator_for(config);
    let joint = EstimatorConfig {
        method: EstimatorMethod::Joint,
        ..estimator
    };
    let mut out = ScenarioResult {
        by_iterations: if with_iterations {
            TABLE4_K
                .iter()
                .map(|&k| (k, MethodErrors::default()))
                .collect()
        } else {
            Vec::new()
        },
        ..Default::default()
    };
    for r in records {
        let (cl, bl) = observation(config, &r.current[0]);
        let (cr, br) = observation(config, &r.current[1]);
        let past: Vec<Observation> = r.past.iter().map(|i| observation(config, i).0).collect();
        let true_bias = [bl, br];
        match geolocate_filtered(&cl, &cr, &past, &estimator) {
            Ok(f) => out.paper.push(
                f.estimate.position,
                r.target,
                Some((f.estimate.yaw_bias, true_bias)),
            ),
            Err(_) => out.paper.rejected += 1,
        }
        match geolocate_configured(&cl, &cr, &past, &joint) {
            Ok(f) => out.joint.push(
                f.estimate.position,
                r.target,
                Some((f.estimate.yaw_bias, true_bias)),
            ),
            Err(_) => out.joint.rejected += 1,
        }
        match one_shot(&cl, r.range_left_m) {
            Ok(p) => out.one_shot.push(p, r.target, None),
            Err(_) => out.one_shot.rejected += 1,
        }
        for (k, errors) in out.by_iterations.iter_mut() {
            let fixed = EstimatorConfig {
                max_iterations: *k,
                bias_tolerance_deg: 0.0,
                ..estimator
            };
            match geolocate_filtered(&cl, &cr, &past, &fixed) {
                Ok(f) => errors.push(
                    f.estimate.position,
                    r.target,
                    Some((f.estimate.yaw_bias, true_bias)),
                ),
                Err(_) => errors.rejected += 1,
            }
        }
    }
    out
}
