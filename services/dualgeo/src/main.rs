//! `dualgeo`: the ground station's command line.
//!
//! `simulate` renders a scenario preset into a recording. Until the image pipeline lands (issue #5) `run`
//! exercises the estimator on the built-in synthetic scenario (exact rays with the
//! paper's navigation noise) and prints accuracy and solve time beside the one-shot
//! baseline.

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
    /// Run the main job on the built-in default scenario.
    Run(synthetic_job::RunArgs),
    /// Render a simulator preset into a recording.
    Simulate(simulate::SimulateArgs),
    /// Check a recording completely (every row and every image).
    Validate(validate::ValidateArgs),
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::Run(args) => synthetic_job::run(&args),
        Command::Simulate(args) => simulate::run(&args),
        Command::Validate(args) => validate::run(&args),
    }
}
