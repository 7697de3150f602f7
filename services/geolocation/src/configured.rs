//! The configured estimator on one observation set: what the geolocation service
//! publishes and `dualgeo evaluate`'s scene suite measures, in one place.
//!
//! The per-window estimate comes first ([`geolocate_configured`]: the consistency
//! filter of eq. 29–32, then the paper's iteration, or the joint estimator). With
//! `method = "temporal"` the stateful filter is then fed the same set, started from that
//! window estimate the first time.

use crate::{
    geolocate_configured, Estimate, EstimatorConfig, EstimatorError, Observation, PastImage,
    TemporalEstimator,
};

/// One set's estimate, and what the temporal filter did with it.
#[derive(Debug, Clone)]
pub struct SetEstimate {
    pub estimate: Estimate,
    /// Target velocity (v_x, v_y) in m/s, when the temporal filter ran.
    pub velocity: Option<[f64; 2]>,
    /// Its 1σ per axis, m/s.
    pub velocity_std_mps: Option<[f64; 2]>,
    /// The temporal filter re-opened its covariance (bias step suspected).
    pub reopened: bool,
    /// Rays the temporal filter gated out.
    pub rays_rejected: usize,
    /// The temporal filter's quality state; a per-window estimate is `Tracking` (it
    /// is made from this set's rays alone).
    pub quality: crate::temporal::Quality,
}

/// `current` is the current (left, right) pair; `past` the past images with their
/// identities (UAV, frame sequence number) and capture times, in the order matching
/// gave them.
/// `temporal` must be `Some` exactly when `config.method` is `Temporal`.
pub fn estimate_set(
    t_s: f64,
    current: [&Observation; 2],
    past: &[PastImage],
    config: &EstimatorConfig,
    temporal: Option<&mut TemporalEstimator>,
) -> Result<SetEstimate, EstimatorError> {
    let past_only: Vec<Observation> = past.iter().map(|image| image.observation).collect();
    let window = geolocate_configured(current[0], current[1], &past_only, config);
    match temporal {
        None => window.map(|f| SetEstimate {
            estimate: f.estimate,
            velocity: None,
            velocity_std_mps: None,
            reopened: false,
            rays_rejected: 0,
            quality: crate::temporal::Quality::Tracking,
        }),
        Some(filter) => {
            let start = window.as_ref().ok().map(|f| &f.estimate);
            filter.update(t_s, current, past, start).map(of_filter)
        }
    }
}

/// The temporal filter's prediction at `t_s`, taking none of the set's rays (its
/// detections are another vehicle's: `target_identity.rs`); `None` before the start.
pub fn coast_set(
    t_s: f64,
    current: [&Observation; 2],
    temporal: &mut TemporalEstimator,
) -> Option<Result<SetEstimate, EstimatorError>> {
    temporal.coast(t_s, current).map(|r| r.map(of_filter))
}

fn of_filter(t: crate::temporal::TemporalEstimate) -> SetEstimate {
    SetEstimate {
        estimate: t.estimate,
        velocity: Some(t.velocity),
        velocity_std_mps: Some(t.velocity_std_mps),
        reopened: t.reopened,
        rays_rejected: t.rays_rejected,
        quality: t.quality,
    }
}
