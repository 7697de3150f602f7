//! `dualgeo simulate`: render a scenario preset into a recording (format v1).

use acquisition::sim::{record, ScenarioArgs, Simulator};
use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct SimulateArgs {
    #[command(flatten)]
    scenario: ScenarioArgs,
    /// Output folder for the recording (must not exist or be empty).
    #[arg(long, required_unless_present_any = ["list", "print"])]
    out: Option<PathBuf>,
    /// List the presets and exit.
    #[arg(long)]
    list: bool,
    /// Print the preset, fully resolved, as TOML and exit.
    #[arg(long)]
    print: bool,
}

pub fn run(args: &SimulateArgs) -> Result<()> {
    let presets = args.scenario.presets()?;
    if args.list {
        for name in presets.names() {
            let description = presets
                .get(name)
                .map(|c| c.description)
                .unwrap_or_else(|e| format!("INVALID: {e}"));
            println!("{name:14} {description}");
        }
        return Ok(());
    }
    let config = args.scenario.config()?;
    if args.print {
        print!(
            "{}",
            toml::to_string(&config).context("serialising the preset")?
        );
        return Ok(());
    }
    let out = args.out.as_ref().context("--out is required")?;
    let started = Instant::now();
    let mut sim = Simulator::new(config)?;
    let total = sim.frame_count();
    let bar = if std::io::stderr().is_terminal() {
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template(
                "{spinner} rendering {pos}/{len} stereo pairs [{bar:30}] {per_sec} eta {eta}",
            )
            .context("progress template")?
            .progress_chars("=> "),
        );
        bar
    } else {
        ProgressBar::hidden()
    };
    let summary = record(&mut sim, &args.scenario.preset, out, |done, total| {
        bar.set_position(done);
        if bar.is_hidden() && (done % 300 == 0 || done == total) {
            eprintln!("simulate: {done}/{total} stereo pairs");
        }
    })
    .with_context(|| format!("writing recording {}", out.display()))?;
    bar.finish_and_clear();
    println!(
        "wrote {} ({} stereo pairs, {} x {}, {:.1} s) in {:.1} s; target outside the image in {} frames",
        out.display(),
        summary.frames_per_uav,
        sim.config().camera.width,
        sim.config().camera.height,
        sim.config().duration_s,
        started.elapsed().as_secs_f64(),
        summary.target_outside
    );
    Ok(())
}
