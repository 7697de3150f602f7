//! Issue #13's recovery figure: one looped run of a recording in which services are
//! killed (SIGKILL) `--kills` times at random moments (fixed seed; services chosen at
//! random), each 1–2.5 s after every service runs again and only while estimates flow
//! in the middle of a pass (`LapGuard`: every pass of a looped recording starts over
//! with a warm-up that a kill landing there would measure). Prints, per service and over
//! all kills, the percentiles of kill → estimates resumed (the first valid estimate
//! of a pair captured after the death; `restarts.csv` of `dualgeo run`), the pairs
//! lost, and whether any estimate was out of order or non-finite.
//!
//! `--max-restarts` is raised for the run so the policy's crash-loop limit does not end
//! it (the kills are chosen at random: one service can be hit often in a minute).
//!
//! Needs the workspace's binaries (`cargo build --release --workspace`).
//! Run: `cargo run --release -p dualgeo-bench --bin chaos [-- --kills 100 --source sim]`

#[path = "../../../tests/support/chaos.rs"]
mod chaos;

use anyhow::{bail, Result};
use chaos::{kill_services, quantile, read_restarts, recoveries, LapGuard, Rng, SERVICES};
use clap::Parser;
use std::path::PathBuf;
use std::process::{Command, Stdio};

#[derive(Parser)]
struct Args {
    /// SIGKILLs to send.
    #[arg(long, default_value_t = 100)]
    kills: usize,
    /// `recording` (a 16 s recording of the default scenario, simulated first) or `sim`
    /// (the live simulator, whose restart builds the town again).
    #[arg(long, default_value = "recording")]
    source: String,
    #[arg(long, default_value_t = 2026)]
    seed: u64,
    /// Scratch directory (removed afterwards unless --keep).
    #[arg(long)]
    scratch: Option<PathBuf>,
    #[arg(long)]
    keep: bool,
}

fn dualgeo() -> Result<PathBuf> {
    dualgeo_bench::dualgeo_binary()
}

fn main() -> Result<()> {
    let args = Args::parse();
    let scratch = args.scratch.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("dualgeo-bench-chaos-{}", std::process::id()))
    });
    std::fs::create_dir_all(&scratch)?;
    let out = scratch.join("out");
    let (source, guard) = match args.source.as_str() {
        "sim" => ("sim".to_string(), LapGuard::unlooped(&out)),
        "recording" => {
            let rec = scratch.join("rec");
            chaos::simulate_default(&dualgeo()?, 16, &rec).map_err(anyhow::Error::msg)?;
            (rec.display().to_string(), LapGuard::new(&out, &rec)?)
        }
        other => bail!("--source must be recording or sim, got {other:?}"),
    };
    // ~2.6 s per kill (gap + recovery), ~40 % of each 16 s pass outside the guard's
    // window, plus warm-up and the end.
    let run_for = 10.0 + args.kills as f64 * 5.0;
    let mut run = Command::new(dualgeo()?)
        .args([
            "run",
            "--loop",
            "--max-restarts",
            "1000",
            "--source",
            &source,
        ])
        .args(["--run-for-s", &format!("{run_for:.0}"), "--out"])
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()?;
    let mut rng = Rng::new(args.seed);
    let kills = kill_services(
        run.id(),
        args.kills,
        &mut rng,
        (1.0, 2.5),
        &guard,
        |_, rng| SERVICES[(rng.next_u64() % 4) as usize],
        |n| {
            if n % 10 == 0 {
                eprintln!("{n}/{} kills", args.kills);
            }
        },
    );
    let status = run.wait()?;
    let mut stdout = String::new();
    if let Some(mut s) = run.stdout.take() {
        use std::io::Read;
        s.read_to_string(&mut stdout)?;
    }
    if !status.success() {
        bail!(
            "dualgeo run failed ({status}) after {} kills:\n{stdout}",
            kills.len()
        );
    }
    let rows = read_restarts(&out);
    let rec = recoveries(&kills, &rows);
    println!(
        "{} kills of a looped {} run ({} seen by the supervisor)",
        kills.len(),
        args.source,
        rows.len()
    );
    println!("kill → estimates resumed, ms   count    p50    p90    p99    max  unrecovered");
    for name in SERVICES.iter().copied().chain(["all"]) {
        let of: Vec<&Option<f64>> = rec
            .iter()
            .filter(|(s, _)| name == "all" || *s == name)
            .map(|(_, ms)| ms)
            .collect();
        let mut ms: Vec<f64> = of.iter().filter_map(|m| **m).collect();
        ms.sort_by(f64::total_cmp);
        println!(
            "  {name:<28} {:>5} {:>6.0} {:>6.0} {:>6.0} {:>6.0} {:>12}",
            of.len(),
            quantile(&ms, 0.5),
            quantile(&ms, 0.9),
            quantile(&ms, 0.99),
            ms.last().copied().unwrap_or(f64::NAN),
            of.len() - ms.len()
        );
    }
    let counters: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("counters.json"))?)?;
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json"))?)?;
    println!(
        "pairs lost in restarts {}, estimates out {}, out of order {}, non-finite {}",
        report["pairs_lost_in_restarts"],
        report["estimates_out"],
        counters.get("supervisor.out_of_order").unwrap_or(&0.into()),
        counters.get("supervisor.non_finite").unwrap_or(&0.into()),
    );
    if let Some(acc) = report["accuracy"].as_object() {
        println!(
            "accuracy over the run: {}",
            serde_json::Value::Object(acc.clone())
        );
    }
    if args.keep {
        println!("outputs in {}", out.display());
    } else {
        let _ = std::fs::remove_dir_all(&scratch);
    }
    Ok(())
}
