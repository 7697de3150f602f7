//! What the geolocation service does with one observation set, without the transport:
//! the other vehicles' word on the target's detections (`target_identity.rs`), the
//! target's estimate or the filter's prediction ([`crate::set_message`]), then the
//! other vehicles' tracks ([`crate::others_message`]). The service shell (`main.rs`)
//! and `dualgeo evaluate`'s in-process chain both call [`Geolocator::estimate`], so the
//! Monte Carlo scores the service's own decisions.
//!
//! Counters (into the caller's [`StageStats`]): those of `set_message` and
//! `others_message`, and `sets_refused` (matching refused the pair as two vehicles),
//! `target_on_track` (the other vehicles say the target's detections are another
//! tracked vehicle's), `target_in_doubt` (right after a gap in the sets they put it in
//! doubt); in all three the filter's prediction is published, the set's rays untaken.

use crate::others_message::{add_tracks, detection_identity};
use crate::set_message::{coast_message, estimate_message};
use crate::target_identity::IdentityCheck;
use crate::tracks::{TrackConfig, Tracks};
use crate::{EstimatorConfig, TemporalEstimator};
use shared_types::messages::{EstimateMsg, ObservationSetMsg};
use shared_types::stats::StageStats;

/// The service's state between sets: the configured estimator's filter (`None` for the
/// per-window methods), the other vehicles' tracks and the identity evidence.
pub struct Geolocator {
    pub config: EstimatorConfig,
    pub track_config: TrackConfig,
    pub temporal: Option<TemporalEstimator>,
    pub tracks: Tracks,
    /// Not checkpointed: after a restart the evidence builds up again in a few pairs.
    identity: IdentityCheck,
}

impl Geolocator {
    /// `temporal` must be `Some` exactly when `config.method` is `Temporal`.
    pub fn new(
        config: EstimatorConfig,
        track_config: TrackConfig,
        temporal: Option<TemporalEstimator>,
        tracks: Tracks,
    ) -> Self {
        Self {
            config,
            track_config,
            temporal,
            tracks,
            identity: IdentityCheck::default(),
        }
    }

    /// A new stream segment (a looped recording starting over): the filter, the tracks
    /// and the evidence start over, as for a new stream.
    pub fn start_over(&mut self) {
        if let Some(t) = self.temporal.as_mut() {
            t.reset();
        }
        self.tracks.start_over();
        self.identity = IdentityCheck::default();
    }

    /// The estimate message of one set (its status says when there is none).
    pub fn estimate(&mut self, set: &ObservationSetMsg, stats: &mut StageStats) -> EstimateMsg {
        let track_config = self.track_config;
        // The other vehicles say whether the target's detections are one of them
        // (`target_identity`): then the filter coasts.
        let check = track_config.enabled && track_config.identity_check;
        let elsewhere = match (&self.temporal, check && set.refused == 0) {
            (Some(filter), true) => {
                detection_identity(set, filter, &self.tracks, &mut self.identity, &self.config)
            }
            _ => None,
        };
        // Right after a gap in the sets (the target hidden), a pair the other
        // vehicles put in doubt (`target_identity`, "After a gap").
        self.identity.arrived(set.t_s);
        let doubt = check
            && set.refused == 0
            && elsewhere.is_none()
            && self.identity.reacquiring(set.t_s)
            && self.identity.in_doubt();
        if doubt {
            stats.count("target_in_doubt", 1);
        }
        // A refused set (matching's pair check: two vehicles), one whose detections
        // are another tracked vehicle's and one in doubt give the filter's prediction.
        let coast = set.refused != 0 || elsewhere.is_some() || doubt;
        if set.refused != 0 {
            stats.count("sets_refused", 1);
        }
        if let Some(id) = elsewhere {
            stats.count("target_on_track", 1);
            tracing::debug!(
                pair = set.pair_seq,
                track = id,
                "the target's detections are another vehicle's: coasting"
            );
        }
        let mut msg = if coast {
            coast_message(set, &self.config, self.temporal.as_mut(), stats)
        } else {
            estimate_message(set, &self.config, self.temporal.as_mut(), stats)
        };
        if track_config.enabled {
            add_tracks(set, &mut msg, &mut self.tracks, &self.config, stats, !coast);
        }
        msg
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::set_message::tests::set_at;
    use shared_types::messages::EstimateStatus;

    fn geolocator() -> Geolocator {
        let config = EstimatorConfig::default();
        let tracks = TrackConfig::default();
        Geolocator::new(
            config,
            tracks,
            Some(TemporalEstimator::new(config).unwrap()),
            Tracks::new(tracks).unwrap(),
        )
    }

    fn refused(t_s: f64) -> ObservationSetMsg {
        ObservationSetMsg {
            refused: 1,
            ..set_at(t_s)
        }
    }

    /// A refused set (matching: two vehicles) is the filter's prediction, none of its
    /// rays taken; before the start, and again after a new segment, there is none.
    #[test]
    fn a_refused_set_gives_the_prediction_and_a_new_segment_forgets_the_filter() {
        let mut g = geolocator();
        let mut stats = StageStats::new("t");
        let before = g.estimate(&refused(9.7), &mut stats);
        assert_eq!(before.status, EstimateStatus::Rejected as u32);
        assert_eq!(stats.counter("sets_refused"), 1);
        assert_eq!(stats.counter("rejected.not_started"), 1);
        let mut last = None;
        for k in 0..20 {
            last = Some(g.estimate(&set_at(9.8 + 0.1 * k as f64), &mut stats));
        }
        let last = last.unwrap();
        assert_eq!(last.status, EstimateStatus::Ok as u32);
        assert!(last.images_used > 0);
        let coasted = g.estimate(&refused(11.85), &mut stats);
        assert_eq!(coasted.status, EstimateStatus::Ok as u32);
        assert_eq!(coasted.images_used, 0);
        assert_eq!(stats.counter("sets_refused"), 2);
        let not_started = stats.counter("rejected.not_started");
        g.start_over();
        let after = g.estimate(&refused(11.9), &mut stats);
        assert_eq!(after.status, EstimateStatus::Rejected as u32);
        assert_eq!(stats.counter("rejected.not_started"), not_started + 1);
    }
}
