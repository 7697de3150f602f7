//! Issue #14, live: a flight played as if flying (tests/support/live_sender.rs: both
//! videos streamed over UDP by the ffmpeg CLI, MAVLink telemetry at 50 Hz per message
//! type over UDP) into `dualgeo run --source live.toml`. Every telemetry message sent
//! is received (0 lost), pairs become estimates, and the live faults a ground station
//! meets are counted, never fatal: a video stream that stalls and then sends its
//! backlog (late frames dropped: their pose would be the wrong one) and a telemetry
//! link that goes silent (frames without a pose dropped, no estimate from them).

#[path = "support/live_sender.rs"]
mod live_sender;
#[path = "support/scratch.rs"]
mod scratch;

use live_sender::{
    have_ffmpeg, record_flight, start_run, stop_run, write_live_toml, LivePorts, LiveSender,
};
use scratch::Scratch;
use serde_json::Value;
use std::time::Duration;

/// The flight's frame rate: half the preset's, as `e2e_live_gimbal` plays it. Two
/// `ffmpeg` re-encoders stand in for the UAVs' own encoders on the same two cores as
/// the pipeline; at 30 FPS, on a machine running 2.3× slower than usual, matching lost
/// 200 frames at its queue and the run made 58 estimates against the 60 asked (140
/// the day before). At 15 FPS, on the same machine, the run made 55, 58 and 59
/// estimates (about 118 pairs detected, a third of them the matching rings' warm-up),
/// losing 4 frames; the test asks for half of that. This test is about the live
/// link's faults; throughput is the `live_flight` benchmark's.
const FRAME_RATE_HZ: f64 = 15.0;

fn json(path: &std::path::Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("read json")).expect("json")
}

#[test]
fn a_live_flight_over_udp_loses_no_telemetry_and_survives_stalls() {
    if !have_ffmpeg() {
        eprintln!("SKIPPED: the ffmpeg CLI is not installed (scripts/setup.sh installs it)");
        return;
    }
    let dir = Scratch::new("live-flight");
    let recorded = dir.join("recorded");
    let dualgeo = std::path::Path::new(env!("CARGO_BIN_EXE_dualgeo"));
    record_flight(dualgeo, "default", Some(FRAME_RATE_HZ), 16, &recorded);
    let ports = LivePorts::pick();
    let live = dir.join("live.toml");
    write_live_toml(&recorded, &live, ports);

    let out = dir.join("out");
    let run = start_run(dualgeo, &live, &out, ports);
    let sender = LiveSender::start(&recorded, ports);
    std::thread::sleep(Duration::from_secs(5));
    sender.stall_video(0, Duration::from_millis(1200));
    std::thread::sleep(Duration::from_secs(2));
    sender.silence_telemetry(Duration::from_secs(1));
    std::thread::sleep(Duration::from_secs(5));
    let sent: u64 = sender.stop().iter().sum();
    // The last datagrams land; then the operator stops the run.
    let (clean, log) = stop_run(run);
    assert!(clean, "{log}");

    let c = json(&out.join("counters.json"));
    let n = |k: &str| c[format!("acquisition.source.{k}")].as_u64().unwrap_or(0);
    eprintln!("sent {sent}; acquisition's counters: {c}");
    // 13 s of streaming, two UAVs, two message types at 50 Hz, less the 1 s outage.
    assert!(sent > 2000, "only {sent} messages sent");
    assert_eq!(
        n("telemetry_messages"),
        sent,
        "every message sent was received\n{log}"
    );
    assert_eq!(n("telemetry_lost"), 0);
    assert_eq!(n("telemetry_crc_errors") + n("telemetry_garbage"), 0);
    // Three quarters of ~13 s of both videos.
    let expected = 2.0 * 13.0 * FRAME_RATE_HZ;
    assert!(
        n("video_frames") as f64 > 0.75 * expected,
        "{} of ~{expected} frames decoded",
        n("video_frames")
    );
    // The stall's backlog came late; the silent link left frames without a pose.
    assert!(
        n("late_frames") + n("video_overruns") > 0,
        "the stall went unseen\n{c}"
    );
    assert!(
        n("no_pose_position") + n("no_pose_attitude") > 0,
        "the outage went unseen\n{c}"
    );

    let report = json(&out.join("report.json"));
    let estimates = report["estimates_out"].as_u64().unwrap();
    eprintln!("{estimates} estimates");
    assert!(estimates > 30, "only {estimates} estimates in 13 s\n{log}");
    assert!(
        report["latency_us"]["end_to_end"]["p50"].as_f64().is_some(),
        "{report}"
    );
}
