//! The command-line choice of a simulated scenario, shared by `dualgeo simulate`,
//! `dualgeo run` and the acquisition service: a preset, optionally from another
//! presets file, with the duration and noise seed overridable.

use super::{Presets, SimConfig, SimError};
use std::path::PathBuf;

#[derive(Debug, Clone, clap::Args)]
pub struct ScenarioArgs {
    /// Simulator preset (see `dualgeo simulate --list`).
    #[arg(long, default_value = "default")]
    pub preset: String,
    /// A presets file instead of the built-in one (services/acquisition/presets/scenarios.toml).
    #[arg(long)]
    pub presets: Option<PathBuf>,
    /// Override the preset's duration, seconds.
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Override the preset's noise seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Live simulator only: inject a live-input fault into this share of the pairs
    /// (0–1; kinds in turn; `acquisition::sim::faults`), to exercise the live-input gate.
    #[arg(long)]
    pub inject_faults: Option<f64>,
}

impl ScenarioArgs {
    /// The presets these arguments read from.
    pub fn presets(&self) -> Result<Presets, SimError> {
        match &self.presets {
            Some(path) => Presets::from_file(path),
            None => Ok(Presets::builtin()),
        }
    }

    /// The chosen preset with the overrides applied.
    pub fn config(&self) -> Result<SimConfig, SimError> {
        let mut config = self.presets()?.get(&self.preset)?;
        if let Some(d) = self.duration_s {
            config.duration_s = d;
        }
        if let Some(s) = self.seed {
            config.seed = s;
        }
        Ok(config)
    }

    /// The same choice as command-line arguments, to pass on to a child process.
    pub fn to_args(&self) -> Vec<String> {
        let mut out = vec!["--preset".to_string(), self.preset.clone()];
        if let Some(p) = &self.presets {
            out.extend(["--presets".into(), p.display().to_string()]);
        }
        if let Some(d) = self.duration_s {
            out.extend(["--duration-s".into(), d.to_string()]);
        }
        if let Some(s) = self.seed {
            out.extend(["--seed".into(), s.to_string()]);
        }
        if let Some(r) = self.inject_faults {
            out.extend(["--inject-faults".into(), r.to_string()]);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        scenario: ScenarioArgs,
    }

    #[test]
    fn overrides_apply_and_round_trip_through_arguments() {
        let cli = Cli::parse_from([
            "x",
            "--preset",
            "table1",
            "--duration-s",
            "2.5",
            "--seed",
            "9",
        ]);
        let config = cli.scenario.config().unwrap();
        assert_eq!((config.duration_s, config.seed), (2.5, 9));
        let again = Cli::parse_from(std::iter::once("x".to_string()).chain(cli.scenario.to_args()));
        assert_eq!(again.scenario.config().unwrap(), config);
        let bad = Cli::parse_from(["x", "--preset", "nope"]);
        assert!(bad.scenario.config().is_err());
    }
}
