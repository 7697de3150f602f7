//! Shared helpers for dualgeo's benchmark binaries: timing loops recorded in
//! hdrhistogram and a one-line percentile summary.

pub mod budget;

use hdrhistogram::Histogram;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Percentiles of a histogram (the same struct the latency report uses; here the
/// values are nanoseconds).
pub use shared_types::stats::Percentiles;

/// `p50 12.3 µs  p90 …  (n=…)` for a histogram of nanoseconds.
pub fn micros_line(h: &Histogram<u64>) -> String {
    let p = Percentiles::of(h);
    let us = |ns: u64| ns as f64 / 1e3;
    format!(
        "p50 {:8.2} µs  p90 {:8.2} µs  p99 {:8.2} µs  p99.9 {:8.2} µs  max {:9.2} µs  (n={})",
        us(p.p50),
        us(p.p90),
        us(p.p99),
        us(p.p999),
        us(p.max),
        h.len()
    )
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

/// The `dualgeo` binary next to the running bench binary (both in target/release).
pub fn dualgeo_binary() -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe()?;
    let path = exe
        .parent()
        .ok_or_else(|| anyhow::anyhow!("bench binary has no folder"))?
        .join("dualgeo");
    if !path.is_file() {
        anyhow::bail!(
            "{} not found: run `cargo build --release --workspace` first",
            path.display()
        );
    }
    Ok(path)
}
