//! Issue #15: the honest end-to-end clock and `--trace`. A recording replayed at its
//! own rate with `--trace`: the trace is Chrome trace-event JSON with a track per
//! process; every span of a pair that became an estimate lies inside that estimate's
//! end-to-end interval (capture → published); and the clock is the honest one: a
//! pair's capture is its due time on the replay clock and its decoding starts no
//! earlier, so decoding is inside the end-to-end time and the pacing wait is not.
//! Keyframe work (ORB, matching with past images) is on matching's refresh lane, never
//! on an estimate's path (issue #24).

#[path = "support/scratch.rs"]
mod scratch;

use scratch::Scratch;
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

fn dualgeo() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dualgeo"))
}

#[test]
fn every_span_nests_in_its_estimates_end_to_end_and_capture_is_the_due_time() {
    let dir = Scratch::new("latency-trace");
    let rec = dir.join("rec");
    let o = dualgeo()
        .args([
            "simulate",
            "--preset",
            "default",
            "--duration-s",
            "6",
            "--out",
        ])
        .arg(&rec)
        .output()
        .expect("simulate");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let trace = dir.join("trace.json");
    let o = dualgeo()
        .args(["run", "--source"])
        .arg(&rec)
        .arg("--out")
        .arg(dir.join("out"))
        .arg("--trace")
        .arg(&trace)
        .output()
        .expect("run");
    assert!(
        o.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let doc: Value = serde_json::from_slice(&std::fs::read(&trace).expect("trace file"))
        .expect("the trace is JSON");
    let events = doc["traceEvents"].as_array().expect("traceEvents");

    let processes: BTreeSet<&str> = events
        .iter()
        .filter(|e| e["name"] == "process_name")
        .filter_map(|e| e["args"]["name"].as_str())
        .collect();
    assert_eq!(
        processes,
        BTreeSet::from(["acquisition", "detection", "geolocation", "matching"])
    );
    let ts = |e: &Value| e["ts"].as_f64().expect("ts");
    let pair = |e: &Value| e["args"]["pair"].as_u64();

    // Each estimate's end-to-end interval: its async begin and end.
    let mut e2e: BTreeMap<u64, (f64, f64)> = BTreeMap::new();
    let mut begins: BTreeMap<String, (u64, f64)> = BTreeMap::new();
    for e in events.iter().filter(|e| e["name"] == "end_to_end") {
        let id = e["id"].as_str().expect("id").to_string();
        match e["ph"].as_str() {
            Some("b") => {
                begins.insert(id, (pair(e).expect("pair"), ts(e)));
            }
            Some("e") => {
                let (p, start) = begins.remove(&id).expect("a begin before its end");
                e2e.insert(p, (start, ts(e)));
            }
            other => panic!("end_to_end as {other:?}"),
        }
    }
    // A real-time replay: how many pairs become estimates depends on the machine's
    // speed (late pairs are skipped, issue #15). Here 6 s made 68 (alone); CI, on a
    // machine running 2.3× slower than usual, 14, below the 20 this asked. Every
    // traced estimate is checked below; a few are enough.
    eprintln!("{} estimates traced", e2e.len());
    assert!(e2e.len() > 5, "only {} estimates traced", e2e.len());

    // Every span of those pairs nests inside (1 ns of rounding allowed).
    let eps = 1e-3;
    let mut names = BTreeSet::new();
    let mut checked = 0;
    let mut decode_after_capture_us = Vec::new();
    for e in events.iter().filter(|e| e["ph"] == "X" || e["ph"] == "b") {
        let Some((start, end)) = pair(e).and_then(|p| e2e.get(&p)) else {
            continue;
        };
        let name = e["name"].as_str().unwrap_or_default();
        names.insert(name.to_string());
        // The refresh thread's work carries the frame it refreshed, and lands later:
        // it is not on that pair's path (checked below).
        if name.starts_with("refresh") {
            continue;
        }
        let (a, b) = if e["ph"] == "X" {
            (ts(e), ts(e) + e["dur"].as_f64().expect("dur"))
        } else {
            let id = &e["id"];
            let end_ev = events
                .iter()
                .find(|x| {
                    x["ph"] == "e"
                        && &x["id"] == id
                        && x["name"] == e["name"]
                        && x["cat"] == e["cat"]
                })
                .expect("the async span's end");
            (ts(e), ts(end_ev))
        };
        assert!(
            a >= start - eps && b <= end + eps,
            "{name} of pair {:?} [{a}, {b}] outside its end-to-end [{start}, {end}]",
            pair(e)
        );
        if name == "decode" {
            decode_after_capture_us.push(a - start);
        }
        checked += 1;
    }
    for want in [
        "decode",
        "publish",
        "wait",
        "detect",
        "track",
        "match_pair",
        "past",
        "F",
        "transfer",
        "estimate",
        "end_to_end",
    ] {
        assert!(names.contains(want), "no {want} span: {names:?}");
    }
    // Issue #24: no keyframe work (ORB, Hamming matching with a past image) on any
    // estimate's path; it runs on matching's refresh thread, a lane of its own.
    for absent in ["orb", "match"] {
        assert!(!names.contains(absent), "{absent} on the per-pair path");
    }
    let matching_pid = events
        .iter()
        .find(|e| e["name"] == "process_name" && e["args"]["name"] == "matching")
        .map(|e| e["pid"].clone())
        .expect("matching's pid");
    let refresh_lane: BTreeSet<&str> = events
        .iter()
        .filter(|e| e["ph"] == "X" && e["pid"] == matching_pid && e["tid"] == 5)
        .filter_map(|e| e["name"].as_str())
        .collect();
    for want in ["refresh", "refresh_orb", "refresh_match", "refresh_F"] {
        assert!(
            refresh_lane.contains(want),
            "no {want} on the refresh lane: {refresh_lane:?}"
        );
    }
    assert!(
        checked > 20 * e2e.len(),
        "{checked} spans for {} estimates",
        e2e.len()
    );

    // The clock starts at each pair's moment on the replay clock: every capture lies
    // on the recording's 1/30 s grid (a pair skipped because the machine fell behind
    // leaves a gap, never an offset), whatever decoding and the load did; decoding,
    // inside (above), starts no earlier than it.
    let first = e2e.values().next().map(|(b, _)| *b).expect("an estimate");
    let period_us = 1e6 / 30.0;
    for (p, (b, _)) in &e2e {
        let periods = (b - first) / period_us;
        assert!(
            (periods - periods.round()).abs() * period_us < 50.0,
            "pair {p} captured {} µs after the first, off the frame grid",
            b - first
        );
    }
    assert!(!decode_after_capture_us.is_empty());
}

#[test]
fn a_trace_into_a_missing_directory_is_refused_before_anything_starts() {
    let dir = Scratch::new("latency-trace-bad");
    let o = dualgeo()
        .args([
            "run",
            "--duration-s",
            "1",
            "--trace",
            "/no/such/dir/t.json",
            "--out",
        ])
        .arg(dir.join("out"))
        .output()
        .expect("run");
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("no directory"));
    assert!(!dir.join("out/track.csv").exists());
}
