//! End-to-end: `suite_traffic` seeds 1–5 flown for 20 s as the multi-target evaluation
//! flies them, through the real processes (`dualgeo evaluate --multi-target` runs
//! `dualgeo simulate`'s renderer, `dualgeo run` and `dualgeo score`), once for two
//! checks (issues #23 and #26):
//!
//! **A look-alike in one view is not the target's estimate** (seed 3,
//! `matching::chain::target_pair`): from 4.5 s the right camera's detector took the red
//! look-alike 225 px from the target while the left one stayed on the target. Before
//! the cross-view check every yaw-bias hypothesis explained that pair by turning the
//! biases 20–40°, and the estimate was 10–16 m off while stating ±1.5 m (the target
//! located in 1 % of its pairs over 24 s). Matching now finds the target among the
//! right camera's candidates where the left detection maps, and mends the pair; the
//! two sets before it can (no keyframe shared yet, unchecked) no longer re-open a yaw
//! bias. Since the detectors follow a measured camera swing the right camera does not
//! take the look-alike in the first place (no pair mended).
//!
//! **After the bridge the target's estimate stays on the target:**
//! - Seed 5: both red cars pass under the bridge and the look-alike comes out first,
//!   a few metres ahead of where the target should be. Its rays are within one pair's
//!   GPS and attitude noise of the target's prediction, and the filter took them: the
//!   target located in 49 % of its pairs. The other vehicles of each pair, placed
//!   relative to the detection, now say it is the look-alike's track
//!   (`geolocation::target_identity`, counted `target_on_track`): the filter coasts
//!   until the detectors are back on the target.
//! - Seed 4: the same, with one other vehicle in view, whose track had widened while
//!   nothing was seen: the evidence built slower than the filter walked onto the
//!   look-alike (62 %). Right after such a gap a pair in doubt is coasted too
//!   (`target_in_doubt`).
//! - Seeds 4 and 5 since the detector remembers a look-alike that vanished beside the
//!   target (`detection::tracked`): it no longer takes it when it comes out first, and
//!   neither geolocation rule is reached here (both unit-tested in
//!   `geolocation::target_identity`); the seeds are held to their located share.
//! - Seed 2: the two cameras took different cars; every pair was refused as two
//!   vehicles and, with no estimate, no gate brought them back: 73 %. A refused pair
//!   now gives the filter's prediction (`sets_refused`), whose gate does.
//! - On every seed, none of the target's estimates is of the look-alike (issue #23).
//!
//! One flight for both: the look-alike check had flown seeds 1–3 for 10 s of its own
//! (57 s of CI).

#[path = "support/multi_target_eval.rs"]
mod multi_target_eval;
#[path = "support/scratch.rs"]
mod scratch;

use multi_target_eval::{fly, Flown};
use scratch::Scratch;

#[test]
fn suite_traffic_keeps_the_target_past_a_look_alike_and_the_bridge() {
    let dir = Scratch::new("traffic");
    let flown = fly(&dir, "suite_traffic", 5, 20.0);
    a_look_alike_in_one_view_is_not_the_targets_estimate(&flown);
    the_targets_estimate_stays_on_the_target_after_the_bridge(&flown);
}

/// Seed 3: the right camera's look-alike is mended away or never taken.
fn a_look_alike_in_one_view_is_not_the_targets_estimate(flown: &Flown) {
    let name = "suite_traffic-003";
    let run = flown.run(name);
    let located = flown.target_located(name);
    let bias = run["yaw_bias_mae_deg"].as_array().expect("bias MAE");
    let bias: Vec<f64> = bias.iter().filter_map(|b| b.as_f64()).collect();
    // 0.80 with the pair check alone; 0.975 since two unchecked sets on the
    // look-alike (4.47 and 4.50 s) no longer re-open the right bias (the filter's
    // drift monitor winsorises each ray, `geolocation::temporal`; 0.06 without it at
    // the default tempered weights). Measured on 10 s flights.
    assert!(
        located >= 0.9,
        "seed 3: target located in {located} of its pairs"
    );
    // And it was the pair check that did it, or (since the detectors follow a
    // measured camera swing, `detection::camera_swing`) the right camera no longer
    // took the look-alike at all: the swing at 4.4 s is followed, no pair mended.
    let counters = flown.counters(name);
    let count = |name: &str| counters[name].as_u64().unwrap_or(0);
    assert!(
        count("matching.target_pair_repaired") > 0 || count("detection.swings_followed") > 0,
        "seed 3: neither a pair mended nor a swing followed: {counters}"
    );
    assert!(
        bias.len() == 2 && bias.iter().all(|b| *b < 4.0),
        "seed 3: yaw-bias MAE {bias:?}°"
    );
}

/// Seeds 2, 4 and 5 located after the bridge; no seed's estimate of the look-alike.
fn the_targets_estimate_stays_on_the_target_after_the_bridge(flown: &Flown) {
    // (seed, counter that shows the mechanism at work, located before it).
    for (seed, counter, before) in [
        (2, Some("geolocation.sets_refused"), 0.73),
        (4, None, 0.62),
        (5, None, 0.49),
    ] {
        let name = format!("suite_traffic-{seed:03}");
        let located = flown.target_located(&name);
        assert!(
            located >= 0.9,
            "seed {seed}: target located in {located} of its pairs ({before} before)"
        );
        if let Some(counter) = counter {
            let counters = flown.counters(&name);
            let n = counters[counter].as_u64().unwrap_or(0);
            assert!(n > 0, "seed {seed}: no {counter}: {counters}");
        }
    }
    // Issue #23's target: the look-alike is never the target's estimate, on any seed
    // (`dualgeo run`, 2026-11-28: none on seeds 1–8 of the 24 s flights).
    for seed in 1..=5 {
        let name = format!("suite_traffic-{seed:03}");
        let n = flown.look_alike_estimates(&name);
        assert_eq!(
            n, 0,
            "seed {seed}: {n} of the target's estimates of the look-alike"
        );
    }
}
