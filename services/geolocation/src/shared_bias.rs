//! Several targets: another vehicle's position with the yaw biases the target's filter
//! estimated. The biases belong to the UAVs' AHRS, not to a vehicle, so every vehicle
//! both UAVs see shares them: its altitude comes from Section 2.2 (eq. 16–23) with the
//! yaws corrected by them (eq. 19), its (x_P, y_P) from Section 2.1's regression
//! (eq. 12–15) with their estimate as a prior (`regression::BiasPrior`), iterated as
//! [`crate::iteration`] does. Their uncertainty then widens the vehicle's covariance,
//! and one window of a single vehicle never re-estimates them on its own (the weak
//! point of Tables 2–3).
//!
//! Not yet (a choice to revisit): the vehicles' rows do not feed back into the
//! biases' estimate; the target's filter alone estimates them.

use crate::altitude::estimate_altitude;
use crate::ground_model::PreparedRay;
use crate::observation::validate_set;
use crate::regression::{solve_regression_with_prior, BiasPrior};
use crate::{EstimatorConfig, EstimatorError, Observation};
use nalgebra::{Matrix2, Point3, Vector2};

/// The UAVs' yaw biases as the target's filter knows them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SharedBiases {
    /// (δψ_L, δψ_R), radians.
    pub mean: [f64; 2],
    /// Their covariance, rad².
    pub covariance: Matrix2<f64>,
}

/// Another vehicle located with the shared biases.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OtherFix {
    /// (x, y, z), world ENU metres.
    pub position: Point3<f64>,
    /// Covariance of (x, y), m², the biases' uncertainty included.
    pub covariance_xy: Matrix2<f64>,
    /// Covariance of (x, y) were the biases known exactly, m² (the Schur complement
    /// of the biases' block): what is left of it in a difference with another
    /// vehicle located through the same images with the same biases.
    pub covariance_xy_given_biases: Matrix2<f64>,
    /// How its (x, y) moves with the biases it is given, m/rad: ∂(x, y)/∂(δψ_L, δψ_R)
    /// of the prior's mean, K = P'_xb Λ (P' the regression's covariance with the
    /// prior, eq. 15; Λ the prior's information). The window re-estimates the biases
    /// from its own rows, so a loose prior moves the fix less than the biases held
    /// fixed would (P_xb P_bb⁻¹, which K tends to as the prior tightens). Two vehicles
    /// located through the same images do not share their biases' error: a yaw error
    /// turns each UAV's rays about the UAV, so their difference moves by about the
    /// yaw error times their separation (1 m per 2° at 30 m).
    pub bias_sensitivity: Matrix2<f64>,
    /// Covariance of the part of its (x, y) error that persists from pair to pair
    /// (the biases' error, and for a fix relative to the target the target's own
    /// estimate's), m²: a track that averages its fixes cannot average this away, so
    /// it adds it to the covariance it states.
    pub persistent_xy: Matrix2<f64>,
    /// How its z moves with the biases it is given, m/rad: ∂z/∂δψ of eq. (16)–(23)
    /// with the yaws corrected by them (eq. 19), by finite differences, times how the
    /// window's biases move with the prior's mean (P'_bb Λ).
    pub altitude_bias_sensitivity: [f64; 2],
    /// Variance of the part of its z error that persists from pair to pair, m² (as
    /// `persistent_xy`).
    pub persistent_z_var: f64,
    /// Standard error of z (eq. 22 residuals), metres.
    pub altitude_std_error_m: f64,
    /// The altitude its z is relative to, m: for a vehicle located relative to the
    /// target, the target's estimate at this pair (z is that plus the two windows'
    /// difference, so the target's error moves every such fix alike); `None` for a
    /// vehicle located alone.
    pub reference_z: Option<f64>,
    /// Its colour (BGR, the two views' mean), when known: appearance for
    /// re-identification.
    pub colour_bgr: Option<[f64; 3]>,
    /// Its covariance is its error's as stated: a vehicle located alone, whose
    /// images' GPS and attitude errors cancel against nothing. The tracks take it
    /// unscaled and learn no noise scale from it (their learnt scale is that of fixes
    /// relative to the target, whose stated covariance holds errors the difference
    /// cancels), and only into a confirmed track whose gate it falls in: it starts
    /// no track, and leaves the track's altitude (its own is metres off).
    pub as_stated: bool,
}

