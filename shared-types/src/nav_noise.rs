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

/// How the errors of successive samples relate (issue #23).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum NavErrorModel {
    /// The paper's model: every sample's errors drawn afresh, N(0, σ).
    #[default]
    White,
    /// As real sensors make them: each error is a first-order Gauss–Markov process
    /// (exponentially correlated, time constant τ) whose stationary σ is the noise's
    /// σ, plus a white jitter. A consumer GPS wanders with τ of minutes; an AHRS's
    /// attitude errors drift over seconds.
    GaussMarkov {
        position_tau_s: f64,
        position_jitter_m: f64,
        attitude_tau_s: f64,
        attitude_jitter_deg: f64,
    },
}

impl NavErrorModel {
    /// A consumer GPS (τ 120 s, 0.3 m jitter) with an AHRS whose errors drift over
    /// 10 s (0.2° jitter).
    pub fn consumer_gps() -> Self {
        NavErrorModel::GaussMarkov {
            position_tau_s: 120.0,
            position_jitter_m: 0.3,
            attitude_tau_s: 10.0,
            attitude_jitter_deg: 0.2,
        }
    }

    pub fn is_white(&self) -> bool {
        matches!(self, NavErrorModel::White)
    }

    pub fn is_valid(&self) -> bool {
        match *self {
            NavErrorModel::White => true,
            NavErrorModel::GaussMarkov {
                position_tau_s,
                position_jitter_m,
                attitude_tau_s,
                attitude_jitter_deg,
            } => {
                let positive = |v: f64| v.is_finite() && v > 0.0;
                let non_negative = |v: f64| v.is_finite() && v >= 0.0;
                positive(position_tau_s)
                    && positive(attitude_tau_s)
                    && non_negative(position_jitter_m)
                    && non_negative(attitude_jitter_deg)
            }
        }
    }
}

/// One UAV's navigation errors as they evolve from sample to sample.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct NavErrorState {
    /// The correlated part of the (x, y, z, yaw, pitch, roll) errors, m and degrees.
    correlated: Option<[f64; 6]>,
    t_s: f64,
}

impl NavErrorState {
    /// The errors of a sample at `t_s`: metres (x, y, z) and degrees (yaw, pitch,
    /// roll). `normal` draws N(0, 1).
    pub fn next(
        &mut self,
        noise: &NavNoise,
        t_s: f64,
        mut normal: impl FnMut() -> f64,
    ) -> [f64; 6] {
        let [px, py, pz] = noise.sigma_position_m;
        let [ay, ap, ar] = noise.sigma_attitude_deg;
        let sigma = [px, py, pz, ay, ap, ar];
        match noise.model {
            // No draw for an axis without noise: the same seed gives the same errors
            // as before the correlated model existed.
            NavErrorModel::White => sigma.map(|s| if s > 0.0 { s * normal() } else { 0.0 }),
            NavErrorModel::GaussMarkov {
                position_tau_s,
                position_jitter_m,
                attitude_tau_s,
                attitude_jitter_deg,
            } => {
                let dt = (t_s - self.t_s).max(0.0);
                self.t_s = t_s;
                let c = match self.correlated.as_mut() {
                    // The first sample comes from the stationary distribution.
                    None => self.correlated.insert(sigma.map(|s| s * normal())),
                    Some(c) => {
                        for (k, e) in c.iter_mut().enumerate() {
                            let tau = if k < 3 {
                                position_tau_s
                            } else {
                                attitude_tau_s
                            };
                            let a = (-dt / tau).exp();
                            *e = a * *e + sigma[k] * (1.0 - a * a).max(0.0).sqrt() * normal();
                        }
                        c
                    }
                };
                let c = *c;
                std::array::from_fn(|k| {
                    let jitter = if k < 3 {
                        position_jitter_m
                    } else {
                        attitude_jitter_deg
                    };
                    c[k] + jitter * normal()
                })
            }
        }
    }
}

/// Gaussian σ's of the measured navigation state.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NavNoise {
    /// σ per position axis (x, y, z), metres (with a Gauss–Markov model: the
    /// stationary σ of the correlated part).
    pub sigma_position_m: [f64; 3],
    /// σ per attitude angle (yaw, pitch, roll), degrees.
    pub sigma_attitude_deg: [f64; 3],
    /// White (the paper's, the default) or correlated over time.
    #[serde(default, skip_serializing_if = "NavErrorModel::is_white")]
    pub model: NavErrorModel,
}

impl NavNoise {
    pub const NONE: NavNoise = NavNoise {
        sigma_position_m: [0.0; 3],
        sigma_attitude_deg: [0.0; 3],
        model: NavErrorModel::White,
    };

    /// The same σ on every axis and on every angle (the paper's protocol).
    pub fn isotropic(sigma_position_m: f64, sigma_attitude_deg: f64) -> Self {
        Self {
            sigma_position_m: [sigma_position_m; 3],
            sigma_attitude_deg: [sigma_attitude_deg; 3],
            model: NavErrorModel::White,
        }
    }

    pub fn is_valid(&self) -> bool {
        self.model.is_valid()
            && self
                .sigma_position_m
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

    /// Lag-k autocorrelation of a series.
    fn autocorrelation(v: &[f64], k: usize) -> f64 {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>();
        v.windows(k + 1)
            .map(|w| (w[0] - m) * (w[k] - m))
            .sum::<f64>()
            / var
    }

    #[test]
    fn gauss_markov_errors_wander_with_their_sigma_and_white_ones_do_not() {
        // N(0, 1) by Box–Muller over a xorshift generator (no rand in this crate).
        let mut x: u64 = 0x2545_f491_4f6c_dd1d;
        let mut uniform = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let mut normal = move || {
            let (u, v) = (uniform(), uniform());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let mut draw = |noise: &NavNoise, seconds: f64, dt: f64| {
            let mut state = NavErrorState::default();
            (0..(seconds / dt) as usize)
                .map(|i| state.next(noise, i as f64 * dt, &mut normal)[0])
                .collect::<Vec<f64>>()
        };
        let white = draw(&NavNoise::isotropic(3.0, 2.0), 100.0, 0.1);
        assert!(autocorrelation(&white, 10).abs() < 0.1);
        let gm_noise = NavNoise {
            model: NavErrorModel::GaussMarkov {
                position_tau_s: 5.0,
                position_jitter_m: 0.0,
                attitude_tau_s: 5.0,
                attitude_jitter_deg: 0.0,
            },
            ..NavNoise::isotropic(3.0, 2.0)
        };
        // 1 s lag at τ = 5 s: e^(−0.2) = 0.82; the stationary σ is the noise's σ.
        let gm = draw(&gm_noise, 4000.0, 0.1);
        assert!((autocorrelation(&gm, 10) - 0.82).abs() < 0.05);
        let sd = (gm.iter().map(|x| x * x).sum::<f64>() / gm.len() as f64).sqrt();
        assert!((sd - 3.0).abs() < 0.3, "σ {sd}");
    }
}
