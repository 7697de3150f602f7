//! Section 2.3's filter of wrong corresponding points by the consistency principle
//! (eq. 29–32), and the filtered geolocation that runs it.
//!
//! Each past image g_n forms a group (g_L1, g_R1, g_n) with the two current images; the
//! altitude/regression iteration on that group gives a bias estimate ζ₂ₙ = (δψ_Lⁿ, δψ_Rⁿ).
//! Estimates that agree with most others are kept; a wrong correspondence gives a bias
//! estimate that disagrees with the rest.

use crate::iteration::{geolocate, geolocate_paper, Estimate};
use crate::{EstimatorConfig, EstimatorError, Observation};

/// What eq. (29)–(32) decided for a set of 2N − 2 bias estimates.
#[derive(Debug, Clone, PartialEq)]
pub struct ConsistencyOutcome {
    /// C_n of eq. (29), one per estimate.
    pub factors: Vec<f64>,
    /// C_max.
    pub c_max: f64,
    /// n with C_n = C_max (ties: the estimate with the smallest Σ_m e_nm, then the lowest n).
    pub reference: usize,
    /// S_p of eq. (32): indices m with e_{reference,m} ≥ TH, in increasing order.
    pub rejected: Vec<usize>,
}

/// Eq. (31): e_nm = |δψ_Lⁿ − δψ_Lᵐ| + |δψ_Rⁿ − δψ_Rᵐ|.
pub fn bias_disagreement(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).abs() + (a[1] - b[1]).abs()
}

/// Eq. (29)–(32) for one bias estimate per past image (radians) and threshold TH.
///
/// The N = 2 case is the paper's: with two past images that disagree (e₁₂ ≥ TH) both are
/// eliminated and the geolocation is terminated, returned as
/// [`EstimatorError::InconsistentPastImages`].
pub fn consistency_filter(
    bias_estimates: &[[f64; 2]],
    threshold_rad: f64,
) -> Result<ConsistencyOutcome, EstimatorError> {
    let count = bias_estimates.len();
    if bias_estimates.iter().flatten().any(|v| !v.is_finite()) {
        return Err(EstimatorError::NonFinite {
            index: 0,
            what: "bias estimate given to the consistency filter",
        });
    }
    if count == 0 {
        return Ok(ConsistencyOutcome {
            factors: Vec::new(),
            c_max: 0.0,
            reference: 0,
            rejected: Vec::new(),
        });
    }
    if count == 2 {
        let e = bias_disagreement(bias_estimates[0], bias_estimates[1]);
        if e >= threshold_rad {
            return Err(EstimatorError::InconsistentPastImages {
                disagreement_deg: e.to_degrees(),
            });
        }
    }

    // Eq. (29)–(30): C_n = Σ_{m≠n} 𝕀(e_nm < TH) / (2N − 2).
    let mut factors = Vec::with_capacity(count);
    let mut spread = Vec::with_capacity(count);
    for (n, zeta_n) in bias_estimates.iter().enumerate() {
        let mut agree = 0usize;
        let mut total = 0.0;
        for (m, zeta_m) in bias_estimates.iter().enumerate() {
            if m == n {
                continue;
            }
            let e = bias_disagreement(*zeta_n, *zeta_m);
            total += e;
            if e < threshold_rad {
                agree += 1;
            }
        }
        factors.push(agree as f64 / count as f64);
        spread.push(total);
    }

    // C_max and its estimate.
    let reference = (0..count)
        .max_by(|&a, &b| {
            factors[a]
                .total_cmp(&factors[b])
                .then(spread[b].total_cmp(&spread[a]))
                .then(b.cmp(&a))
        })
        .unwrap_or(0);

    // Eq. (32): S_p = { p_m | e_nm ≥ TH } for the reference n.
    let rejected = (0..count)
        .filter(|&m| {
            bias_disagreement(bias_estimates[reference], bias_estimates[m]) >= threshold_rad
        })
        .collect();
    Ok(ConsistencyOutcome {
        c_max: factors[reference],
        factors,
        reference,
        rejected,
    })
}

/// Why a past image did not take part in the final estimate.
#[derive(Debug, Clone, PartialEq)]
pub enum PastImageRejection {
    /// Its group (g_L1, g_R1, g_n) could not be estimated.
    GroupFailed(EstimatorError),
    /// The consistency filter put it in S_p.
    Inconsistent,
}

