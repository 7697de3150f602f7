//! End-to-end: after the bridge, the target's estimate stays on the target
//! (issues #26 and #23). `suite_traffic` flown as the multi-target evaluation flies its
//! seeds 1–5 for 20 s, through the real processes (`dualgeo evaluate --multi-target`
//! runs `dualgeo simulate`'s renderer, `dualgeo run` and `dualgeo score`).
//!
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

#[path = "support/multi_target_eval.rs"]
mod multi_target_eval;
#[path = "support/scratch.rs"]
mod scratch;

use multi_target_eval::fly;
use scratch::Scratch;

#[test]
fn the_targets_estimate_stays_on_the_target_after_the_bridge() {
    let dir = Scratch::new("bridge-swap");
    let flown = fly(&dir, "suite_traffic", 5, 20.0);
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
