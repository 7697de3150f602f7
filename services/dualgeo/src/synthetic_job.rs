//! `dualgeo run` in synthetic-ray mode: the paper's estimator on exact rays of the
//! built-in scenario with the paper's navigation noise, against the one-shot baseline.

use anyhow::{bail, Context, Result};
use clap::Args;
use geolocation::evaluation::{monte_carlo, ErrorStats, MonteCarloReport};
use geolocation::synthetic::{BiasModel, NavNoise, SyntheticScenario};
use geolocation::EstimatorConfig;
use hdrhistogram::Histogram;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct RunArgs {
    /// Images per geolocation (2N in all, N per UAV), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "4,8")]
    images: Vec<usize>,
    /// Geolocations per row.
    #[arg(long, default_value_t = 400)]
    trials: usize,
    /// Random seed of the navigation noise.
    #[arg(long, default_value_t = 42)]
    seed: u64,
    /// σ of each attitude angle, degrees.
    #[arg(long, default_value_t = 2.0)]
    sigma_att_deg: f64,
    /// σ of each position axis, metres.
    #[arg(long, default_value_t = 3.0)]
    sigma_pos_m: f64,
    /// δψ0 of eq. (34), degrees (δψ_L = 0.2 t + δψ0, δψ_R = 0.2 t − δψ0).
    #[arg(long, default_value_t = 20.0)]
    delta0_deg: f64,
    /// Estimator configuration (TOML; keys of `EstimatorConfig`, unknown keys rejected).
    #[arg(long)]
    config: Option<PathBuf>,
}

pub fn run(args: &RunArgs) -> Result<()> {
    let config = load_config(args.config.as_ref())?;
    if args.trials == 0 {
        bail!("--trials must be at least 1");
    }
    for &n in &args.images {
        if n < 4 || n % 2 != 0 {
            bail!("--images takes even counts of at least 4 (2N in all, N per UAV); got {n}");
        }
    }
    for (name, v) in [
        ("--sigma-att-deg", args.sigma_att_deg),
        ("--sigma-pos-m", args.sigma_pos_m),
        ("--delta0-deg", args.delta0_deg),
    ] {
        if !v.is_finite() || v < 0.0 {
            bail!("{name} must be finite and >= 0; got {v}");
        }
    }
    tracing::info!(?config, "estimator configuration");
    let scenario = SyntheticScenario {
        noise: NavNoise::isotropic(args.sigma_pos_m, args.sigma_att_deg),
        bias: BiasModel::Eq34 {
            delta0_deg: args.delta0_deg,
            rate_deg_s: 0.2,
        },
        ..SyntheticScenario::default()
    };
    tracing::info!(?scenario, "synthetic scenario");

    println!("dualgeo run: synthetic-ray mode (the image pipeline of issue #5 is not built yet)");
    println!(
        "scenario: two nadir UAVs {:.0} m above ground, {:.0} m apart, target at {:.0} m/s; T_re {:.0} m",
        scenario.altitude_agl_m, scenario.uav_separation_m, scenario.speed_mps, scenario.keyframe_spacing_m
    );
    println!(
        "noise: σ_att {}°, σ_pos {} m, yaw biases by eq. (34) with δψ0 = {}°; {} geolocations per row, seed {}",
        args.sigma_att_deg, args.sigma_pos_m, args.delta0_deg, args.trials, args.seed
    );
    println!();
    println!("method    images |  MAE x   MAE y   MAE z | horiz MAE  horiz MAX | δψ_L MAE  δψ_R MAE | solve p50    p99 | rejected");
    let mut one_shot_row = None;
    for &images in &args.images {
        let report = monte_carlo(&scenario, images / 2, args.trials, args.seed, &config);
        print_proposed(&report)?;
        one_shot_row.get_or_insert(report);
    }
    if let Some(report) = one_shot_row {
        let [x, y, z, h, _] = report.one_shot.stats();
        println!(
            "one-shot       1 | {:6.2}  {:6.2}  {:6.2} | {:9.2}  {:9.2} | {:>8}  {:>8} | {:>9} {:>6} | (true range given)",
            x.mae, y.mae, z.mae, h.mae, h.max, "-", "-", "-", "-"
        );
    }
    println!();
    println!("errors in metres and degrees (MAE of eq. 33); solve times in µs per geolocation, one thread");
    Ok(())
}

fn print_proposed(report: &MonteCarloReport) -> Result<()> {
    let [x, y, z, h, _] = report.proposed.stats();
    let bias = |u: usize| ErrorStats::from_errors(&report.bias_deg[u]).mae;
    let mut hist = Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3)?;
    for &ns in &report.solve_ns {
        hist.saturating_record(ns.max(1));
    }
    let us = |q: f64| hist.value_at_quantile(q) as f64 / 1e3;
    let rejected: Vec<String> = report
        .failures
        .iter()
        .map(|(k, v)| format!("{k} {v}"))
        .collect();
    println!(
        "proposed  {:6} | {:6.2}  {:6.2}  {:6.2} | {:9.2}  {:9.2} | {:8.2}  {:8.2} | {:9.1} {:6.1} | {}",
        2 * report.images_per_uav,
        x.mae,
        y.mae,
        z.mae,
        h.mae,
        h.max,
        bias(0),
        bias(1),
        us(0.5),
        us(0.99),
        if rejected.is_empty() { "none".to_string() } else { rejected.join(", ") }
    );
    Ok(())
}

fn load_config(path: Option<&PathBuf>) -> Result<EstimatorConfig> {
    let Some(path) = path else {
        return Ok(EstimatorConfig::default());
    };
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading estimator config {}", path.display()))?;
    let config: EstimatorConfig = toml::from_str(&text)
        .with_context(|| format!("parsing estimator config {}", path.display()))?;
    config
        .validate()
        .with_context(|| format!("estimator config {}", path.display()))?;
    Ok(config)
}
