//! The iteration between target altitude estimation (Section 2.2) and parameter
//! regression (Section 2.1): "there are several iterations between the target altitude
//! estimation and the parameter regression until the estimated yaw-angle biases are less
//! than the given threshold or the number of iterations reaches the given maximum".
//!
//! Round n: z_P⁽ⁿ⁾ from eq. (16)–(23) with yaws corrected by δψ⁽ⁿ⁾ (eq. 19), then the
//! regression of eq. (12)–(15) at z_P⁽ⁿ⁾ gives (x_P, y_P) and the update Δ⁽ⁿ⁾, and
//! δψ⁽ⁿ⁺¹⁾ = δψ⁽ⁿ⁾ + Δ⁽ⁿ⁾. It stops when max |Δ⁽ⁿ⁾| is below the tolerance (the paper's
//! "estimated yaw-angle biases of the current iteration are less than 0.1": the bias
//! *update*, since the biases themselves are e.g. 20°) or after `max_iterations` rounds.

use crate::altitude::estimate_altitude;
use crate::ground_model::PreparedRay;
use crate::observation::validate_set;
use crate::regression::solve_regression;
use crate::{EstimatorConfig, EstimatorError, Observation};
use nalgebra::{Matrix4, Point3};

/// One geolocation of the target's current position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// (x_P, y_P, z_P), world ENU metres.
    pub position: Point3<f64>,
    /// (δψ_L, δψ_R), radians: measured yaw minus true yaw.
    pub yaw_bias: [f64; 2],
    /// Covariance of (x_P, y_P, δψ_L, δψ_R) from the last regression, m² / rad².
    pub covariance: Matrix4<f64>,
    /// Standard error of z_P from the last altitude estimate (eq. 22 residuals), metres.
    pub altitude_std_error_m: f64,
    /// Altitude/regression rounds run.
    pub iterations: usize,
    /// Whether the last bias update was below the tolerance.
    pub converged: bool,
    /// Images the estimate used (2N when nothing was rejected).
    pub images_used: usize,
}

/// The proposed method for one observation set (current and past images of both UAVs):
/// the altitude/regression iteration, starting from δψ⁽⁰⁾ = (0, 0).
pub fn geolocate(
    observations: &[Observation],
    config: &EstimatorConfig,
) -> Result<Estimate, EstimatorError> {
    config.validate()?;
    // Two images (one per UAV) give 4 rows for 4 unknowns; the paper's minimum is
    // the current pair plus one past image per UAV, but a group of Section 2.3 has 3.
    validate_set(observations, 3)?;

    let tolerance = config.bias_tolerance_deg.to_radians();
    let min_angle = config.min_ray_angle_deg.to_radians();
    let mut bias = [0.0f64; 2];
    let rays: Vec<PreparedRay> = observations.iter().map(PreparedRay::new).collect();

    let mut iteration = 0;
    loop {
        iteration += 1;
        let altitude = estimate_altitude(observations, &rays, bias, min_angle)?;
        let solution = solve_regression(observations, &rays, altitude.z_target, bias, config)?;
        bias[0] += solution.bias_update[0];
        bias[1] += solution.bias_update[1];
        let step = solution.bias_update[0]
            .abs()
            .max(solution.bias_update[1].abs());
        let converged = step < tolerance;
        if converged || iteration >= config.max_iterations {
            let estimate = Estimate {
                position: Point3::new(solution.xy.x, solution.xy.y, altitude.z_target),
                yaw_bias: bias,
                covariance: solution.covariance,
                altitude_std_error_m: altitude.std_error_m,
                iterations: iteration,
                converged,
                images_used: observations.len(),
            };
            return check_finite(estimate);
        }
    }
}

