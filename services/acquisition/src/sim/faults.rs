//! Faults injected into the live simulator's stream (`--inject-faults RATE`), so the
//! live-input gate (`crate::live_gate`) and everything after it can be tested on a
//! running pipeline: with probability RATE per pair (fixed seed), the next fault kind
//! in turn is applied to the pair as the source would deliver it. A telemetry gap
//! loses the pair and the next [`GAP_PAIRS`] − 1 in transit.

use crate::live_gate::{Fault, LiveSample};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// Pairs lost in transit for one injected telemetry gap (more than
/// `live_gate::GAP_PERIODS` periods).
pub const GAP_PAIRS: u32 = 6;

pub struct FaultInjector {
    rng: StdRng,
    rate: f64,
    next: usize,
    /// Pairs still to lose for the current gap.
    losing: u32,
    pub injected: u64,
}

impl FaultInjector {
    /// `rate` in [0, 1]; `None` when it is not.
    pub fn new(seed: u64, rate: f64) -> Option<Self> {
        (0.0..=1.0).contains(&rate).then(|| Self {
            rng: StdRng::seed_from_u64(seed ^ 0xfa17),
            rate,
            next: 0,
            losing: 0,
            injected: 0,
        })
    }

    /// Maybe corrupts `pair` (frame period `period_s`); `false` when the pair is lost in
    /// transit and never reaches the gate.
    pub fn apply(&mut self, pair: &mut [LiveSample; 2], period_s: f64) -> bool {
        if self.losing > 0 {
            self.losing -= 1;
            return false;
        }
        if self.rate <= 0.0 || self.rng.random::<f64>() >= self.rate {
            return true;
        }
        let fault = Fault::ALL[self.next % Fault::ALL.len()];
        self.next += 1;
        self.injected += 1;
        let side = self.rng.random_range(0..2usize);
        let s = &mut pair[side];
        match fault {
            Fault::PoseNotFinite => {
                if let Some(p) = s.pose.as_mut() {
                    p.yaw_deg = f64::NAN;
                }
            }
            Fault::TimeBackwards => {
                s.t_s -= 2.0;
            }
            Fault::FrameWithoutPose => s.pose = None,
            Fault::PoseWithoutFrame => s.size = None,
            Fault::WrongFrameSize => {
                s.size = s.size.map(|(w, h)| (w, h / 2));
            }
            Fault::ClockSkew => s.t_s += 0.75 * period_s,
            Fault::TelemetryGap => {
                self.losing = GAP_PAIRS - 1;
                return false;
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::live_gate::LiveGate;
    use shared_types::messages::PoseSample;

    #[test]
    fn every_injected_fault_is_caught_by_the_gate_and_the_stream_goes_on() {
        let period = 1.0 / 30.0;
        let mut injector = FaultInjector::new(1, 0.2).unwrap();
        let mut gate = LiveGate::new((64, 48), period);
        let (mut passed, mut lost) = (0, 0);
        for i in 0..3000 {
            let s = LiveSample {
                t_s: i as f64 * period,
                pose: Some(PoseSample {
                    z_m: 100.0,
                    ..Default::default()
                }),
                size: Some((64, 48)),
            };
            let mut pair = [s, s];
            if !injector.apply(&mut pair, period) {
                lost += 1;
                continue;
            }
            if gate.check(&pair).is_ok() {
                passed += 1;
            }
        }
        for f in Fault::ALL {
            let n = gate.counts().get(&f).copied().unwrap_or(0);
            assert!(n > 0, "{} never caught: {:?}", f.name(), gate.counts());
        }
        let dropped: u64 = gate
            .counts()
            .iter()
            .filter(|(f, _)| **f != Fault::TelemetryGap)
            .map(|(_, n)| n)
            .sum();
        let gaps = gate.counts()[&Fault::TelemetryGap];
        // Every injected fault is caught once: dropped, or a gap counted.
        assert_eq!(dropped + gaps, injector.injected);
        assert_eq!(lost, gaps as usize * GAP_PAIRS as usize);
        assert_eq!(passed + dropped as usize + lost, 3000);
        assert!(FaultInjector::new(1, 1.5).is_none());
    }
}
