//! Issue #25, live: a flight with tracking gimbals played as if flying
//! (tests/support/live_sender.rs also sends each UAV's GIMBAL_DEVICE_ATTITUDE_STATUS,
//! MAVLink 285, at 50 Hz) into `dualgeo run --source live.toml`. The live source reads
//! the gimbal's attitude from the stream as the recorded one does from the `.tlog`:
//! every message arrives, frames get the camera's pose on its gimbal, and pairs become
//! estimates. Its own binary so that it does not share the CPU with the other live test.

#[path = "support/cli.rs"]
mod cli;
#[path = "support/live_sender.rs"]
mod live_sender;
#[path = "support/scratch.rs"]
mod scratch;

use cli::rows;
use live_sender::{
    have_ffmpeg, record_flight, start_run, stop_run, write_live_toml, LivePorts, LiveSender,
};
use scratch::Scratch;
use serde_json::Value;
use std::time::Duration;

fn json(path: &std::path::Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("read json")).expect("json")
}

/// The flight's frame rate: half the preset's. Two `ffmpeg` re-encoders stand in for
/// the UAVs' own encoders on the same two cores as the pipeline; at 30 FPS the
/// machine was saturated and the estimates made in 11 s varied 11–103 from run to run
/// with the machine's speed (measured on this commit's parent and on 43e5ac5 alike).
/// This test is about the gimbal's attitude on the live link; throughput is the
/// `live_flight` benchmark's.
const FRAME_RATE_HZ: f64 = 15.0;
/// Seconds of the flight recorded and played (the first 5 s are the matching rings'
/// warm-up; the filter starts after it, once several sets agree).
const FLIGHT_S: u32 = 23;
const SEND_S: f64 = 22.0;

#[test]
fn a_live_gimbal_flight_gives_each_frame_the_camera_on_its_gimbal() {
    if !have_ffmpeg() {
        eprintln!("SKIPPED: the ffmpeg CLI is not installed (scripts/setup.sh installs it)");
        return;
    }
    let dir = Scratch::new("live-gimbal");
    let recorded = dir.join("recorded");
    let dualgeo = std::path::Path::new(env!("CARGO_BIN_EXE_dualgeo"));
    record_flight(dualgeo, "gimbal", Some(FRAME_RATE_HZ), FLIGHT_S, &recorded);
    let ports = LivePorts::pick();
    let live = dir.join("live.toml");
    write_live_toml(&recorded, &live, ports);

    let out = dir.join("out");
    let run = start_run(dualgeo, &live, &out, ports);
    let sender = LiveSender::start(&recorded, ports);
    std::thread::sleep(Duration::from_secs_f64(SEND_S));
    let sent: u64 = sender.stop().iter().sum();
    let (clean, log) = stop_run(run);
    assert!(clean, "{log}");

    let c = json(&out.join("counters.json"));
    let n = |k: &str| c[format!("acquisition.source.{k}")].as_u64().unwrap_or(0);
    eprintln!("sent {sent}; acquisition's counters: {c}");
    // ~22 s, two UAVs, three message types at 50 Hz.
    assert!(sent > 2 * 3 * 900, "only {sent} messages sent");
    assert_eq!(
        n("telemetry_messages"),
        sent,
        "every message sent was received\n{log}"
    );
    let frames = n("video_frames");
    // Three quarters of what was sent.
    let expected = 2.0 * SEND_S * FRAME_RATE_HZ;
    assert!(
        frames as f64 > 0.75 * expected,
        "{frames} of ~{expected} frames decoded\n{c}"
    );
    // A frame before the first gimbal message has no camera pose; after it, all do.
    assert!(
        n("no_pose_gimbal") * 20 < frames,
        "{} of {frames} frames without the gimbal's attitude\n{c}",
        n("no_pose_gimbal")
    );
    // Pairs become estimates. How many in a run depends on the machine's speed and on
    // when the filter starts: realtime matching keeps only the newest pair (beside the
    // two re-encoders it dropped 0-92 frames in 15 s) and the filter waits for agreeing
    // sets (8-54 sets refused before its start). Measured in 15 s: 38 (CI) to 122
    // estimates; the flight is played for 22 s so that the slowest start leaves many.
    let g = |k: &str| c[format!("geolocation.{k}")].as_u64().unwrap_or(0);
    let report = json(&out.join("report.json"));
    let estimates = report["estimates_out"].as_u64().unwrap();
    eprintln!(
        "{estimates} estimates of {} sets, {} refused before the filter's start",
        g("sets"),
        g("rejected.not_started")
    );
    assert!(estimates >= 20, "only {estimates} estimates\n{log}");
    // ...and the camera's pose on its gimbal is the one used: each estimate's distance
    // to the target's true path, at any time (the live run's clock starts at its first
    // pair, ~3.3 s into the recording here). Measured: median 1.4-3.0 m over four runs
    // (the live chain's H.264 and host-clock poses; the recorded gimbal flight's
    // horizontal MAE is ~1 m). A misread gimbal message (a yaw taken in the wrong frame,
    // a camera taken as nadir) turns the camera by tens of degrees: tens of metres.
    let path: Vec<[f64; 2]> = rows(&recorded.join("truth.csv"))
        .iter()
        .map(|r| ["target_x_m", "target_y_m"].map(|k| r[k].parse::<f64>().expect("truth")))
        .collect();
    let mut off: Vec<f64> = rows(&out.join("track.csv"))
        .iter()
        .filter(|r| r.get("track_id").is_none_or(|id| id == "0"))
        .map(|r| {
            let p = ["x_m", "y_m"].map(|k| r[k].parse::<f64>().expect("track"));
            path.iter()
                .map(|q| (p[0] - q[0]).hypot(p[1] - q[1]))
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    off.sort_by(f64::total_cmp);
    let median = off.get(off.len() / 2).copied().unwrap_or(f64::INFINITY);
    eprintln!(
        "{} estimates, median distance to the true path {median:.2} m",
        off.len()
    );
    assert!(median < 8.0, "median distance to the true path {median} m");
}