/// Smallest bias variance used, rad² (0.01°): keeps the prior's information finite
/// when a filter reports a zero variance.
const MIN_BIAS_VARIANCE: f64 = 3e-8;

/// Locates a vehicle from its `observations` (current and past images of both UAVs)
/// with the shared `biases`.
pub fn locate_with_biases(
    observations: &[Observation],
    biases: &SharedBiases,
    config: &EstimatorConfig,
) -> Result<OtherFix, EstimatorError> {
    // The biases known, one image per UAV is enough: 4 rows and the prior's 2 for the
    // 4 unknowns (past images the vehicle's transfer missed are left out).
    validate_set(observations, 2)?;
    let covariance = biases.covariance + Matrix2::identity() * MIN_BIAS_VARIANCE;
    let information = covariance
        .try_inverse()
        .filter(|m| m.iter().all(|v| v.is_finite()))
        .ok_or(EstimatorError::NonFiniteResult {
            what: "shared bias information",
        })?;
    if !biases.mean.iter().all(|v| v.is_finite()) {
        return Err(EstimatorError::NonFiniteResult {
            what: "shared biases",
        });
    }
    let min_angle = config.min_ray_angle_deg.to_radians();
    let rays: Vec<PreparedRay> = observations.iter().map(PreparedRay::new).collect();
    let tolerance = config.bias_tolerance_deg.to_radians();
    let mut bias = biases.mean;
    let mut last = None;
    // As the paper's iteration: until the bias update is below the tolerance (a
    // tight prior settles it in two rounds) or `max_iterations`.
    for _ in 0..config.max_iterations.max(1) {
        let altitude = estimate_altitude(observations, &rays, bias, min_angle)?;
        // The prior is on δψ; the regression solves for Δ = δψ − bias.
        let prior = BiasPrior {
            information,
            mean: Vector2::new(biases.mean[0] - bias[0], biases.mean[1] - bias[1]),
        };
        let solution = solve_regression_with_prior(
            observations,
            &rays,
            altitude.z_target,
            bias,
            Some(prior),
            config,
        )?;
        bias[0] += solution.bias_update[0];
        bias[1] += solution.bias_update[1];
        let step = solution.bias_update[0]
            .abs()
            .max(solution.bias_update[1].abs());
        last = Some((altitude, solution));
        if step < tolerance {
            break;
        }
    }
    let Some((altitude, solution)) = last else {
        return Err(EstimatorError::NonFiniteResult { what: "no round" });
    };
    let p = &solution.covariance;
    let pxx = p.fixed_view::<2, 2>(0, 0).into_owned();
    let pxb = p.fixed_view::<2, 2>(0, 2).into_owned();
    let pbb = p.fixed_view::<2, 2>(2, 2).into_owned();
    // With the biases known exactly: the Schur complement of their block.
    let given_biases = pbb
        .try_inverse()
        .map_or(pxx, |inv| pxx - pxb * inv * pxb.transpose());
    // The solution is P' (Aᵀ Q⁻¹ b + Λ m): it moves by P' Λ per unit of the prior's
    // mean m, (x, y) by P'_xb Λ and the biases by P'_bb Λ.
    let sensitivity = pxb * information;
    let biases_follow = pbb * information;
    let jz = Vector2::from(altitude_sensitivity(observations, &rays, bias, min_angle));
    let kz = biases_follow.transpose() * jz;
    let fix = OtherFix {
        position: Point3::new(solution.xy.x, solution.xy.y, altitude.z_target),
        covariance_xy: pxx,
        covariance_xy_given_biases: given_biases,
        bias_sensitivity: sensitivity,
        persistent_xy: sensitivity * covariance * sensitivity.transpose(),
        altitude_bias_sensitivity: [kz.x, kz.y],
        persistent_z_var: kz.dot(&(covariance * kz)),
        altitude_std_error_m: altitude.std_error_m,
        reference_z: None,
        colour_bgr: None,
        as_stated: true,
    };
    let finite = fix.position.iter().all(|v| v.is_finite())
        && fix.covariance_xy.iter().all(|v| v.is_finite())
        && fix.covariance_xy_given_biases.iter().all(|v| v.is_finite())
        && fix.bias_sensitivity.iter().all(|v| v.is_finite())
        && fix.persistent_xy.iter().all(|v| v.is_finite())
        && fix.persistent_z_var.is_finite()
        && fix.altitude_std_error_m.is_finite();
    if finite {
        Ok(fix)
    } else {
        Err(EstimatorError::NonFiniteResult { what: "other fix" })
    }
}

