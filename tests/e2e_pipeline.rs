//! End-to-end: `dualgeo run`, the four real service processes over iceoryx2, on a short
//! simulated recording.

#[path = "support/chaos.rs"]
mod chaos;
#[path = "support/scratch.rs"]
mod scratch;

use chaos::{service_pid, wait_all_running};
use scratch::{json, Scratch};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn dualgeo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args(args)
        .output()
        .expect("spawn dualgeo")
}

/// `dualgeo run --source REC --rate max --config CONFIG --out OUT`.
fn run_max_with_config(rec: &str, config: &std::path::Path, out: &str) -> Output {
    let config = config.to_str().expect("a UTF-8 path");
    dualgeo(&[
        "run", "--source", rec, "--rate", "max", "--config", config, "--out", out,
    ])
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn keys(v: &serde_json::Value) -> Vec<String> {
    let mut k: Vec<String> = v.as_object().expect("object").keys().cloned().collect();
    k.sort();
    k
}

/// Simulates a 6 s Table 1 recording (no navigation noise), streams it through the
/// pipeline at a low rate, then corrupts one image and streams it again.
#[test]
fn pipeline_on_a_recording_and_a_corrupt_image() {
    let dir = Scratch::new("pipeline");
    let rec = dir.s("rec");
    let o = dualgeo(&[
        "simulate",
        "--preset",
        "table1",
        "--duration-s",
        "6",
        "--out",
        &rec,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));

    // 1. A clean run: estimates, sane accuracy, nothing dropped. Flow-controlled
    // (`--rate max`), so "nothing dropped" holds however busy the machine is: at a
    // fixed 10 pairs/s this assertion failed about once in ten runs when the other
    // tests of this file (live simulator runs) took both cores (issue #13, item 9).
    let out = dir.s("out");
    let o = dualgeo(&["run", "--source", &rec, "--rate", "max", "--out", &out]);
    let (stdout, stderr) = (text(&o.stdout), text(&o.stderr));
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("latency ms") && stdout.contains("end_to_end"),
        "{stdout}"
    );
    let report = json(&dir.join("out/report.json"));
    assert_eq!(
        keys(&report),
        [
            "accuracy",
            "estimates_out",
            "frames_dropped",
            "frames_in",
            "latency_us",
            "pairs_in",
            "pairs_lost_in_restarts",
            "recovery_ms",
            "restarts",
            "throughput_hz"
        ]
    );
    assert_eq!(report["pairs_lost_in_restarts"], 0, "{report}");
    assert!(report["recovery_ms"].is_null(), "{report}");
    assert_eq!(report["restarts"]["matching"], 0, "{report}");
    assert_eq!(report["frames_in"], 360, "{report}");
    assert_eq!(report["pairs_in"], 180, "{report}");
    assert_eq!(report["frames_dropped"], 0, "{report}");
    let estimates = report["estimates_out"].as_u64().unwrap();
    assert!(estimates >= 40, "{report}");
    let acc = &report["accuracy"];
    assert_eq!(keys(acc), ["mae_m", "max_m", "std_m", "yaw_bias_mae_deg"]);
    for axis in ["x", "y", "z"] {
        let mae = acc["mae_m"][axis].as_f64().unwrap();
        assert!(mae > 0.0 && mae < 1.5, "MAE {axis} = {mae}: {report}");
    }
    let lat = &report["latency_us"];
    assert_eq!(
        keys(lat),
        [
            "acquisition",
            "detection",
            "end_to_end",
            "geolocation",
            "matching",
            "transport"
        ]
    );
    for row in [
        "acquisition",
        "detection",
        "end_to_end",
        "geolocation",
        "matching",
        "transport",
    ] {
        assert_eq!(keys(&lat[row]), ["max", "p50", "p90", "p99", "p999"]);
        let (p50, max) = (
            lat[row]["p50"].as_u64().unwrap(),
            lat[row]["max"].as_u64().unwrap(),
        );
        assert!(p50 > 0 && p50 <= max, "{row}: {}", lat[row]);
    }
    assert!(report["throughput_hz"].as_f64().unwrap() > 1.0);

    let track = std::fs::read_to_string(dir.join("out/track.csv")).unwrap();
    assert!(track.starts_with("t_s,pair_seq,x_m,y_m,z_m,lat_deg,lon_deg,alt_m,yaw_bias_left_deg,yaw_bias_right_deg,images_used,iterations,h_acc_m,v_acc_m,quality,track_id\n"));
    assert_eq!(track.lines().count() as u64, estimates + 1);
    let geo = json(&dir.join("out/track.geojson"));
    let first = &geo["features"][0]["geometry"]["coordinates"][0];
    // [lon, lat, alt] near the preset's origin (30.2741 N, 120.1551 E).
    assert!(
        (first[0].as_f64().unwrap() - 120.155).abs() < 0.01,
        "{first}"
    );
    assert!(
        (first[1].as_f64().unwrap() - 30.274).abs() < 0.01,
        "{first}"
    );
    for f in [
        "latency/end_to_end.hgrm",
        "latency/transport.hgrm",
        "latency.png",
        "path.png",
    ] {
        assert!(dir.join(&format!("out/{f}")).is_file(), "{f} missing");
    }
    let hgrm = std::fs::read_to_string(dir.join("out/latency/end_to_end.hgrm")).unwrap();
    assert!(
        hgrm.contains("Percentile") && hgrm.contains("#[Max"),
        "{hgrm}"
    );

    // 2. The temporal estimator in the geolocation service, chosen by configuration,
    // and matching pinned to CPU 0 at SCHED_FIFO 15 (`[realtime]`).
    let config = dir.join("temporal.toml");
    std::fs::write(
        &config,
        "[estimator]\nmethod = \"temporal\"\n[realtime.matching]\ncpus = [0]\nfifo_priority = 15\n",
    )
    .unwrap();
    let out_t = dir.s("out-temporal");
    let o = run_max_with_config(&rec, &config, &out_t);
    let stderr = text(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    // The service read its table and says what it has: all of it, or (without
    // CAP_SYS_NICE, `mode = "auto"`) a warning naming what the kernel refused.
    let applied = stderr
        .lines()
        .find(|l| l.contains("[realtime.matching] applied"))
        .unwrap_or_else(|| panic!("no [realtime.matching] line: {stderr}"));
    if !stderr.contains("running without it") {
        assert!(
            applied.contains("fifo_priority") && applied.contains("15") && applied.contains("[0]"),
            "{applied}"
        );
    }
    let report = json(&dir.join("out-temporal/report.json"));
    assert!(report["estimates_out"].as_u64().unwrap() >= 40, "{report}");
    assert_eq!(
        report["frames_dropped"], 0,
        "--rate max is lossless: {report}"
    );
    let track = std::fs::read_to_string(dir.join("out-temporal/track.csv")).unwrap();
    let last: Vec<&str> = track.lines().last().unwrap().split(',').collect();
    let (h_acc, v_acc): (f64, f64) = (last[12].parse().unwrap(), last[13].parse().unwrap());
    assert!(
        h_acc > 0.0 && h_acc < 5.0 && v_acc > 0.0 && v_acc < 5.0,
        "{track}"
    );

    // 3. A truncated image: named in the log, its pair skipped, the run goes on.
    let victim = dir.join("rec/left/000100.png");
    let bytes = std::fs::read(&victim).unwrap();
    std::fs::write(&victim, &bytes[..bytes.len() / 2]).unwrap();
    let out2 = dir.s("out2");
    let o = dualgeo(&["run", "--source", &rec, "--rate", "max", "--out", &out2]);
    let (stdout, stderr) = (text(&o.stdout), text(&o.stderr));
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("000100.png") && stderr.contains("truncated"),
        "{stderr}"
    );
    assert!(
        stdout.contains("1 pair(s) skipped for unreadable images"),
        "{stdout}"
    );
    let report = json(&dir.join("out2/report.json"));
    assert_eq!(report["pairs_in"], 179, "{report}");
    let counters = json(&dir.join("out2/counters.json"));
    assert_eq!(counters["acquisition.bad_frames"], 1, "{counters}");
}

