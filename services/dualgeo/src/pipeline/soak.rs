//! The soak report (issue #13): every `--sample-every-s` (default 60 s) the supervisor
//! samples each process's resident memory and open file descriptors (from /proc), and
//! each stage's latency p50 / p99 over the interval (the difference of the stages'
//! cumulative histograms, which they save every second), the frames dropped in the
//! interval and the restarts so far. Rows go to `soak.csv` as they are taken; at the
//! end `soak.png` plots them and the run states whether memory and p99 stayed flat:
//!
//! - memory: every process's private RSS (VmRSS less RssShmem) within ±1 % of its
//!   first sample after the warm-up (`--soak-warm-up-s`, default 60 s: the rings,
//!   caches and pools fill first; the sample taken at the end of the warm-up covers it
//!   and is left out too). The shared memory (`shm_kib_*`: iceoryx2's fixed-size
//!   pools of frames and messages) is reported beside it and not judged: a pool's pages
//!   count in RSS from the first time a slot is written, and which slots a run has
//!   written by a given minute depends on how far the subscribers fell behind
//!   (measured: acquisition 87.3 → 90.9 MB when 4 more 640 × 480 frame slots were first
//!   written, RssAnon and RssFile unchanged), so a backlog late in a run steps VmRSS
//!   once up to the pools' size without any leak;
//! - latency: every interval's end-to-end p99 after the warm-up within ±20 % of the
//!   first such interval's.

use super::children::Service;
use super::latency::frames_dropped_of;
use anyhow::{Context, Result};
use hdrhistogram::Histogram;
use shared_types::stats::StageStats;
use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub const PROCESSES: [&str; 5] = [
    "supervisor",
    "acquisition",
    "detection",
    "matching",
    "geolocation",
];
/// (stage, histogram) per latency column.
pub const LATENCIES: [(&str, &str); 4] = [
    ("detection", "compute"),
    ("matching", "compute"),
    ("geolocation", "compute"),
    ("geolocation", "end_to_end"),
];
pub const MEMORY_TOLERANCE: f64 = 0.01;
pub const P99_TOLERANCE: f64 = 0.20;

#[derive(Debug, Clone)]
pub struct Sample {
    pub t_s: f64,
    pub rss_kib: [u64; 5],
    /// The part of `rss_kib` that is shared memory (RssShmem).
    pub shm_kib: [u64; 5],
    pub fds: [u64; 5],
    /// p50 and p99 per [`LATENCIES`] column over the interval, µs (0: no sample).
    pub p50_us: [u64; 4],
    pub p99_us: [u64; 4],
    pub dropped: u64,
    pub restarts: u64,
}

/// Looks at each process's descriptors per sample (see [`Sampler::tick`]).
const FD_LOOKS: usize = 3;

/// VmRSS and RssShmem (KiB) and the open descriptors of a process; zeros when it is
/// gone.
fn proc_figures(pid: u32) -> (u64, u64, u64) {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    let field = |name: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.split_whitespace().next()?.parse().ok())
            .unwrap_or(0)
    };
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd"))
        .map(|d| d.count() as u64)
        .unwrap_or(0);
    (field("VmRSS:"), field("RssShmem:"), fds)
}

impl Sample {
    /// Process `i`'s private resident memory (VmRSS less RssShmem), KiB: what a leak
    /// raises.
    pub fn private_kib(&self, i: usize) -> u64 {
        self.rss_kib[i].saturating_sub(self.shm_kib[i])
    }
}

/// What a sample keeps of the stages' cumulative statistics: the [`LATENCIES`]
/// histograms and the frames dropped so far.
#[derive(Default)]
struct Cumulative {
    latencies: [Option<Histogram<u64>>; 4],
    dropped: u64,
}

impl Cumulative {
    fn load(stats_dir: &Path) -> Self {
        let mut stages = BTreeMap::new();
        for stage in super::children::SERVICES {
            // A file being replaced is read at the next sample.
            if let Ok(Some(s)) = StageStats::load_stage(stats_dir, stage) {
                stages.insert(stage, s);
            }
        }
        let mut latencies: [Option<Histogram<u64>>; 4] = Default::default();
        for (slot, (stage, name)) in latencies.iter_mut().zip(LATENCIES) {
            *slot = stages
                .get_mut(stage)
                .and_then(|s| s.histograms.remove(name));
        }
        let dropped = frames_dropped_of(|stage, c| stages.get(stage).map_or(0, |s| s.counter(c)));
        Self { latencies, dropped }
    }
}

