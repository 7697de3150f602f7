//! The autopilot's clock on the ground station's, for live telemetry: every sample
//! carries its autopilot time and arrives at a host time, and `host − autopilot` is the
//! clock offset plus the link's delay. The smallest value over a sliding window is the
//! offset plus the least delay, the usual one-way estimate (jitter only ever adds
//! delay); the window lets the estimate follow the clocks' drift (ppm: milliseconds an
//! hour). A frame that arrived at host time `h` was captured on the autopilot clock at
//! `h − video_latency_s − offset` (docs/flight-io.md, live time alignment).

use std::collections::VecDeque;

#[derive(Debug, Clone)]
pub struct ClockOffset {
    window_s: f64,
    /// (host time, host − autopilot), the candidates for the minimum: offsets
    /// increasing from front to back (a sliding-window minimum).
    candidates: VecDeque<(f64, f64)>,
}

impl ClockOffset {
    pub fn new(window_s: f64) -> Self {
        Self {
            window_s,
            candidates: VecDeque::new(),
        }
    }

    /// One sample: autopilot time `autopilot_s`, arrived at host time `host_s` (calls
    /// in arrival order, so `host_s` does not decrease).
    pub fn observe(&mut self, host_s: f64, autopilot_s: f64) {
        let offset = host_s - autopilot_s;
        if !offset.is_finite() {
            return;
        }
        while self.candidates.back().is_some_and(|&(_, o)| o >= offset) {
            self.candidates.pop_back();
        }
        self.candidates.push_back((host_s, offset));
        while self
            .candidates
            .front()
            .is_some_and(|&(h, _)| h < host_s - self.window_s)
        {
            self.candidates.pop_front();
        }
    }

    /// host − autopilot, seconds; `None` before the first sample.
    pub fn offset(&self) -> Option<f64> {
        self.candidates.front().map(|&(_, o)| o)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn the_least_delay_wins_and_old_samples_leave_the_window() {
        let mut c = ClockOffset::new(10.0);
        assert_eq!(c.offset(), None);
        c.observe(100.0, 0.0); // delay 0 over an offset of 100
        c.observe(100.5, 0.45); // 50 ms late
        assert_eq!(c.offset(), Some(100.0));
        c.observe(111.0, 10.98); // the first sample has left the window
        assert!((c.offset().unwrap() - 100.02).abs() < 1e-9);
        c.observe(f64::NAN, 0.0);
        assert!(
            (c.offset().unwrap() - 100.02).abs() < 1e-9,
            "NaN is ignored"
        );
    }

    proptest! {
        /// The estimate is the offset plus the least delay that arrived in the window
        /// (arrivals are processed in the order of their host time).
        #[test]
        fn it_is_the_window_minimum(delays in proptest::collection::vec(0.0f64..0.2, 1..200)) {
            let mut arrivals: Vec<(f64, f64)> = delays
                .iter()
                .enumerate()
                .map(|(k, d)| (k as f64 * 0.02 + 50.0 + d, k as f64 * 0.02))
                .collect();
            arrivals.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut c = ClockOffset::new(1.0);
            for &(host, autopilot) in &arrivals {
                c.observe(host, autopilot);
            }
            let newest = arrivals.last().unwrap().0;
            let least = arrivals
                .iter()
                .filter(|(h, _)| *h >= newest - 1.0)
                .map(|(h, a)| h - a)
                .fold(f64::INFINITY, f64::min);
            prop_assert!((c.offset().unwrap() - least).abs() < 1e-9);
        }
    }
}
