//! Issue #25, live: a flight with tracking gimbals played as if flying
//! (tests/support/live_sender.rs also sends each UAV's GIMBAL_DEVICE_ATTITUDE_STATUS,
//! MAVLink 285, at 50 Hz) into `dualgeo run --source live.toml`. The live source reads
//! the gimbal's attitude from the stream as the recorded one does from the `.tlog`:
//! every message arrives, frames get the camera's pose on its gimbal, and pairs become
//! estimates. Its own binary so that it does not share the CPU with the other live test.

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

fn json(path: &std::path::Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("read json")).expect("json")
}

#[test]
fn a_live_gimbal_flight_gives_each_frame_the_camera_on_its_gimbal() {
    if !have_ffmpeg() {
        eprintln!("SKIPPED: the ffmpeg CLI is not installed (scripts/setup.sh installs it)");
        return;
    }
    let dir = Scratch::new("live-gimbal");
    let recorded = dir.join("recorded");
    let dualgeo = std::path::Path::new(env!("CARGO_BIN_EXE_dualgeo"));
    record_flight(dualgeo, "gimbal", 12, &recorded);
    let ports = LivePorts::pick();
    let live = dir.join("live.toml");
    write_live_toml(&recorded, &live, ports);

    let out = dir.join("out");
    let run = start_run(dualgeo, &live, &out, ports);
    let sender = LiveSender::start(&recorded, ports);
    std::thread::sleep(Duration::from_secs(11));
    let sent: u64 = sender.stop().iter().sum();
    let (clean, log) = stop_run(run);
    assert!(clean, "{log}");

    let c = json(&out.join("counters.json"));
    let n = |k: &str| c[format!("acquisition.source.{k}")].as_u64().unwrap_or(0);
    eprintln!("sent {sent}; acquisition's counters: {c}");
    // ~11 s, two UAVs, three message types at 50 Hz.
    assert!(sent > 2 * 3 * 400, "only {sent} messages sent");
    assert_eq!(
        n("telemetry_messages"),
        sent,
        "every message sent was received\n{log}"
    );
    let frames = n("video_frames");
    assert!(frames > 2 * 250, "{frames} frames decoded\n{c}");
    // A frame before the first gimbal message has no camera pose; after it, all do.
    assert!(
        n("no_pose_gimbal") * 20 < frames,
        "{} of {frames} frames without the gimbal's attitude\n{c}",
        n("no_pose_gimbal")
    );
    let report = json(&out.join("report.json"));
    let estimates = report["estimates_out"].as_u64().unwrap();
    assert!(estimates > 40, "only {estimates} estimates\n{log}");
}
