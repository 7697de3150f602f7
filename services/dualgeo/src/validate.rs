//! `dualgeo validate DIR`: check a recording completely (structure, every CSV row, and
//! every image decoded) before using it.

use acquisition::recording::Recording;
use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use shared_types::conventions::Uav;
use std::io::IsTerminal;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ValidateArgs {
    /// The recording folder.
    recording: PathBuf,
}

pub fn run(args: &ValidateArgs) -> Result<()> {
    let rec = Recording::open(&args.recording)
        .with_context(|| format!("recording {} is invalid", args.recording.display()))?;
    let bar = if std::io::stderr().is_terminal() {
        let bar = ProgressBar::new(rec.telemetry.len() as u64);
        bar.set_style(
            ProgressStyle::with_template("decoding images {pos}/{len} [{bar:30}] eta {eta}")?
                .progress_chars("=> "),
        );
        bar
    } else {
        ProgressBar::hidden()
    };
    for i in 0..rec.telemetry.len() {
        rec.read_image(i)
            .with_context(|| format!("recording {} is invalid", args.recording.display()))?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let count = |uav: Uav| rec.telemetry.iter().filter(|r| r.uav == uav).count();
    let span =
        |f: fn(f64, f64) -> f64, init: f64| rec.telemetry.iter().map(|r| r.t_s).fold(init, f);
    println!(
        "{}: valid recording \"{}\": {} left and {} right images, {} stereo pairs, {:.2} s, truth {}",
        args.recording.display(),
        rec.meta.name,
        count(Uav::Left),
        count(Uav::Right),
        rec.pairs().len(),
        span(f64::max, f64::NEG_INFINITY) - span(f64::min, f64::INFINITY),
        if rec.truth.is_some() { "yes" } else { "no" }
    );
    Ok(())
}
