//! `dualgeo`: the ground station's command line.
//!
//! Today it has one subcommand, `run`. Until the image pipeline lands (issue #5) `run`
//! exercises the estimator on the built-in synthetic scenario (exact rays with the
//! paper's navigation noise) and prints accuracy and solve time beside the one-shot
//! baseline.

mod synthetic_job;

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
    }
}
