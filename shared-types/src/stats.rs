//! Latency histograms and counters of one stage, and the files that carry them to the
//! supervisor. Every value is in microseconds. A stage records into a [`StageStats`]
//! while it runs and saves it as `<dir>/<stage>.json` when it stops; the supervisor
//! loads and merges them. Histograms travel in HdrHistogram's V2 encoding (base64), so
//! nothing is lost between processes.

use base64::Engine;
use hdrhistogram::serialization::{Deserializer, Serializer, V2Serializer};
use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Highest recordable latency: 60 s in µs (larger values are clamped).
const MAX_US: u64 = 60_000_000;

#[derive(Debug, thiserror::Error)]
pub enum StatsError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {detail}")]
    Format { path: PathBuf, detail: String },
}

/// One stage's histograms (µs) and counters.
#[derive(Debug, Clone)]
pub struct StageStats {
    pub stage: String,
    pub histograms: BTreeMap<String, Histogram<u64>>,
    pub counters: BTreeMap<String, u64>,
}

#[derive(Serialize, Deserialize)]
struct StatsFile {
    stage: String,
    counters: BTreeMap<String, u64>,
    /// Name → base64 of the V2-serialised histogram.
    histograms: BTreeMap<String, String>,
}

fn new_histogram() -> Histogram<u64> {
    // 3 significant digits from 1 µs to 60 s: ~0.1 % resolution.
    Histogram::new_with_bounds(1, MAX_US, 3).expect("constant bounds 1..60 s, 3 digits, are valid")
}

impl StageStats {
    pub fn new(stage: &str) -> Self {
        Self {
            stage: stage.to_string(),
            histograms: BTreeMap::new(),
            counters: BTreeMap::new(),
        }
    }

    /// Records `us` microseconds under `name`.
    /// Records `us` microseconds under `name` (allocates only for a new name).
    pub fn record(&mut self, name: &str, us: u64) {
        let us = us.clamp(1, MAX_US);
        match self.histograms.get_mut(name) {
            Some(h) => h.saturating_record(us),
            None => {
                let mut h = new_histogram();
                h.saturating_record(us);
                self.histograms.insert(name.to_string(), h);
            }
        }
    }

    /// Adds `n` to the counter `name` (allocates only for a new name).
    pub fn count(&mut self, name: &str, n: u64) {
        match self.counters.get_mut(name) {
            Some(c) => *c += n,
            None => {
                self.counters.insert(name.to_string(), n);
            }
        }
    }

    pub fn counter(&self, name: &str) -> u64 {
        self.counters.get(name).copied().unwrap_or(0)
    }

    /// Adds another stage's data (histograms of one name are merged).
    pub fn merge(&mut self, other: &StageStats) {
        for (name, h) in &other.histograms {
            let mine = self
                .histograms
                .entry(name.clone())
                .or_insert_with(new_histogram);
            // Same bounds everywhere, so `add` cannot fail; a failure would only drop data.
            let _ = mine.add(h);
        }
        for (name, n) in &other.counters {
            self.count(name, *n);
        }
    }

    /// `<dir>/<stage>.<incarnation>.json`: a restarted service (incarnation 1, 2, …)
    /// writes its own file beside the one its killed predecessor left, and
    /// [`StageStats::load_stage`] merges them.
    pub fn file_path(dir: &Path, stage: &str, incarnation: u32) -> PathBuf {
        dir.join(format!("{stage}.{incarnation}.json"))
    }

    /// Writes `<dir>/<stage>.<incarnation>.json` (through a temporary file, so a reader
    /// never sees half). Services call it once a second while they run
    /// ([`crate::shell::StatsSaver`]) and once when they stop, so a killed service loses
    /// at most its last second.
    pub fn save(&self, dir: &Path, incarnation: u32) -> Result<PathBuf, StatsError> {
        let path = Self::file_path(dir, &self.stage, incarnation);
        let mut histograms = BTreeMap::new();
        for (name, h) in &self.histograms {
            let mut bytes = Vec::new();
            V2Serializer::new()
                .serialize(h, &mut bytes)
                .map_err(|e| StatsError::Format {
                    path: path.clone(),
                    detail: format!("serialise {name}: {e:?}"),
                })?;
            histograms.insert(
                name.clone(),
                base64::engine::general_purpose::STANDARD.encode(bytes),
            );
        }
        let file = StatsFile {
            stage: self.stage.clone(),
            counters: self.counters.clone(),
            histograms,
        };
        let text = serde_json::to_string(&file).map_err(|e| StatsError::Format {
            path: path.clone(),
            detail: e.to_string(),
        })?;
        let tmp = path.with_extension("json.tmp");
        let io = |source| StatsError::Io {
            path: path.clone(),
            source,
        };
        std::fs::write(&tmp, text).map_err(io)?;
        std::fs::rename(&tmp, &path).map_err(io)?;
        Ok(path)
    }

