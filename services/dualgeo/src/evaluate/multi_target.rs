//! `dualgeo evaluate --multi-target`: several targets judged over seeds. Each
//! (scene, seed) is made into a flight as the Monte Carlo makes it
//! ([`monte_carlo::seeded`]: the route's start, the biases' signs and every noise
//! follow the seed; white navigation errors), rendered to a recording (JPEG 95),
//! streamed through `dualgeo run` (the four real services, `--rate max`) and scored
//! against its truth_targets.csv ([`crate::score`]). Writes OUT/multi-target-seeds.md
//! and OUT/multi-target-seeds.json; each run's score is kept in
//! OUT/multi-target-seeds/runs/ and read back instead of flown again (`--fresh` flies
//! every run again).

use super::monte_carlo::{seeded, NavModel};
use crate::score::{input, look_alike, metrics};
use acquisition::recording::ImageEncoding;
use acquisition::sim::render::VEHICLE_TOP_BGR;
use acquisition::sim::{record, Presets, SimConfig, Simulator};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One vehicle of a run: (id, located share, MAE x, y, z, share of its located
/// estimates inside their h_acc, and inside their v_acc; NaN-free: `None` never
/// located / none stated).
pub type VehicleFigures = (u32, f64, Option<[f64; 3]>, Option<f64>, Option<f64>);

/// Bump when a change makes kept runs stale (the chain, the scorer, the seeding; 15:
/// the camera swing, refused pairs' predictions and the identity test; 16: the yaw
/// biases' rate states; 17: the target's estimates of a look-alike counted; 18: the
/// other vehicles' fixes through the images' pose errors the filter estimated; 19:
/// the tracks' travel test from marks; 20: `[matching] min_past_images = 1` and the
/// travel test with the drop of the tracks' persistent covariance).
const RUN_FORMAT: u32 = 20;

/// What the evaluation runs.
#[derive(Debug, Clone)]
pub struct Plan {
    pub scenes: Vec<String>,
    /// Seeds `first_seed .. first_seed + seeds` of every scene.
    pub first_seed: u64,
    pub seeds: u64,
    /// Seconds of each run; `None`: the preset's.
    pub duration_s: Option<f64>,
    /// Pairs before the first estimate + this are not scored.
    pub warm_up_s: f64,
    pub out: PathBuf,
    pub reuse: bool,
    /// Keep each run's recording and output in DIR/SCENE-SEED/ (else a scratch folder).
    pub keep_flights: Option<PathBuf>,
}

/// One scored run, as kept in runs/.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunScore {
    pub format: u32,
    pub scene: String,
    pub seed: u64,
    pub duration_s: f64,
    /// Wall time of rendering, running and scoring it, s.
    pub cost_s: f64,
    pub gospa_m: f64,
    pub mota: f64,
    pub idf1: f64,
    pub id_switches: u64,
    /// Vehicles seen in view of both UAVs at least once.
    pub vehicles: u64,
    /// Scored time, s (pairs / frame rate).
    pub scored_s: f64,
    /// Matched / in view over every vehicle and pair (CLEAR MOT, 2 m).
    pub located_share: f64,
    pub per_vehicle: Vec<VehicleFigures>,
    pub yaw_bias_mae_deg: Option<[f64; 2]>,
    /// The target's estimates (track 0, from the first) of a moving car coloured like
    /// it ([`look_alike::target_on_look_alike`]).
    #[serde(default)]
    pub look_alike_estimates: u64,
}

/// The truth_targets.csv ids (1 + the traffic index) of the moving cars whose roof is
/// the target's colour.
fn look_alike_ids(config: &SimConfig) -> Vec<u32> {
    let target = config.vehicle.colour_bgr.unwrap_or(VEHICLE_TOP_BGR);
    (0u32..)
        .zip(&config.traffic)
        .filter(|(_, car)| car.colour_bgr == target && car.speed_factor > 0.0)
        .map(|(i, _)| i + 1)
        .collect()
}

fn run_path(plan: &Plan, scene: &str, seed: u64) -> PathBuf {
    plan.out
        .join("multi-target-seeds")
        .join("runs")
        .join(format!("{scene}-{seed:03}.json"))
}

