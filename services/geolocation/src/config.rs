//! Estimator configuration: the σ's of Q1, Q2, Q3 (eq. 8–10), the iteration's stopping
//! rule and the consistency threshold TH (eq. 30). User-facing units are metres,
//! pixels and degrees; the estimator converts to radians once.

use crate::EstimatorError;
use serde::{Deserialize, Serialize};

/// Standard deviations of one UAV's measured navigation state.
///
/// τ1 (eq. 5) = (x_v, y_v, z_v, x_p, y_p, θ, φ) gets the diagonal covariance
/// `Q1 = diag(σx², σy², σz², σpx², σpx², σθ², σφ²)`; the yaw ψ gets `σψ²` (Q3's entry
/// for this UAV).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseModel {
    pub sigma_position_m: [f64; 3],
    pub sigma_pixel_px: f64,
    pub sigma_pitch_deg: f64,
    pub sigma_roll_deg: f64,
    pub sigma_yaw_deg: f64,
    /// Time constant of the position error, seconds: 0 (the default, the paper's
    /// model) draws it afresh for every sample; above 0 it is a first-order
    /// Gauss–Markov process whose stationary σ is `sigma_position_m`, plus white
    /// `position_jitter_m`, as a consumer GPS wanders (the temporal filter then
    /// carries it as a state per UAV and cannot average it away).
    pub position_tau_s: f64,
    pub position_jitter_m: f64,
    /// The same for the attitude errors (σ's of yaw, pitch, roll above).
    pub attitude_tau_s: f64,
    pub attitude_jitter_deg: f64,
}

impl NoiseModel {
    /// The same σ on every position axis and on every attitude angle.
    pub fn isotropic(sigma_pos_m: f64, sigma_att_deg: f64, sigma_pixel_px: f64) -> Self {
        Self {
            sigma_position_m: [sigma_pos_m; 3],
            sigma_pixel_px,
            sigma_pitch_deg: sigma_att_deg,
            sigma_roll_deg: sigma_att_deg,
            sigma_yaw_deg: sigma_att_deg,
            position_tau_s: 0.0,
            position_jitter_m: 0.0,
            attitude_tau_s: 0.0,
            attitude_jitter_deg: 0.0,
        }
    }

    /// Whether any error is correlated over time (a Gauss–Markov state in the filter).
    pub fn is_correlated(&self) -> bool {
        self.position_tau_s > 0.0 || self.attitude_tau_s > 0.0
    }

    /// Variances of τ1 in the order of eq. (5), in m², px² and rad².
    pub fn tau1_variances(&self) -> [f64; 7] {
        let [sx, sy, sz] = self.sigma_position_m;
        let px = self.sigma_pixel_px;
        let th = self.sigma_pitch_deg.to_radians();
        let ph = self.sigma_roll_deg.to_radians();
        [
            sx * sx,
            sy * sy,
            sz * sz,
            px * px,
            px * px,
            th * th,
            ph * ph,
        ]
    }

    /// σψ² in rad² (this UAV's diagonal entry of Q3).
    pub fn yaw_variance(&self) -> f64 {
        self.sigma_yaw_deg.to_radians().powi(2)
    }

    fn validate(&self) -> Result<(), EstimatorError> {
        let all = [
            self.sigma_position_m[0],
            self.sigma_position_m[1],
            self.sigma_position_m[2],
            self.sigma_pixel_px,
            self.sigma_pitch_deg,
            self.sigma_roll_deg,
            self.sigma_yaw_deg,
            self.position_tau_s,
            self.position_jitter_m,
            self.attitude_tau_s,
            self.attitude_jitter_deg,
        ];
        if all.iter().all(|s| s.is_finite() && *s >= 0.0) {
            Ok(())
        } else {
            Err(EstimatorError::Config(format!(
                "noise σ's and time constants must be finite and >= 0, got {self:?}"
            )))
        }
    }
}

impl Default for NoiseModel {
    /// The paper's Table 2 protocol (σ_att 2°, σ_pos 3 m) with a 1 px matching σ.
    fn default() -> Self {
        Self::isotropic(3.0, 2.0, 1.0)
    }
}

/// Which estimator runs after the consistency filter.
///
/// The default is the one that wins across the scene suite (docs/evaluation.md, "Scene
/// suite"): the temporal filter. `method = "paper"` gives the paper's per-window
/// estimator, which `dualgeo evaluate` uses to reproduce the paper's tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EstimatorMethod {
    /// The paper's alternation of altitude (eq. 16–23) and regression (eq. 12–15).
    Paper,
    /// The paper's estimate refined by one joint weighted least squares over
    /// (x, y, z, δψ_L, δψ_R) on every kept ray (`joint.rs`).
    Joint,
    /// The biases and the target carried across geolocations (`temporal.rs`): a
    /// stateful filter fed by the paper's per-window estimate of each set. The default.
    #[default]
    Temporal,
}

