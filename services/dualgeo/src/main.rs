//! `dualgeo`: the ground station's command line.
//!
//! - `run`: the main job: the four service processes over iceoryx2 (see `pipeline`).
//! - `simulate`: renders a scenario preset into a recording.
//! - `validate`: checks a recording completely.
//! - `evaluate`: the paper's evaluation on the simulator (docs/evaluation.md).
//! - `synthetic`: the estimator alone on exact synthetic rays with the paper's
//!   navigation noise, beside the one-shot baseline.

mod evaluate;
mod pipeline;
mod plot_font;
mod score;
mod simulate;
mod synthetic_job;
mod validate;

use anyhow::Result;
use clap::{Parser, Subcommand};
use tracing_subscriber::EnvFilter;

#[derive(Parser)]
#[command(
    name = "dualgeo",
    version,
    about = "Dual-UAV moving-target geolocation"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the pipeline (four processes over shared memory) on the live simulator or a
    /// recording; prints the latency table and accuracy, writes track, report and plots.
    Run(Box<pipeline::RunArgs>),
    /// The paper's experiments (Tables 1–4, Figures 8–12) on the simulator, beside the
    /// paper's numbers; writes docs/evaluation.md and its plots.
    Evaluate(evaluate::EvaluateArgs),
    /// The estimator alone on exact synthetic rays (Monte Carlo), beside one-shot.
    Synthetic(synthetic_job::RunArgs),
    /// Render a simulator preset into a recording.
    Simulate(simulate::SimulateArgs),
    /// Check a recording completely (every row and every image).
    Validate(validate::ValidateArgs),
    /// Score a run's track.csv against every vehicle of a recording (GOSPA, MOTA,
    /// IDF1, identity switches, per-vehicle MAE).
    Score(score::ScoreArgs),
}

fn main() -> Result<()> {
    // Like other Unix tools, end quietly when the reader of our output goes away
    // (`dualgeo simulate --list | head`) instead of panicking on a broken pipe.
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe { libc::signal(libc::SIGPIPE, libc::SIG_DFL) };
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::Run(args) => pipeline::run(&args),
        Command::Synthetic(args) => synthetic_job::run(&args),
        Command::Evaluate(args) => evaluate::run(&args),
        Command::Simulate(args) => simulate::run(&args),
        Command::Validate(args) => validate::run(&args),
        Command::Score(args) => score::run(&args),
    }
}