pub struct Sampler {
    every: Duration,
    next: Instant,
    start: Instant,
    stats_dir: PathBuf,
    csv: csv::Writer<File>,
    /// The cumulative figures at the previous sample: only what the report uses (the
    /// stages' full statistics are parsed and dropped), so the sampler's own memory is
    /// the same at every sample.
    prev: Cumulative,
    pub samples: Vec<Sample>,
}

impl Sampler {
    pub fn new(out: &Path, stats_dir: &Path, every: Duration) -> Result<Self> {
        let path = out.join("soak.csv");
        let mut csv =
            csv::Writer::from_path(&path).with_context(|| format!("create {}", path.display()))?;
        let mut header = vec!["t_s".to_string()];
        header.extend(PROCESSES.iter().map(|p| format!("rss_kib_{p}")));
        header.extend(PROCESSES.iter().map(|p| format!("fds_{p}")));
        header.extend(PROCESSES.iter().map(|p| format!("shm_kib_{p}")));
        for (stage, h) in LATENCIES {
            header.push(format!("p50_us_{stage}_{h}"));
            header.push(format!("p99_us_{stage}_{h}"));
        }
        header.extend(["frames_dropped".into(), "restarts".into()]);
        csv.write_record(&header)?;
        csv.flush()?;
        Ok(Self {
            every,
            next: Instant::now() + every,
            start: Instant::now(),
            stats_dir: stats_dir.to_path_buf(),
            csv,
            // Taken now, so every sample holds the same: the first interval is the
            // difference from the start, and the sampler's own memory does not grow
            // between the first sample and the second.
            prev: Cumulative::load(stats_dir),
            samples: Vec::new(),
        })
    }

    /// Takes a sample when one is due.
    pub fn tick(&mut self, services: &[Service], restarts: u64) -> Result<()> {
        if Instant::now() < self.next {
            return Ok(());
        }
        self.next += self.every;
        let mut rss_kib = [0; 5];
        let mut shm_kib = [0; 5];
        let mut fds = [u64::MAX; 5];
        let pids = PROCESSES.map(|name| match name {
            "supervisor" => Some(std::process::id()),
            n => services.iter().find(|s| s.name == n).map(Service::pid),
        });
        // Descriptors *held*: the fewest of three looks 3 ms apart, so one opened for a
        // moment (an image being read, the statistics being saved) is not counted as
        // held. A leak holds its descriptors and shows in every look.
        for round in 0..FD_LOOKS {
            if round > 0 {
                std::thread::sleep(Duration::from_millis(3));
            }
            for (i, pid) in pids.iter().enumerate() {
                let (rss, shm, n) = pid.map_or((0, 0, 0), proc_figures);
                fds[i] = fds[i].min(n);
                if round == 0 {
                    rss_kib[i] = rss;
                    shm_kib[i] = shm;
                }
            }
        }
        let now = Cumulative::load(&self.stats_dir);
        let mut p50_us = [0; 4];
        let mut p99_us = [0; 4];
        for i in 0..LATENCIES.len() {
            let Some(mut h) = now.latencies[i].clone() else {
                continue;
            };
            if let Some(p) = &self.prev.latencies[i] {
                if h.subtract(p).is_err() {
                    continue;
                }
            }
            if !h.is_empty() {
                p50_us[i] = h.value_at_quantile(0.5);
                p99_us[i] = h.value_at_quantile(0.99);
            }
        }
        let sample = Sample {
            t_s: self.start.elapsed().as_secs_f64(),
            rss_kib,
            shm_kib,
            fds,
            p50_us,
            p99_us,
            dropped: now.dropped.saturating_sub(self.prev.dropped),
            restarts,
        };
        let mut row = vec![format!("{:.1}", sample.t_s)];
        row.extend(sample.rss_kib.iter().map(u64::to_string));
        row.extend(sample.fds.iter().map(u64::to_string));
        row.extend(sample.shm_kib.iter().map(u64::to_string));
        for i in 0..4 {
            row.push(sample.p50_us[i].to_string());
            row.push(sample.p99_us[i].to_string());
        }
        row.extend([sample.dropped.to_string(), sample.restarts.to_string()]);
        self.csv.write_record(&row)?;
        self.csv.flush()?;
        self.samples.push(sample);
        self.prev = now;
        // The sample parsed a few MB of statistics and dropped them: hand the freed
        // pages back, so the supervisor's RSS reads the same after every sample
        // (without it, ±1 MB from one sample to the next).
        // SAFETY: malloc_trim only releases free memory of glibc's heaps.
        unsafe { libc::malloc_trim(0) };
        Ok(())
    }
}