    /// Every incarnation's file of `stage` in `dir`, merged; `None` when there is none.
    pub fn load_stage(dir: &Path, stage: &str) -> Result<Option<Self>, StatsError> {
        let entries = std::fs::read_dir(dir).map_err(|source| StatsError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let prefix = format!("{stage}.");
        let mut merged: Option<Self> = None;
        let mut paths: Vec<PathBuf> = entries
            .flatten()
            .map(|e| e.path())
            .filter(|p| {
                p.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
                    n.strip_prefix(&prefix)
                        .and_then(|rest| rest.strip_suffix(".json"))
                        .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
                })
            })
            .collect();
        paths.sort();
        for path in paths {
            let s = Self::load(&path)?;
            merged.get_or_insert_with(|| Self::new(stage)).merge(&s);
        }
        Ok(merged)
    }

    pub fn load(path: &Path) -> Result<Self, StatsError> {
        let text = std::fs::read_to_string(path).map_err(|source| StatsError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let format = |detail: String| StatsError::Format {
            path: path.to_path_buf(),
            detail,
        };
        let file: StatsFile = serde_json::from_str(&text).map_err(|e| format(e.to_string()))?;
        let mut histograms = BTreeMap::new();
        for (name, b64) in file.histograms {
            let bytes = base64::engine::general_purpose::STANDARD
                .decode(b64)
                .map_err(|e| format(format!("{name}: {e}")))?;
            let h: Histogram<u64> = Deserializer::new()
                .deserialize(&mut bytes.as_slice())
                .map_err(|e| format(format!("{name}: {e:?}")))?;
            histograms.insert(name, h);
        }
        Ok(Self {
            stage: file.stage,
            histograms,
            counters: file.counters,
        })
    }
}

/// The percentiles the latency table and report.json quote, µs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Percentiles {
    pub p50: u64,
    pub p90: u64,
    pub p99: u64,
    pub p999: u64,
    pub max: u64,
}

impl Percentiles {
    pub fn of(h: &Histogram<u64>) -> Self {
        Self {
            p50: h.value_at_quantile(0.5),
            p90: h.value_at_quantile(0.9),
            p99: h.value_at_quantile(0.99),
            p999: h.value_at_quantile(0.999),
            max: h.max(),
        }
    }
}

/// HdrHistogram's percentile distribution text (the `.hgrm` format its plotter reads):
/// Value, Percentile, TotalCount, 1/(1−Percentile), values in `unit_scale` units
/// (1000.0 turns µs into ms).
pub fn percentile_distribution(h: &Histogram<u64>, unit_scale: f64) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:>12} {:>14} {:>10} {:>14}\n",
        "Value", "Percentile", "TotalCount", "1/(1-Percentile)"
    );
    let mut last_count = 0;
    for v in h.iter_quantiles(5) {
        let q = v.quantile_iterated_to();
        let value = v.value_iterated_to() as f64 / unit_scale;
        let count = last_count + v.count_since_last_iteration();
        last_count = count;
        if q < 1.0 {
            let _ = writeln!(
                out,
                "{value:12.3} {q:14.12} {count:10} {:14.2}",
                1.0 / (1.0 - q)
            );
        } else {
            let _ = writeln!(out, "{value:12.3} {q:14.12} {count:10}");
        }
    }
    let _ = writeln!(
        out,
        "#[Mean    = {:12.3}, StdDeviation   = {:12.3}]",
        h.mean() / unit_scale,
        h.stdev() / unit_scale
    );
    let _ = writeln!(
        out,
        "#[Max     = {:12.3}, Total count    = {:12}]",
        h.max() as f64 / unit_scale,
        h.len()
    );
    let _ = writeln!(
        out,
        "#[Buckets = {:12}, SubBuckets     = {:12}]",
        h.buckets(),
        h.distinct_values()
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn save_load_merge_round_trip() {
        let dir = std::env::temp_dir().join(format!("dualgeo-stats-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut a = StageStats::new("detection");
        for us in 1..=1000 {
            a.record("compute", us);
        }
        a.count("frames", 1000);
        let path = a.save(&dir, 0).unwrap();
        let b = StageStats::load(&path).unwrap();
        assert_eq!(b.counter("frames"), 1000);
        let p = Percentiles::of(&b.histograms["compute"]);
        assert!((499..=501).contains(&p.p50), "{p:?}");
        assert!((989..=991).contains(&p.p99), "{p:?}");
        assert_eq!(p.max, 1000);
        let mut merged = StageStats::new("all");
        merged.merge(&a);
        merged.merge(&b);
        assert_eq!(merged.histograms["compute"].len(), 2000);
        assert_eq!(merged.counter("frames"), 2000);
        // A restarted incarnation's file is merged with its predecessor's.
        a.save(&dir, 1).unwrap();
        std::fs::write(dir.join("detection.1.json.tmp"), "half").unwrap();
        let both = StageStats::load_stage(&dir, "detection").unwrap().unwrap();
        assert_eq!(both.counter("frames"), 2000);
        assert!(StageStats::load_stage(&dir, "matching").unwrap().is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn corrupt_file_is_a_clear_error() {
        let dir = std::env::temp_dir().join(format!("dualgeo-stats-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("x.json");
        std::fs::write(&path, "{not json").unwrap();
        let e = StageStats::load(&path).unwrap_err().to_string();
        assert!(e.contains("x.json"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn hgrm_has_the_plotter_columns_and_ends_at_100_percent() {
        let mut h = new_histogram();
        for us in [100, 200, 300, 5000] {
            h.record(us).unwrap();
        }
        let text = percentile_distribution(&h, 1000.0);
        assert!(text.starts_with("       Value     Percentile TotalCount 1/(1-Percentile)"));
        assert!(text.contains("#[Max     ="));
        let last_row = text
            .lines()
            .rfind(|l| !l.starts_with('#') && !l.trim().is_empty())
            .unwrap();
        assert!(last_row.contains("1.000000000000"), "{last_row}");
        assert!(last_row.trim_start().starts_with("5.00"), "{last_row}");
    }
}