/// Renders, runs and scores one (scene, seed).
fn fly(plan: &Plan, presets: &Presets, scene: &str, seed: u64) -> Result<RunScore> {
    let started = Instant::now();
    let mut config = seeded(
        presets
            .get(scene)
            .with_context(|| format!("preset {scene}"))?,
        seed,
        NavModel::White,
    );
    if let Some(d) = plan.duration_s {
        config.duration_s = d;
    }
    let frame_rate = config.frame_rate_hz;
    let duration_s = config.duration_s;
    let look_alikes = look_alike_ids(&config);
    let scratch = tempfile::tempdir().context("a scratch folder")?;
    let work = match &plan.keep_flights {
        Some(dir) => {
            let kept = dir.join(format!("{scene}-{seed:03}"));
            if kept.exists() {
                std::fs::remove_dir_all(&kept)
                    .with_context(|| format!("clear {}", kept.display()))?;
            }
            std::fs::create_dir_all(&kept).with_context(|| format!("create {}", kept.display()))?;
            kept
        }
        None => scratch.path().to_path_buf(),
    };
    let rec = work.join("rec");
    let mut sim = Simulator::new(config)?;
    record(
        &mut sim,
        scene,
        &rec,
        ImageEncoding::Jpeg { quality: 95 },
        |_, _| {},
    )?;
    let out = work.join("run");
    let exe = std::env::current_exe().context("the dualgeo executable")?;
    let status = std::process::Command::new(exe)
        .arg("run")
        .arg("--source")
        .arg(&rec)
        .args(["--rate", "max", "--out"])
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .context("start dualgeo run")?;
    if !status.success() {
        bail!("dualgeo run on {scene} seed {seed} failed ({status})");
    }
    let loaded = input::load(&rec, &out.join("track.csv"), plan.warm_up_s)?;
    let score = metrics::score(&loaded.frames, metrics::Params::default());
    if score.pairs == 0 || score.clear.truth == 0 {
        bail!(
            "{scene} seed {seed}: no pair scored ({duration_s} s is too short for the \
             first estimate and a {} s warm-up)",
            plan.warm_up_s
        );
    }
    let yaw_bias_mae_deg = loaded.yaw_bias_mae_deg();
    let look_alike_estimates =
        look_alike::target_on_look_alike(&rec, &out.join("track.csv"), &look_alikes)?;
    Ok(RunScore {
        format: RUN_FORMAT,
        scene: scene.to_string(),
        seed,
        duration_s,
        cost_s: started.elapsed().as_secs_f64(),
        gospa_m: score.gospa.mean_m,
        mota: score.clear.mota,
        idf1: score.id.idf1,
        id_switches: score.clear.id_switches,
        vehicles: score.vehicles.len() as u64,
        scored_s: score.pairs as f64 / frame_rate,
        located_share: score.clear.matches as f64 / score.clear.truth.max(1) as f64,
        per_vehicle: score
            .vehicles
            .iter()
            .map(|v| {
                (
                    v.id,
                    v.located_share,
                    v.mae_m,
                    v.inside_h_acc,
                    v.inside_v_acc,
                )
            })
            .collect(),
        yaw_bias_mae_deg,
        look_alike_estimates,
    })
}

