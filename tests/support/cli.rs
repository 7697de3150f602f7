//! Running the `dualgeo` binary and reading its CSV outputs, for the end-to-end tests
//! of the `dualgeo` package (`CARGO_BIN_EXE_dualgeo`). Included (`#[path]`).

#![allow(dead_code)] // each includer uses part of it

use std::collections::HashMap;
use std::process::Command;

/// Runs `dualgeo ARGS` and fails the test with its stderr unless it succeeds.
pub fn dualgeo(args: &[&str]) {
    let o = Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args(args)
        .output()
        .expect("spawn dualgeo");
    assert!(
        o.status.success(),
        "dualgeo {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// A CSV file's rows, each keyed by the header's names.
pub fn rows(path: &std::path::Path) -> Vec<HashMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    lines
        .map(|l| {
            header
                .iter()
                .zip(l.split(','))
                .map(|(h, v)| (h.to_string(), v.to_string()))
                .collect()
        })
        .collect()
}
