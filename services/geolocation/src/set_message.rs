//! The geolocation service's intake: an [`ObservationSetMsg`] as it arrives from shared
//! memory in, an [`EstimateMsg`] out. Every field of the message is untrusted (the fuzz
//! target `observations` feeds it arbitrary bytes): a bad entry, count or value gives a
//! `BadInput` or `Rejected` status with its counter, never a panic and never a
//! non-finite estimate.

use crate::TemporalSnapshot;
use crate::{
    coast_set, estimate_set, EstimatorConfig, EstimatorError, Observation, PastImage,
    TemporalEstimator,
};
use serde::{Deserialize, Serialize};
use shared_types::messages::{EstimateMsg, EstimateStatus, ObservationEntry, ObservationSetMsg};
use shared_types::stats::StageStats;

/// The kind tag of the service's checkpoint (`shared_types::checkpoint`).
pub const CHECKPOINT_KIND: u32 = 2;

/// What a restarted geolocation service resumes from (its checkpoint's content).
#[derive(Debug, Serialize, Deserialize)]
pub struct Resume {
    /// Pair and stream time of the last estimate published.
    pub last_pair_seq: u64,
    pub last_t_s: f64,
    /// The temporal filter (`None` for the per-window methods, which keep no state).
    pub filter: Option<TemporalSnapshot>,
    /// The other vehicles' tracks (`None` with `[tracks] enabled = false`).
    pub tracks: Option<crate::tracks::TracksSnapshot>,
    /// The stream segment of the last set estimated (`FrameHeader::segment`).
    pub segment: u32,
}

/// What a set's stream segment means against that of the last set estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SegmentStep {
    /// The same segment (or the service's first set): go on.
    Same,
    /// The stream jumped (a looped recording starting over): the filter and the
    /// tracks start over, as for a new stream. The world they hold is gone: a filter
    /// carried over the jump coasted 64 m off for a second while stating ±2 m.
    New,
    /// A set of a segment already left behind: dropped (`stale_sets`).
    Old,
}

pub fn segment_step(segment: u32, last: Option<u32>) -> SegmentStep {
    match last {
        Some(s) if segment > s => SegmentStep::New,
        Some(s) if segment < s => SegmentStep::Old,
        _ => SegmentStep::Same,
    }
}

/// Whether a set must be dropped unseen (`stale_sets`): its time is not finite, or not
/// newer than the last estimate published. Keeps estimates in time order across a
/// restart, and a NaN time can never become the "last" one and disable the check.
pub fn is_stale(t_s: f64, last_t_s: Option<f64>) -> bool {
    !t_s.is_finite() || last_t_s.is_some_and(|t| t_s <= t)
}

/// No NaN leaves the service: an estimate with a non-finite value is a rejection.
pub fn finite(msg: &EstimateMsg) -> bool {
    msg.position
        .iter()
        .chain(&msg.yaw_bias_deg)
        .chain(&msg.covariance)
        .all(|v| v.is_finite())
        && msg.altitude_std_error_m.is_finite()
}

/// The estimate message of `set` before anything is estimated: the set's pair and
/// times, status `Ok`, the velocity and range unknown (NaN until estimated).
pub fn unestimated(set: &ObservationSetMsg) -> EstimateMsg {
    EstimateMsg {
        pair_seq: set.pair_seq,
        capture_ns: set.capture_ns,
        t_s: set.t_s,
        velocity_mps: [f64::NAN; 2],
        velocity_acc_mps: f64::NAN,
        range_m: f64::NAN,
        ..Default::default()
    }
}

/// The estimate of one observation set, or why there is none (the status, and a
/// counter in `stats`). A non-finite result is turned into `rejected.non_finite`.
pub fn estimate_message(
    set: &ObservationSetMsg,
    config: &EstimatorConfig,
    temporal: Option<&mut TemporalEstimator>,
    stats: &mut StageStats,
) -> EstimateMsg {
    let msg = estimate_unchecked(set, config, temporal, stats, false);
    checked(msg, config, stats)
}

