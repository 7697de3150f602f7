//! The outside clients' Python (pymavlink, Foxglove's mcap, in a venv made by
//! scripts/py_test_env.sh). Included (`#[path]`) by the end-to-end tests that decode
//! dualgeo's outputs with them.

#![allow(dead_code)] // each includer uses part of it

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository's root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The venv's python with pymavlink and mcap, or why there is none.
pub fn python() -> Result<PathBuf, String> {
    let o = Command::new("bash")
        .arg(root().join("scripts/py_test_env.sh"))
        .output()
        .map_err(|e| e.to_string())?;
    if !o.status.success() {
        return Err(String::from_utf8_lossy(&o.stderr).into_owned());
    }
    Ok(PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()))
}