/// Every run of the plan, kept ones read back.
pub fn run(plan: &Plan, bar: &indicatif::ProgressBar) -> Result<Vec<RunScore>> {
    let presets = Presets::builtin();
    let mut runs = Vec::new();
    bar.set_length(plan.scenes.len() as u64 * plan.seeds);
    for scene in &plan.scenes {
        for seed in plan.first_seed..plan.first_seed + plan.seeds {
            bar.set_message(format!("multi-target: {scene} seed {seed}"));
            let path = run_path(plan, scene, seed);
            let kept = plan
                .reuse
                .then(|| std::fs::read_to_string(&path).ok())
                .flatten()
                .and_then(|t| serde_json::from_str::<RunScore>(&t).ok())
                .filter(|r| {
                    r.format == RUN_FORMAT
                        && plan
                            .duration_s
                            .is_none_or(|d| (r.duration_s - d).abs() < 1e-9)
                });
            let score = match kept {
                Some(r) => r,
                None => {
                    let r = fly(plan, &presets, scene, seed)?;
                    if let Some(dir) = path.parent() {
                        std::fs::create_dir_all(dir)
                            .with_context(|| format!("create {}", dir.display()))?;
                    }
                    std::fs::write(&path, serde_json::to_string_pretty(&r)? + "\n")
                        .with_context(|| format!("write {}", path.display()))?;
                    r
                }
            };
            runs.push(score);
            bar.inc(1);
        }
    }
    Ok(runs)
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

fn range(v: &[f64]) -> (f64, f64) {
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (lo, hi)
}

/// The report: per scene, the median and range over seeds; per vehicle, its located
/// share and MAE over seeds.
pub fn report(runs: &[RunScore], command: &str, wall_s: f64) -> String {
    let mut out = format!(
        "# Several targets over seeds\n\nWritten by `{command}` ({wall_s:.0} s of wall time; \
         kept runs are read back). Each seed is a flight as the Monte Carlo makes it (route \
         start, bias signs and noise follow the seed; white navigation errors), rendered \
         (JPEG 95), streamed through `dualgeo run` at `--rate max` and scored by `dualgeo \
         score` after a warm-up ([multi-target.md](multi-target.md) defines the metrics).\n\n"
    );
    let mut scenes: Vec<&str> = runs.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    for scene in scenes {
        let rs: Vec<&RunScore> = runs.iter().filter(|r| r.scene == scene).collect();
        let col = |f: fn(&RunScore) -> f64| -> Vec<f64> { rs.iter().map(|r| f(r)).collect() };
        let cell = |v: Vec<f64>, digits: usize| {
            let (lo, hi) = range(&v);
            format!(
                "{:.*} ({:.*}–{:.*})",
                digits,
                median(v),
                digits,
                lo,
                digits,
                hi
            )
        };
        let switches_per_min: Vec<f64> = rs
            .iter()
            .map(|r| {
                r.id_switches as f64 / r.vehicles.max(1) as f64 / (r.scored_s / 60.0).max(1e-9)
            })
            .collect();
        out += &format!(
            "## {scene}: {} seeds\n\nMedian (range) over seeds.\n\n\
             | GOSPA (m) | MOTA | IDF1 | (vehicle, pair) located | identity switches per vehicle-minute | yaw-bias MAE L / R (°) | the target's estimates of a look-alike |\n\
             | --- | --- | --- | --- | --- | --- | --- |\n",
            rs.len()
        );
        let bias = |k: usize| -> Vec<f64> {
            rs.iter()
                .filter_map(|r| r.yaw_bias_mae_deg.map(|b| b[k]))
                .collect()
        };
        let bias_cell = |k: usize| {
            let b = bias(k);
            if b.is_empty() {
                "-".to_string()
            } else {
                format!("{:.2}", median(b))
            }
        };
        let look_alikes: u64 = rs.iter().map(|r| r.look_alike_estimates).sum();
        let look_alike_runs = rs.iter().filter(|r| r.look_alike_estimates > 0).count();
        let look_alike_cell = match look_alike_runs {
            0 => "0".to_string(),
            1 => format!("**{look_alikes}** in 1 run"),
            n => format!("**{look_alikes}** in {n} runs"),
        };
        out += &format!(
            "| {} | {} | {} | {} | {} | {} / {} | {look_alike_cell} |\n\n",
            cell(col(|r| r.gospa_m), 2),
            cell(col(|r| r.mota), 2),
            cell(col(|r| r.idf1), 2),
            cell(col(|r| 100.0 * r.located_share), 1),
            cell(switches_per_min, 2),
            bias_cell(0),
            bias_cell(1),
        );
        let mut ids: Vec<u32> = rs
            .iter()
            .flat_map(|r| r.per_vehicle.iter().map(|v| v.0))
            .collect();
        ids.sort_unstable();
        ids.dedup();
        out += "| vehicle | located (median over seeds, range) | MAE x / y / z (m, median over the seeds that located it) | located estimates inside h_acc / v_acc (median, range) |\n| --- | --- | --- | --- |\n";
        for id in ids {
            let of: Vec<&VehicleFigures> = rs
                .iter()
                .filter_map(|r| r.per_vehicle.iter().find(|v| v.0 == id))
                .collect();
            let shares: Vec<f64> = of.iter().map(|v| 100.0 * v.1).collect();
            let mae: Vec<[f64; 3]> = of.iter().filter_map(|v| v.2).collect();
            let axis = |k: usize| median(mae.iter().map(|m| m[k]).collect());
            let mae_cell = if mae.is_empty() {
                "never located".to_string()
            } else {
                format!("{:.2} / {:.2} / {:.2}", axis(0), axis(1), axis(2))
            };
            let inside = |share: fn(&VehicleFigures) -> Option<f64>| {
                let v: Vec<f64> = of
                    .iter()
                    .filter_map(|v| share(v))
                    .map(|f| 100.0 * f)
                    .collect();
                if v.is_empty() {
                    "—".to_string()
                } else {
                    format!("{} %", cell(v, 0))
                }
            };
            let inside_cell = format!("{} / {}", inside(|v| v.3), inside(|v| v.4));
            out += &format!(
                "| {id}{} | {} % | {mae_cell} | {inside_cell} |\n",
                if id == 0 { " (the target)" } else { "" },
                cell(shares, 1)
            );
        }
        out += "\n";
    }
    out
}

/// Runs the plan and writes OUT/multi-target-seeds.md and .json.
pub fn evaluate(plan: &Plan, command: &str) -> Result<()> {
    let started = Instant::now();
    let bar = indicatif::ProgressBar::new(0);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg:36} {bar:40} {pos}/{len} {elapsed_precise}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let runs = run(plan, &bar)?;
    bar.finish();
    let text = report(&runs, command, started.elapsed().as_secs_f64());
    write(&plan.out, "multi-target-seeds.md", &text)?;
    write(
        &plan.out,
        "multi-target-seeds.json",
        &(serde_json::to_string_pretty(&runs)? + "\n"),
    )?;
    print!("{text}");
    println!(
        "written to {}",
        plan.out.join("multi-target-seeds.md").display()
    );
    Ok(())
}

