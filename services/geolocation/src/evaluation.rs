//! Error statistics in the paper's layout (MAE of eq. 33, STD, MAX) and a fixed-seed
//! Monte Carlo of the proposed method against the one-shot baseline on a
//! [`SyntheticScenario`]. Truth is read here, after estimation, never by the estimator.

use crate::one_shot::one_shot;
use crate::synthetic::SyntheticScenario;
use crate::{geolocate, EstimatorConfig};
use rand::rngs::StdRng;
use rand::SeedableRng;
use std::collections::BTreeMap;
use std::time::Instant;

/// MAE (eq. 33), STD and MAX of a set of errors. STD is the standard deviation of the
/// absolute errors (the paper's tables pair it with the MAE).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ErrorStats {
    pub mae: f64,
    pub std: f64,
    pub max: f64,
    pub count: usize,
}

impl ErrorStats {
    pub fn from_errors(errors: &[f64]) -> Self {
        let n = errors.len();
        if n == 0 {
            return Self::default();
        }
        let abs = || errors.iter().map(|e| e.abs());
        let mae = abs().sum::<f64>() / n as f64;
        let var = abs().map(|a| (a - mae).powi(2)).sum::<f64>() / n as f64;
        Self {
            mae,
            std: var.sqrt(),
            max: abs().fold(0.0, f64::max),
            count: n,
        }
    }
}

/// Errors of one method over a Monte Carlo run, metres (per axis and horizontal).
#[derive(Debug, Clone, Default)]
pub struct PositionErrors {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub z: Vec<f64>,
    pub horizontal: Vec<f64>,
    pub distance: Vec<f64>,
}

impl PositionErrors {
    fn push(&mut self, est: nalgebra::Point3<f64>, truth: nalgebra::Point3<f64>) {
        let d = est - truth;
        self.x.push(d.x);
        self.y.push(d.y);
        self.z.push(d.z);
        self.horizontal.push(d.xy().norm());
        self.distance.push(d.norm());
    }

    pub fn stats(&self) -> [ErrorStats; 5] {
        [&self.x, &self.y, &self.z, &self.horizontal, &self.distance]
            .map(|e| ErrorStats::from_errors(e))
    }
}

/// Outcome of [`monte_carlo`].
#[derive(Debug, Clone, Default)]
pub struct MonteCarloReport {
    pub images_per_uav: usize,
    pub trials: usize,
    pub proposed: PositionErrors,
    /// Yaw-bias errors, degrees: left, right.
    pub bias_deg: [Vec<f64>; 2],
    /// One-shot errors, one per current image (left and right).
    pub one_shot: PositionErrors,
    pub iterations: Vec<usize>,
    /// Wall time of each `geolocate` call, nanoseconds (single thread).
    pub solve_ns: Vec<u64>,
    /// Rejected trials by reason (`EstimatorError::kind`, or `out_of_view`).
    pub failures: BTreeMap<&'static str, usize>,
}

/// Runs `trials` geolocations at t = t₀ + 0.25 s · i with a fixed seed.
pub fn monte_carlo(
    scenario: &SyntheticScenario,
    images_per_uav: usize,
    trials: usize,
    seed: u64,
    config: &EstimatorConfig,
) -> MonteCarloReport {
    let mut rng = StdRng::seed_from_u64(seed);
    let t0 = scenario.keyframe_interval_s() * images_per_uav as f64;
    let mut report = MonteCarloReport {
        images_per_uav,
        trials,
        ..Default::default()
    };
    for i in 0..trials {
        let trial = match scenario.trial(t0 + 0.25 * i as f64, images_per_uav, &mut rng) {
            Ok(t) => t,
            Err(_) => {
                *report.failures.entry("out_of_view").or_default() += 1;
                continue;
            }
        };
        for (k, range) in trial.ranges_m.iter().enumerate() {
            if let Ok(p) = one_shot(&trial.observations[k], *range) {
                report.one_shot.push(p, trial.target);
            }
        }
        let started = Instant::now();
        let result = geolocate(&trial.observations, config);
        report.solve_ns.push(started.elapsed().as_nanos() as u64);
        match result {
            Ok(est) => {
                report.proposed.push(est.position, trial.target);
                for u in 0..2 {
                    report.bias_deg[u].push((est.yaw_bias[u] - trial.yaw_bias[u]).to_degrees());
                }
                report.iterations.push(est.iterations);
            }
            Err(e) => *report.failures.entry(e.kind()).or_default() += 1,
        }
    }
    report
}