/// [`estimate_message`] taking none of the set's rays: the temporal filter's
/// prediction (`coasting`), for a set whose detections are another vehicle's
/// (`target_identity.rs`) or two vehicles (a refused set). Without a started temporal
/// filter, rejected (`rejected.not_started`).
pub fn coast_message(
    set: &ObservationSetMsg,
    config: &EstimatorConfig,
    temporal: Option<&mut TemporalEstimator>,
    stats: &mut StageStats,
) -> EstimateMsg {
    let msg = estimate_unchecked(set, config, temporal, stats, true);
    checked(msg, config, stats)
}

/// A valid estimate that is not finite is rejected, one less accurate than
/// `max_h_acc_m` withheld (counted).
fn checked(mut msg: EstimateMsg, config: &EstimatorConfig, stats: &mut StageStats) -> EstimateMsg {
    if msg.status == EstimateStatus::Ok as u32 && !finite(&msg) {
        stats.count("rejected.non_finite", 1);
        msg.status = EstimateStatus::Rejected as u32;
    }
    if msg.status == EstimateStatus::Ok as u32
        && config.max_h_acc_m > 0.0
        && h_acc(&msg) > config.max_h_acc_m
    {
        stats.count("withheld.h_acc", 1);
        msg.status = EstimateStatus::Withheld as u32;
    }
    msg
}

/// √(σ_x² + σ_y²) of an estimate, m.
/// The set's past images (`entries` after the current pair, with their decoded
/// observations) as the temporal filter takes them, and how many rotations were
/// refused. A rotation vector that is not finite or turns more than π is no
/// measurement (matching writes `log R`, at most π): it is dropped, never passed on.
fn past_images(
    entries: &[ObservationEntry],
    observations: &[Observation],
) -> (Vec<PastImage>, usize) {
    let mut refused = 0;
    let past = entries
        .iter()
        .zip(observations)
        .map(|(entry, o)| PastImage {
            id: (o.uav, entry.frame_seq),
            t_s: entry.t_s,
            observation: *o,
            rotation_from: [0, 1].map(|side| {
                let v = entry.rotation_from(side).map(nalgebra::Vector3::from)?;
                let angle = v.norm();
                if angle.is_finite() && angle <= std::f64::consts::PI + 1e-9 {
                    Some(v)
                } else {
                    refused += 1;
                    None
                }
            }),
        })
        .collect();
    (past, refused)
}

pub fn h_acc(msg: &EstimateMsg) -> f64 {
    (msg.covariance[0] + msg.covariance[5]).max(0.0).sqrt()
}

