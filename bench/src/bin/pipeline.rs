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
//! 5. a soak: the JPEG recording looped at its own rate for `--soak-s` (10 minutes by
//!    default), run once after the others, with per-minute p99 and memory from its
//!    soak.csv (`dualgeo run --loop --sample-every-s 60`).
//!
//! `--realtime FILE` runs every row a second time with `--config FILE` (a `[realtime]`
//! section: CPU affinity, SCHED_FIFO, locked memory), interleaved with the plain one and
//! labelled with the file's name: e.g. `no-priorities.toml` with `mode = "off"`
//! measures the default priorities against none in one run.
//!
//! Each run is repeated `--repeats` times (3 by default; one run of a 2-core machine
//! shared with other work is not a measurement) and each figure is the median over the
//! repeats, printed with their range and beside the committed one
//! (`bench/baselines/pipeline.json`) as a ratio: the latency regression guard.
//! `--save-baseline` makes this run the committed one; `--write-docs` regenerates the
//! measured section of docs/pipeline.md (between its `bench:pipeline` markers), with
//! the latency budget of each paced run from its first run's trace.
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
    /// Runs of each row; each figure is the median over them.
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Also run every row with `--config FILE` (its `[realtime]` priorities), labelled
    /// with the file's name.
    #[arg(long, value_name = "FILE")]
    realtime: Option<PathBuf>,
    /// Seconds of the soak row (the JPEG recording looped at its own rate, sampled
    /// every minute, run once after the other rows); 0 leaves it out.
    #[arg(long, default_value_t = 600.0)]
    soak_s: f64,
}

/// The soak row's warm-up and sampling interval (`dualgeo run --soak-warm-up-s`,
/// `--sample-every-s`): per-minute figures after the first minute.
const SOAK_INTERVAL_S: f64 = 60.0;

