//! The gate every live stereo pair passes before it is sent (issue #13): a live
//! source cannot refuse to start over bad content the way a recording is refused, so
//! each bad sample is dropped, counted by kind, logged the first time its kind is seen,
//! and the stream goes on. A recording's pairs pass the same gate (they were checked
//! when it was opened, so nothing is dropped there).
//!
//! | fault | what the gate does |
//! | --- | --- |
//! | `pose_not_finite`: a NaN or ±inf in the pose or the time | drops the pair |
//! | `time_backwards`: a sample not newer than the UAV's last accepted one | drops the pair |
//! | `frame_without_pose`, `pose_without_frame` | drops the pair |
//! | `wrong_frame_size`: pixels of another size than the stream's | drops the pair |
//! | `clock_skew`: left and right times further apart than the pairing window (half a frame period) | drops the pair |
//! | `telemetry_gap`: more than [`GAP_PERIODS`] frame periods since the UAV's last sample (received, good or not) | counts it; the pair itself is checked as any other |

use shared_types::messages::PoseSample;
use std::collections::BTreeMap;

/// A gap longer than this many frame periods is counted as a telemetry gap.
pub const GAP_PERIODS: f64 = 3.0;

/// One UAV's sample as the source delivered it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveSample {
    pub t_s: f64,
    pub pose: Option<PoseSample>,
    /// Width and height of the pixels; `None`: no frame came with this pose.
    pub size: Option<(u32, u32)>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Fault {
    PoseNotFinite,
    TimeBackwards,
    FrameWithoutPose,
    PoseWithoutFrame,
    WrongFrameSize,
    ClockSkew,
    TelemetryGap,
}

impl Fault {
    pub const ALL: [Fault; 7] = [
        Fault::PoseNotFinite,
        Fault::TimeBackwards,
        Fault::FrameWithoutPose,
        Fault::PoseWithoutFrame,
        Fault::WrongFrameSize,
        Fault::ClockSkew,
        Fault::TelemetryGap,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Fault::PoseNotFinite => "pose_not_finite",
            Fault::TimeBackwards => "time_backwards",
            Fault::FrameWithoutPose => "frame_without_pose",
            Fault::PoseWithoutFrame => "pose_without_frame",
            Fault::WrongFrameSize => "wrong_frame_size",
            Fault::ClockSkew => "clock_skew",
            Fault::TelemetryGap => "telemetry_gap",
        }
    }
}

pub struct LiveGate {
    size: (u32, u32),
    period_s: f64,
    /// Per UAV: the last accepted sample's time (for time going backwards) and the
    /// newest finite time seen at all (for gaps: dropped samples are not a gap).
    last_t: [Option<f64>; 2],
    seen_t: [Option<f64>; 2],
    counts: BTreeMap<Fault, u64>,
}

impl LiveGate {
    /// A gate for frames of `size` every `period_s`.
    pub fn new(size: (u32, u32), period_s: f64) -> Self {
        Self {
            size,
            period_s,
            last_t: [None, None],
            seen_t: [None, None],
            counts: BTreeMap::new(),
        }
    }

    fn note(&mut self, fault: Fault) {
        let n = self.counts.entry(fault).or_default();
        *n += 1;
        if *n == 1 {
            tracing::warn!(
                fault = fault.name(),
                "live input fault: dropped and counted from now on (totals when the stream stops)"
            );
        }
    }

    /// One UAV's sample on its own: the pose it carries, or why it is dropped.
    fn sample(&self, uav: usize, s: &LiveSample) -> Result<PoseSample, Fault> {
        let (pose, size) = match (s.pose, s.size) {
            (None, Some(_)) => return Err(Fault::FrameWithoutPose),
            (Some(_), None) => return Err(Fault::PoseWithoutFrame),
            (None, None) => return Err(Fault::FrameWithoutPose),
            (Some(p), Some(size)) => (p, size),
        };
        if !(s.t_s.is_finite() && pose.is_finite()) {
            return Err(Fault::PoseNotFinite);
        }
        if size != self.size {
            return Err(Fault::WrongFrameSize);
        }
        if self.last_t[uav].is_some_and(|last| s.t_s <= last) {
            return Err(Fault::TimeBackwards);
        }
        Ok(pose)
    }