fn write(dir: &Path, name: &str, text: &str) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("create {}", dir.display()))?;
    let path = dir.join(name);
    std::fs::write(&path, text).with_context(|| format!("write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(seed: u64, share: f64, switches: u64) -> RunScore {
        RunScore {
            format: RUN_FORMAT,
            scene: "multi_town".into(),
            seed,
            duration_s: 24.0,
            cost_s: 40.0,
            gospa_m: 6.0 + seed as f64,
            mota: 0.2,
            idf1: 0.4,
            id_switches: switches,
            vehicles: 2,
            scored_s: 30.0,
            located_share: share,
            per_vehicle: vec![
                (0, 0.9, Some([0.5, 0.5, 1.0]), Some(0.6), Some(0.7)),
                (1, share, None, None, None),
            ],
            yaw_bias_mae_deg: Some([2.0, 3.0]),
            look_alike_estimates: seed - 1,
        }
    }

    #[test]
    fn the_report_gives_medians_ranges_and_rates() {
        let text = report(
            &[run(1, 0.5, 0), run(2, 0.7, 2), run(3, 0.6, 1)],
            "cmd",
            10.0,
        );
        assert!(text.contains("## multi_town: 3 seeds"), "{text}");
        // GOSPA 7, 8, 9: median 8, range 7–9.
        assert!(text.contains("| 8.00 (7.00–9.00) |"), "{text}");
        // Switches per vehicle-minute: 0, 2, 1 over 2 vehicles and half a minute.
        assert!(text.contains("| 1.00 (0.00–2.00) |"), "{text}");
        assert!(
            text.contains("| 1 | 60.0 (50.0–70.0) % | never located |"),
            "{text}"
        );
        assert!(
            text.contains(
                "| 0 (the target) | 90.0 (90.0–90.0) % | 0.50 / 0.50 / 1.00 | 60 (60–60) % / 70 (70–70) % |"
            ),
            "{text}"
        );
        // Of a look-alike: 0, 1 and 2 estimates.
        assert!(text.contains("| 2.00 / 3.00 | **3** in 2 runs |"), "{text}");
    }
}