/// The soak row's figures from its report.json and soak.csv: frames dropped, the
/// whole run's end-to-end p99, the largest departure of a minute's p99 from the first
/// minute's after the warm-up, and the largest departure of a process's memory from
/// its first sample after the warm-up (in %).
fn soak_figures(label: &str, out: &Path) -> Result<Vec<Figure>> {
    let r = report(out)?;
    let text = std::fs::read_to_string(out.join("soak.csv"))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .context("soak.csv is empty")?
        .split(',')
        .collect();
    let col = |name: &str| header.iter().position(|h| *h == name);
    let p99_col = col("p99_us_geolocation_end_to_end").context("soak.csv: no p99 column")?;
    // Each process's private memory: its RSS less its shared memory where soak.csv
    // has that column (iceoryx2's fixed pools count as their slots are first written;
    // `dualgeo run`'s verdict judges the same).
    let rss_cols: Vec<(usize, Option<usize>)> = (0..header.len())
        .filter_map(|i| {
            let process = header[i].strip_prefix("rss_kib_")?;
            Some((i, col(&format!("shm_kib_{process}"))))
        })
        .collect();
    let rows: Vec<Vec<f64>> = lines
        .map(|l| {
            l.split(',')
                .map(|v| v.parse().unwrap_or(f64::NAN))
                .collect()
        })
        .filter(|row: &Vec<f64>| row[0] > SOAK_INTERVAL_S + 1e-6)
        .collect();
    let drift = |values: Vec<f64>| -> f64 {
        let values: Vec<f64> = values.into_iter().filter(|v| *v > 0.0).collect();
        let Some(first) = values.first().copied() else {
            return f64::NAN;
        };
        values
            .iter()
            .map(|v| 100.0 * (v - first) / first)
            .fold(0.0, |w: f64, d| if d.abs() > w.abs() { d } else { w })
    };
    let p99_drift = drift(rows.iter().map(|r| r[p99_col]).collect());
    let rss_drift = rss_cols
        .iter()
        .map(|&(c, shm)| {
            drift(
                rows.iter()
                    .map(|r| r[c] - shm.map_or(0.0, |s| r[s]))
                    .collect(),
            )
        })
        .fold(0.0, |w: f64, d| if d.abs() > w.abs() { d } else { w });
    Ok(vec![
        (
            format!("{label}: frames dropped"),
            "0".into(),
            r["frames_dropped"].as_f64().unwrap_or(f64::NAN),
            true,
        ),
        (
            format!("{label}: end-to-end p99 ms"),
            "–".into(),
            r["latency_us"]["end_to_end"]["p99"]
                .as_f64()
                .unwrap_or(f64::NAN)
                / 1e3,
            true,
        ),
        (
            format!("{label}: per-minute p99, largest drift from the first %"),
            "within ±20".into(),
            p99_drift,
            true,
        ),
        (
            format!("{label}: memory, largest drift of a process %"),
            "within ±1".into(),
            rss_drift,
            true,
        ),
    ])
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
            "≤ 33 (live, JPEG), ≤ 40 (PNG)".into(),
            ms("end_to_end", "p99"),
            true,
        ),
        (
            format!("{label}: end-to-end p99.9 ms"),
            "≤ 50 (live, JPEG)".into(),
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

    if args.repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    // The default scenario recorded as PNG (the format's default) and as JPEG 95.
    let simulate = |out: &str, extra: &[&str]| {
        let mut a = vec!["simulate", "--preset", "default", "--duration-s", &d];
        a.extend_from_slice(extra);
        a.extend_from_slice(&["--out", out]);
        run(&a)
    };
    simulate(&s("rec"), &[])?;
    simulate(&s("rec_jpeg"), &["--jpeg-quality", "95"])?;
    // (label, `dualgeo run` arguments before --out, CPU figure, traced)
    let (rec, rec_jpeg) = (s("rec"), s("rec_jpeg"));
    let base: [(&str, Vec<&str>, bool, bool); 4] = [
        ("live simulator", vec!["--duration-s", &d], false, true),
        ("replay, realtime", vec!["--source", &rec], false, true),
        (
            "replay, --rate max",
            vec!["--source", &rec, "--rate", "max"],
            true,
            false,
        ),
        (
            "replay JPEG 95, realtime",
            vec!["--source", &rec_jpeg],
            false,
            false,
        ),
    ];
    let realtime = match &args.realtime {
        Some(path) => {
            let full = path
                .canonicalize()
                .with_context(|| format!("--realtime {}", path.display()))?;
            let name = full
                .file_stem()
                .map_or("realtime".into(), |s| s.to_string_lossy().into_owned());
            Some((full.display().to_string(), name))
        }
        None => None,
    };
    let mut rows: Vec<(String, Vec<&str>, bool, bool)> = Vec::new();
    for (label, extra, with_cpu, traced) in &base {
        rows.push((label.to_string(), extra.clone(), *with_cpu, *traced));
        if let Some((config, name)) = &realtime {
            let mut with = extra.clone();
            with.extend(["--config", config.as_str()]);
            rows.push((format!("{label} [{name}]"), with, *with_cpu, false));
        }
    }
    // Each row's figures, one list per repeat; the rows interleaved so that a slow
    // spell of the machine falls on every row alike.
    let mut per_row: Vec<Vec<Vec<Figure>>> = vec![Vec::new(); rows.len()];
    let total = rows.len() * args.repeats;
    for k in 0..args.repeats {
        for (i, (label, extra, with_cpu, traced)) in rows.iter().enumerate() {
            eprintln!(
                "[{}/{total}] {label}, run {} of {}",
                k * rows.len() + i + 1,
                k + 1,
                args.repeats
            );
            let out = s(&format!("row{i}-{k}"));
            let mut a = vec!["run"];
            a.extend(extra.iter().copied());
            a.extend(["--out", &out]);
            let trace = s(&format!("row{i}-{k}.trace.json"));
            if *traced {
                a.extend(["--trace", &trace]);
            }
            run(&a)?;
            per_row[i].push(figures(label, &report(Path::new(&out))?, *with_cpu));
        }
    }
    // The soak row: once (it is long), after the others.
    let mut soak: Vec<Figure> = Vec::new();
    if args.soak_s > 0.0 {
        let label = format!("soak {:.0} min, JPEG replay looped", args.soak_s / 60.0);
        eprintln!("[soak] {label}");
        let out = s("soak");
        let (run_for, every) = (args.soak_s.to_string(), SOAK_INTERVAL_S.to_string());
        run(&[
            "run",
            "--source",
            &rec_jpeg,
            "--loop",
            "--run-for-s",
            &run_for,
            "--sample-every-s",
            &every,
            "--soak-warm-up-s",
            &every,
            "--out",
            &out,
        ])?;
        soak = soak_figures(&label, Path::new(&out))?;
    }
    // (name, target, median, lower is better) and the repeats' range.
    let mut now: Vec<Figure> = Vec::new();
    let mut ranges: BTreeMap<String, (f64, f64)> = BTreeMap::new();
    for runs in &per_row {
        for (j, (name, target, _, lower)) in runs[0].iter().enumerate() {
            let mut sorted: Vec<f64> = runs.iter().map(|r| r[j].2).collect();
            sorted.sort_by(f64::total_cmp);
            ranges.insert(name.clone(), (sorted[0], sorted[sorted.len() - 1]));
            let median = budget::percentile(&sorted, 0.5);
            now.push((name.clone(), target.clone(), median, *lower));
        }
    }
    for (name, target, value, lower) in soak {
        ranges.insert(name.clone(), (value, value));
        now.push((name, target, value, lower));
    }

    let before: BTreeMap<String, f64> = std::fs::read_to_string(BASELINE)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    let mut table = format!(
        "| figure | target | now (median of {n}) | range | committed | now / committed |\n| --- | --- | ---: | ---: | ---: | ---: |\n",
        n = args.repeats
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
        let (lo, hi) = ranges.get(name).copied().unwrap_or((f64::NAN, f64::NAN));
        table.push_str(&format!(
            "| {name} | {target} | {value:.2} | {lo:.2}–{hi:.2} | {b} | {ratio} |\n"
        ));
    }
    // The budgets from the first repeat's traces.
    let traced = |label: &str| {
        let i = rows.iter().position(|r| r.0 == label).unwrap_or(0);
        scratch.join(format!("row{i}-0.trace.json"))
    };
    let budgets = [
        ("live simulator", traced("live simulator")),
        ("replay, realtime", traced("replay, realtime")),
    ]
    .map(|(label, path)| -> Result<(String, String)> {
        let lane = budget::refresh_lane(&budget::refreshes(&path)?);
        let t = budget::table(&budget::read(&path)?);
        Ok((label.to_string(), format!("{t}\n{lane}\n")))
    });
    println!("\n{table}");
    let with = args
        .realtime
        .as_ref()
        .map_or(String::new(), |p| format!(" --realtime {}", p.display()));
    let mut docs = format!(
        "Measured by `cargo run --release -p dualgeo-bench --bin pipeline -- --duration-s {d}{with}` \
         (640×480, 8 images, the default estimator and priorities, this 2-core machine; each \
         row run {n} times, interleaved: the median and the range; the soak row once, its \
         minutes after the first). \"committed\" is bench/baselines/pipeline.json.\n\n{table}",
        n = args.repeats
    );
    for b in budgets {
        let (label, t) = b?;
        println!("latency budget, {label} (from its first run's trace):\n{t}");
        docs.push_str(&format!(
            "\n**Latency budget, {label}** (from its first run's `--trace`):\n\n{t}"
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