/// ∂z/∂(δψ_L, δψ_R) of the altitude (eq. 16–23) at `bias`, m/rad, by finite
/// differences of 1e-4 rad (the midpoints' selection makes no closed form worth its
/// code). The two one-sided differences must agree (within half the larger and
/// 1 m/rad): a step that crosses the near-parallel threshold of a ray pair jumps by
/// metres, and the smaller of two disagreeing ones is taken. 0 where the altitude
/// refuses a neighbour.
fn altitude_sensitivity(
    observations: &[Observation],
    rays: &[PreparedRay],
    bias: [f64; 2],
    min_angle_rad: f64,
) -> [f64; 2] {
    const STEP_RAD: f64 = 1e-4;
    let at = |b: [f64; 2]| {
        estimate_altitude(observations, rays, b, min_angle_rad)
            .ok()
            .map(|a| a.z_target)
            .filter(|z| z.is_finite())
    };
    let Some(here) = at(bias) else {
        return [0.0; 2];
    };
    std::array::from_fn(|k| {
        let moved = |step: f64| {
            let mut b = bias;
            b[k] += step;
            at(b)
        };
        match (moved(STEP_RAD), moved(-STEP_RAD)) {
            (Some(up), Some(down)) => {
                let (fwd, bwd) = ((up - here) / STEP_RAD, (here - down) / STEP_RAD);
                if (fwd - bwd).abs() <= 0.5 * fwd.abs().max(bwd.abs()) + 1.0 {
                    (fwd + bwd) / 2.0
                } else if fwd.abs() < bwd.abs() {
                    fwd
                } else {
                    bwd
                }
            }
            _ => 0.0,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{NavNoise, SyntheticScenario};
    use rand::rngs::StdRng;
    use rand::SeedableRng;

    fn biases(mean_deg: [f64; 2], sigma_deg: f64) -> SharedBiases {
        SharedBiases {
            mean: mean_deg.map(f64::to_radians),
            covariance: Matrix2::identity() * sigma_deg.to_radians().powi(2),
        }
    }

    /// Without navigation noise and with the true (constant) biases known tightly, the
    /// vehicle is where it is; with biases 5° off and known tightly, it is off; with
    /// the same wrong biases held loosely (σ 30°), the images pull it back.
    #[test]
    fn the_prior_decides_as_its_confidence_says() {
        let s = SyntheticScenario {
            noise: NavNoise::NONE,
            bias: shared_types::nav_noise::BiasModel::Constant {
                left_deg: 20.0,
                right_deg: -15.0,
            },
            ..SyntheticScenario::default()
        };
        let trial = s.trial(6.0, 4, &mut StdRng::seed_from_u64(3)).unwrap();
        let truth = [
            trial.yaw_bias[0].to_degrees(),
            trial.yaw_bias[1].to_degrees(),
        ];
        let cfg = EstimatorConfig::default();
        let error = |b: &SharedBiases| {
            let fix = locate_with_biases(&trial.observations, b, &cfg).unwrap();
            (fix.position - trial.target).xy().norm()
        };
        let exact = error(&biases(truth, 0.1));
        assert!(exact < 0.05, "{exact}");
        let off = [truth[0] + 5.0, truth[1] - 5.0];
        let tight = error(&biases(off, 0.1));
        let loose = error(&biases(off, 30.0));
        // The paper's estimate of this window without any prior, for scale.
        let alone = (crate::geolocate(&trial.observations, &cfg)
            .unwrap()
            .position
            - trial.target)
            .xy()
            .norm();
        assert!(tight > 3.0, "{tight}");
        assert!(
            loose < tight / 4.0 && loose < alone + 1.0,
            "{loose} ({alone} alone)"
        );
        // The covariance says so.
        let fix = locate_with_biases(&trial.observations, &biases(truth, 0.1), &cfg).unwrap();
        let wide = locate_with_biases(&trial.observations, &biases(truth, 5.0), &cfg).unwrap();
        assert!(wide.covariance_xy.trace() > fix.covariance_xy.trace());
        assert!(wide.covariance_xy_given_biases.trace() < wide.covariance_xy.trace());
    }

    /// `bias_sensitivity` is how the fix moves when the biases it is given (the
    /// prior's mean) move: a finite difference agrees within 2 %, with a tight prior
    /// (σ 0.001°: the biases held) and with a loose one (σ 3°: the window's own rows
    /// pull the biases back, and the fix moves 6 % less than with the biases held,
    /// which the 2 % tells apart). The same for z.
    #[test]
    fn the_bias_sensitivity_is_the_fixs_own_derivative() {
        let s = SyntheticScenario::default();
        let trial = s.trial(6.0, 4, &mut StdRng::seed_from_u64(5)).unwrap();
        // Iterated to convergence, so that a 0.05° step is not lost in the tolerance.
        let cfg = EstimatorConfig {
            bias_tolerance_deg: 1e-7,
            max_iterations: 60,
            ..EstimatorConfig::default()
        };
        let mut held = Matrix2::zeros();
        for sigma_deg in [0.001, 3.0] {
            let at = |b: [f64; 2]| {
                locate_with_biases(&trial.observations, &biases(b, sigma_deg), &cfg).unwrap()
            };
            let base = at([3.0, -2.0]);
            let step_deg = 0.05;
            for k in 0..2 {
                let mut b = [3.0, -2.0];
                b[k] += step_deg;
                let moved = at(b);
                let dxy = (moved.position - base.position).xy() / step_deg.to_radians();
                let predicted = base.bias_sensitivity.column(k).into_owned();
                assert!(predicted.norm() > 1.0, "σ {sigma_deg}°: {predicted}");
                assert!(
                    (dxy - predicted).norm() < 0.02 * predicted.norm(),
                    "σ {sigma_deg}°, bias {k}: {dxy} vs {predicted}"
                );
                let dz = (moved.position.z - base.position.z) / step_deg.to_radians();
                let predicted_z = base.altitude_bias_sensitivity[k];
                assert!(
                    (dz - predicted_z).abs() < 0.02 * predicted_z.abs() + 0.05,
                    "σ {sigma_deg}°, z, bias {k}: {dz} vs {predicted_z}"
                );
            }
            if sigma_deg < 0.01 {
                held = base.bias_sensitivity;
                assert!(base.altitude_bias_sensitivity.iter().any(|j| j.abs() > 1.0));
            } else {
                // Loosely held biases move the fix less.
                assert!(
                    base.bias_sensitivity.norm() < 0.97 * held.norm(),
                    "{} vs {}",
                    base.bias_sensitivity.norm(),
                    held.norm()
                );
                assert!(base.persistent_xy.trace() > 0.0);
            }
        }
    }

    #[test]
    fn bad_biases_are_refused() {
        let s = SyntheticScenario::default();
        let trial = s.trial(6.0, 4, &mut StdRng::seed_from_u64(3)).unwrap();
        let cfg = EstimatorConfig::default();
        let mut b = biases([0.0, 0.0], 1.0);
        b.mean[0] = f64::NAN;
        assert!(locate_with_biases(&trial.observations, &b, &cfg).is_err());
        let mut b = biases([0.0, 0.0], 1.0);
        b.covariance[(0, 0)] = f64::INFINITY;
        assert!(locate_with_biases(&trial.observations, &b, &cfg).is_err());
        let one = biases([0.0; 2], 1.0);
        assert!(locate_with_biases(&trial.observations[..1], &one, &cfg).is_err());
        // The current pair alone does, the biases known.
        assert!(locate_with_biases(&trial.observations[..2], &one, &cfg).is_ok());
    }
}
