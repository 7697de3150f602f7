//! Benchmark: one geolocation (the whole altitude/regression iteration of
//! `geolocation::geolocate`) with 4 and 8 images in all (N = 2 and 4 per UAV), on the
//! synthetic scenario under the paper's Table 2 protocol. Single-threaded: one core.
//!
//! Target (issue #2): median ≤ 50 µs for 8 images.
//!
//! Run: `cargo run --release -p dualgeo-bench --bin estimator [-- --seconds 3]`

use anyhow::Context;
use clap::Parser;
use dualgeo_bench::{micros_line, time_calls};
use geolocation::synthetic::SyntheticScenario;
use geolocation::{geolocate, EstimatorConfig};
use rand::rngs::StdRng;
use rand::SeedableRng;
use std::hint::black_box;
use std::time::Duration;

#[derive(Parser)]
struct Args {
    /// Seconds of timed calls per case.
    #[arg(long, default_value_t = 3.0)]
    seconds: f64,
    /// Distinct synthetic observation sets cycled through.
    #[arg(long, default_value_t = 1000)]
    sets: usize,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let scenario = SyntheticScenario::default();
    let config = EstimatorConfig::default();
    println!("estimator benchmark: geolocation::geolocate, Table 2 protocol (σ_att 2°, σ_pos 3 m, δψ0 20°), one thread");
    let mut medians = Vec::new();
    for images_per_uav in [2usize, 4] {
        let mut rng = StdRng::seed_from_u64(2023);
        let t0 = scenario.keyframe_interval_s() * images_per_uav as f64;
        let sets = (0..args.sets)
            .map(|i| scenario.trial(t0 + 0.1 * i as f64, images_per_uav, &mut rng))
            .collect::<Result<Vec<_>, _>>()
            .context("synthetic scenario")?;
        let mut iterations = 0usize;
        let mut failures = std::collections::BTreeMap::<&'static str, usize>::new();
        let h = time_calls(
            200,
            1000,
            Duration::from_secs_f64(args.seconds),
            |i| match black_box(geolocate(
                black_box(&sets[i % sets.len()].observations),
                &config,
            )) {
                Ok(e) => iterations += e.iterations,
                Err(e) => *failures.entry(e.kind()).or_default() += 1,
            },
        );
        let images = 2 * images_per_uav;
        println!("  {images} images: {}", micros_line(&h));
        println!(
            "             mean iterations {:.2}, rejected {failures:?}",
            iterations as f64 / (h.len() as f64 + 200.0)
        );
        medians.push((images, h.value_at_quantile(0.5)));
    }
    if let [(_, a), (n8, b)] = medians[..] {
        println!(
            "  ratio {n8} images / 4 images (median): {:.2}; target for {n8} images: median ≤ 50 µs → {}",
            b as f64 / a as f64,
            if b <= 50_000 { "met" } else { "MISSED" }
        );
    }
    Ok(())
}