fn estimate_unchecked(
    set: &ObservationSetMsg,
    config: &EstimatorConfig,
    temporal: Option<&mut TemporalEstimator>,
    stats: &mut StageStats,
    coast: bool,
) -> EstimateMsg {
    let mut msg = unestimated(set);
    if !set.t_s.is_finite() {
        stats.count("bad_input", 1);
        tracing::warn!(pair = set.pair_seq, "observation set time is not finite");
        msg.status = EstimateStatus::BadInput as u32;
        return msg;
    }
    let observations: Result<Vec<Observation>, _> = set
        .entries()
        .iter()
        .enumerate()
        .map(|(i, e)| Observation::from_entry(e, i))
        .collect();
    let observations = match observations {
        Ok(o) if o.len() >= 2 && set.count as usize == o.len() => o,
        Ok(_) => {
            stats.count("bad_input", 1);
            tracing::warn!(
                pair = set.pair_seq,
                count = set.count,
                "observation set count is invalid"
            );
            msg.status = EstimateStatus::BadInput as u32;
            return msg;
        }
        Err(e) => {
            stats.count("bad_input", 1);
            tracing::warn!(pair = set.pair_seq, "observation set rejected: {e}");
            msg.status = EstimateStatus::BadInput as u32;
            return msg;
        }
    };
    let (past, refused_rotations) = past_images(&set.entries()[2..], &observations[2..]);
    if refused_rotations > 0 {
        stats.count("bad_rotation", refused_rotations as u64);
        tracing::warn!(
            pair = set.pair_seq,
            refused_rotations,
            "past images' rotations not finite or beyond π: not taken"
        );
    }
    let current = [&observations[0], &observations[1]];
    let result = if coast {
        temporal
            .and_then(|filter| coast_set(set.t_s, current, filter))
            .unwrap_or(Err(EstimatorError::NotStarted {
                reason: "a set whose rays may not be taken, and no filter to predict",
            }))
    } else {
        estimate_set(set.t_s, current, &past, config, temporal)
    };
    let result = result.inspect(|e| {
        if e.reopened {
            stats.count("temporal_reopened", 1);
            tracing::info!(
                pair = set.pair_seq,
                "bias step suspected: covariance re-opened"
            );
        }
        if e.velocity.is_some() {
            stats.count("temporal_rays_rejected", e.rays_rejected as u64);
        }
    });
    match result {
        Ok(set_estimate) => {
            if let (Some(v), Some(sd)) = (set_estimate.velocity, set_estimate.velocity_std_mps) {
                msg.velocity_mps = v;
                msg.velocity_acc_mps = sd[0].hypot(sd[1]);
            }
            let e = set_estimate.estimate;
            msg.range_m = (e.position - observations[0].position).norm();
            stats.count("estimates", 1);
            msg.position = [e.position.x, e.position.y, e.position.z];
            msg.yaw_bias_deg = [e.yaw_bias[0].to_degrees(), e.yaw_bias[1].to_degrees()];
            for (i, v) in e.covariance.transpose().iter().enumerate() {
                msg.covariance[i] = *v;
            }
            msg.altitude_std_error_m = e.altitude_std_error_m;
            msg.images_used = e.images_used as u32;
            msg.iterations = e.iterations as u32;
            msg.converged = e.converged as u32;
            msg.quality = set_estimate.quality as u64;
            stats.count(&format!("quality.{}", set_estimate.quality.name()), 1);
        }
        Err(e) => {
            stats.count(&format!("rejected.{}", e.kind()), 1);
            tracing::debug!(pair = set.pair_seq, "no estimate: {e}");
            msg.status = EstimateStatus::Rejected as u32;
        }
    }
    msg
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::synthetic::SyntheticScenario;
    use rand::SeedableRng;

    pub(crate) fn set_at(t_s: f64) -> ObservationSetMsg {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let trial = SyntheticScenario::default()
            .trial(t_s, 4, &mut rng)
            .expect("the default scenario keeps the target in view");
        let mut set = ObservationSetMsg {
            t_s,
            ..Default::default()
        };
        for (i, (slot, o)) in set.entries.iter_mut().zip(&trial.observations).enumerate() {
            *slot = o.to_entry();
            slot.frame_seq = i as u64;
            slot.t_s = t_s;
            set.count += 1;
        }
        set
    }

    #[test]
    fn a_good_set_gives_a_finite_estimate() {
        let config = EstimatorConfig {
            method: crate::EstimatorMethod::Paper,
            ..Default::default()
        };
        let mut stats = StageStats::new("t");
        let msg = estimate_message(&set_at(10.0), &config, None, &mut stats);
        assert_eq!(msg.status, EstimateStatus::Ok as u32);
        assert!(finite(&msg));
        assert_eq!(stats.counter("estimates"), 1);
    }

    #[test]
    fn bad_sets_are_counted_not_estimated() {
        let config = EstimatorConfig::default();
        let mut temporal = TemporalEstimator::new(config).unwrap();
        let mut stats = StageStats::new("t");
        let mut nan_pixel = set_at(10.0);
        nan_pixel.entries[3].pixel[0] = f64::NAN;
        let mut one = set_at(10.0);
        one.count = 1;
        let mut nan_time = set_at(10.0);
        nan_time.t_s = f64::NAN;
        for set in [nan_pixel, one, nan_time] {
            let msg = estimate_message(&set, &config, Some(&mut temporal), &mut stats);
            assert_eq!(msg.status, EstimateStatus::BadInput as u32);
        }
        assert_eq!(stats.counter("bad_input"), 3);
        // The filter was not touched: good sets start it (three agreeing window
        // estimates; the first two are refused and counted) and it estimates.
        for t in [10.3, 10.4] {
            let msg = estimate_message(&set_at(t), &config, Some(&mut temporal), &mut stats);
            assert_eq!(msg.status, EstimateStatus::Rejected as u32);
        }
        assert_eq!(stats.counter("rejected.not_started"), 2);
        let msg = estimate_message(&set_at(10.5), &config, Some(&mut temporal), &mut stats);
        assert_eq!(msg.status, EstimateStatus::Ok as u32);
    }

    /// Feeds the sets that start the filter (it needs three agreeing ones).
    fn start(temporal: &mut TemporalEstimator, config: &EstimatorConfig, stats: &mut StageStats) {
        for t in [9.8, 9.9] {
            estimate_message(&set_at(t), config, Some(temporal), stats);
        }
    }

    #[test]
    fn estimates_above_max_h_acc_are_withheld_and_counted() {
        let config = EstimatorConfig::default();
        let mut temporal = TemporalEstimator::new(config).unwrap();
        let mut stats = StageStats::new("t");
        // The first estimate of the filter is converging: its h_acc is large.
        start(&mut temporal, &config, &mut stats);
        let open = estimate_message(&set_at(10.0), &config, Some(&mut temporal), &mut stats);
        assert_eq!(open.status, EstimateStatus::Ok as u32);
        assert_eq!(open.quality, crate::Quality::Converging as u64);
        let strict = EstimatorConfig {
            max_h_acc_m: h_acc(&open) / 2.0,
            ..config
        };
        let mut temporal = TemporalEstimator::new(strict).unwrap();
        start(&mut temporal, &strict, &mut stats);
        let msg = estimate_message(&set_at(10.0), &strict, Some(&mut temporal), &mut stats);
        assert_eq!(msg.status, EstimateStatus::Withheld as u32);
        assert_eq!(stats.counter("withheld.h_acc"), 1);
    }

    /// A set whose rays may not be taken (refused, or another vehicle's) gives the
    /// filter's prediction: before the start nothing; after it, the position the
    /// filter predicts (its own `predict_target`), not `tracking`, no image used;
    /// the same set taken as usual moves the estimate.
    #[test]
    fn a_coasted_set_gives_the_prediction_and_takes_no_ray() {
        let config = EstimatorConfig::default();
        let mut temporal = TemporalEstimator::new(config).unwrap();
        let mut stats = StageStats::new("t");
        let before = coast_message(&set_at(9.7), &config, Some(&mut temporal), &mut stats);
        assert_eq!(before.status, EstimateStatus::Rejected as u32);
        assert_eq!(stats.counter("rejected.not_started"), 1);
        start(&mut temporal, &config, &mut stats);
        for k in 0..20 {
            estimate_message(
                &set_at(10.0 + 0.1 * k as f64),
                &config,
                Some(&mut temporal),
                &mut stats,
            );
        }
        let t = 12.05;
        let predicted = temporal.predict_target(t).expect("started");
        let mut far = set_at(t);
        // Both detections 40 px off: taken, they would move the estimate.
        for e in &mut far.entries[..2] {
            e.pixel[0] += 40.0;
        }
        let mut coasting = temporal.clone();
        let coasted = coast_message(&far, &config, Some(&mut coasting), &mut stats);
        assert_eq!(coasted.status, EstimateStatus::Ok as u32);
        assert_eq!(coasted.images_used, 0);
        assert_ne!(coasted.quality, crate::Quality::Tracking as u64);
        for (a, b) in coasted.position[..2].iter().zip(predicted.position) {
            assert!(
                (a - b).abs() < 1e-6,
                "{:?} {:?}",
                coasted.position,
                predicted.position
            );
        }
        let taken = estimate_message(&far, &config, Some(&mut temporal), &mut stats);
        let moved = (taken.position[0] - coasted.position[0])
            .hypot(taken.position[1] - coasted.position[1]);
        assert!(
            taken.images_used > 0 && moved > 0.1,
            "taken: moved {moved} m"
        );
    }

    /// A set of a later segment starts the filter over: the next set is not
    /// estimated from the old world (the filter needs its agreeing starts again).
    #[test]
    fn a_past_images_rotations_are_decoded_and_bad_ones_refused() {
        use shared_types::conventions::Uav;
        let o = |uav| Observation {
            uav,
            position: nalgebra::Point3::new(0.0, 0.0, 100.0),
            attitude: shared_types::conventions::Attitude::new(0.0, 0.0, 0.0),
            mount: shared_types::conventions::Mount::NADIR,
            pixel: nalgebra::Vector2::new(320.0, 240.0),
            intrinsics: shared_types::conventions::Intrinsics::new(554.0, 554.0, 319.5, 239.5),
        };
        let mut entry = o(Uav::Right).to_entry();
        entry.frame_seq = 7;
        entry.rotation = [[0.01, -0.02, 0.3], [f64::NAN, 0.0, 0.0]];
        entry.rotation_valid = 0b11;
        let (past, refused) = past_images(&[entry], &[o(Uav::Right)]);
        assert_eq!(past[0].id, (Uav::Right, 7));
        assert_eq!(
            past[0].rotation_from,
            [Some(nalgebra::Vector3::new(0.01, -0.02, 0.3)), None]
        );
        assert_eq!(refused, 1);
        // Finite but huge (its norm overflows), or beyond π: refused too.
        entry.rotation = [[1e300, 1e300, 0.0], [4.0, 0.0, 0.0]];
        assert_eq!(past_images(&[entry], &[o(Uav::Right)]).1, 2);
        entry.rotation_valid = 0;
        let (past, refused) = past_images(&[entry], &[o(Uav::Right)]);
        assert_eq!((past[0].rotation_from, refused), ([None; 2], 0));
    }

    #[test]
    fn a_new_segment_starts_the_filter_over() {
        assert_eq!(segment_step(0, None), SegmentStep::Same);
        assert_eq!(segment_step(3, None), SegmentStep::Same);
        assert_eq!(segment_step(1, Some(1)), SegmentStep::Same);
        assert_eq!(segment_step(2, Some(1)), SegmentStep::New);
        assert_eq!(segment_step(0, Some(1)), SegmentStep::Old);
        let config = EstimatorConfig::default();
        let mut temporal = TemporalEstimator::new(config).unwrap();
        let mut stats = StageStats::new("t");
        start(&mut temporal, &config, &mut stats);
        let msg = estimate_message(&set_at(10.0), &config, Some(&mut temporal), &mut stats);
        assert_eq!(msg.status, EstimateStatus::Ok as u32);
        temporal.reset();
        let msg = estimate_message(&set_at(10.1), &config, Some(&mut temporal), &mut stats);
        assert_eq!(msg.status, EstimateStatus::Rejected as u32);
        assert_eq!(stats.counter("rejected.not_started"), 3);
    }

    #[test]
    fn staleness_never_trusts_a_non_finite_time() {
        assert!(!is_stale(1.0, None));
        assert!(is_stale(1.0, Some(1.0)));
        assert!(!is_stale(1.5, Some(1.0)));
        assert!(is_stale(f64::NAN, None));
        assert!(is_stale(f64::INFINITY, Some(1.0)));
    }
}
