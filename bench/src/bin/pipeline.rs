//! The pipeline's latency and throughput targets (issues #5 and #15), measured by
//! running the real `dualgeo run` (four processes) and reading its report.json and
//! its `--trace`:
//!
//! 1. the README's live simulator (`default` preset, 2 × 30 FPS);
//! 2. a recording of the same scenario replayed at its own rate (realtime);
//! 3. the same recording with `--rate max`;
//! 4. the same scenario recorded as JPEG (quality 95) replayed at its own rate: the
//!    decode cost PNG and JPEG recordings put on the end-to-end clock.
//!
//! Each figure is printed beside the committed one (`bench/baselines/pipeline.json`)
//! as a ratio: the latency regression guard. `--save-baseline` makes this run the
//! committed one; `--write-docs` regenerates the measured section of docs/pipeline.md
//! (between its `bench:pipeline` markers), with the latency budget of each paced run
//! from its trace.
//!
//! Needs the workspace's binaries (`cargo build --release --workspace`).
//! Run: `cargo run --release -p dualgeo-bench --bin pipeline [-- --duration-s 20]`

use anyhow::{bail, Context, Result};
use clap::Parser;
use dualgeo_bench::budget;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

#[derive(Parser)]
struct Args {
    /// Seconds of the scenario to stream in each run.
    #[arg(long, default_value_t = 20.0)]
    duration_s: f64,
    /// Scratch directory (removed afterwards unless given).
    #[arg(long)]
    scratch: Option<PathBuf>,
    /// Write this run's figures as the committed baseline.
    #[arg(long)]
    save_baseline: bool,
    /// Regenerate the measured section of docs/pipeline.md.
    #[arg(long)]
    write_docs: bool,
}

const ROOT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
const BASELINE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/baselines/pipeline.json");

fn run(args: &[&str]) -> Result<()> {
    let status = Command::new(dualgeo_bench::dualgeo_binary()?)
        .args(args)
        .status()?;
    if !status.success() {
        bail!("dualgeo {} failed: {status}", args.join(" "));
    }
    Ok(())
}

fn report(out: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(out.join("report.json"))?;
    Ok(serde_json::from_str(&text)?)
}

/// (name, target, value, lower is better) of one run.
type Figure = (String, String, f64, bool);

fn figures(label: &str, r: &Value, with_cpu: bool) -> Vec<Figure> {
    let ms = |row: &str, p: &str| r["latency_us"][row][p].as_f64().unwrap_or(f64::NAN) / 1e3;
    let mut f = vec![
        (
            format!("{label}: frames dropped"),
            "0".into(),
            r["frames_dropped"].as_f64().unwrap_or(f64::NAN),
            true,
        ),
        (
            format!("{label}: end-to-end p50 ms"),
            "–".into(),
            ms("end_to_end", "p50"),
            true,
        ),
        (
            format!("{label}: end-to-end p99 ms"),
            "≤ 25 (replay), ≤ 33 (live)".into(),
            ms("end_to_end", "p99"),
            true,
        ),
        (
            format!("{label}: end-to-end p99.9 ms"),
            "≤ 33 (replay)".into(),
            ms("end_to_end", "p999"),
            true,
        ),
        (
            format!("{label}: estimates/s"),
            "≥ 60 (max)".into(),
            r["throughput_hz"].as_f64().unwrap_or(f64::NAN),
            false,
        ),
    ];
    if with_cpu {
        // The stages' own work per geolocation: the pair's source time, both frames'
        // detection, matching and geolocation (a sum of medians).
        let cpu = ms("acquisition", "p50")
            + 2.0 * ms("detection", "p50")
            + ms("matching", "p50")
            + ms("geolocation", "p50");
        f.push((
            format!("{label}: CPU per geolocation ms (sum of stage medians)"),
            "≤ 10".into(),
            cpu,
            true,
        ));
    }
    f
}

