//! Issue #13's chaos test: during one looped run of a recording, every service is
//! killed (SIGKILL) twice at random moments (fixed seed) while estimates flow in the
//! middle of a pass (`chaos::LapGuard`: each pass starts over with a warm-up, which a
//! kill landing there would measure instead of the restart). The run must end normally
//! with complete outputs; estimates must resume after each kill; no estimate may be
//! out of order or non-finite; the restarted services must have resumed from their
//! checkpoints (stream position, keyframe rings, filter state).
//!
//! How fast they resume is a speed figure, measured by the 100-kill benchmark with
//! recovery percentiles (`bench/src/bin/chaos.rs`, docs/reliability.md), not here: on
//! a shared CI machine one geolocation restart took 1 136 ms where it usually takes
//! 100–400 ms.

#[path = "support/chaos.rs"]
mod chaos;

#[path = "support/scratch.rs"]
mod scratch;

use chaos::{kill_services, read_restarts, recoveries, LapGuard, Rng, SERVICES};
use scratch::{json, Scratch};
use std::process::{Command, Stdio};

#[test]
fn services_killed_at_random_moments_are_restarted_and_the_track_goes_on() {
    let dir = Scratch::new("chaos");
    let rec = dir.0.join("rec");
    let out = dir.0.join("out");
    let dualgeo = std::path::Path::new(env!("CARGO_BIN_EXE_dualgeo"));
    // Two passes and a bit: most kills in the first, some after the jump (a restart
    // in the second segment resumes it, not the first).
    chaos::simulate_default(dualgeo, 16, &rec).unwrap();

    let run = Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args(["run", "--loop", "--run-for-s", "36", "--source"])
        .arg(&rec)
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn dualgeo run");
    // Each service twice, in an order drawn from the seed.
    let mut rng = Rng::new(13);
    let mut order: Vec<&'static str> = SERVICES.iter().chain(&SERVICES).copied().collect();
    for i in (1..order.len()).rev() {
        order.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
    }
    let guard = LapGuard::new(&out, &rec).unwrap();
    let kills = kill_services(
        run.id(),
        order.len(),
        &mut rng,
        (1.0, 2.0),
        &guard,
        |i, _| order[i],
        |_| {},
    );
    let o = run.wait_with_output().expect("wait for dualgeo run");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert_eq!(
        kills.len(),
        8,
        "not every kill happened: {kills:?}\n{stderr}"
    );

    // Complete outputs.
    for f in [
        "report.json",
        "counters.json",
        "track.csv",
        "track.geojson",
        "latency.png",
        "restarts.csv",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let report = json(&out.join("report.json"));
    for s in SERVICES {
        assert_eq!(report["restarts"][s], 2, "{report}");
    }
    assert_eq!(report["recovery_ms"]["unrecovered"], 0, "{report}");

    // Estimates resumed after each kill. The bound is not the speed target (the
    // benchmark's): it tells a restart from a pipeline left wedged for seconds, or a
    // service held at the supervisor's crash-loop backoff cap (4 s).
    let rows = read_restarts(&out);
    for (service, ms) in recoveries(&kills, &rows) {
        let ms = ms.unwrap_or_else(|| panic!("{service}: no recovery in {rows:?}"));
        eprintln!("{service} killed: estimates resumed after {ms:.0} ms");
        assert!(
            ms < 4000.0,
            "{service}: estimates resumed {ms:.0} ms after the kill"
        );
    }

    // Nothing stale, nothing wrong: the supervisor's guard found nothing to drop, and
    // the track is finite and strictly in time order.
    let counters = json(&out.join("counters.json"));
    for guard in ["supervisor.out_of_order", "supervisor.non_finite"] {
        assert!(counters.get(guard).is_none(), "{guard}: {counters}");
    }
    // A looped recording is good input: the live-input gate drops nothing across
    // passes and restarts.
    let faults: Vec<&String> = counters
        .as_object()
        .unwrap()
        .keys()
        .filter(|k| k.contains("live_faults"))
        .collect();
    assert!(faults.is_empty(), "{faults:?}: {counters}");
    let track = std::fs::read_to_string(out.join("track.csv")).unwrap();
    // Each vehicle's rows strictly in time order (the other vehicles' tracks share
    // their pair's time with the target's row).
    let mut last_t: std::collections::HashMap<String, f64> = Default::default();
    let mut rows_seen = 0;
    for line in track.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let t: f64 = f[0].parse().unwrap();
        let last = last_t
            .entry(f.last().unwrap_or(&"").to_string())
            .or_insert(f64::NEG_INFINITY);
        assert!(t > *last, "out of order at {line}");
        *last = t;
        for v in [2, 3, 4, 8, 9, 12, 13] {
            let x: f64 = f[v].parse().unwrap_or(f64::NAN);
            assert!(x.is_finite(), "column {v} not finite: {line}");
        }
        rows_seen += 1;
    }
    assert!(rows_seen > 200, "{rows_seen} estimates");

    // State survived: each restarted service resumed from its checkpoint.
    assert_eq!(counters["acquisition.resumed"], 2, "{counters}");
    assert_eq!(counters["geolocation.resumed"], 2, "{counters}");
    assert!(
        counters["matching.keyframes_restored"].as_u64().unwrap() >= 2 * 6,
        "{counters}"
    );
    // Every restart found its keyframe store whole (a store naming a keyframe file
    // that was never written is refused, and the rings are rebuilt from nothing).
    assert!(
        counters.get("matching.checkpoint_refused").is_none(),
        "{counters}"
    );
    // A resumed filter goes on as sure as before: a fresh one would start again from
    // σ = 15 m per axis (h_acc ≈ 21 m) after each geolocation restart. Each pass starts
    // a fresh filter on purpose: its first second is left out.
    let lap_s = 16.0;
    let mut seen_in_lap = std::collections::BTreeMap::new();
    let mut worst = 0.0f64;
    for l in track.lines().skip(1) {
        let f: Vec<&str> = l.split(',').collect();
        if f[15] != "0" {
            continue;
        }
        let t: f64 = f[0].parse().unwrap();
        let n = seen_in_lap.entry((t / lap_s) as u64).or_insert(0);
        *n += 1;
        if *n > 30 {
            worst = worst.max(f[12].parse().unwrap());
        }
    }
    assert!(
        worst < 10.0,
        "h_acc up to {worst:.1} m after the filter converged"
    );
    assert!(
        counters["geolocation.segments"].as_u64().unwrap() >= 1,
        "{counters}"
    );
    assert!(stderr.contains("resumed from the checkpoint"), "{stderr}");
}