/// The largest relative departure of `values` from their first, or `None` with fewer
/// than two values (or a first of 0).
pub fn drift(values: impl IntoIterator<Item = u64>) -> Option<f64> {
    let v: Vec<f64> = values.into_iter().map(|x| x as f64).collect();
    let first = *v.first()?;
    if v.len() < 2 || first <= 0.0 {
        return None;
    }
    v.iter()
        .map(|x| (x - first) / first)
        .max_by(|a, b| a.abs().total_cmp(&b.abs()))
}

/// One line per criterion: whether memory and p99 stayed flat after `warm_up_s`.
pub fn verdict(all: &[Sample], warm_up_s: f64) -> Vec<String> {
    let mut lines = Vec::new();
    // A sample covers the interval before it: the one taken at the end of the warm-up
    // still holds the warm-up.
    let start = all.partition_point(|s| s.t_s <= warm_up_s + 1e-6);
    let samples = &all[start..];
    if samples.len() < 2 {
        lines.push(format!(
            "soak: {} sample(s) after the {warm_up_s:.0} s warm-up; flatness needs two (run longer, or lower --sample-every-s or --soak-warm-up-s)",
            samples.len()
        ));
        return lines;
    }
    let mut worst: Option<(&str, f64)> = None;
    for (i, p) in PROCESSES.iter().enumerate() {
        if let Some(d) = drift(samples.iter().map(|s| s.private_kib(i))) {
            if worst.is_none_or(|(_, w)| d.abs() > w.abs()) {
                worst = Some((p, d));
            }
        }
    }
    if let Some((p, d)) = worst {
        lines.push(format!(
            "soak: RSS (private, shared memory left out) {} within ±{:.0} % of the first sample after the warm-up (largest drift: {p} {:+.2} %)",
            if d.abs() <= MEMORY_TOLERANCE {
                "stayed"
            } else {
                "did NOT stay"
            },
            MEMORY_TOLERANCE * 100.0,
            d * 100.0
        ));
    }
    let e2e: Vec<u64> = samples
        .iter()
        .map(|s| s.p99_us[3])
        .filter(|v| *v > 0)
        .collect();
    if let Some(d) = drift(e2e.iter().copied()) {
        lines.push(format!(
            "soak: end-to-end p99 {} within ±{:.0} % of the first interval's {:.1} ms (largest drift {:+.1} %)",
            if d.abs() <= P99_TOLERANCE { "stayed" } else { "did NOT stay" },
            P99_TOLERANCE * 100.0,
            e2e[0] as f64 / 1e3,
            d * 100.0
        ));
    }
    let dropped: u64 = all.iter().map(|s| s.dropped).sum();
    lines.push(format!(
        "soak: {} samples over {:.0} s, {dropped} frames dropped, {} restarts",
        all.len(),
        all.last().map_or(0.0, |s| s.t_s),
        all.last().map_or(0, |s| s.restarts)
    ));
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drift_is_the_largest_departure_from_the_first() {
        assert_eq!(drift([100, 101, 100, 100]), Some(0.01));
        assert_eq!(drift([100, 97, 102]), Some(-0.03));
        assert_eq!(drift([100]), None);
        assert_eq!(drift([0, 5]), None);
    }

    #[test]
    fn the_process_figures_of_this_test_are_read() {
        let (rss, shm, fds) = proc_figures(std::process::id());
        assert!(
            rss > 0 && shm <= rss && fds >= 3,
            "{rss} KiB, {shm} KiB shared, {fds} fds"
        );
        assert_eq!(proc_figures(u32::MAX), (0, 0, 0));
    }
}
