//! End-to-end: a look-alike taken by one camera is not made the target's estimate
//! (issue #23, `matching::chain::target_pair`). `suite_traffic` flown as the
//! multi-target evaluation flies its seed 3: from 4.5 s the right camera's detector
//! takes the red look-alike 225 px from the target while the left one stays on the
//! target. Before the cross-view check every yaw-bias hypothesis explained that pair
//! by turning the biases 20–40°, and the estimate was 10–16 m off while stating ±1.5 m
//! (the target located in 1 % of its pairs over 24 s). Matching now finds the target
//! among the right camera's candidates where the left detection maps, and mends the
//! pair; the two sets before it can (no keyframe shared yet, unchecked) no longer
//! re-open a yaw bias. Since the detectors follow a measured camera swing the right
//! camera does not take the look-alike in the first place (no pair mended). Through the real processes (`dualgeo evaluate --multi-target` runs
//! `dualgeo simulate`'s renderer, `dualgeo run` and `dualgeo score`).

#[path = "support/multi_target_eval.rs"]
mod multi_target_eval;
#[path = "support/scratch.rs"]
mod scratch;

use multi_target_eval::fly;
use scratch::Scratch;

#[test]
fn a_look_alike_in_one_view_is_not_the_targets_estimate() {
    let dir = Scratch::new("look-alike");
    let flown = fly(&dir, "suite_traffic", 3, 10.0);
    let run = flown.run("suite_traffic-003");
    let located = flown.target_located("suite_traffic-003");
    let bias = run["yaw_bias_mae_deg"].as_array().expect("bias MAE");
    let bias: Vec<f64> = bias.iter().filter_map(|b| b.as_f64()).collect();
    // 0.80 with the pair check alone; 0.975 since two unchecked sets on the
    // look-alike (4.47 and 4.50 s) no longer re-open the right bias (the filter's
    // drift monitor winsorises each ray, `geolocation::temporal`; 0.06 without it at
    // the default tempered weights).
    assert!(located >= 0.9, "target located in {located} of its pairs");
    // And it was the pair check that did it, or (since the detectors follow a
    // measured camera swing, `detection::camera_swing`) the right camera no longer
    // took the look-alike at all: the swing at 4.4 s is followed, no pair mended.
    let counters = flown.counters("suite_traffic-003");
    let count = |name: &str| counters[name].as_u64().unwrap_or(0);
    assert!(
        count("matching.target_pair_repaired") > 0 || count("detection.swings_followed") > 0,
        "neither a pair mended nor a swing followed: {counters}"
    );
    assert!(
        bias.len() == 2 && bias.iter().all(|b| *b < 4.0),
        "yaw-bias MAE {bias:?}°"
    );
}