    /// Checks a stereo pair: `Ok` with its poses, or the fault it was dropped for
    /// (counted). A telemetry gap is counted and the pair accepted.
    pub fn check(&mut self, pair: &[LiveSample; 2]) -> Result<[PoseSample; 2], Fault> {
        // Both UAVs' clocks move on (no short-circuit), then one gap is counted.
        let gaps = [0, 1].map(|u| {
            let t = pair[u].t_s;
            let gap = t.is_finite()
                && self.seen_t[u].is_some_and(|seen| t - seen > GAP_PERIODS * self.period_s);
            if t.is_finite() && self.seen_t[u].is_none_or(|seen| t > seen) {
                self.seen_t[u] = Some(t);
            }
            gap
        });
        if gaps.iter().any(|g| *g) {
            self.note(Fault::TelemetryGap);
        }
        let checked = [self.sample(0, &pair[0]), self.sample(1, &pair[1])];
        let poses = match checked {
            [Ok(l), Ok(r)] => [l, r],
            [Err(f), _] | [_, Err(f)] => {
                self.note(f);
                return Err(f);
            }
        };
        if (pair[0].t_s - pair[1].t_s).abs() > 0.5 * self.period_s {
            self.note(Fault::ClockSkew);
            return Err(Fault::ClockSkew);
        }
        self.last_t = [Some(pair[0].t_s), Some(pair[1].t_s)];
        Ok(poses)
    }

    /// A pair at `t_s` that acquisition skipped on purpose (it fell behind the clock):
    /// the UAVs' clocks move on, so the skip is not taken for a telemetry gap.
    pub fn skipped(&mut self, t_s: f64) {
        if !t_s.is_finite() {
            return;
        }
        for seen in &mut self.seen_t {
            if seen.is_none_or(|s| t_s > s) {
                *seen = Some(t_s);
            }
        }
    }

    /// Faults seen so far, all kinds.
    pub fn total(&self) -> u64 {
        self.counts.values().sum()
    }

    /// Faults seen so far, by kind.
    pub fn counts(&self) -> &BTreeMap<Fault, u64> {
        &self.counts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIZE: (u32, u32) = (640, 480);
    const PERIOD: f64 = 1.0 / 30.0;

    fn pose() -> PoseSample {
        PoseSample {
            z_m: 100.0,
            yaw_deg: 20.0,
            ..Default::default()
        }
    }

    fn good(t: f64) -> [LiveSample; 2] {
        let s = LiveSample {
            t_s: t,
            pose: Some(pose()),
            size: Some(SIZE),
        };
        [s, s]
    }

    /// The gate after a good first pair at t = 0.
    fn gate() -> LiveGate {
        let mut g = LiveGate::new(SIZE, PERIOD);
        assert!(g.check(&good(0.0)).is_ok());
        g
    }

    fn expect(fault: Fault, pair: [LiveSample; 2]) {
        let mut g = gate();
        assert_eq!(g.check(&pair), Err(fault), "{pair:?}");
        assert_eq!(g.counts()[&fault], 1);
        // The stream goes on: the next good pair passes.
        assert!(g.check(&good(1.0)).is_ok());
    }

    #[test]
    fn a_nan_or_infinite_pose_or_time_is_dropped() {
        let mut p = good(PERIOD);
        p[0].pose.as_mut().unwrap().yaw_deg = f64::NAN;
        expect(Fault::PoseNotFinite, p);
        let mut p = good(PERIOD);
        p[1].pose.as_mut().unwrap().x_m = f64::INFINITY;
        expect(Fault::PoseNotFinite, p);
        let mut p = good(PERIOD);
        p[1].t_s = f64::NAN;
        expect(Fault::PoseNotFinite, p);
    }

    #[test]
    fn time_going_backwards_is_dropped() {
        expect(Fault::TimeBackwards, good(-0.5));
        expect(Fault::TimeBackwards, good(0.0));
    }

    #[test]
    fn a_frame_without_a_pose_and_a_pose_without_a_frame_are_dropped() {
        let mut p = good(PERIOD);
        p[0].pose = None;
        expect(Fault::FrameWithoutPose, p);
        let mut p = good(PERIOD);
        p[1].size = None;
        expect(Fault::PoseWithoutFrame, p);
    }

    #[test]
    fn a_frame_of_the_wrong_size_is_dropped() {
        let mut p = good(PERIOD);
        p[1].size = Some((640, 360));
        expect(Fault::WrongFrameSize, p);
    }

    #[test]
    fn left_right_skew_beyond_the_pairing_window_is_dropped() {
        let mut p = good(PERIOD);
        p[1].t_s += 0.6 * PERIOD;
        expect(Fault::ClockSkew, p);
        let mut p = good(PERIOD);
        p[1].t_s += 0.4 * PERIOD;
        assert!(gate().check(&p).is_ok());
    }

    #[test]
    fn pairs_skipped_on_purpose_are_no_telemetry_gap() {
        let mut g = gate();
        for k in 1..6 {
            g.skipped(k as f64 * PERIOD);
        }
        assert!(g.check(&good(6.0 * PERIOD)).is_ok());
        assert_eq!(g.total(), 0, "{:?}", g.counts());
    }

    #[test]
    fn a_telemetry_gap_is_counted_and_the_pair_kept() {
        let mut g = gate();
        assert!(g.check(&good(0.5)).is_ok());
        assert_eq!(g.counts()[&Fault::TelemetryGap], 1);
        assert!(g.check(&good(0.5 + PERIOD)).is_ok());
        assert_eq!(g.counts()[&Fault::TelemetryGap], 1);
    }
}
