//! Issue #13's CI soak: a looped recording for 60 s with the soak report sampled every
//! 5 s. The report is written as the run goes (soak.csv, track.csv readable while it
//! runs), every process is sampled, no descriptor leaks after the warm-up, and memory's
//! floor rises by at most 2 % or 1.5 MiB over the 40 s after it (the 1 % target is for
//! the 1 h soak in docs/reliability.md: 40 s cannot show a slow leak, a fast one it can).

#[path = "support/chaos.rs"]
mod chaos;
#[path = "support/scratch.rs"]
mod scratch;

use scratch::Scratch;
use std::process::{Command, Stdio};
use std::time::Duration;

/// How far a process's memory floor may rise from 30 s to the end, at least (KiB).
const FLOOR_SLACK_KIB: f64 = 1536.0;
/// How far any sample may be above the first floor, at least (KiB).
const PEAK_SLACK_KIB: f64 = 2048.0;

#[test]
fn a_sixty_second_soak_reports_flat_memory_and_streams_its_outputs() {
    let dir = Scratch::new("soak");
    let rec = dir.0.join("rec");
    let out = dir.0.join("out");
    let dualgeo = std::path::Path::new(env!("CARGO_BIN_EXE_dualgeo"));
    // Each pass starts over with a few seconds of warm-up: 10 s passes keep estimates
    // flowing for most of the run.
    chaos::simulate_default(dualgeo, 10, &rec).unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args([
            "run",
            "--loop",
            "--run-for-s",
            "60",
            "--sample-every-s",
            "5",
        ])
        .args(["--soak-warm-up-s", "20", "--source"])
        .arg(&rec)
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn dualgeo run");
    // Streamed: half-way through, the track and the soak rows are already on disk.
    std::thread::sleep(Duration::from_secs(35));
    let rows = |f: &str| {
        std::fs::read_to_string(out.join(f))
            .map(|t| t.lines().count())
            .unwrap_or(0)
    };
    let (track_mid, soak_mid) = (rows("track.csv"), rows("soak.csv"));
    let o = run.wait_with_output().expect("wait for dualgeo run");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(track_mid > 50, "track.csv had {track_mid} lines after 35 s");
    assert!(soak_mid >= 5, "soak.csv had {soak_mid} lines after 35 s");
    assert!(rows("track.csv") > track_mid);
    assert!(out.join("soak.png").is_file());
    assert!(stdout.contains("soak: RSS"), "{stdout}");

    let text = std::fs::read_to_string(out.join("soak.csv")).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let samples: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert!(samples.len() >= 11, "{} samples", samples.len());
    // Memory is judged from 30 s. Matching's working set still stepped up by ~1 MiB
    // between the samples at 21 and 26 s in one clean-clone CI run (40 300 → 41 324 KiB,
    // then flat within 0.4 %), where three runs here were already at 41.1–41.5 MB at
    // 21 s. Its likely cause (not traced): OpenCV keeps data per thread and per function (buffers of
    // ORB, KLT, parallel_for_), allocated the first time a thread runs that function,
    // and which of rayon's workers (and OpenCV's own pool) picks up which task varies
    // from run to run; the set of (thread, function) pairs grows to all of them and
    // stops (docs/reliability.md's hour: 41.1–41.6 MB, a plateau). When the last pair
    // comes after the warm-up, the floor steps once. A leak keeps rising after it.
    let after: Vec<&Vec<f64>> = samples.iter().filter(|s| s[0] > 30.5).collect();
    for (col, name) in header.iter().enumerate() {
        let mut values: Vec<f64> = after.iter().map(|s| s[col]).collect();
        if let Some(process) = name.strip_prefix("rss_kib_") {
            // Private memory: the RSS less the shared memory. iceoryx2's pools are fixed
            // in size, and their pages count in RSS from the first time a slot is
            // written: in a run of the whole test suite here acquisition was at
            // 86 776 KiB until a backlog at ~40 s first wrote 4 more 640 x 480 frame
            // slots, then 90 376-91 000 KiB, flat (its RssAnon and RssFile unchanged;
            // runs alone are at 90 884 from the start). `shm_kib_*` is reported and
            // not judged here (docs/reliability.md).
            let shm = header
                .iter()
                .position(|h| *h == format!("shm_kib_{process}"))
                .expect("a shm_kib column per process");
            for (v, s) in values.iter_mut().zip(&after) {
                *v -= s[shm];
            }
            eprintln!(
                "shm_kib_{process}: {:?}",
                after.iter().map(|s| s[shm]).collect::<Vec<_>>()
            );
            assert!(values.iter().all(|v| *v > 1000.0), "{name}: {values:?}");
            // A leak raises the floor; a sample taken while a process holds a transient
            // working set only rises above it. The floor of the last three samples is
            // held to the floor of the first three, and no sample may be far above it.
            //
            // How far is measured, not chosen: geolocation is a single-threaded 10 MB
            // process with a 3-4 MB heap, and glibc keeps freed heap resident until the
            // top of the heap is free, so its RSS wanders and comes back. In a 10 min
            // run (default preset, 10 s passes looped, sampled every 10 s) its VmRSS
            // ranged 9 716-10 632 KiB with no trend (elevated by 916 KiB for 60 s, then
            // back to 9 800); sampled every second, it stepped 9 336 -> 10 392 KiB
            // between 25 and 37 s; a CI run failed at 2 % with 10 340 then 10 700 KiB.
            // So the allowance is 2 % (10 %) or a fixed 1.5 MiB (2 MiB) for the floor
            // (the peak), whichever is larger. The fixed part only matters for the
            // processes under ~75 MB (20 MB); a leak faster than ~60 KiB/s (~75 KiB/s in
            // the 90 MB acquisition) still fails here, and the hour in
            // docs/reliability.md is the test of a slow one.
            eprintln!("{name} less shm_kib_{process}: {values:?}");
            assert!(values.len() >= 5, "{name}: {values:?}");
            let floor = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
            let (head, tail) = (floor(&values[..3]), floor(&values[values.len() - 3..]));
            let rise = tail - head;
            assert!(
                rise <= (0.02 * head).max(FLOOR_SLACK_KIB),
                "{name}: floor rose {rise:.0} KiB ({:.1} %): {values:?}",
                rise / head * 100.0
            );
            let peak = values.iter().copied().fold(0.0, f64::max);
            assert!(
                peak - head <= (0.10 * head).max(PEAK_SLACK_KIB),
                "{name}: peak {:.1} % above the floor: {values:?}",
                (peak / head - 1.0) * 100.0
            );
        }
        if name.starts_with("fds_") {
            assert!(
                values.iter().all(|v| *v == values[0] && *v > 2.0),
                "{name}: {values:?}"
            );
        }
    }
}
