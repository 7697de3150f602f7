//! The latency table: every stage's histograms merged into the five rows the report
//! quotes, printed, and written as HdrHistogram percentile files (`.hgrm`).
//!
//! | row | histogram |
//! | --- | --- |
//! | acquisition | acquisition `produce` per pair: the source's own time (decode or render, and the copy into the loaned samples; live: from the frames' moment, the wait for telemetry and the copy) |
//! | transport | every hop's `transport` (publish → the consumer woke): frames → detection and matching, detections → matching, observations → geolocation, estimates → supervisor |
//! | detection | detection `compute` per frame |
//! | matching | matching `compute` per pair (ORB of the pair + matching + E + transfer) |
//! | geolocation | geolocation `compute` per observation set |
//! | end_to_end | capture → estimate published (geolocation `end_to_end`) |

use anyhow::{Context, Result};
use hdrhistogram::Histogram;
use serde::Serialize;
use shared_types::stats::{percentile_distribution, Percentiles, StageStats};
use std::collections::BTreeMap;
use std::path::Path;

pub const ROWS: [&str; 6] = [
    "acquisition",
    "transport",
    "detection",
    "matching",
    "geolocation",
    "end_to_end",
];

/// Frames that entered the pipeline (or were due to) and never reached a geolocation
/// attempt: pairs acquisition could not loan or skipped because it fell more than a
/// frame behind the clock (×2), frames overwritten before detection
/// or matching read them, frames detection shed (late with a newer one waiting),
/// frames matching skipped to stay current, and observation sets
/// geolocation missed (×2). `counter(stage, name)` reads the counters.
pub fn frames_dropped_of(counter: impl Fn(&str, &str) -> u64) -> u64 {
    2 * counter("acquisition", "pairs_dropped")
        + 2 * counter("acquisition", "pairs_behind")
        + counter("detection", "frames_lost")
        + counter("detection", "frames_shed")
        + counter("matching", "frames_lost")
        + counter("matching", "frames_dropped")
        + 2 * counter("geolocation", "sets_lost")
}

/// The stages' stats files plus the supervisor's own.
pub struct Gathered {
    pub stages: BTreeMap<String, StageStats>,
}

impl Gathered {
    pub fn load(stats_dir: &Path, supervisor: &StageStats) -> Result<Self> {
        let mut stages = BTreeMap::new();
        for name in super::children::SERVICES {
            let s = StageStats::load_stage(stats_dir, name)
                .with_context(|| format!("the {name} service's statistics"))?
                .with_context(|| {
                    format!(
                        "the {name} service left no statistics in {}",
                        stats_dir.display()
                    )
                })?;
            stages.insert(name.to_string(), s);
        }
        stages.insert("supervisor".into(), supervisor.clone());
        Ok(Self { stages })
    }

    pub fn counter(&self, stage: &str, name: &str) -> u64 {
        self.stages.get(stage).map_or(0, |s| s.counter(name))
    }

    /// All counters of all stages, `<stage>.<name>`.
    pub fn counters(&self) -> BTreeMap<String, u64> {
        let mut out = BTreeMap::new();
        for (stage, s) in &self.stages {
            for (k, v) in &s.counters {
                out.insert(format!("{stage}.{k}"), *v);
            }
        }
        out
    }

    fn histogram(&self, stage: &str, name: &str) -> Option<&Histogram<u64>> {
        self.stages.get(stage)?.histograms.get(name)
    }

    /// The histogram behind one table row.
    pub fn row(&self, row: &str) -> Option<Histogram<u64>> {
        match row {
            "transport" => {
                let mut merged: Option<Histogram<u64>> = None;
                for stage in self.stages.keys() {
                    if let Some(h) = self.histogram(stage, "transport") {
                        match &mut merged {
                            Some(m) => {
                                let _ = m.add(h);
                            }
                            None => merged = Some(h.clone()),
                        }
                    }
                }
                merged
            }
            "acquisition" => self.histogram("acquisition", "produce").cloned(),
            "detection" => self.histogram("detection", "compute").cloned(),
            "matching" => self.histogram("matching", "compute").cloned(),
            "geolocation" => self.histogram("geolocation", "compute").cloned(),
            "end_to_end" => self.histogram("geolocation", "end_to_end").cloned(),
            _ => None,
        }
    }
}

/// `latency_us` of report.json: each row's percentiles (zeros when a row saw nothing).
#[derive(Debug, Serialize)]
pub struct LatencyReport {
    pub acquisition: Percentiles,
    pub transport: Percentiles,
    pub detection: Percentiles,
    pub matching: Percentiles,
    pub geolocation: Percentiles,
    pub end_to_end: Percentiles,
}

pub fn report(g: &Gathered) -> LatencyReport {
    let p = |row| g.row(row).map(|h| Percentiles::of(&h)).unwrap_or_default();
    LatencyReport {
        acquisition: p("acquisition"),
        transport: p("transport"),
        detection: p("detection"),
        matching: p("matching"),
        geolocation: p("geolocation"),
        end_to_end: p("end_to_end"),
    }
}

/// The table `dualgeo run` prints, in milliseconds.
pub fn table(g: &Gathered) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<12} {:>9} {:>9} {:>9} {:>9} {:>9} {:>8}",
        "latency ms", "p50", "p90", "p99", "p99.9", "max", "count"
    );
    for row in ROWS {
        match g.row(row) {
            Some(h) => {
                let p = Percentiles::of(&h);
                let ms = |us: u64| us as f64 / 1000.0;
                let _ = writeln!(
                    out,
                    "{row:<12} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>8}",
                    ms(p.p50),
                    ms(p.p90),
                    ms(p.p99),
                    ms(p.p999),
                    ms(p.max),
                    h.len()
                );
            }
            None => {
                let _ = writeln!(out, "{row:<12} {:>9}", "-");
            }
        }
    }
    out
}

/// Writes `<dir>/<row>.hgrm` (milliseconds) for every row that has data.
pub fn write_hgrm(g: &Gathered, dir: &Path) -> Result<Vec<(String, Histogram<u64>)>> {
    std::fs::create_dir_all(dir).with_context(|| format!("create {}", dir.display()))?;
    let mut written = Vec::new();
    for row in ROWS {
        if let Some(h) = g.row(row) {
            let path = dir.join(format!("{row}.hgrm"));
            std::fs::write(&path, percentile_distribution(&h, 1000.0))
                .with_context(|| format!("write {}", path.display()))?;
            written.push((row.to_string(), h));
        }
    }
    Ok(written)
}