/// Everything the paper's per-window estimator can be tuned with.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EstimatorConfig {
    /// Q1 (left UAV) and Q2 (right UAV) with each UAV's yaw σ for Q3.
    pub noise_left: NoiseModel,
    pub noise_right: NoiseModel,
    /// Stop when the largest bias update of an iteration is below this (paper: 0.1°).
    pub bias_tolerance_deg: f64,
    /// Stop after this many altitude/regression rounds (paper: 20).
    pub max_iterations: usize,
    /// Left/right ray pairs closer to parallel than this are skipped in eq. (16).
    pub min_ray_angle_deg: f64,
    /// TH of eq. (30), on e_nm of eq. (31) (sum of both UAVs' bias differences).
    /// The paper gives no value; 3° separates a wrong correspondence from right ones
    /// on noise-free data (see the consistency tests) while tolerating matching noise.
    pub consistency_threshold_deg: f64,
    /// Past images the consistency filter must have to compare (those whose group
    /// (g_L1, g_R1, g_n) could be estimated) for a filtered estimate. Eq. (29)–(32)
    /// judges a past image by its agreement with the others, so a lone past image is
    /// never checked. At the default 2, a geolocation with fewer is refused
    /// (`too_few_past_images_to_compare`) instead of returned unchecked: on the
    /// Table 1 route, two such geolocations were 60 and 84 m off (docs/matching.md).
    /// It counts the past images before the filter, not after: under the Table 2
    /// noise the filter rejects many, and counting after it refused 493 of 550 sets
    /// (137 this way, 106 without the rule). 0 or 1 = the paper's behaviour.
    pub min_past_images_to_compare: usize,
    /// The estimator after the consistency filter.
    pub method: EstimatorMethod,
    /// Huber corner of the joint estimator, on each image's whitened residual norm
    /// (0 = plain least squares).
    pub joint_huber_k: f64,
    /// σ of the joint estimator's zero-mean prior on each yaw bias, degrees (0 = none).
    pub joint_bias_prior_deg: f64,
    /// The temporal filter's tuning (`method = "temporal"`).
    pub temporal: crate::temporal::TemporalConfig,
    /// Withhold an estimate whose h_acc (√(σ_x² + σ_y²), m) is above this: it is
    /// published as `Withheld` and counted (`withheld.h_acc`), never sent to ground
    /// control. 0 = off (the default: every estimate goes out with its honest accuracy).
    pub max_h_acc_m: f64,
    /// Raise a UAV's white navigation σ's (or its jitter, where its error model is
    /// correlated) to what its own pose samples show when they are noisier than
    /// `noise_*` says (`telemetry_noise.rs`); never lowered. On by default.
    pub noise_from_telemetry: bool,
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            noise_left: NoiseModel::default(),
            noise_right: NoiseModel::default(),
            bias_tolerance_deg: 0.1,
            max_iterations: 20,
            min_ray_angle_deg: 1.0,
            consistency_threshold_deg: 3.0,
            min_past_images_to_compare: 2,
            method: EstimatorMethod::default(),
            joint_huber_k: 2.0,
            joint_bias_prior_deg: 30.0,
            temporal: crate::temporal::TemporalConfig::default(),
            max_h_acc_m: 0.0,
            noise_from_telemetry: true,
        }
    }
}

impl EstimatorConfig {
    /// The noise model of a UAV (left = Q1, right = Q2).
    pub fn noise(&self, uav: shared_types::conventions::Uav) -> &NoiseModel {
        match uav {
            shared_types::conventions::Uav::Left => &self.noise_left,
            shared_types::conventions::Uav::Right => &self.noise_right,
        }
    }

    pub fn validate(&self) -> Result<(), EstimatorError> {
        self.noise_left.validate()?;
        self.noise_right.validate()?;
        let positive = |v: f64, name: &str| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(EstimatorError::Config(format!(
                    "{name} must be finite and >= 0, got {v}"
                )))
            }
        };
        positive(self.bias_tolerance_deg, "bias_tolerance_deg")?;
        positive(self.min_ray_angle_deg, "min_ray_angle_deg")?;
        positive(self.consistency_threshold_deg, "consistency_threshold_deg")?;
        positive(self.joint_huber_k, "joint_huber_k")?;
        positive(self.joint_bias_prior_deg, "joint_bias_prior_deg")?;
        positive(self.max_h_acc_m, "max_h_acc_m")?;
        if self.max_iterations == 0 {
            return Err(EstimatorError::Config(
                "max_iterations must be at least 1".into(),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_round_trip_and_partial_tables() {
        let text = toml::to_string(&EstimatorConfig::default()).unwrap();
        let back: EstimatorConfig = toml::from_str(&text).unwrap();
        assert_eq!(back, EstimatorConfig::default());
        let partial: EstimatorConfig =
            toml::from_str("max_iterations = 7\n[noise_right]\nsigma_pixel_px = 2.5\n").unwrap();
        assert_eq!(partial.max_iterations, 7);
        assert_eq!(partial.noise_right.sigma_pixel_px, 2.5);
        assert_eq!(partial.noise_right.sigma_yaw_deg, 2.0);
        assert!(toml::from_str::<EstimatorConfig>("max_iteratons = 7").is_err());
    }

    #[test]
    fn the_temporal_filter_is_the_default_and_paper_one_line_away() {
        assert_eq!(EstimatorConfig::default().method, EstimatorMethod::Temporal);
        let paper: EstimatorConfig = toml::from_str("method = \"paper\"").unwrap();
        assert_eq!(paper.method, EstimatorMethod::Paper);
    }
}
