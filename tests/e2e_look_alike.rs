//! End-to-end: a look-alike taken by one camera is not made the target's estimate
//! (issue #23, `matching::chain::target_pair`). `suite_traffic` flown as the
//! multi-target evaluation flies its seed 3: from 4.5 s the right camera's detector
//! takes the red look-alike 225 px from the target while the left one stays on the
//! target. Before the cross-view check every yaw-bias hypothesis explained that pair
//! by turning the biases 20–40°, and the estimate was 10–16 m off while stating ±1.5 m
//! (the target located in 1 % of its pairs over 24 s). Matching now finds the target
//! among the right camera's candidates where the left detection maps, and mends the
//! pair; the two sets before it can (no keyframe shared yet, unchecked) no longer
//! re-open a yaw bias. Through the real processes (`dualgeo evaluate --multi-target` runs
//! `dualgeo simulate`'s renderer, `dualgeo run` and `dualgeo score`).

#[path = "support/scratch.rs"]
mod scratch;

use scratch::{json, Scratch};
use std::process::Command;

#[test]
fn a_look_alike_in_one_view_is_not_the_targets_estimate() {
    let dir = Scratch::new("look-alike");
    let out = dir.s("eval");
    let flights = dir.s("flights");
    let o = Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args([
            "evaluate",
            "--multi-target",
            "--scenes",
            "suite_traffic",
            "--scene-seeds",
            "3",
            "--mc-duration-s",
            "10",
            "--out",
            &out,
            "--keep-flights",
            &flights,
        ])
        .output()
        .expect("spawn dualgeo");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run = json(
        &std::path::Path::new(&out)
            .join("multi-target-seeds")
            .join("runs")
            .join("suite_traffic-003.json"),
    );
    // (id, located share, MAE, inside h_acc, inside v_acc) per vehicle; 0 the target.
    let target = run["per_vehicle"]
        .as_array()
        .expect("per_vehicle")
        .iter()
        .find(|v| v[0] == 0)
        .expect("the target scored");
    let located = target[1].as_f64().expect("located share");
    let bias = run["yaw_bias_mae_deg"].as_array().expect("bias MAE");
    let bias: Vec<f64> = bias.iter().filter_map(|b| b.as_f64()).collect();
    // 0.80 with the pair check alone; 0.975 since two unchecked sets on the
    // look-alike (4.47 and 4.50 s) no longer re-open the right bias (the filter's
    // drift monitor winsorises each ray, `geolocation::temporal`; 0.06 without it at
    // the default tempered weights).
    assert!(located >= 0.9, "target located in {located} of its pairs");
    // And it was the mending that did it.
    let counters = json(
        &std::path::Path::new(&flights)
            .join("suite_traffic-003")
            .join("run")
            .join("counters.json"),
    );
    let mended = counters["matching.target_pair_repaired"]
        .as_u64()
        .unwrap_or(0);
    assert!(mended > 0, "no pair mended: {counters}");
    assert!(
        bias.len() == 2 && bias.iter().all(|b| *b < 4.0),
        "yaw-bias MAE {bias:?}°"
    );
}
