//! `dualgeo evaluate --multi-target` flown into a scratch folder, and what its runs
//! say of the target (the look-alike tests). Included (`#[path]`) by the end-to-end
//! tests.

#![allow(dead_code)] // each includer uses part of it

use crate::scratch::{json, Scratch};
use std::path::{Path, PathBuf};
use std::process::Command;

/// One evaluation's report folder and kept flights.
pub struct Flown {
    pub out: PathBuf,
    pub flights: PathBuf,
}

/// Flies `scene`'s seeds 1…`seeds` for `duration_s` through the real processes,
/// keeping every flight.
pub fn fly(dir: &Scratch, scene: &str, seeds: u32, duration_s: f64) -> Flown {
    let (out, flights) = (dir.s("eval"), dir.s("flights"));
    let o = Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args([
            "evaluate",
            "--multi-target",
            "--scenes",
            scene,
            "--scene-seeds",
            &seeds.to_string(),
            "--mc-duration-s",
            &duration_s.to_string(),
            "--out",
            &out,
            "--keep-flights",
            &flights,
        ])
        .output()
        .expect("spawn dualgeo");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    Flown {
        out: out.into(),
        flights: flights.into(),
    }
}

impl Flown {
    /// The scored run `name` (`SCENE-SEED`).
    pub fn run(&self, name: &str) -> serde_json::Value {
        json(
            &self
                .out
                .join("multi-target-seeds")
                .join("runs")
                .join(format!("{name}.json")),
        )
    }

    /// The share of the target's pairs located in run `name`.
    pub fn target_located(&self, name: &str) -> f64 {
        // (id, located share, MAE, inside h_acc, inside v_acc) per vehicle; 0 the target.
        let run = self.run(name);
        let target = run["per_vehicle"]
            .as_array()
            .expect("per_vehicle")
            .iter()
            .find(|v| v[0] == 0)
            .cloned()
            .expect("the target scored");
        target[1].as_f64().expect("located share")
    }

    /// The target's estimates of a look-alike in run `name` (nearer a car coloured like
    /// it than the target and over 2 m off, from the first estimate).
    pub fn look_alike_estimates(&self, name: &str) -> u64 {
        self.run(name)["look_alike_estimates"]
            .as_u64()
            .expect("look_alike_estimates")
    }

    /// `dualgeo run`'s counters of flight `name`.
    pub fn counters(&self, name: &str) -> serde_json::Value {
        json(
            &Path::new(&self.flights)
                .join(name)
                .join("run")
                .join("counters.json"),
        )
    }
}
