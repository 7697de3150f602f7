//! `dualgeo score`: a run's track.csv against every vehicle of a recording
//! (truth_targets.csv, else truth.csv's one target), with multi-target metrics: GOSPA
//! with its switching term, CLEAR MOT (MOTA, identity switches), IDF1, and per vehicle
//! the located share and MAE; the yaw-bias MAE. Any recording in the format can be
//! scored, made here or elsewhere. Evaluation only: no stage reads truth.

pub mod input;
pub mod look_alike;
pub mod metrics;

use anyhow::{Context, Result};
use clap::Args;
use serde::Serialize;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ScoreArgs {
    /// The recording the run read (its truth.csv, and truth_targets.csv when present).
    #[arg(long)]
    pub recording: PathBuf,
    /// The run's track.csv, or the run's output folder holding it.
    #[arg(long)]
    pub track: PathBuf,
    /// Pairs before the run's first estimate + this are not scored.
    #[arg(long, default_value_t = 0.0)]
    pub warm_up_s: f64,
    /// GOSPA's cutoff c, metres (p = 2, α = 2).
    #[arg(long, default_value_t = 5.0)]
    pub cutoff_m: f64,
    /// The match threshold of CLEAR MOT, IDF1 and the located share, metres
    /// (horizontal distance).
    #[arg(long, default_value_t = 2.0)]
    pub threshold_m: f64,
    /// GOSPA's switching penalty γ, metres.
    #[arg(long, default_value_t = 2.0)]
    pub switch_penalty_m: f64,
    /// Also write the scores as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// What `--json` writes.
#[derive(Debug, Serialize)]
pub struct ScoreReport {
    pub recording: PathBuf,
    pub track: PathBuf,
    pub truth_file: &'static str,
    pub warm_up_s: f64,
    pub unpaired_track_rows: u64,
    /// Mean |estimated − true| yaw bias over the scored pairs with an estimate, left
    /// and right, degrees (`None` without the columns).
    pub yaw_bias_mae_deg: Option<[f64; 2]>,
    #[serde(flatten)]
    pub score: metrics::MultiScore,
}

pub fn run(args: &ScoreArgs) -> Result<()> {
    let params = metrics::Params {
        cutoff_m: args.cutoff_m,
        threshold_m: args.threshold_m,
        switch_penalty_m: args.switch_penalty_m,
    };
    let positive = [params.cutoff_m, params.threshold_m];
    anyhow::ensure!(
        positive.iter().all(|v| v.is_finite() && *v > 0.0)
            && params.switch_penalty_m.is_finite()
            && params.switch_penalty_m >= 0.0
            && args.warm_up_s.is_finite()
            && args.warm_up_s >= 0.0,
        "--cutoff-m and --threshold-m must be > 0, --switch-penalty-m and --warm-up-s ≥ 0"
    );
    let track = if args.track.is_dir() {
        args.track.join("track.csv")
    } else {
        args.track.clone()
    };
    let loaded = input::load(&args.recording, &track, args.warm_up_s)?;
    let score = metrics::score(&loaded.frames, params);
    let yaw_bias_mae_deg = loaded.yaw_bias_mae_deg();
    let report = ScoreReport {
        recording: args.recording.clone(),
        track,
        truth_file: loaded.truth_file,
        warm_up_s: args.warm_up_s,
        unpaired_track_rows: loaded.unpaired_rows,
        yaw_bias_mae_deg,
        score,
    };
    print!("{}", table(&report));
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, text + "\n").with_context(|| format!("write {}", path.display()))?;
    }
    Ok(())
}

/// The scores as a reader would look at them.
pub fn table(r: &ScoreReport) -> String {
    let s = &r.score;
    let p = &s.params;
    let mut out = format!(
        "scored {} pairs against {} ({} estimates of vehicles out of view not counted{})\n",
        s.pairs,
        r.truth_file,
        s.dont_care_estimates,
        if r.unpaired_track_rows > 0 {
            format!(
                ", {} track rows at no pair or repeating a track at theirs",
                r.unpaired_track_rows
            )
        } else {
            String::new()
        }
    );
    out += &format!(
        "GOSPA (c {} m, p 2, γ {} m): {:.2} m per pair = localisation {:.2} m rms, {:.2} missed and {:.2} false per pair, {} switches\n",
        p.cutoff_m,
        p.switch_penalty_m,
        s.gospa.mean_m,
        s.gospa.localisation_rms_m,
        s.gospa.missed_per_pair,
        s.gospa.false_per_pair,
        s.gospa.switches
    );
    out += &format!(
        "CLEAR MOT (within {} m): MOTA {:.3}, MOTP {:.2} m; {} vehicle-pairs, {} matched, {} missed, {} false, {} identity switches\n",
        p.threshold_m,
        s.clear.mota,
        s.clear.motp_m,
        s.clear.truth,
        s.clear.matches,
        s.clear.misses,
        s.clear.false_positives,
        s.clear.id_switches
    );
    out += &format!(
        "IDF1 {:.3} (IDTP {}, IDFP {}, IDFN {})\n",
        s.id.idf1, s.id.idtp, s.id.idfp, s.id.idfn
    );
    if let Some([l, rr]) = r.yaw_bias_mae_deg {
        out += &format!("yaw-bias MAE: left {l:.2}°, right {rr:.2}°\n");
    }
    out += "vehicle  in view  located  MAE x / y / z (m)    inside h_acc  inside v_acc  switches  tracks\n";
    for v in &s.vehicles {
        let tracks: Vec<String> = v.tracks.iter().map(u32::to_string).collect();
        out += &format!(
            "{:>7}  {:>7}  {:>6.1}%  {:<19}  {:>12}  {:>12}  {:>8}  {}\n",
            v.id,
            v.in_view,
            100.0 * v.located_share,
            v.mae_m.map_or("-".to_string(), |[x, y, z]| format!(
                "{x:>5.2} / {y:>5.2} / {z:>5.2}"
            )),
            v.inside_h_acc
                .map_or("-".to_string(), |f| format!("{:.0} %", 100.0 * f)),
            v.inside_v_acc
                .map_or("-".to_string(), |f| format!("{:.0} %", 100.0 * f)),
            v.id_switches,
            if tracks.is_empty() {
                "-".to_string()
            } else {
                tracks.join(",")
            }
        );
    }
    for e in &s.switch_events {
        out += &format!(
            "identity switch at t = {:.2} s: vehicle {} from track {} to track {}\n",
            e.t_s, e.vehicle, e.from_track, e.to_track
        );
    }
    out
}
