//! End-to-end: `dualgeo evaluate --quick` writes the whole report and its plots.

use std::process::Command;

#[test]
fn quick_evaluation_writes_every_table_and_figure() {
    let out = std::env::temp_dir().join(format!("dualgeo-e2e-{}-evaluate", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    struct Cleanup(std::path::PathBuf);
    impl Drop for Cleanup {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
    let _guard = Cleanup(out.clone());
    let o = Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args([
            "evaluate",
            "--quick",
            "--scenes",
            "suite_town",
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .expect("spawn dualgeo");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(out.join("evaluation.md")).unwrap();
    for section in [
        "## Table 1",
        "## Table 2",
        "## Table 3",
        "## Table 4",
        "## Figure 9",
        "## Figure 10",
        "## Figure 11",
        "## Figure 12",
        "## Targets (issue #6)",
        "## Scene suite",
    ] {
        assert!(md.contains(section), "{section} missing");
    }
    // The paper's numbers sit beside ours.
    assert!(md.contains("| paper, after filter, 8 images | 0.151 / 0.125 / 0.692"));
    assert!(md.contains("| 8 | 2.448 / 1.931 / 7.819 |"));
    let non_finite = md
        .split(|c: char| !c.is_alphanumeric())
        .any(|word| word == "inf" || word == "NaN");
    assert!(!non_finite, "non-finite figure in the report");
    // Every estimator produced numbers for every sweep level: 4 methods × 5 levels.
    assert_eq!(md.matches("| joint, 8 images |").count(), 20);
    for png in ["fig8_path", "fig9", "fig10", "fig11", "fig12"] {
        let p = out.join(format!("evaluation/{png}.png"));
        let bytes = std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert!(
            bytes.starts_with(b"\x89PNG") && bytes.len() > 10_000,
            "{png}"
        );
    }
}