fn check_finite(estimate: Estimate) -> Result<Estimate, EstimatorError> {
    let finite = estimate.position.iter().all(|v| v.is_finite())
        && estimate.yaw_bias.iter().all(|v| v.is_finite())
        && estimate.altitude_std_error_m.is_finite();
    if finite {
        Ok(estimate)
    } else {
        Err(EstimatorError::NonFiniteResult { what: "estimate" })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{NavNoise, SyntheticScenario};
    use rand::rngs::StdRng;
    use rand::SeedableRng;
    use shared_types::conventions::Uav;

    fn trial() -> Vec<Observation> {
        let s = SyntheticScenario {
            noise: NavNoise::NONE,
            ..SyntheticScenario::default()
        };
        s.trial(6.0, 4, &mut StdRng::seed_from_u64(7))
            .unwrap()
            .observations
    }

    #[test]
    fn nan_and_inf_anywhere_are_rejected_with_the_image_index() {
        let cfg = EstimatorConfig::default();
        let mut obs = trial();
        obs[3].pixel.y = f64::NAN;
        assert_eq!(
            geolocate(&obs, &cfg),
            Err(EstimatorError::NonFinite {
                index: 3,
                what: "pixel"
            })
        );
        let mut obs = trial();
        obs[5].attitude.pitch = f64::INFINITY;
        assert!(matches!(
            geolocate(&obs, &cfg),
            Err(EstimatorError::NonFinite {
                index: 5,
                what: "attitude"
            })
        ));
        let mut obs = trial();
        obs[0].position.z = f64::NEG_INFINITY;
        assert!(matches!(
            geolocate(&obs, &cfg),
            Err(EstimatorError::NonFinite { index: 0, .. })
        ));
        let mut obs = trial();
        obs[1].intrinsics.fx = 0.0;
        assert!(matches!(
            geolocate(&obs, &cfg),
            Err(EstimatorError::BadIntrinsics { index: 1 })
        ));
    }

    #[test]
    fn too_few_images_or_one_uav_only() {
        let cfg = EstimatorConfig::default();
        let obs = trial();
        assert!(matches!(
            geolocate(&obs[..2], &cfg),
            Err(EstimatorError::TooFewImages { .. })
        ));
        let left_only: Vec<_> = obs.iter().copied().filter(|o| o.uav == Uav::Left).collect();
        assert!(matches!(
            geolocate(&left_only, &cfg),
            Err(EstimatorError::TooFewImages { right: 0, .. })
        ));
    }

    #[test]
    fn near_parallel_rays_are_rejected() {
        // Both UAVs at the same place looking at the same pixel: every pair parallel.
        let mut obs = trial();
        let (l, r) = (obs[0], obs[1]);
        for o in obs.iter_mut() {
            *o = if o.uav == Uav::Left {
                l
            } else {
                Observation {
                    uav: Uav::Right,
                    ..l
                }
            };
        }
        let _ = r;
        assert!(matches!(
            geolocate(&obs, &EstimatorConfig::default()),
            Err(EstimatorError::NoValidRayPair { near_parallel, .. }) if near_parallel > 0
        ));
    }

    #[test]
    fn target_above_the_uav_is_rejected() {
        // A GPS glitch puts the first left past image 5 m below the ground: the altitude
        // from the other pairs is above that UAV, so eq. (1) cannot use the image.
        let mut obs = trial();
        obs[2].position.z = SyntheticScenario::default().ground_z_m - 5.0;
        assert!(matches!(
            geolocate(&obs, &EstimatorConfig::default()),
            Err(EstimatorError::TargetAboveUav { index: 2, .. })
        ));
    }

    #[test]
    fn singular_regression_is_reported() {
        // One image per UAV at the principal point straight below: ∂F/∂ψ = 0, so the
        // bias columns of eq. (13) vanish and the normal matrix is singular.
        let mut obs = trial();
        obs.truncate(2);
        obs.push(obs[0]);
        for o in obs.iter_mut() {
            o.attitude.pitch = 0.0;
            o.attitude.roll = 0.0;
            o.pixel = nalgebra::Vector2::new(o.intrinsics.cx, o.intrinsics.cy);
        }
        assert!(matches!(
            geolocate(&obs, &EstimatorConfig::default()),
            Err(EstimatorError::SingularNormalMatrix { .. })
                | Err(EstimatorError::NoValidRayPair { .. })
        ));
    }

    #[test]
    fn bad_config_is_rejected() {
        let cfg = EstimatorConfig {
            max_iterations: 0,
            ..EstimatorConfig::default()
        };
        assert!(matches!(
            geolocate(&trial(), &cfg),
            Err(EstimatorError::Config(_))
        ));
        let mut cfg = EstimatorConfig::default();
        cfg.noise_left.sigma_yaw_deg = f64::NAN;
        assert!(matches!(
            geolocate(&trial(), &cfg),
            Err(EstimatorError::Config(_))
        ));
    }
}
