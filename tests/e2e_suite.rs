//! End-to-end: a short run of three scene-suite scenes (issue #12) through the real
//! `dualgeo evaluate --suite-only`, asserting from `suite.json`:
//!
//! - the located share and MAE bounds per scene and protocol (bounds from the full
//!   suite's figures with headroom for the sparser sampling: docs/evaluation.md);
//! - on `suite_town`, whose target passes under a bridge, no estimate while the target
//!   is hidden, and no confident wrong one: every error within 4 h_acc.
//!
//! Fixed seeds (the presets'); ~2 minutes on 2 cores.

use std::process::Command;

struct Cleanup(std::path::PathBuf);
impl Drop for Cleanup {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// (scene, protocol index, least located share %, MAE x/y bound m, MAE z bound m).
const BOUNDS: [(&str, usize, f64, f64, f64); 6] = [
    ("suite_town", 0, 90.0, 0.25, 0.5),
    ("suite_town", 1, 90.0, 2.5, 2.0),
    ("suite_photo_urban", 0, 90.0, 0.25, 0.5),
    ("suite_photo_urban", 1, 90.0, 3.0, 2.0),
    ("suite_degraded", 0, 90.0, 0.25, 0.5),
    ("suite_degraded", 1, 90.0, 3.0, 2.0),
];

#[test]
fn a_short_suite_locates_its_scenes_and_never_a_hidden_target() {
    let out = std::env::temp_dir().join(format!("dualgeo-e2e-{}-suite", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let _guard = Cleanup(out.clone());
    let o = Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args([
            "evaluate",
            "--suite-only",
            "--scenes",
            "suite_town,suite_photo_urban,suite_degraded",
            "--every",
            "3",
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .expect("spawn dualgeo");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(out.join("suite.md")).unwrap();
    assert!(
        md.contains("### Table 1") && md.contains("### Table 2"),
        "{md}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("suite.json")).unwrap()).unwrap();
    let scenes = json["scenes"].as_array().expect("scenes");
    assert_eq!(scenes.len(), 3);
    let protocol = |name: &str, p: usize| {
        scenes
            .iter()
            .find(|s| s["scene"] == name)
            .unwrap_or_else(|| panic!("{name} missing"))["protocols"][p]
            .clone()
    };
    for (name, p, least_pct, xy, z) in BOUNDS {
        let r = protocol(name, p);
        let visible = r["visible_pairs"].as_f64().unwrap();
        let located = r["located_pairs"].as_f64().unwrap();
        assert!(visible > 30.0, "{name}/{p}: only {visible} visible pairs");
        let share = 100.0 * located / visible;
        let mae: Vec<f64> = r["default_mae_m"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        eprintln!("{name} protocol {p}: located {share:.1} %, MAE {mae:?}");
        assert!(share >= least_pct, "{name}/{p}: located {share:.1} %");
        assert!(
            mae[0] <= xy && mae[1] <= xy && mae[2] <= z,
            "{name}/{p}: MAE {mae:?}"
        );
        assert!(mae.iter().all(|v| v.is_finite()));
    }
    // The bridge: hidden pairs exist, none was located, and nothing was confidently
    // wrong (with true poses, where h_acc means what it says).
    let town = protocol("suite_town", 0);
    assert!(town["not_visible_pairs"].as_u64().unwrap() >= 5, "{town}");
    assert_eq!(town["located_while_not_visible"], 0, "{town}");
    let worst = town["worst_h_error_over_h_acc"].as_f64().unwrap();
    assert!(worst <= 4.0, "an error of {worst:.1} h_acc on suite_town");
}
