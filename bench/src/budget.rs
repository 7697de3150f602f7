//! The latency budget of a run from its `--trace` file (issue #15): for every pair that
//! became an estimate, the steps of its critical path from the capture moment to the
//! estimate published, each step's p50 and p99, and what the slowest 1 % of pairs
//! spent their time on.
//!
//! Steps, in order: acquisition `decode` (or `render`) and `publish`; the wait for
//! detection and `detect` (the later of the two UAVs); the wait for matching and
//! `track` (`orb` with tracking off; the later UAV); `match_pair` (F from tracked correspondences, transfer); the
//! wait for geolocation and `estimate`. Matching's refresh thread (ORB and matching
//! with past images, issue #24) is on no estimate's path; its lane is summarised
//! apart ([`refresh_lane`]). `other` is what the steps leave unexplained:
//! time between them (a detection done before matching took it up, matching waiting
//! for the other UAV's detection) and scheduling.

use anyhow::{Context, Result};
use serde_json::Value;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

pub const STEPS: [&str; 10] = [
    "decode or render",
    "publish",
    "detection wait",
    "detect",
    "matching wait",
    "orb or track",
    "match_pair",
    "geolocation wait",
    "estimate",
    "other",
];

/// One estimate's end-to-end time and its steps, microseconds.
#[derive(Debug, Clone, Default)]
pub struct PairBudget {
    pub end_to_end_us: f64,
    pub steps: [f64; STEPS.len()],
}

fn step_index(process: &str, name: &str) -> Option<usize> {
    Some(match (process, name) {
        ("acquisition", "decode" | "render") => 0,
        ("acquisition", "publish") => 1,
        ("detection", "wait") => 2,
        ("detection", "detect") => 3,
        ("matching", "wait") => 4,
        ("matching", "orb" | "track") => 5,
        ("matching", "match_pair") => 6,
        ("geolocation", "wait") => 7,
        ("geolocation", "estimate") => 8,
        _ => return None,
    })
}

/// The events of a Chrome trace written by `dualgeo run --trace`.
fn trace_events(path: &Path) -> Result<Vec<Value>> {
    let doc: Value = serde_json::from_slice(
        &std::fs::read(path).with_context(|| format!("read {}", path.display()))?,
    )?;
    match doc {
        Value::Object(mut m) => match m.remove("traceEvents") {
            Some(Value::Array(events)) => Ok(events),
            _ => anyhow::bail!("no traceEvents in {}", path.display()),
        },
        _ => anyhow::bail!("{} is not a trace", path.display()),
    }
}

/// Every estimate's budget in a Chrome trace written by `dualgeo run --trace`.
pub fn read(path: &Path) -> Result<Vec<PairBudget>> {
    let events = &trace_events(path)?;
    let mut names: HashMap<u64, String> = HashMap::new();
    for e in events.iter().filter(|e| e["name"] == "process_name") {
        if let (Some(pid), Some(n)) = (e["pid"].as_u64(), e["args"]["name"].as_str()) {
            names.insert(pid, n.to_string());
        }
    }
    let process = |e: &Value| e["pid"].as_u64().and_then(|p| names.get(&p)).cloned();
    // Async begins waiting for their ends: (cat, id) → (pair, ts).
    let mut open: HashMap<(String, String), (u64, f64)> = HashMap::new();
    let mut pairs: BTreeMap<u64, PairBudget> = BTreeMap::new();
    let mut spans: Vec<(u64, usize, f64)> = Vec::new();
    for e in events {
        let ph = e["ph"].as_str().unwrap_or_default();
        let name = e["name"].as_str().unwrap_or_default();
        let ts = e["ts"].as_f64().unwrap_or(0.0);
        match ph {
            "X" => {
                let (Some(p), Some(pair)) = (process(e), e["args"]["pair"].as_u64()) else {
                    continue;
                };
                if let Some(i) = step_index(&p, name) {
                    spans.push((pair, i, e["dur"].as_f64().unwrap_or(0.0)));
                }
            }
            "b" => {
                let key = (e["cat"].to_string(), e["id"].to_string());
                if let Some(pair) = e["args"]["pair"].as_u64() {
                    open.insert(key, (pair, ts));
                }
            }
            "e" => {
                let key = (e["cat"].to_string(), e["id"].to_string());
                let Some((pair, start)) = open.remove(&key) else {
                    continue;
                };
                let Some(p) = process(e) else { continue };
                if name == "end_to_end" {
                    pairs.entry(pair).or_default().end_to_end_us = ts - start;
                } else if let Some(i) = step_index(&p, name) {
                    spans.push((pair, i, ts - start));
                }
            }
            _ => {}
        }
    }
    // Per step the longest instance (two UAVs, or a retried stage).
    for (pair, i, dur) in spans {
        if let Some(b) = pairs.get_mut(&pair) {
            b.steps[i] = b.steps[i].max(dur);
        }
    }
    let mut out: Vec<PairBudget> = pairs
        .into_values()
        .filter(|b| b.end_to_end_us > 0.0)
        .collect();
    for b in &mut out {
        let known: f64 = b.steps[..STEPS.len() - 1].iter().sum();
        b.steps[STEPS.len() - 1] = (b.end_to_end_us - known).max(0.0);
    }
    Ok(out)
}