fn main() -> Result<()> {
    let args = Args::parse();
    let scratch = args.scratch.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("dualgeo-bench-pipeline-{}", std::process::id()))
    });
    std::fs::create_dir_all(&scratch)?;
    let s = |p: &str| scratch.join(p).display().to_string();
    let d = args.duration_s.to_string();

    run(&[
        "run",
        "--duration-s",
        &d,
        "--out",
        &s("live"),
        "--trace",
        &s("live.trace.json"),
    ])?;
    // The default scenario recorded as PNG (the format's default) and as JPEG 95.
    let simulate = |out: &str, extra: &[&str]| {
        let mut a = vec!["simulate", "--preset", "default", "--duration-s", &d];
        a.extend_from_slice(extra);
        a.extend_from_slice(&["--out", out]);
        run(&a)
    };
    simulate(&s("rec"), &[])?;
    run(&[
        "run",
        "--source",
        &s("rec"),
        "--out",
        &s("replay"),
        "--trace",
        &s("replay.trace.json"),
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
    simulate(&s("rec_jpeg"), &["--jpeg-quality", "95"])?;
    run(&[
        "run",
        "--source",
        &s("rec_jpeg"),
        "--out",
        &s("replay_jpeg"),
    ])?;

    let mut now: Vec<Figure> = Vec::new();
    now.extend(figures(
        "live simulator",
        &report(&scratch.join("live"))?,
        false,
    ));
    now.extend(figures(
        "replay, realtime",
        &report(&scratch.join("replay"))?,
        false,
    ));
    now.extend(figures(
        "replay, --rate max",
        &report(&scratch.join("max"))?,
        true,
    ));
    now.extend(figures(
        "replay JPEG 95, realtime",
        &report(&scratch.join("replay_jpeg"))?,
        false,
    ));

    let before: BTreeMap<String, f64> = std::fs::read_to_string(BASELINE)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    let mut table = String::from(
        "| figure | target | now | committed | now / committed |\n| --- | --- | ---: | ---: | ---: |\n",
    );
    for (name, target, value, _) in &now {
        let (b, ratio) = match before.get(name) {
            Some(&b) if b != 0.0 => (format!("{b:.2}"), format!("{:.2}", value / b)),
            Some(&b) => (
                format!("{b:.2}"),
                if *value == 0.0 {
                    "=".into()
                } else {
                    "–".into()
                },
            ),
            None => ("–".into(), "–".into()),
        };
        table.push_str(&format!(
            "| {name} | {target} | {value:.2} | {b} | {ratio} |\n"
        ));
    }
    let budgets = [
        ("live simulator", scratch.join("live.trace.json")),
        ("replay, realtime", scratch.join("replay.trace.json")),
    ]
    .map(|(label, path)| -> Result<(String, String)> {
        Ok((label.to_string(), budget::table(&budget::read(&path)?)))
    });
    println!("\n{table}");
    let mut docs = format!(
        "Measured by `cargo run --release -p dualgeo-bench --bin pipeline -- --duration-s {d}` \
         (640×480, 8 images, the default estimator, this 2-core machine). \"committed\" is \
         bench/baselines/pipeline.json.\n\n{table}"
    );
    for b in budgets {
        let (label, t) = b?;
        println!("latency budget, {label} (from its trace):\n{t}");
        docs.push_str(&format!(
            "\n**Latency budget, {label}** (from its `--trace`):\n\n{t}"
        ));
    }
    if args.save_baseline {
        let values: BTreeMap<&str, f64> = now.iter().map(|(n, _, v, _)| (n.as_str(), *v)).collect();
        std::fs::write(
            BASELINE,
            serde_json::to_string_pretty(&json!(values))? + "\n",
        )
        .with_context(|| format!("write {BASELINE}"))?;
        println!("baseline written: {BASELINE}");
    }
    if args.write_docs {
        let path = Path::new(ROOT).join("docs/pipeline.md");
        let text = std::fs::read_to_string(&path)?;
        let (open, close) = ("<!-- bench:pipeline -->", "<!-- /bench:pipeline -->");
        let (Some(a), Some(b)) = (text.find(open), text.find(close)) else {
            bail!("{}: no {open} … {close} section", path.display());
        };
        let new = format!("{}{open}\n{docs}{}", &text[..a], &text[b..]);
        std::fs::write(&path, new)?;
        println!("docs regenerated: {}", path.display());
    }
    if args.scratch.is_none() {
        let _ = std::fs::remove_dir_all(&scratch);
    }
    Ok(())
}