/// A filtered geolocation and what was left out.
#[derive(Debug, Clone, PartialEq)]
pub struct FilteredEstimate {
    pub estimate: Estimate,
    /// Per past image (same order as given): `None` if kept, else why it was rejected.
    pub past_rejections: Vec<Option<PastImageRejection>>,
    /// The consistency filter's decision over the groups that could be estimated.
    pub consistency: ConsistencyOutcome,
}

/// Section 2.3 then 2.1–2.2: estimate each group (g_L1, g_R1, g_n), filter by eq.
/// (29)–(32), and run the altitude/regression iteration on the current pair plus the
/// past images that survived.
pub fn geolocate_filtered(
    current_left: &Observation,
    current_right: &Observation,
    past: &[Observation],
    config: &EstimatorConfig,
) -> Result<FilteredEstimate, EstimatorError> {
    filtered_with(current_left, current_right, past, config, geolocate)
}

/// [`geolocate_filtered`] with the paper's iteration exactly (no restarts for oblique
/// rays, `iteration::geolocate_paper`): the evaluation's "paper's method" columns.
pub fn geolocate_filtered_paper(
    current_left: &Observation,
    current_right: &Observation,
    past: &[Observation],
    config: &EstimatorConfig,
) -> Result<FilteredEstimate, EstimatorError> {
    filtered_with(current_left, current_right, past, config, geolocate_paper)
}

type Solve = fn(&[Observation], &EstimatorConfig) -> Result<Estimate, EstimatorError>;

fn filtered_with(
    current_left: &Observation,
    current_right: &Observation,
    past: &[Observation],
    config: &EstimatorConfig,
    geolocate: Solve,
) -> Result<FilteredEstimate, EstimatorError> {
    let mut past_rejections: Vec<Option<PastImageRejection>> = vec![None; past.len()];
    let mut group_biases = Vec::with_capacity(past.len());
    let mut group_index = Vec::with_capacity(past.len());
    for (n, image) in past.iter().enumerate() {
        match geolocate(&[*current_left, *current_right, *image], config) {
            Ok(group) => {
                group_biases.push(group.yaw_bias);
                group_index.push(n);
            }
            Err(e) => past_rejections[n] = Some(PastImageRejection::GroupFailed(e)),
        }
    }
    if group_biases.len() < config.min_past_images_to_compare {
        return Err(EstimatorError::TooFewPastImagesToCompare {
            estimated: group_biases.len(),
            required: config.min_past_images_to_compare,
        });
    }
    let consistency =
        consistency_filter(&group_biases, config.consistency_threshold_deg.to_radians())?;
    for &m in &consistency.rejected {
        past_rejections[group_index[m]] = Some(PastImageRejection::Inconsistent);
    }

    let mut kept = Vec::with_capacity(past.len() + 2);
    kept.push(*current_left);
    kept.push(*current_right);
    kept.extend(
        past.iter()
            .zip(&past_rejections)
            .filter(|(_, r)| r.is_none())
            .map(|(o, _)| *o),
    );
    let estimate = geolocate(&kept, config)?;
    Ok(FilteredEstimate {
        estimate,
        past_rejections,
        consistency,
    })
}

