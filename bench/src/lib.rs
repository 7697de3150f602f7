//! Shared helpers for dualgeo's benchmark binaries: timing loops recorded in
//! hdrhistogram and a one-line percentile summary.

use hdrhistogram::Histogram;
use std::time::{Duration, Instant};

/// Latency percentiles in nanoseconds.
#[derive(Debug, Clone, Copy)]
pub struct Percentiles {
    pub samples: u64,
    pub p50: u64,
    pub p90: u64,
    pub p99: u64,
    pub p999: u64,
    pub max: u64,
}

impl Percentiles {
    pub fn of(h: &Histogram<u64>) -> Self {
        Self {
            samples: h.len(),
            p50: h.value_at_quantile(0.50),
            p90: h.value_at_quantile(0.90),
            p99: h.value_at_quantile(0.99),
            p999: h.value_at_quantile(0.999),
            max: h.max(),
        }
    }

    /// `p50 12.3 µs  p90 …` in microseconds.
    pub fn micros_line(&self) -> String {
        let us = |ns: u64| ns as f64 / 1e3;
        format!(
            "p50 {:8.2} µs  p90 {:8.2} µs  p99 {:8.2} µs  p99.9 {:8.2} µs  max {:9.2} µs  (n={})",
            us(self.p50),
            us(self.p90),
            us(self.p99),
            us(self.p999),
            us(self.max),
            self.samples
        )
    }
}

/// Calls `f(i)` for `warmup` then for at least `min_time` (and `min_calls` calls),
/// recording each call's wall time in a histogram (1 ns to 10 s, 3 significant digits).
pub fn time_calls(
    warmup: usize,
    min_calls: usize,
    min_time: Duration,
    mut f: impl FnMut(usize),
) -> Histogram<u64> {
    for i in 0..warmup {
        f(i);
    }
    let mut h = Histogram::<u64>::new_with_bounds(1, 10_000_000_000, 3)
        .expect("static histogram bounds are valid");
    let start = Instant::now();
    let mut i = 0;
    while i < min_calls || start.elapsed() < min_time {
        let t = Instant::now();
        f(i);
        let ns = t.elapsed().as_nanos() as u64;
        h.saturating_record(ns.max(1));
        i += 1;
    }
    h
}
