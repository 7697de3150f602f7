//! Issue #5's pipeline targets, measured by running the real `dualgeo run` (four
//! processes) and reading its report.json:
//!
//! 1. live simulator, `default` preset at 30 FPS (2 × 30 frames/s): frames dropped
//!    (target 0) and end-to-end p99 (target ≤ 33 ms, one frame period);
//! 2. a recording of the same scenario streamed with `--rate max`: geolocations per
//!    second (target ≥ 44, twice the paper's 22 FPS).
//!
//! Needs the workspace's binaries (`cargo build --release --workspace`).
//! Run: `cargo run --release -p dualgeo-bench --bin pipeline [-- --duration-s 20]`

use anyhow::{bail, Result};
use clap::Parser;
use std::path::{Path, PathBuf};
use std::process::Command;

#[derive(Parser)]
struct Args {
    /// Seconds of the scenario to stream in each run.
    #[arg(long, default_value_t = 20.0)]
    duration_s: f64,
    /// Scratch directory (removed afterwards).
    #[arg(long)]
    scratch: Option<PathBuf>,
}

fn dualgeo() -> Result<PathBuf> {
    dualgeo_bench::dualgeo_binary()
}

fn run(args: &[&str]) -> Result<()> {
    let status = Command::new(dualgeo()?).args(args).status()?;
    if !status.success() {
        bail!("dualgeo {} failed: {status}", args.join(" "));
    }
    Ok(())
}

fn report(out: &Path) -> Result<serde_json::Value> {
    let text = std::fs::read_to_string(out.join("report.json"))?;
    Ok(serde_json::from_str(&text)?)
}

fn main() -> Result<()> {
    let args = Args::parse();
    let scratch = args.scratch.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("dualgeo-bench-pipeline-{}", std::process::id()))
    });
    std::fs::create_dir_all(&scratch)?;
    let s = |p: &str| scratch.join(p).display().to_string();
    let d = args.duration_s.to_string();

    run(&["run", "--duration-s", &d, "--out", &s("live")])?;
    let live = report(&scratch.join("live"))?;
    run(&[
        "simulate",
        "--preset",
        "default",
        "--duration-s",
        &d,
        "--out",
        &s("rec"),
    ])?;
    run(&[
        "run",
        "--source",
        &s("rec"),
        "--rate",
        "max",
        "--out",
        &s("max"),
    ])?;
    let max = report(&scratch.join("max"))?;

    let ms = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN) / 1000.0;
    let e2e = &live["latency_us"]["end_to_end"];
    println!("\npipeline targets (640×480, 8 images, this machine)");
    println!("| measure | target | measured |");
    println!("| --- | --- | --- |");
    println!(
        "| live 2×30 FPS: frames dropped | 0 | {} of {} |",
        live["frames_dropped"], live["frames_in"]
    );
    println!(
        "| live: end-to-end p50 / p99 | p99 ≤ 33 ms | {:.1} / {:.1} ms |",
        ms(&e2e["p50"]),
        ms(&e2e["p99"])
    );
    println!(
        "| live: geolocations/s | – | {:.1} |",
        live["throughput_hz"].as_f64().unwrap_or(0.0)
    );
    println!(
        "| live: transport p50 / p99 | p99 ≤ 50 µs | {} / {} µs |",
        live["latency_us"]["transport"]["p50"], live["latency_us"]["transport"]["p99"]
    );
    println!(
        "| `--rate max` (recording): geolocations/s | ≥ 44 | {:.1} |",
        max["throughput_hz"].as_f64().unwrap_or(0.0)
    );
    println!(
        "| `--rate max`: matching p50 / p99 | – | {:.1} / {:.1} ms |",
        ms(&max["latency_us"]["matching"]["p50"]),
        ms(&max["latency_us"]["matching"]["p99"])
    );
    if args.scratch.is_none() {
        let _ = std::fs::remove_dir_all(&scratch);
    }
    Ok(())
}
