//! Navigation-state error models used by every simulator in dualgeo (the geometric
//! scenario of the estimator tests and the image simulator): Gaussian noise per position
//! axis and per attitude angle, and the yaw biases of the paper's eq. (34).

use serde::{Deserialize, Serialize};

/// How the measured yaws are biased (measured = true + bias).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum BiasModel {
    /// Eq. (34): δψ_L = rate·t + δψ0, δψ_R = rate·t − δψ0 (degrees, t in seconds).
    Eq34 { delta0_deg: f64, rate_deg_s: f64 },
    /// Constant biases, degrees.
    Constant { left_deg: f64, right_deg: f64 },
}

impl BiasModel {
    /// (δψ_L, δψ_R) at time `t_s`, radians.
    pub fn at(&self, t_s: f64) -> [f64; 2] {
        match *self {
            BiasModel::Eq34 {
                delta0_deg,
                rate_deg_s,
            } => [
                (rate_deg_s * t_s + delta0_deg).to_radians(),
                (rate_deg_s * t_s - delta0_deg).to_radians(),
            ],
            BiasModel::Constant {
                left_deg,
                right_deg,
            } => [left_deg.to_radians(), right_deg.to_radians()],
        }
    }

    pub const NONE: BiasModel = BiasModel::Constant {
        left_deg: 0.0,
        right_deg: 0.0,
    };
}

/// Gaussian σ's of the measured navigation state.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NavNoise {
    /// σ per position axis (x, y, z), metres.
    pub sigma_position_m: [f64; 3],
    /// σ per attitude angle (yaw, pitch, roll), degrees.
    pub sigma_attitude_deg: [f64; 3],
}

impl NavNoise {
    pub const NONE: NavNoise = NavNoise {
        sigma_position_m: [0.0; 3],
        sigma_attitude_deg: [0.0; 3],
    };

    /// The same σ on every axis and on every angle (the paper's protocol).
    pub fn isotropic(sigma_position_m: f64, sigma_attitude_deg: f64) -> Self {
        Self {
            sigma_position_m: [sigma_position_m; 3],
            sigma_attitude_deg: [sigma_attitude_deg; 3],
        }
    }

    pub fn is_valid(&self) -> bool {
        self.sigma_position_m
            .iter()
            .chain(&self.sigma_attitude_deg)
            .all(|s| s.is_finite() && *s >= 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq34_biases_have_opposite_offsets_and_common_drift() {
        let b = BiasModel::Eq34 {
            delta0_deg: 20.0,
            rate_deg_s: 0.2,
        };
        let [l, r] = b.at(10.0).map(f64::to_degrees);
        assert!((l - 22.0).abs() < 1e-12 && (r + 18.0).abs() < 1e-12);
    }
}