/// The durations (µs) of matching's refresh thread's jobs in a trace (its own lane,
/// off every estimate's path: `matching::chain::refresh`).
pub fn refreshes(path: &Path) -> Result<Vec<f64>> {
    let events = trace_events(path)?;
    let matching = events
        .iter()
        .find(|e| e["name"] == "process_name" && e["args"]["name"] == "matching")
        .map(|e| e["pid"].clone());
    Ok(events
        .iter()
        .filter(|e| {
            e["ph"] == "X" && e["name"] == "refresh" && Some(&e["pid"]) == matching.as_ref()
        })
        .filter_map(|e| e["dur"].as_f64())
        .collect())
}

/// One line on the refresh lane: how many jobs, their p50 and p99.
pub fn refresh_lane(durations: &[f64]) -> String {
    let mut v = durations.to_vec();
    v.sort_by(f64::total_cmp);
    format!(
        "Refresh thread (off the critical path): {} refreshes, p50 {:.2} ms, p99 {:.2} ms.",
        v.len(),
        percentile(&v, 0.5) / 1e3,
        percentile(&v, 0.99) / 1e3
    )
}

/// The `q` quantile of ascending `sorted` (the nearest rank; NaN when empty).
pub fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i]
}

/// The budget as a markdown table (ms): each step's p50 and p99, and its mean share of
/// the slowest 1 % of estimates.
pub fn table(budgets: &[PairBudget]) -> String {
    let mut e2e: Vec<f64> = budgets.iter().map(|b| b.end_to_end_us).collect();
    e2e.sort_by(f64::total_cmp);
    let p99 = percentile(&e2e, 0.99);
    let slow: Vec<&PairBudget> = budgets.iter().filter(|b| b.end_to_end_us >= p99).collect();
    let mut out = String::from(
        "| step | p50 ms | p99 ms | share of the slowest 1 % |\n| --- | ---: | ---: | ---: |\n",
    );
    for (i, step) in STEPS.iter().enumerate() {
        let mut v: Vec<f64> = budgets.iter().map(|b| b.steps[i]).collect();
        v.sort_by(f64::total_cmp);
        let share = slow
            .iter()
            .map(|b| b.steps[i] / b.end_to_end_us)
            .sum::<f64>()
            / slow.len().max(1) as f64;
        out.push_str(&format!(
            "| {step} | {:.2} | {:.2} | {:.0} % |\n",
            percentile(&v, 0.5) / 1e3,
            percentile(&v, 0.99) / 1e3,
            100.0 * share
        ));
    }
    out.push_str(&format!(
        "| **end-to-end** | **{:.2}** | **{:.2}** | {} estimates |\n",
        percentile(&e2e, 0.5) / 1e3,
        p99 / 1e3,
        budgets.len()
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn a_pairs_steps_and_the_rest_add_up_to_its_end_to_end() {
        let doc = json!({"traceEvents": [
            {"name": "process_name", "ph": "M", "pid": 1, "args": {"name": "acquisition"}},
            {"name": "process_name", "ph": "M", "pid": 2, "args": {"name": "detection"}},
            {"name": "process_name", "ph": "M", "pid": 4, "args": {"name": "geolocation"}},
            {"name": "end_to_end", "cat": "geolocation.end_to_end", "ph": "b", "id": "5-2", "pid": 4, "ts": 0.0, "args": {"pair": 5}},
            {"name": "decode", "ph": "X", "pid": 1, "ts": 0.0, "dur": 10.0, "args": {"pair": 5}},
            {"name": "detect", "ph": "X", "pid": 2, "ts": 12.0, "dur": 4.0, "args": {"pair": 5, "uav": 0}},
            {"name": "detect", "ph": "X", "pid": 2, "ts": 16.0, "dur": 6.0, "args": {"pair": 5, "uav": 1}},
            {"name": "end_to_end", "cat": "geolocation.end_to_end", "ph": "e", "id": "5-2", "pid": 4, "ts": 30.0},
        ]});
        let path = std::env::temp_dir().join(format!("budget-test-{}.json", std::process::id()));
        std::fs::write(&path, doc.to_string()).unwrap();
        let b = read(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert_eq!(b.len(), 1);
        assert_eq!(b[0].end_to_end_us, 30.0);
        assert_eq!(b[0].steps[0], 10.0);
        assert_eq!(b[0].steps[3], 6.0, "the later UAV's");
        assert_eq!(b[0].steps[STEPS.len() - 1], 14.0);
        assert!(table(&b).contains("| decode or render | 0.01 |"));
    }

    #[test]
    fn the_refresh_lane_counts_matchings_refresh_jobs_only() {
        let doc = json!({"traceEvents": [
            {"name": "process_name", "ph": "M", "pid": 3, "args": {"name": "matching"}},
            {"name": "process_name", "ph": "M", "pid": 2, "args": {"name": "detection"}},
            {"name": "refresh", "ph": "X", "pid": 3, "tid": 5, "ts": 0.0, "dur": 20000.0, "args": {"pair": 5}},
            {"name": "refresh", "ph": "X", "pid": 3, "tid": 5, "ts": 40000.0, "dur": 30000.0, "args": {"pair": 11}},
            {"name": "refresh_orb", "ph": "X", "pid": 3, "tid": 5, "ts": 0.0, "dur": 5000.0, "args": {"pair": 5}},
            {"name": "refresh", "ph": "X", "pid": 2, "tid": 0, "ts": 0.0, "dur": 1.0, "args": {"pair": 5}},
        ]});
        let path = std::env::temp_dir().join(format!("lane-test-{}.json", std::process::id()));
        std::fs::write(&path, doc.to_string()).unwrap();
        let d = refreshes(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert_eq!(d, vec![20000.0, 30000.0]);
        assert!(
            refresh_lane(&d).contains("2 refreshes, p50 30.00 ms"),
            "{}",
            refresh_lane(&d)
        );
    }
}
