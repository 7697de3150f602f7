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
//! doubt); in all three the filter's prediction is published, the set's rays untaken;
//! `sets_noise_raised` (sets estimated with a UAV's navigation noise raised to what its
//! pose samples show, [`crate::telemetry_noise`]); `sets_target_unseen` (a camera did
//! not find the target: no target estimate, the other vehicles' tracks predicted or,
//! after `[tracks] alone_after_s`, the vehicles located alone).

use crate::others_message::{
    add_coasted_tracks, add_tracks, add_unseen_tracks, detection_identity,
};
use crate::set_message::{coast_message, estimate_message, unestimated};
use crate::target_identity::IdentityCheck;
use crate::telemetry_noise::{MeasuredNoise, NoiseRaise};
use crate::tracks::{TrackConfig, Tracks};
use crate::{EstimatorConfig, TemporalEstimator};
use shared_types::conventions::Uav;
use shared_types::messages::{EstimateMsg, EstimateStatus, ObservationSetMsg};
use shared_types::stats::StageStats;

/// The service's state between sets: the configured estimator's filter (`None` for the
/// per-window methods), the other vehicles' tracks and the identity evidence.
pub struct Geolocator {
    /// As configured (`[estimator]`).
    pub config: EstimatorConfig,
    pub track_config: TrackConfig,
    pub temporal: Option<TemporalEstimator>,
    pub tracks: Tracks,
    /// Not checkpointed: after a restart the evidence builds up again in a few pairs.
    identity: IdentityCheck,
    /// Which UAVs' σ's the pose samples have shown to be above the configured ones
    /// (`telemetry_noise`; matching measures the samples and each set carries it). Not
    /// checkpointed: after a restart the configured noise holds until the next set
    /// shows more again.
    raise: NoiseRaise,
    /// `config` with each UAV's noise raised to what its pose samples show
    /// (`[estimator] noise_from_telemetry`); what every estimate is made with.
    effective: EstimatorConfig,
    /// The last set with the target's detections in both images, s: how long it has
    /// been hidden (`[tracks] alone_after_s`). Not checkpointed.
    target_seen_s: Option<f64>,
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
            raise: NoiseRaise::new(),
            effective: config,
            target_seen_s: None,
        }
    }

    /// Where the set's pose-sample noise (measured by matching over every frame it was
    /// given) shows a UAV noisier than configured, raises its σ's in the estimates'
    /// config and the filter's.
    fn measure_noise(&mut self, set: &ObservationSetMsg, stats: &mut StageStats) {
        if !self.config.noise_from_telemetry {
            return;
        }
        let mut effective = self.config;
        for uav in [Uav::Left, Uav::Right] {
            let measured = MeasuredNoise::from_msg(&set.pose_noise[uav.index()]);
            let raised = self
                .raise
                .raised(uav, measured.as_ref(), self.config.noise(uav));
            match uav {
                Uav::Left => effective.noise_left = raised,
                Uav::Right => effective.noise_right = raised,
            }
        }
        if effective != self.effective {
            for uav in [Uav::Left, Uav::Right] {
                let (configured, now) = (self.config.noise(uav), effective.noise(uav));
                if self.effective.noise(uav) == configured && now != configured {
                    tracing::info!(
                        uav = ?uav,
                        sigma_position_m = ?now.sigma_position_m,
                        sigma_yaw_pitch_roll_deg = ?[now.sigma_yaw_deg, now.sigma_pitch_deg, now.sigma_roll_deg],
                        position_jitter_m = now.position_jitter_m,
                        attitude_jitter_deg = now.attitude_jitter_deg,
                        "the pose samples are noisier than configured: σ's raised"
                    );
                }
            }
            if let Some(t) = self.temporal.as_mut() {
                // Only σ's differ from the configuration the filter was built with.
                if let Err(e) = t.set_noise(effective.noise_left, effective.noise_right) {
                    tracing::warn!("measured noise not taken: {e}");
                    return;
                }
            }
            self.effective = effective;
        }
        if self.effective != self.config {
            stats.count("sets_noise_raised", 1);
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
        // The same stream from its start: measured again from the configuration, so
        // that every pass of a loop gives the same estimates.
        self.raise = NoiseRaise::new();
        self.effective = self.config;
        self.target_seen_s = None;
        if let Some(t) = self.temporal.as_mut() {
            if let Err(e) = t.set_noise(self.config.noise_left, self.config.noise_right) {
                tracing::warn!("configured noise not restored: {e}");
            }
        }
    }

    /// The estimate message of one set (its status says when there is none).
    pub fn estimate(&mut self, set: &ObservationSetMsg, stats: &mut StageStats) -> EstimateMsg {
        if set.refused == ObservationSetMsg::TARGET_UNSEEN {
            return self.target_unseen(set, stats);
        }
        self.target_seen_s = Some(set.t_s);
        self.measure_noise(set, stats);
        let track_config = self.track_config;
        // The other vehicles say whether the target's detections are one of them
        // (`target_identity`): then the filter coasts.
        let check = track_config.enabled && track_config.identity_check;
        let elsewhere = match (&self.temporal, check && set.refused == 0) {
            (Some(filter), true) => detection_identity(
                set,
                filter,
                &self.tracks,
                &mut self.identity,
                &self.effective,
            ),
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
            coast_message(set, &self.effective, self.temporal.as_mut(), stats)
        } else {
            estimate_message(set, &self.effective, self.temporal.as_mut(), stats)
        };
        if track_config.enabled {
            add_tracks(
                set,
                &mut msg,
                &mut self.tracks,
                &self.effective,
                stats,
                !coast,
                self.temporal
                    .as_ref()
                    .and_then(|t| t.pose_errors_at(set.t_s)),
            );
        }
        msg
    }

    /// A pair whose target a camera did not find (hidden): no target estimate; once
    /// the target has been hidden `[tracks] alone_after_s`, the other vehicles it
    /// carries located alone (`add_unseen_tracks`), before that the tracks predicted
    /// to it (`add_coasted_tracks`: a short gap, under a bridge, is bridged better by
    /// the tracks' predictions than by fixes metres off). Nothing of the filter, the
    /// measured noise or the identity check's gap changes, so the target's estimates
    /// are the same as without such pairs as long as the tracks' word on its
    /// detections is.
    fn target_unseen(&mut self, set: &ObservationSetMsg, stats: &mut StageStats) -> EstimateMsg {
        stats.count("sets_target_unseen", 1);
        let mut msg = EstimateMsg {
            status: EstimateStatus::Rejected as u32,
            ..unestimated(set)
        };
        if self.track_config.enabled && set.t_s.is_finite() {
            let hidden_for = self.target_seen_s.map(|t| set.t_s - t);
            if hidden_for.is_some_and(|h| h >= self.track_config.alone_after_s) {
                add_unseen_tracks(
                    set,
                    &mut msg,
                    &mut self.tracks,
                    self.temporal.as_ref(),
                    &self.effective,
                    stats,
                );
            } else {
                add_coasted_tracks(set.t_s, &mut msg, &mut self.tracks, stats);
            }
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

    /// A pair without the target (`TARGET_UNSEEN`: no entries) gives no target
    /// estimate and leaves the filter as it was: the estimates after such pairs are
    /// those of a run without them.
    #[test]
    fn a_pair_without_the_target_changes_no_estimate() {
        let unseen = |t_s: f64| ObservationSetMsg {
            refused: ObservationSetMsg::TARGET_UNSEEN,
            t_s,
            count: 0,
            ..Default::default()
        };
        let (mut with, mut without) = (geolocator(), geolocator());
        let mut stats = StageStats::new("t");
        for k in 0..30 {
            let t = 9.8 + 0.1 * k as f64;
            if (10..15).contains(&k) {
                let m = with.estimate(&unseen(t), &mut stats);
                assert_eq!(m.status, EstimateStatus::Rejected as u32);
                assert_eq!(m.track_count, 0);
                continue;
            }
            let a = with.estimate(&set_at(t), &mut stats);
            let b = without.estimate(&set_at(t), &mut StageStats::new("u"));
            // Bit for bit (Debug: NaN fields compare unequal).
            assert_eq!(format!("{a:?}"), format!("{b:?}"), "set {k}");
        }
        assert_eq!(stats.counter("sets_target_unseen"), 5);
        assert_eq!(stats.counter("bad_input"), 0);
    }

    /// A set whose pose noise (matching's measurement) shows the left UAV twice as
    /// noisy as configured raises the left σ's in the filter, from then on; the right's
    /// stay; `noise_from_telemetry = false`, a new segment or too few chords leave the
    /// configuration as it is.
    #[test]
    fn the_sets_pose_noise_raises_the_filters_sigmas() {
        use shared_types::messages::PoseNoise;
        let noisy = |t_s: f64, chords: u32| {
            let mut set = set_at(t_s);
            set.pose_noise[0] = PoseNoise {
                sigma: [6.0, 6.0, 6.0, 4.0, 4.0, 4.0],
                mean_step_s: 1.0 / 30.0,
                chords,
                _reserved: 0,
            };
            set
        };
        let left = |g: &Geolocator| g.temporal.as_ref().unwrap().config.noise_left;
        let right = |g: &Geolocator| g.temporal.as_ref().unwrap().config.noise_right;
        let configured = crate::NoiseModel::default();
        let mut g = geolocator();
        let mut stats = StageStats::new("t");
        g.estimate(&noisy(9.8, 10), &mut stats);
        assert_eq!(left(&g), configured, "10 chords are too few");
        g.estimate(&noisy(9.9, 300), &mut stats);
        assert_eq!(left(&g).sigma_position_m, [6.0; 3]);
        assert_eq!(left(&g).sigma_yaw_deg, 4.0);
        assert_eq!(right(&g), configured);
        assert_eq!(stats.counter("sets_noise_raised"), 1);
        // Latched: a later set nearer the configuration keeps it raised to σ̂.
        let mut calmer = noisy(10.0, 300);
        calmer.pose_noise[0].sigma = [3.3; 6];
        g.estimate(&calmer, &mut stats);
        assert_eq!(left(&g).sigma_position_m, [3.3; 3]);
        assert_eq!(left(&g).sigma_yaw_deg, 3.3);
        g.start_over();
        assert_eq!(left(&g), configured);
        let mut off = geolocator();
        off.config.noise_from_telemetry = false;
        off.estimate(&noisy(9.9, 300), &mut stats);
        assert_eq!(left(&off), configured);
    }
}
