//! Issue #14: a flight (per UAV an MP4 video and a MAVLink .tlog, flight.toml) written
//! by the simulator and replayed through the whole pipeline; and the bad flight input
//! a ground station meets (damaged or cut logs, telemetry gaps, an offset with no
//! overlap), each a counted drop or a clear error before start, never a panic.

#[path = "support/scratch.rs"]
mod scratch;

use scratch::Scratch;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn dualgeo() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dualgeo"))
}

fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn simulate_flight(dir: &Path, seconds: u32) -> PathBuf {
    let o = dualgeo()
        .args(["simulate", "--preset", "default", "--duration-s"])
        .arg(seconds.to_string())
        .arg("--flight-out")
        .arg(dir)
        .output()
        .expect("run dualgeo simulate");
    assert!(o.status.success(), "{}", text(&o));
    for f in [
        "flight.toml",
        "left.mp4",
        "right.mp4",
        "left.tlog",
        "right.tlog",
        "truth.csv",
        "telemetry.csv",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    dir.join("flight.toml")
}

fn run(flight: &Path, out: &Path) -> Output {
    dualgeo()
        .args(["run", "--rate", "max", "--source"])
        .arg(flight)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run dualgeo run")
}

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("read json")).expect("json")
}

/// Byte offsets of the records of a tlog (8-byte time, then a MAVLink 2 frame).
fn records(bytes: &[u8]) -> Vec<usize> {
    let mut at = 0;
    let mut out = Vec::new();
    while at + 9 < bytes.len() {
        out.push(at);
        let len = bytes[at + 9] as usize;
        at += 8 + 10 + len + 2;
    }
    out
}

#[test]
fn a_simulated_flight_replays_through_the_pipeline() {
    let dir = Scratch::new("flight");
    let flight = simulate_flight(&dir.0.join("flight"), 8);
    let out = dir.0.join("out");
    let o = run(&flight, &out);
    assert!(o.status.success(), "{}", text(&o));
    let report = json(&out.join("report.json"));
    let estimates = report["estimates_out"].as_u64().unwrap_or(0);
    assert!(
        estimates > 100,
        "{estimates} estimates from 240 pairs\n{report}"
    );
    let mae = &report["accuracy"]["mae_m"];
    for axis in ["x", "y"] {
        let m = mae[axis].as_f64().unwrap_or(f64::NAN);
        assert!(m < 3.0, "MAE {axis} {m} m: {report}");
    }
    let counters = json(&out.join("counters.json"));
    for name in ["no_pose_position", "no_pose_attitude", "tlog_crc_errors"] {
        assert!(
            counters.get(format!("acquisition.source.{name}")).is_none(),
            "{name}: {counters}"
        );
    }

    // A left video shorter than its telemetry (and than the right video): the stream
    // ends with it, cleanly.
    let short = dir.0.join("short");
    simulate_flight(&short, 3);
    std::fs::copy(short.join("left.mp4"), dir.0.join("flight/left.mp4")).unwrap();
    let out = dir.0.join("out-short");
    let o = run(&flight, &out);
    assert!(o.status.success(), "{}", text(&o));
    let report = json(&out.join("report.json"));
    assert_eq!(report["pairs_in"], 90, "{report}");
}

#[test]
fn damaged_telemetry_is_dropped_and_counted_and_no_overlap_is_refused() {
    let dir = Scratch::new("flight-bad");
    let flight = simulate_flight(&dir.0.join("flight"), 5);
    let log = dir.0.join("flight/left.tlog");
    let mut bytes = std::fs::read(&log).unwrap();
    let at = records(&bytes);
    // A one-second gap (records of 1.5–2.5 s: 30 frames × 2 messages), one record with
    // a bad CRC, and the end cut in the middle of a record.
    let (gap_from, gap_to) = (at[90], at[150]);
    let corrupt = at[20] + 8 + 12;
    bytes[corrupt] ^= 0x5a;
    bytes.drain(gap_from..gap_to);
    bytes.truncate(bytes.len() - 7);
    std::fs::write(&log, &bytes).unwrap();

    let out = dir.0.join("out");
    let o = run(&flight, &out);
    assert!(o.status.success(), "{}", text(&o));
    let counters = json(&out.join("counters.json"));
    let count = |name: &str| {
        counters[format!("acquisition.source.{name}")]
            .as_u64()
            .unwrap_or(0)
    };
    assert_eq!(count("tlog_crc_errors"), 1, "{counters}");
    assert_eq!(count("tlog_truncated"), 1, "{counters}");
    let no_pose = count("no_pose_position") + count("no_pose_attitude");
    // The gap's frames, less the frame period at each end where a sample is near.
    assert!(
        (26..=32).contains(&no_pose),
        "{no_pose} pairs without a pose: {counters}"
    );
    // No estimate from the gap: every estimate's time has telemetry within a period.
    let track = std::fs::read_to_string(out.join("track.csv")).unwrap();
    for line in track.lines().skip(1) {
        let t: f64 = line.split(',').next().unwrap().parse().unwrap();
        assert!(
            !(1.52..2.48).contains(&t),
            "an estimate at {t} s, inside the gap"
        );
    }

    // An offset that puts the telemetry after the video: refused before start.
    let toml = std::fs::read_to_string(&flight).unwrap();
    let shifted = toml.replacen("time_offset_s = 100.0", "time_offset_s = 900.0", 1);
    assert_ne!(toml, shifted, "flight.toml has no time_offset_s = 100.0");
    std::fs::write(&flight, shifted).unwrap();
    let o = run(&flight, &dir.0.join("out2"));
    assert!(!o.status.success());
    assert!(text(&o).contains("no overlap"), "{}", text(&o));

    // A video the flight names is missing: the reader acquisition uses refuses it
    // before any process starts (no service ran, none was restarted).
    std::fs::write(&flight, toml).unwrap();
    std::fs::remove_file(dir.0.join("flight/right.mp4")).unwrap();
    let out3 = dir.0.join("out3");
    let o = run(&flight, &out3);
    assert!(!o.status.success());
    assert!(text(&o).contains("right.mp4"), "{}", text(&o));
    assert!(!out3.join("stats").exists(), "no service started");
}
