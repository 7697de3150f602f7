//! End-to-end: `dualgeo evaluate --quick` writes the whole report and its plots.

#[path = "support/scratch.rs"]
mod scratch;

use scratch::Scratch;
use std::process::Command;

#[test]
fn quick_evaluation_writes_every_table_and_figure() {
    let dir = Scratch::new("evaluate");
    let out = dir.0.clone();
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

/// Issue #23: the Monte Carlo smoke run (two seeds of a short `default` scene under
/// both navigation-error models, and through H.264 at crf 28) writes its tables, JSON
/// and plots, and a second call resumes from the kept runs instead of flying them
/// again; flown again, they repeat (x264 and its decoder included).
#[test]
fn monte_carlo_smoke_run_writes_its_report_and_resumes() {
    let dir = Scratch::new("mc");
    let out = dir.0.clone();
    let run = |fresh: bool| {
        let o = Command::new(env!("CARGO_BIN_EXE_dualgeo"))
            .args([
                "evaluate",
                "--monte-carlo",
                "--quick",
                "--scenes",
                "default",
                "--seeds",
                "2",
                "--mc-duration-s",
                "12",
                "--out",
                out.to_str().unwrap(),
            ])
            .args(fresh.then_some("--fresh"))
            .output()
            .expect("spawn dualgeo");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    run(false);
    let md = std::fs::read_to_string(out.join("monte-carlo.md")).unwrap();
    assert!(md.contains("### white navigation errors"));
    assert!(md.contains("### correlated navigation errors"));
    assert_eq!(md.matches("| `default` | 2 |").count(), 2, "{md}");
    // Item 5: the same seeds through H.264 at crf 28 (--quick's one crf).
    assert!(md.contains("### H.264 video link"), "{md}");
    let link_row = md
        .lines()
        .find(|l| l.starts_with("| H.264 crf 28 | 2 |"))
        .unwrap_or_else(|| panic!("no crf 28 row: {md}"));
    assert!(
        !link_row.contains("NaN") && !link_row.contains("inf"),
        "{link_row}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("monte-carlo.json")).unwrap())
            .unwrap();
    let scenes = json["scenes"].as_array().unwrap();
    assert_eq!(scenes.len(), 3);
    assert_eq!(scenes.iter().filter(|s| s["crf"] == 28).count(), 1);
    for s in scenes {
        let summary = &s["summary"];
        assert_eq!(summary["runs"], 2);
        assert!(summary["estimates"].as_u64().unwrap() > 100, "{s}");
        for key in [
            "within_h_acc_pct",
            "within_v_acc_pct",
            "mean_nees",
            "gross_pct",
        ] {
            assert!(
                summary[key].as_f64().is_some_and(f64::is_finite),
                "{key}: {s}"
            );
        }
    }
    for png in ["default-white-horizontal", "default-gauss-markov-vertical"] {
        let bytes = std::fs::read(out.join(format!("monte-carlo/{png}.png"))).unwrap();
        assert!(
            bytes.starts_with(b"\x89PNG") && bytes.len() > 10_000,
            "{png}"
        );
    }
    let runs = out.join("monte-carlo/runs");
    assert_eq!(std::fs::read_dir(&runs).unwrap().count(), 6);
    // Resumed: the kept runs are read back, so every table row is the same (the JSON's
    // last binary digit may move: serde_json's float parsing is not exact round-trip).
    let rows = || -> Vec<String> {
        std::fs::read_to_string(out.join("monte-carlo.md"))
            .unwrap()
            .lines()
            .filter(|l| l.starts_with("| "))
            .map(str::to_string)
            .collect()
    };
    let before = rows();
    let stamps: Vec<_> = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().metadata().unwrap().modified().unwrap())
        .collect();
    run(false);
    assert_eq!(rows(), before);
    let after: Vec<_> = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().metadata().unwrap().modified().unwrap())
        .collect();
    assert_eq!(stamps, after, "a kept run was flown again");
    // Item 6: flown again (`--fresh`), every run is the same to the last bit.
    let contents = || -> Vec<(std::ffi::OsString, Vec<u8>)> {
        let mut v: Vec<_> = std::fs::read_dir(&runs)
            .unwrap()
            .map(|e| {
                let e = e.unwrap();
                (e.file_name(), std::fs::read(e.path()).unwrap())
            })
            .collect();
        v.sort();
        v
    };
    let kept = contents();
    run(true);
    assert_eq!(contents(), kept, "a run flown again gave another result");
    assert_eq!(rows(), before);
}
