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
    geolocate_configured, geolocate_filtered_paper, one_shot, EstimatorConfig, EstimatorMethod,
    NoiseModel, Observation, PastImage, TemporalEstimator,
};
use nalgebra::Vector2;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use shared_types::conventions::wrap_angle;
use shared_types::messages::PoseSample;
use shared_types::nav_noise::NavErrorModel;

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
    pub(crate) fn push(
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

/// Calibration of a method's stated 1σ: how often the true error is inside 1σ and 2σ.
/// Horizontal: radial error against h_acc = √(σ_x² + σ_y²) (a calibrated circular
/// Gaussian puts 63 % inside, 98 % inside 2 h_acc); vertical: |z error| against
/// v_acc = σ_z (68 %, 95 %).
#[derive(Debug, Default, Clone, Copy)]
pub struct Calibration {
    pub n: usize,
    pub h1: usize,
    pub h2: usize,
    pub v1: usize,
    pub v2: usize,
    /// The largest horizontal error over its stated h_acc: a confident wrong estimate
    /// shows here even when it is one in a thousand.
    pub worst_h_ratio: f64,
}

impl Calibration {
    pub(crate) fn push(&mut self, est: &geolocation::Estimate, truth: nalgebra::Point3<f64>) {
        let h_acc = (est.covariance[(0, 0)] + est.covariance[(1, 1)])
            .max(0.0)
            .sqrt();
        let v_acc = est.altitude_std_error_m;
        let d = est.position - truth;
        let (h, v) = ((d.x * d.x + d.y * d.y).sqrt(), d.z.abs());
        if !(h_acc.is_finite() && v_acc.is_finite()) {
            return;
        }
        self.n += 1;
        self.h1 += (h <= h_acc) as usize;
        self.h2 += (h <= 2.0 * h_acc) as usize;
        self.v1 += (v <= v_acc) as usize;
        self.v2 += (v <= 2.0 * v_acc) as usize;
        if h_acc > 0.0 {
            self.worst_h_ratio = self.worst_h_ratio.max(h / h_acc);
        }
    }

    pub fn shares(&self) -> [f64; 4] {
        let f = |k: usize| {
            if self.n == 0 {
                f64::NAN
            } else {
                100.0 * k as f64 / self.n as f64
            }
        };
        [f(self.h1), f(self.h2), f(self.v1), f(self.v2)]
    }
}

/// The bias-step scenario: a step added to the biases from `at_s` on.
#[derive(Debug, Clone, Copy)]
pub struct BiasStep {
    pub at_s: f64,
    pub step_deg: [f64; 2],
}

/// Seconds after the start of the run before the temporal filter's errors count.
pub const WARM_UP_S: f64 = 10.0;

/// Everything one scenario gives, for one N.
#[derive(Debug, Default, Clone)]
pub struct ScenarioResult {
    pub paper: MethodErrors,
    pub joint: MethodErrors,
    /// The temporal filter, after the warm-up.
    pub temporal: MethodErrors,
    pub one_shot: MethodErrors,
    pub calibration: [Calibration; 3],
    /// (t, left bias error, right bias error) of the temporal filter, degrees, all times.
    pub temporal_bias_track: Vec<(f64, f64, f64)>,
    /// Mean, p99 and largest time of one temporal update, µs.
    pub temporal_update_us: (f64, f64, f64),
    /// Times the temporal filter re-opened its covariance (suspected bias steps).
    pub temporal_reopens: Vec<f64>,
    /// Table 4: k → (|δψ_L|, |δψ_R|, |z|) errors after k iterations (paper's method).
    pub by_iterations: Vec<(usize, MethodErrors)>,
}

pub const TABLE4_K: [usize; 8] = [1, 2, 3, 4, 8, 12, 16, 20];

fn measured(config: &SimConfig, step: Option<BiasStep>, image: &ImageRef) -> (PoseSample, f64) {
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
    let mut bias = config.bias.at(image.t_s)[image.uav.index()];
    if let Some(s) = step {
        if image.t_s >= s.at_s {
            bias += s.step_deg[image.uav.index()].to_radians();
        }
    }
    // The AHRS errs on the body's angles: a mounted camera's equivalent attitude is
    // turned back to its body's, the errors drawn there, the mount applied again.
    let mount = p.mount.mount();
    let body = if mount.is_nadir() {
        *p
    } else {
        let a = mount.body_attitude(p.attitude());
        PoseSample {
            yaw_deg: a.yaw.to_degrees(),
            pitch_deg: a.pitch.to_degrees(),
            roll_deg: a.roll.to_degrees(),
            ..*p
        }
    };
    let pose = PoseSample {
        x_m: body.x_m + draw(n.sigma_position_m[0]),
        y_m: body.y_m + draw(n.sigma_position_m[1]),
        z_m: body.z_m + draw(n.sigma_position_m[2]),
        yaw_deg: body.yaw_deg + bias.to_degrees() + draw(n.sigma_attitude_deg[0]),
        pitch_deg: body.pitch_deg + draw(n.sigma_attitude_deg[1]),
        roll_deg: body.roll_deg + draw(n.sigma_attitude_deg[2]),
        mount: p.mount,
    };
    let pose = if mount.is_nadir() {
        pose
    } else {
        pose.on_mount(mount)
    };
    (pose, bias)
}

fn observation(config: &SimConfig, step: Option<BiasStep>, image: &ImageRef) -> (Observation, f64) {
    let (pose, bias) = measured(config, step, image);
    (
        Observation {
            uav: image.uav,
            position: pose.position(),
            attitude: pose.attitude(),
            mount: pose.mount.mount(),
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
    let mut model = NoiseModel::isotropic(pos, att, 1.0);
    // A user states their sensors' error model; the evaluation states the simulator's.
    if let NavErrorModel::GaussMarkov {
        position_tau_s,
        position_jitter_m,
        attitude_tau_s,
        attitude_jitter_deg,
    } = n.model
    {
        model.position_tau_s = position_tau_s;
        model.position_jitter_m = position_jitter_m.max(0.05);
        model.attitude_tau_s = attitude_tau_s;
        model.attitude_jitter_deg = attitude_jitter_deg.max(0.05);
    }
    EstimatorConfig {
        noise_left: model,
        noise_right: model,
        // The paper's tables are reproduced with the paper's method; the joint and
        // temporal rows set their own.
        method: EstimatorMethod::Paper,
        ..EstimatorConfig::default()
    }
}

pub fn run(
    config: &SimConfig,
    records: &[Record],
    with_iterations: bool,
    step: Option<BiasStep>,
) -> ScenarioResult {
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
    let mut temporal = TemporalEstimator::new(estimator).ok();
    let start_t = records.first().map_or(0.0, |r| r.current[0].t_s);
    let mut update_us: Vec<f64> = Vec::new();
    for r in records {
        let t_s = r.current[0].t_s;
        let (cl, bl) = observation(config, step, &r.current[0]);
        let (cr, br) = observation(config, step, &r.current[1]);
        let past_ids: Vec<PastImage> = r
            .past
            .iter()
            .map(|i| PastImage {
                id: (i.uav, i.seq),
                t_s: i.t_s,
                observation: observation(config, step, i).0,
                // The paper's tables: the rays alone, as the paper has them.
                rotation_from: [None; 2],
            })
            .collect();
        let past: Vec<Observation> = past_ids.iter().map(|image| image.observation).collect();
        let true_bias = [bl, br];
        let paper = geolocate_filtered_paper(&cl, &cr, &past, &estimator);
        match &paper {
            Ok(f) => {
                out.paper.push(
                    f.estimate.position,
                    r.target,
                    Some((f.estimate.yaw_bias, true_bias)),
                );
                out.calibration[0].push(&f.estimate, r.target);
            }
            Err(_) => out.paper.rejected += 1,
        }
        match geolocate_configured(&cl, &cr, &past, &joint) {
            Ok(f) => {
                out.joint.push(
                    f.estimate.position,
                    r.target,
                    Some((f.estimate.yaw_bias, true_bias)),
                );
                out.calibration[1].push(&f.estimate, r.target);
            }
            Err(_) => out.joint.rejected += 1,
        }
        if let Some(filter) = temporal.as_mut() {
            let window = paper.as_ref().ok().map(|f| &f.estimate);
            let started = std::time::Instant::now();
            let result = filter.update(t_s, [&cl, &cr], &past_ids, window);
            update_us.push(started.elapsed().as_secs_f64() * 1e6);
            match result {
                Ok(e) => {
                    if e.reopened {
                        out.temporal_reopens.push(t_s);
                    }
                    let b = e.estimate.yaw_bias;
                    out.temporal_bias_track.push((
                        t_s,
                        wrap_angle(b[0] - true_bias[0]).to_degrees(),
                        wrap_angle(b[1] - true_bias[1]).to_degrees(),
                    ));
                    if t_s - start_t >= WARM_UP_S {
                        out.temporal
                            .push(e.estimate.position, r.target, Some((b, true_bias)));
                        out.calibration[2].push(&e.estimate, r.target);
                    }
                }
                Err(_) => out.temporal.rejected += 1,
            }
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
            match geolocate_filtered_paper(&cl, &cr, &past, &fixed) {
                Ok(f) => errors.push(
                    f.estimate.position,
                    r.target,
                    Some((f.estimate.yaw_bias, true_bias)),
                ),
                Err(_) => errors.rejected += 1,
            }
        }
    }
    if !update_us.is_empty() {
        let mean = update_us.iter().sum::<f64>() / update_us.len() as f64;
        update_us.sort_by(f64::total_cmp);
        let p99 = update_us[(update_us.len() * 99 / 100).min(update_us.len() - 1)];
        let max = update_us[update_us.len() - 1];
        out.temporal_update_us = (mean, p99, max);
    }
    out
}