/// [`geolocate_filtered`], then, when `config.method` is `Joint`, the joint estimator
/// on the same kept images, started from the paper's estimate.
pub fn geolocate_configured(
    current_left: &Observation,
    current_right: &Observation,
    past: &[Observation],
    config: &EstimatorConfig,
) -> Result<FilteredEstimate, EstimatorError> {
    let mut filtered = geolocate_filtered(current_left, current_right, past, config)?;
    if config.method == crate::config::EstimatorMethod::Joint {
        let mut kept = vec![*current_left, *current_right];
        kept.extend(
            past.iter()
                .zip(&filtered.past_rejections)
                .filter(|(_, r)| r.is_none())
                .map(|(o, _)| *o),
        );
        let e = &filtered.estimate;
        filtered.estimate = crate::joint::geolocate_joint(&kept, (e.position, e.yaw_bias), config)?;
    }
    Ok(filtered)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn deg(l: f64, r: f64) -> [f64; 2] {
        [l.to_radians(), r.to_radians()]
    }

    #[test]
    fn configured_joint_method_recovers_exact_data_and_matches_the_paper() {
        use crate::synthetic::SyntheticScenario;
        use rand::SeedableRng;
        use shared_types::nav_noise::{BiasModel, NavNoise};
        let scenario = SyntheticScenario {
            noise: NavNoise::NONE,
            sigma_pixel_px: 0.0,
            bias: BiasModel::Constant {
                left_deg: 9.0,
                right_deg: -11.0,
            },
            ..SyntheticScenario::default()
        };
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let trial = scenario.trial(15.0, 4, &mut rng).unwrap();
        let o = &trial.observations;
        // Without the bias prior: on exact data the joint least squares is exact.
        let joint = EstimatorConfig {
            method: crate::config::EstimatorMethod::Joint,
            joint_bias_prior_deg: 0.0,
            ..EstimatorConfig::default()
        };
        let paper =
            geolocate_configured(&o[0], &o[1], &o[2..], &EstimatorConfig::default()).unwrap();
        let refined = geolocate_configured(&o[0], &o[1], &o[2..], &joint).unwrap();
        let paper_error = (paper.estimate.position - trial.target).norm();
        let error = (refined.estimate.position - trial.target).norm();
        assert!(
            error < 0.05,
            "joint {error} m, paper {paper_error} m, {:?} / {:?}",
            refined.estimate.yaw_bias,
            trial.yaw_bias
        );
        assert!((refined.estimate.yaw_bias[0] - trial.yaw_bias[0]).abs() < 1e-3);
        assert!((refined.estimate.yaw_bias[1] - trial.yaw_bias[1]).abs() < 1e-3);
        assert_eq!(refined.past_rejections, paper.past_rejections);
    }

    #[test]
    fn a_lone_past_image_is_refused_unless_configured_otherwise() {
        use crate::synthetic::SyntheticScenario;
        use rand::SeedableRng;
        use shared_types::nav_noise::NavNoise;
        let scenario = SyntheticScenario {
            noise: NavNoise::NONE,
            sigma_pixel_px: 0.0,
            ..SyntheticScenario::default()
        };
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let trial = scenario.trial(15.0, 4, &mut rng).unwrap();
        let o = &trial.observations;
        let config = EstimatorConfig::default();
        assert_eq!(config.min_past_images_to_compare, 2);
        // Two past images: compared, estimated.
        assert!(geolocate_filtered(&o[0], &o[1], &o[2..4], &config).is_ok());
        // One: nothing to compare it with.
        let e = geolocate_filtered(&o[0], &o[1], &o[2..3], &config).unwrap_err();
        assert_eq!(
            e,
            EstimatorError::TooFewPastImagesToCompare {
                estimated: 1,
                required: 2
            }
        );
        assert_eq!(e.kind(), "too_few_past_images_to_compare");
        // The paper's behaviour on request.
        let paper = EstimatorConfig {
            min_past_images_to_compare: 1,
            ..config
        };
        let lone = geolocate_filtered(&o[0], &o[1], &o[2..3], &paper).unwrap();
        assert_eq!(lone.past_rejections, vec![None]);
    }

    #[test]
    fn outlier_is_rejected_and_agreeing_estimates_kept() {
        let est = [
            deg(20.0, -20.0),
            deg(20.5, -19.8),
            deg(35.0, -5.0), // planted outlier
            deg(19.7, -20.3),
            deg(20.2, -20.1),
            deg(19.9, -19.6),
        ];
        let out = consistency_filter(&est, 3f64.to_radians()).unwrap();
        assert_eq!(out.rejected, vec![2]);
        assert_eq!(out.factors[2], 0.0);
        // Five agreeing estimates: each agrees with the four others → C = 4/6.
        assert!((out.c_max - 4.0 / 6.0).abs() < 1e-12);
        assert_ne!(out.reference, 2);
    }

    #[test]
    fn n_equals_two_terminates_on_disagreement() {
        let err = consistency_filter(&[deg(20.0, -20.0), deg(26.0, -20.0)], 3f64.to_radians());
        assert!(matches!(
            err,
            Err(EstimatorError::InconsistentPastImages { disagreement_deg }) if (disagreement_deg - 6.0).abs() < 1e-9
        ));
        let ok =
            consistency_filter(&[deg(20.0, -20.0), deg(21.0, -20.0)], 3f64.to_radians()).unwrap();
        assert!(ok.rejected.is_empty());
    }

    #[test]
    fn threshold_is_strict_for_agreement() {
        // e = TH counts as disagreement (eq. 30: 1 only if e < TH; eq. 32: e ≥ TH rejected).
        let th = 2f64.to_radians();
        let out = consistency_filter(&[[0.0, 0.0], [th, 0.0], [0.0, 0.0]], th).unwrap();
        assert_eq!(out.rejected, vec![1]);
    }

    #[test]
    fn nan_is_rejected_with_a_reason() {
        let r = consistency_filter(&[[f64::NAN, 0.0], [0.0, 0.0], [0.0, 0.0]], 0.05);
        assert!(matches!(r, Err(EstimatorError::NonFinite { .. })));
    }
}
