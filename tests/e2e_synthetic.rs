//! End-to-end: the real `dualgeo` binary, as a user runs it.

use std::path::PathBuf;
use std::process::{Command, Output};

fn dualgeo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args(args)
        .output()
        .expect("spawn dualgeo")
}

fn text(out: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A scratch file removed when dropped, even if the test fails.
struct TempFile(PathBuf);

impl TempFile {
    fn new(name: &str, contents: &str) -> Self {
        let path = std::env::temp_dir().join(format!("dualgeo-e2e-{}-{name}", std::process::id()));
        std::fs::write(&path, contents).expect("write temp file");
        Self(path)
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Pulls the numeric columns of the `proposed <images>` row.
fn proposed_row(stdout: &str, images: usize) -> Vec<f64> {
    let line = stdout
        .lines()
        .find(|l| {
            l.starts_with("proposed") && l.split_whitespace().nth(1) == Some(&images.to_string())
        })
        .unwrap_or_else(|| panic!("no proposed {images} row in:\n{stdout}"));
    line.split(|c: char| c.is_whitespace() || c == '|')
        .filter_map(|w| w.parse::<f64>().ok())
        .collect()
}

#[test]
fn run_prints_accuracy_table_for_the_default_scenario() {
    let out = dualgeo(&["synthetic", "--trials", "120"]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(stdout.contains("synthetic-ray mode"), "{stdout}");
    // Columns: images, MAE x, y, z, horiz MAE, horiz MAX, δψ_L, δψ_R, p50, p99.
    let row8 = proposed_row(&stdout, 8);
    let row4 = proposed_row(&stdout, 4);
    assert_eq!(row8.len(), 10, "{row8:?}");
    let one_shot = stdout
        .lines()
        .find(|l| l.starts_with("one-shot"))
        .expect("one-shot row");
    let one_shot_h: f64 = one_shot
        .split(|c: char| c.is_whitespace() || c == '|')
        .filter_map(|w| w.parse::<f64>().ok())
        .nth(4)
        .expect("one-shot horizontal MAE");
    assert!(
        row8[4] < one_shot_h,
        "8-image horizontal MAE {} vs one-shot {one_shot_h}",
        row8[4]
    );
    assert!(
        row8[6] < row4[6] && row8[7] < row4[7],
        "bias MAE should fall from 4 to 8 images"
    );
    assert!(stdout
        .lines()
        .filter(|l| l.starts_with("proposed"))
        .all(|l| l.ends_with("none")));
}

#[test]
fn same_seed_same_numbers() {
    let args = [
        "synthetic",
        "--trials",
        "40",
        "--images",
        "8",
        "--seed",
        "7",
    ];
    let (a, b) = (dualgeo(&args), dualgeo(&args));
    let strip = |o: &Output| {
        // Solve times vary run to run; compare everything before them.
        proposed_row(&text(o).0, 8)[..8].to_vec()
    };
    assert_eq!(strip(&a), strip(&b));
}

#[test]
fn bad_arguments_fail_with_a_clear_message() {
    let out = dualgeo(&["synthetic", "--images", "5"]);
    assert!(!out.status.success());
    assert!(
        text(&out).1.contains("even counts of at least 4"),
        "{}",
        text(&out).1
    );

    let out = dualgeo(&["synthetic", "--sigma-att-deg", "NaN"]);
    assert!(!out.status.success());
    assert!(
        text(&out).1.contains("--sigma-att-deg must be finite"),
        "{}",
        text(&out).1
    );
}

#[test]
fn config_file_is_read_and_bad_ones_are_named() {
    let good = TempFile::new(
        "good.toml",
        "max_iterations = 3\n[noise_left]\nsigma_yaw_deg = 4.0\n",
    );
    let out = dualgeo(&[
        "synthetic",
        "--trials",
        "20",
        "--images",
        "8",
        "--config",
        good.0.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out).1);

    let bad = TempFile::new("bad.toml", "max_iteratons = 3\n");
    let out = dualgeo(&["synthetic", "--config", bad.0.to_str().unwrap()]);
    let stderr = text(&out).1;
    assert!(!out.status.success());
    assert!(
        stderr.contains("bad.toml") && stderr.contains("max_iteratons"),
        "{stderr}"
    );

    let invalid = TempFile::new("invalid.toml", "max_iterations = 0\n");
    let out = dualgeo(&["synthetic", "--config", invalid.0.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(
        text(&out).1.contains("max_iterations must be at least 1"),
        "{}",
        text(&out).1
    );
}