#[test]
fn bad_input_at_the_boundary_is_a_clear_error() {
    let dir = Scratch::new("bad-args");
    let o = dualgeo(&["run", "--source", &dir.s("nowhere"), "--out", &dir.s("out")]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("not a directory"),
        "{}",
        text(&o.stderr)
    );

    std::fs::create_dir_all(&dir.0).unwrap();
    let config = dir.join("bad.toml");
    let models = concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/models/yolov2-tiny");
    let bad_class = format!(
        "[detection]\nkind = \"yolo\"\n[detection.yolo]\nmodel = \"{models}/yolov2-tiny.weights\"\nconfig = \"{models}/yolov2-tiny.cfg\"\nnames = \"{models}/coco.names\"\nclasses = [\"cars\"]\n"
    );
    // Each bad configuration is refused before any process starts, naming its section.
    for (toml, says) in [
        ("[matching]\norb_features = 3\n", "[matching]"),
        // The learned detector's model is loaded: a class its names file lacks.
        (bad_class.as_str(), "\"cars\" is not in"),
        ("[detection]\nkind = \"yolo\"\n", "needs a [detection.yolo]"),
        // A CPU the machine does not have.
        (
            "[realtime.detection]\ncpus = [4096]\n",
            "[realtime.detection] cpus: CPU 4096",
        ),
    ] {
        std::fs::write(&config, toml).unwrap();
        let o = dualgeo(&[
            "run",
            "--config",
            config.to_str().unwrap(),
            "--out",
            &dir.s("out"),
        ]);
        assert!(!o.status.success(), "{toml}");
        assert!(text(&o.stderr).contains(says), "{}", text(&o.stderr));
    }

    // A recording the reader refuses (here a NaN in telemetry.csv) is refused before any
    // process starts, naming the file, line and column: no service ran, none restarted.
    let rec = dir.join("rec");
    let o = dualgeo(&[
        "simulate",
        "--duration-s",
        "0.2",
        "--out",
        rec.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let telemetry = rec.join("telemetry.csv");
    let csv = std::fs::read_to_string(&telemetry).unwrap();
    let mut lines: Vec<String> = csv.lines().map(String::from).collect();
    let mut fields: Vec<&str> = lines[3].split(',').collect();
    fields[7] = "nan";
    lines[3] = fields.join(",");
    std::fs::write(&telemetry, lines.join("\n") + "\n").unwrap();
    let out = dir.join("out-rec");
    let o = dualgeo(&[
        "run",
        "--source",
        rec.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = text(&o.stderr);
    assert!(
        err.contains("telemetry.csv line 4") && err.contains("yaw_deg"),
        "{err}"
    );
    assert!(!out.join("stats").exists(), "no service started");

    // A service refused its input or configuration exits 78 (not restarted by the
    // supervisor, `shell::EXIT_PERMANENT`); it fails before it opens any shared memory.
    let binary = |name: &str| {
        std::path::Path::new(env!("CARGO_BIN_EXE_dualgeo"))
            .with_file_name(format!("dualgeo-{name}"))
    };
    let service = |name: &str, args: &[&str]| {
        Command::new(binary(name))
            .args(["--run-id", "bad-input", "--stats-dir", &dir.s("stats")])
            .args(args)
            .output()
            .expect("spawn a service")
    };
    let o = service("acquisition", &["--source", &dir.s("nowhere")]);
    assert_eq!(o.status.code(), Some(78), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("nowhere"), "{}", text(&o.stderr));
    std::fs::write(&config, "[detection]\nhue = 3\n").unwrap();
    let o = service("detection", &["--config", config.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(78), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("hue"), "{}", text(&o.stderr));
}

/// `dualgeo run ARGS` with its output captured.
fn spawn_run(args: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .arg("run")
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn dualgeo")
}

/// No service of the run `pid` is left but (at most) `except`.
fn assert_stopped(pid: u32, except: &str) {
    for name in chaos::SERVICES.iter().filter(|s| **s != except) {
        assert!(service_pid(pid, name).is_none(), "{name} left running");
    }
}

/// With `--restart never`, a service that dies mid-run ends the run with its name and
/// a non-zero exit, and the other services are stopped (no process left behind).
#[test]
fn a_dying_service_ends_the_run_clearly() {
    let dir = Scratch::new("dying");
    let run = spawn_run(&["--loop", "--restart", "never", "--out", &dir.s("out")]);
    let pid = run.id();
    // Wait until all four run, then kill matching.
    assert!(
        wait_all_running(pid, Duration::from_secs(60)),
        "services did not start"
    );
    std::thread::sleep(Duration::from_millis(1500));
    let victim = service_pid(pid, "matching").expect("matching runs");
    // SAFETY: kill(2) on a pid read from /proc just now.
    unsafe { libc::kill(victim as i32, libc::SIGKILL) };
    let o = run.wait_with_output().expect("wait for dualgeo");
    let stderr = text(&o.stderr);
    assert!(!o.status.success(), "{stderr}");
    assert!(
        stderr.contains("matching service ended unexpectedly (signal 9)"),
        "{stderr}"
    );
    assert_stopped(pid, "matching");
}

/// Under the default policy a dead service is restarted, but one that dies more often
/// than `--max-restarts` within the window ends the run, naming it.
#[test]
fn a_service_that_keeps_dying_ends_the_run_after_max_restarts() {
    let dir = Scratch::new("crash-loop");
    let run = spawn_run(&["--loop", "--max-restarts", "1", "--out", &dir.s("out")]);
    let pid = run.id();
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut killed = Vec::new();
    while killed.len() < 2 {
        assert!(Instant::now() < deadline, "detection was not (re)started");
        if wait_all_running(pid, Duration::from_secs(30)) {
            if let Some(d) = service_pid(pid, "detection").filter(|d| !killed.contains(d)) {
                std::thread::sleep(Duration::from_millis(500));
                // SAFETY: kill(2) on a pid read from /proc just now.
                unsafe { libc::kill(d as i32, libc::SIGKILL) };
                killed.push(d);
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let o = run.wait_with_output().expect("wait for dualgeo");
    let stderr = text(&o.stderr);
    assert!(!o.status.success(), "{stderr}");
    assert!(stderr.contains("restarting it"), "{stderr}");
    assert!(
        stderr.contains("detection service died 2 times within 60 s"),
        "{stderr}"
    );
    assert_stopped(pid, "detection");
}

/// Issue #13: bad live input is dropped and counted, never fatal. The live simulator
/// delivers every kind of live-input fault in turn (`--inject-faults`); the run goes
/// on and ends normally, each kind is counted, logged once when first seen and once in
/// the totals, and estimates keep coming.
#[test]
fn live_input_faults_are_dropped_counted_and_the_run_goes_on() {
    let dir = Scratch::new("live-faults");
    // 300 pairs, flow-controlled: the same pairs and the same faults on every run,
    // however busy the machine.
    let o = dualgeo(&[
        "run",
        "--inject-faults",
        "0.1",
        "--duration-s",
        "10",
        "--rate",
        "max",
        "--out",
        &dir.s("out"),
    ]);
    let (stdout, stderr) = (text(&o.stdout), text(&o.stderr));
    assert!(o.status.success(), "{stdout}\n{stderr}");
    let counters = json(&dir.join("out/counters.json"));
    let kinds = [
        "pose_not_finite",
        "time_backwards",
        "frame_without_pose",
        "pose_without_frame",
        "wrong_frame_size",
        "clock_skew",
        "telemetry_gap",
    ];
    for kind in kinds {
        let n = counters[format!("acquisition.live_faults.{kind}")]
            .as_u64()
            .unwrap_or(0);
        assert!(n > 0, "{kind} not counted: {counters}");
        let first_seen = format!("\"{kind}\"");
        assert_eq!(stderr.matches(&first_seen).count(), 1, "{kind}: {stderr}");
    }
    let totals = stderr
        .lines()
        .find(|l| l.contains("live input faults:"))
        .unwrap_or_else(|| panic!("no totals line: {stderr}"));
    for kind in kinds {
        assert!(totals.contains(kind), "{totals}");
    }
    let report = json(&dir.join("out/report.json"));
    assert!(report["estimates_out"].as_u64().unwrap() > 50, "{report}");
    assert_eq!(report["restarts"]["acquisition"], 0, "{report}");
}

/// Issue #23 item 6: the same recording with `--rate max` gives the same `track.csv`
/// byte for byte, three replays in a row (the default scene's navigation noise and
/// yaw biases, the default estimator). Every random choice in the chain is seeded from
/// what is computed, keyframe links are kept in ordered maps, and flow control keeps
/// one pair in flight, so neither scheduling nor hashing can change an estimate.
#[test]
fn a_replay_repeats_byte_for_byte() {
    let dir = Scratch::new("replay");
    let rec = dir.s("rec");
    let o = dualgeo(&[
        "simulate",
        "--preset",
        "default",
        "--duration-s",
        "8",
        "--jpeg-quality",
        "95",
        "--out",
        &rec,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let tracks: Vec<String> = (0..3)
        .map(|i| {
            let out = dir.s(&format!("out{i}"));
            let o = dualgeo(&["run", "--source", &rec, "--rate", "max", "--out", &out]);
            assert!(o.status.success(), "{}", text(&o.stderr));
            std::fs::read_to_string(dir.join(&format!("out{i}/track.csv"))).unwrap()
        })
        .collect();
    assert!(tracks[0].lines().count() > 50, "{}", tracks[0]);
    for (i, t) in tracks.iter().enumerate().skip(1) {
        let differs = tracks[0].lines().zip(t.lines()).position(|(a, b)| a != b);
        assert!(
            &tracks[0] == t,
            "replay {i} differs from the first (line {differs:?}, {} vs {} lines)",
            tracks[0].lines().count(),
            t.lines().count()
        );
    }
    // Two passes (`--laps 2`): the second is a stream segment of its own, so every
    // stage starts over at the jump and the second pass repeats the first exactly
    // (carried over, the filter coasted 64 m off at ±2 m for a second, then the
    // detector's gate held the target out for another).
    let out = dir.s("laps");
    let o = dualgeo(&[
        "run", "--source", &rec, "--rate", "max", "--laps", "2", "--out", &out,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let pairs = std::fs::read_dir(dir.join("rec/left")).unwrap().count() as u64;
    let looped = std::fs::read_to_string(dir.join("laps/track.csv")).unwrap();
    let rows: Vec<(f64, u64, String)> = looped
        .lines()
        .skip(1)
        .map(|l| {
            let mut f = l.splitn(3, ',');
            let t: f64 = f.next().unwrap().parse().unwrap();
            let seq: u64 = f.next().unwrap().parse().unwrap();
            (t, seq, f.next().unwrap().to_string())
        })
        .collect();
    let (first, second): (Vec<_>, Vec<_>) = rows.iter().partition(|r| r.1 < pairs);
    let once: Vec<&str> = tracks[0].lines().skip(1).collect();
    assert_eq!(
        first
            .iter()
            .map(|r| format!("{:.6},{},{}", r.0, r.1, r.2))
            .collect::<Vec<_>>(),
        once,
        "the first pass is the plain replay"
    );
    assert_eq!(first.len(), second.len(), "{looped}");
    let lap_s = second[0].0 - first[0].0;
    for (a, b) in first.iter().zip(&second) {
        assert_eq!(b.1, a.1 + pairs, "{a:?} / {b:?}");
        assert!((b.0 - a.0 - lap_s).abs() < 2e-6, "{a:?} / {b:?}");
        assert_eq!(a.2, b.2, "pair {} of the second pass", b.1);
    }
    let counters = std::fs::read_to_string(dir.join("laps/counters.json")).unwrap();
    for stage in ["detection", "matching", "geolocation"] {
        assert!(
            counters.contains(&format!("\"{stage}.segments\": 1")),
            "{stage}: {counters}"
        );
    }
}

/// `[detection] kind = "yolo"`: the detection service runs the installed YOLOv2-tiny
/// model on its own thread (synchronously under `--rate max`) and counts its runs. COCO
/// has no top-down red box: the model finds nothing on the simulator's vehicle
/// (docs/matching.md, "Detection"), so this checks the chain, not the model.
#[test]
fn the_configured_learned_detector_runs_in_the_detection_service() {
    let dir = Scratch::new("yolo-run");
    let rec = dir.s("rec");
    let o = dualgeo(&["simulate", "--duration-s", "2", "--out", &rec]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let models = concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/models/yolov2-tiny");
    let config = dir.join("yolo.toml");
    std::fs::write(
        &config,
        format!(
            "[detection]\nkind = \"yolo\"\n[detection.yolo]\nmodel = \"{models}/yolov2-tiny.weights\"\nconfig = \"{models}/yolov2-tiny.cfg\"\nnames = \"{models}/coco.names\"\nclasses = [\"car\", \"bus\", \"truck\"]\ninput_size = 416\n"
        ),
    )
    .unwrap();
    let o = run_max_with_config(&rec, &config, &dir.s("out"));
    assert!(o.status.success(), "{}", text(&o.stderr));
    let counters = json(&dir.join("out/counters.json"));
    // 60 frames per camera; nothing found, so each camera's frames all go to the
    // model, one at a time: at least one run per camera.
    let runs = counters["detection.model_runs"].as_u64().unwrap_or(0);
    assert!(runs >= 2, "{counters}");
    assert_eq!(counters["detection.frames"], 120, "{counters}");
}

/// `[detection] kind = "motion"` in the real detection service: a silver car (the
/// colour detector's red is absent) is found by its motion, designated per camera at
/// the frame the detector first looks, and geolocated.
#[test]
fn the_motion_detector_runs_in_the_detection_service() {
    let dir = Scratch::new("motion-run");
    let rec = dir.s("rec");
    let o = dualgeo(&[
        "simulate",
        "--preset",
        "silver_parked",
        "--duration-s",
        "4",
        "--out",
        &rec,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    // The operator's click: the target's pixel in frame 20 of each camera (the test
    // reads truth.csv; the detector never does).
    let truth = std::fs::read_to_string(dir.join("rec/truth.csv")).unwrap();
    let click = |uav: &str| {
        let row = truth
            .lines()
            .find(|l| l.starts_with(&format!("{uav},20,")))
            .unwrap();
        let f: Vec<&str> = row.split(',').collect();
        format!("[{}, {}]", f[12], f[13])
    };
    let config = dir.join("motion.toml");
    std::fs::write(
        &config,
        format!(
            "[detection]\nkind = \"motion\"\n[detection.motion]\nacquire_px = [{}, {}]\n",
            click("left"),
            click("right")
        ),
    )
    .unwrap();
    let o = run_max_with_config(&rec, &config, &dir.s("out"));
    assert!(o.status.success(), "{}", text(&o.stderr));
    let counters = json(&dir.join("out/counters.json"));
    assert_eq!(counters["detection.frames"], 240, "{counters}");
    assert!(
        counters["detection.acquired"].as_u64().unwrap_or(0) >= 2,
        "{counters}"
    );
    // From frame 20 on, 100 frames per camera: most of them found.
    let found = counters["detection.found"].as_u64().unwrap_or(0);
    assert!(found >= 160, "{counters}");
    // The keyframe rings need ~3.5 s of baseline: a few estimates at the end.
    let track = std::fs::read_to_string(dir.join("out/track.csv")).unwrap();
    assert!(track.lines().count() >= 3, "{track}");
}
