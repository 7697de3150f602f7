//! Issue #14's live target: a simulated flight played as if flying
//! (tests/support/live_sender.rs: both videos streamed over loopback UDP by the ffmpeg
//! CLI at 30 FPS, MAVLink telemetry at 50 Hz per message type and UAV) into the real
//! `dualgeo run --source live.toml`; prints the telemetry sent against received and
//! lost, the video counters, and dualgeo's own latency table.
//!
//! Run: `cargo run --release -p dualgeo-bench --bin live_flight [-- --seconds 30]`
//! (needs the `ffmpeg` CLI: scripts/setup.sh installs it).

#[path = "../../../tests/support/live_sender.rs"]
mod live_sender;

use anyhow::{bail, Context, Result};
use clap::Parser;
use live_sender::{have_ffmpeg, write_live_toml, LivePorts, LiveSender};
use std::process::Command;
use std::time::{Duration, Instant};

#[derive(Parser)]
struct Args {
    /// Seconds of live streaming.
    #[arg(long, default_value_t = 30)]
    seconds: u64,
    /// Keep the flight and the run's outputs here (default: a temporary folder,
    /// removed at the end).
    #[arg(long)]
    keep: Option<std::path::PathBuf>,
}

fn main() -> Result<()> {
    let args = Args::parse();
    if !have_ffmpeg() {
        bail!("the ffmpeg CLI is needed (scripts/setup.sh installs it)");
    }
    let dualgeo = dualgeo_bench::dualgeo_binary()?;
    let dir = args.keep.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("dualgeo-live-flight-{}", std::process::id()))
    });
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    let recorded = dir.join("recorded");
    let s = Command::new(&dualgeo)
        .args(["simulate", "--preset", "default", "--duration-s"])
        .arg((args.seconds + 10).to_string())
        .arg("--flight-out")
        .arg(&recorded)
        .status()?;
    if !s.success() {
        bail!("dualgeo simulate failed");
    }
    let ports = LivePorts::pick();
    let live = dir.join("live.toml");
    write_live_toml(&recorded, &live, ports);
    let out = dir.join("out");
    let mut run = Command::new(&dualgeo)
        .args(["run", "--source"])
        .arg(&live)
        .arg("--out")
        .arg(&out)
        .spawn()
        .context("dualgeo run")?;
    let deadline = Instant::now() + Duration::from_secs(60);
    while !ports.telemetry_bound() {
        if Instant::now() > deadline {
            let _ = run.kill();
            bail!("dualgeo never bound the telemetry ports");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let sender = LiveSender::start(&recorded, ports);
    std::thread::sleep(Duration::from_secs(args.seconds));
    let sent = sender.stop();
    // Let the last datagrams and frames through, then stop dualgeo as an operator would.
    std::thread::sleep(Duration::from_millis(500));
    // SAFETY: signalling our own child.
    unsafe { libc::kill(run.id() as libc::pid_t, libc::SIGINT) };
    let status = run.wait()?;
    if !status.success() {
        bail!("dualgeo run ended with {status}");
    }
    let counters: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("counters.json"))?)?;
    let n = |k: &str| {
        counters[format!("acquisition.source.{k}")]
            .as_u64()
            .unwrap_or(0)
    };
    let total: u64 = sent.iter().sum();
    println!();
    println!(
        "telemetry: sent {total} ({} + {}), received {}, lost on the link {}, CRC errors {}",
        sent[0],
        sent[1],
        n("telemetry_messages"),
        n("telemetry_lost"),
        n("telemetry_crc_errors")
    );
    println!(
        "video: decoded {}, overruns {}, late {}, stalls {}, unpaired {}, no pose {}",
        n("video_frames"),
        n("video_overruns"),
        n("late_frames"),
        n("video_stalls"),
        n("unpaired_frames"),
        n("no_pose_position") + n("no_pose_attitude")
    );
    if args.keep.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    Ok(())
}
