//! Per-frame spans for latency profiling (`dualgeo run --trace FILE`, issue #15).
//!
//! Each process records the spans of its work per frame or pair (decode, publish,
//! detection, ORB, each past-image match, F, transfer, estimate, and the waits between
//! them) on CLOCK_MONOTONIC, the clock every dualgeo process shares, and appends them
//! as JSON lines to `<trace-dir>/<process>.<incarnation>.jsonl` at most once a second
//! and on exit. The supervisor merges the files into one Chrome trace-event JSON
//! (`dualgeo::pipeline::trace_file`), which Perfetto and chrome://tracing open.
//!
//! Off by default: a [`Tracer`] that is off holds no buffer and each call is one
//! branch, so a run without `--trace` pays nothing measurable.

use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// One span: `name` of work on `pair` (the pair's or the frame's sequence number),
/// from `start_ns` to `end_ns` (CLOCK_MONOTONIC); `uav` for per-frame work.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Span {
    pub name: String,
    pub pair: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uav: Option<u8>,
    /// The past frame (its sequence number) a matching step worked on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keyframe: Option<u64>,
    pub start_ns: u64,
    pub end_ns: u64,
}

/// How often a tracer appends its spans to its file.
const FLUSH_INTERVAL: Duration = Duration::from_secs(1);
/// Spans buffered at most before a flush is forced.
const MAX_BUFFERED: usize = 16_384;

#[derive(Debug)]
pub struct Tracer {
    on: Option<On>,
}

#[derive(Debug)]
struct On {
    path: PathBuf,
    spans: Vec<Span>,
    last_flush: Instant,
    /// Spans that could not be written (the file is not writable): dropped.
    lost: u64,
}

impl Tracer {
    /// A tracer that records nothing.
    pub fn off() -> Self {
        Self { on: None }
    }

    /// A tracer writing `<dir>/<process>.<incarnation>.jsonl` when `dir` is given.
    pub fn new(dir: Option<&Path>, process: &str, incarnation: u32) -> Self {
        Self {
            on: dir.map(|d| On {
                path: d.join(format!("{process}.{incarnation}.jsonl")),
                spans: Vec::new(),
                last_flush: Instant::now(),
                lost: 0,
            }),
        }
    }

    pub fn is_on(&self) -> bool {
        self.on.is_some()
    }

    /// Records a span (nothing when off).
    #[inline]
    pub fn span(&mut self, name: &str, pair: u64, uav: Option<u8>, start_ns: u64, end_ns: u64) {
        self.past_span(name, pair, uav, None, start_ns, end_ns);
    }

    /// Records a span of work on a past frame `keyframe` (nothing when off).
    #[inline]
    pub fn past_span(
        &mut self,
        name: &str,
        pair: u64,
        uav: Option<u8>,
        keyframe: Option<u64>,
        start_ns: u64,
        end_ns: u64,
    ) {
        if let Some(on) = &mut self.on {
            on.spans.push(Span {
                name: name.to_string(),
                pair,
                uav,
                keyframe,
                start_ns,
                end_ns: end_ns.max(start_ns),
            });
            if on.spans.len() >= MAX_BUFFERED {
                on.flush();
            }
        }
    }

    /// Appends the buffered spans if a second has passed since the last time.
    pub fn maybe_flush(&mut self) {
        if let Some(on) = &mut self.on {
            if on.last_flush.elapsed() >= FLUSH_INTERVAL {
                on.flush();
            }
        }
    }

    /// Appends the buffered spans now (on exit).
    pub fn flush(&mut self) {
        if let Some(on) = &mut self.on {
            on.flush();
        }
    }
}

impl On {
    fn flush(&mut self) {
        self.last_flush = Instant::now();
        if self.spans.is_empty() {
            return;
        }
        let written = (|| -> std::io::Result<()> {
            let f = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&self.path)?;
            let mut w = std::io::BufWriter::new(f);
            for s in &self.spans {
                serde_json::to_writer(&mut w, s)?;
                w.write_all(b"\n")?;
            }
            w.flush()
        })();
        if let Err(e) = written {
            if self.lost == 0 {
                tracing::warn!(path = %self.path.display(), error = %e, "trace spans not written");
            }
            self.lost += self.spans.len() as u64;
        }
        self.spans.clear();
    }
}

impl Drop for Tracer {
    fn drop(&mut self) {
        self.flush();
    }
}

/// Every span of a trace directory's files, with the process each came from
/// (`acquisition`, `detection`, ...); a line that does not parse (a file cut by a kill)
/// is skipped and counted.
pub fn read_dir(dir: &Path) -> std::io::Result<(Vec<(String, Span)>, u64)> {
    let mut out = Vec::new();
    let mut bad = 0;
    let mut entries: Vec<_> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "jsonl"))
        .collect();
    entries.sort();
    for path in entries {
        let name = path
            .file_stem()
            .and_then(|s| s.to_str())
            .and_then(|s| s.split('.').next())
            .unwrap_or("unknown")
            .to_string();
        for line in std::fs::read_to_string(&path)?.lines() {
            match serde_json::from_str::<Span>(line) {
                Ok(s) => out.push((name.clone(), s)),
                Err(_) => bad += 1,
            }
        }
    }
    Ok((out, bad))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_off_tracer_records_nothing_and_an_on_one_writes_lines() {
        let mut off = Tracer::off();
        off.span("x", 1, None, 1, 2);
        assert!(!off.is_on());
        let dir = std::env::temp_dir().join(format!("dualgeo-trace-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        {
            let mut t = Tracer::new(Some(&dir), "matching", 1);
            t.span("orb", 7, Some(0), 100, 200);
            t.span("backwards", 8, None, 300, 250);
        } // dropped: flushed
        std::fs::write(dir.join("detection.0.jsonl"), "{\"cut").unwrap();
        let (spans, bad) = read_dir(&dir).unwrap();
        assert_eq!(bad, 1);
        assert_eq!(spans.len(), 2);
        assert_eq!(spans[0].0, "matching");
        assert_eq!(spans[0].1.uav, Some(0));
        assert_eq!(spans[1].1.end_ns, 300, "an end before the start is clamped");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
