//! `dualgeo run --trace FILE`: the spans every process appended under `<out>/trace/`
//! (`shared_types::trace`) merged into one Chrome trace-event JSON file, which
//! Perfetto (ui.perfetto.dev) and chrome://tracing open.
//!
//! One process per dualgeo process (`pid`), named; work is a complete event (`X`) on a
//! thread of its process: acquisition's pairs (tid 0), per UAV (tid 1 left, 2 right:
//! detection, ORB), matching's pair (tid 0), its past-image jobs on lanes (tid 10 +
//! the job's place in its pair) and its refresh thread (tid 5: `refresh` and its
//! steps, keyed by the frame it refreshed), geolocation (tid 0). Waits (a message
//! published → its consumer started on it, a refresh queued → started) and each
//! estimate's end-to-end interval (its capture → published) overlap from one frame to
//! the next, so they are async events (`b`/`e`, id = the pair). Times are microseconds from the first span; every event carries its
//! pair in `args`.

use anyhow::{Context, Result};
use serde_json::{json, Value};
use shared_types::trace::{read_dir, Span};
use std::collections::HashMap;
use std::path::Path;

const PROCESSES: [&str; 4] = ["acquisition", "detection", "matching", "geolocation"];

fn pid(process: &str) -> u64 {
    PROCESSES
        .iter()
        .position(|p| *p == process)
        .map_or(9, |i| i as u64 + 1)
}

/// Async (overlapping) spans.
fn is_async(name: &str) -> bool {
    matches!(name, "wait" | "end_to_end" | "refresh_queued")
}

/// What `write` wrote.
pub struct TraceSummary {
    pub spans: usize,
    pub unreadable_lines: u64,
}

/// Merges `dir`'s span files into the Chrome trace `file`.
pub fn write(dir: &Path, file: &Path) -> Result<TraceSummary> {
    let (spans, unreadable_lines) =
        read_dir(dir).with_context(|| format!("read the spans in {}", dir.display()))?;
    let events = events(&spans);
    let doc = json!({"displayTimeUnit": "ms", "traceEvents": events});
    std::fs::write(file, serde_json::to_vec(&doc)?)
        .with_context(|| format!("write {}", file.display()))?;
    Ok(TraceSummary {
        spans: spans.len(),
        unreadable_lines,
    })
}

/// The trace events of `spans` (process, span), metadata first.
pub fn events(spans: &[(String, Span)]) -> Vec<Value> {
    let t0 = spans.iter().map(|(_, s)| s.start_ns).min().unwrap_or(0);
    let us = |ns: u64| (ns.saturating_sub(t0)) as f64 / 1e3;
    let mut out = Vec::with_capacity(spans.len() + 16);
    for p in PROCESSES {
        out.push(json!({"name": "process_name", "ph": "M", "pid": pid(p), "args": {"name": p}}));
        out.push(json!({"name": "process_sort_index", "ph": "M", "pid": pid(p), "args": {"sort_index": pid(p)}}));
        for (tid, name) in [(0, "pairs"), (1, "left"), (2, "right"), (5, "refresh")] {
            out.push(json!({"name": "thread_name", "ph": "M", "pid": pid(p), "tid": tid, "args": {"name": name}}));
        }
    }
    // Matching's past-image jobs: a lane per job within its pair.
    let mut lanes: HashMap<(u64, u8, u64), u64> = HashMap::new();
    let mut next_lane: HashMap<u64, u64> = HashMap::new();
    for (process, s) in spans {
        let pid = pid(process);
        let mut args = json!({"pair": s.pair});
        if let Some(k) = s.keyframe {
            args["keyframe"] = json!(k);
        }
        if let Some(u) = s.uav {
            args["uav"] = json!(u);
        }
        if is_async(&s.name) {
            let cat = format!("{process}.{}", s.name);
            let id = format!("{}-{}", s.pair, s.uav.map_or(2, u64::from));
            out.push(json!({"name": s.name, "cat": cat, "ph": "b", "id": id, "pid": pid, "tid": 0, "ts": us(s.start_ns), "args": args}));
            out.push(json!({"name": s.name, "cat": cat, "ph": "e", "id": id, "pid": pid, "tid": 0, "ts": us(s.end_ns)}));
            continue;
        }
        let tid = match (s.keyframe, s.uav) {
            _ if s.name.starts_with("refresh") => 5,
            (Some(k), Some(u)) => {
                let key = (s.pair, u, k);
                let lane = match lanes.get(&key) {
                    Some(l) => *l,
                    None => {
                        let n = next_lane.entry(s.pair).or_insert(0);
                        *n += 1;
                        lanes.insert(key, *n);
                        *n
                    }
                };
                10 + lane
            }
            (None, Some(u)) => 1 + u64::from(u.min(1)),
            _ => 0,
        };
        out.push(json!({
            "name": s.name,
            "cat": process,
            "ph": "X",
            "pid": pid,
            "tid": tid,
            "ts": us(s.start_ns),
            "dur": (s.end_ns - s.start_ns) as f64 / 1e3,
            "args": args,
        }));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn span(name: &str, pair: u64, uav: Option<u8>, keyframe: Option<u64>, a: u64, b: u64) -> Span {
        Span {
            name: name.into(),
            pair,
            uav,
            keyframe,
            start_ns: a,
            end_ns: b,
        }
    }

    #[test]
    fn spans_become_complete_and_async_events_on_their_tracks() {
        let spans = vec![
            (
                "detection".to_string(),
                span("detect", 3, Some(1), None, 2_000, 5_000),
            ),
            (
                "matching".to_string(),
                span("F", 3, Some(0), Some(1), 6_000, 7_500),
            ),
            (
                "matching".to_string(),
                span("F", 3, Some(0), Some(2), 6_000, 7_000),
            ),
            (
                "matching".to_string(),
                span("match", 3, Some(0), Some(1), 5_500, 6_000),
            ),
            (
                "geolocation".to_string(),
                span("end_to_end", 3, None, None, 1_000, 9_000),
            ),
        ];
        let ev = events(&spans);
        let work: Vec<&Value> = ev.iter().filter(|e| e["ph"] == "X").collect();
        assert_eq!(work.len(), 4);
        assert_eq!(work[0]["pid"], 2);
        assert_eq!(work[0]["tid"], 2, "right");
        assert_eq!(work[0]["ts"], 1.0, "µs from the first span");
        assert_eq!(work[0]["dur"], 3.0);
        assert_eq!(work[1]["tid"], 11);
        assert_eq!(work[2]["tid"], 12, "another past frame, another lane");
        assert_eq!(work[3]["tid"], 11, "the same past frame, the same lane");
        let b: Vec<&Value> = ev.iter().filter(|e| e["ph"] == "b").collect();
        let e: Vec<&Value> = ev.iter().filter(|e| e["ph"] == "e").collect();
        assert_eq!((b.len(), e.len()), (1, 1));
        assert_eq!(
            (b[0]["ts"].as_f64(), e[0]["ts"].as_f64()),
            (Some(0.0), Some(8.0))
        );
        assert_eq!(b[0]["args"]["pair"], 3);
        let names = ev.iter().filter(|e| e["name"] == "process_name").count();
        assert_eq!(names, 4);
    }
}
