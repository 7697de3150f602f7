//! A scratch folder per test, removed even when the test fails, and JSON reading.
//! Included (`#[path]`) by the end-to-end tests.

#![allow(dead_code)] // each includer uses part of it

use std::path::{Path, PathBuf};

pub struct Scratch(pub PathBuf);

impl Scratch {
    /// `<tmp>/dualgeo-e2e-<pid>-<name>`, emptied.
    pub fn new(name: &str) -> Self {
        let p = std::env::temp_dir().join(format!("dualgeo-e2e-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        Self(p)
    }

    pub fn join(&self, p: &str) -> PathBuf {
        self.0.join(p)
    }

    pub fn s(&self, p: &str) -> String {
        self.join(p).display().to_string()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

pub fn json(path: &Path) -> serde_json::Value {
    let t = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&t).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}
