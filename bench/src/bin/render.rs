//! Benchmark: the simulator's live-source cost. Renders stereo pairs of the `default`
//! preset (both views in parallel, one thread each, as the acquisition service does)
//! and single views, at 640×480 and optionally larger frames.
//!
//! Target (issue #3): a stereo pair of 640×480 frames in ≤ 25 ms on this 2-core machine.
//!
//! Run: `cargo run --release -p dualgeo-bench --bin render [-- --sizes 640x480,1920x1080,3840x2160]`

use acquisition::sim::{Presets, Simulator};
use anyhow::{bail, Result};
use clap::Parser;
use dualgeo_bench::{time_calls, Percentiles};
use shared_types::conventions::Uav;
use std::time::{Duration, Instant};

#[derive(Parser)]
struct Args {
    /// Frame sizes, WIDTHxHEIGHT, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "640x480")]
    sizes: Vec<String>,
    /// Seconds of timed renders per case.
    #[arg(long, default_value_t = 3.0)]
    seconds: f64,
}

fn main() -> Result<()> {
    let args = Args::parse();
    let base = Presets::builtin().get("default")?;
    let started = Instant::now();
    let first = Simulator::new(base.clone())?;
    println!(
        "town generation (ground {}x{} texels): {:.0} ms",
        (2.0 * base.city.half_extent_m / base.city.ground_metres_per_texel) as u32,
        (2.0 * base.city.half_extent_m / base.city.ground_metres_per_texel) as u32,
        started.elapsed().as_secs_f64() * 1e3
    );
    let city = first.city().clone();
    for size in &args.sizes {
        let Some((w, h)) = size
            .split_once('x')
            .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
        else {
            bail!("--sizes takes WIDTHxHEIGHT, got {size}");
        };
        let mut config = base.clone();
        config.camera.width = w;
        config.camera.height = h;
        config.duration_s = 1e6;
        let mut sim = Simulator::with_city(config, city.clone())?;
        let stride = 3 * w as usize;
        let (mut left, mut right) = (
            vec![0u8; stride * h as usize],
            vec![0u8; stride * h as usize],
        );
        let steps: Vec<_> = (0..300).filter_map(|_| sim.step()).collect();
        let seconds = Duration::from_secs_f64(args.seconds);
        let pair = time_calls(5, 20, seconds, |i| {
            sim.render_pair(&steps[i % steps.len()], &mut left, &mut right, stride)
        });
        let single = time_calls(5, 20, seconds, |i| {
            sim.render(&steps[i % steps.len()], Uav::Left, &mut left, stride)
        });
        let (p, s) = (Percentiles::of(&pair), Percentiles::of(&single));
        println!(
            "{w}x{h} stereo pair (2 threads): {}",
            ms_line(&p, pair.len())
        );
        println!(
            "{w}x{h} one view (1 thread):    {}",
            ms_line(&s, single.len())
        );
        println!(
            "  pair / single-view median: {:.2}",
            p.p50 as f64 / s.p50 as f64
        );
        if (w, h) == (640, 480) {
            println!(
                "  target: stereo pair ≤ 25 ms (median) → {}",
                if p.p50 <= 25_000_000 {
                    "met".to_string()
                } else {
                    format!("MISSED by {:.1} ms", (p.p50 as f64 - 25e6) / 1e6)
                }
            );
        }
    }
    Ok(())
}

fn ms_line(p: &Percentiles, samples: u64) -> String {
    let ms = |ns: u64| ns as f64 / 1e6;
    format!(
        "p50 {:7.2} ms  p90 {:7.2} ms  p99 {:7.2} ms  max {:7.2} ms  (n={})",
        ms(p.p50),
        ms(p.p90),
        ms(p.p99),
        ms(p.max),
        samples
    )
}
