//! The chain on rendered frames of the `table1` scenario (no navigation noise).
//! Truth is read by the test only.

#[path = "support/render.rs"]
mod render;

use acquisition::sim::{Presets, SimFrame, Simulator};
use detection::{ColourBlobConfig, ColourBlobDetector};
use geolocation::EstimatorConfig;
use matching::{ChainOutcome, MatchingConfig, VisionChain};
use nalgebra::Point3;
use std::collections::HashMap;

/// What one run of the chain over the first 16 s of `table1` gave.
struct Transfer {
    located: usize,
    /// Transfer errors against the true projection, sorted (px).
    errors: Vec<f64>,
    /// The same through the true F's, sorted (px).
    true_f_errors: Vec<f64>,
    /// 3-D errors of the filtered estimates, sorted (m).
    position_errors: Vec<f64>,
    /// Past points whose two sides were both carried by tracking.
    chained: usize,
    /// Past-point sides matched by brute force (no guide).
    brute_force: usize,
    /// The first located pair with past points of both UAVs (its step) and its past
    /// images per UAV.
    first: Option<(u64, [usize; 2])>,
}

impl Transfer {
    fn median(v: &[f64]) -> f64 {
        v[v.len() / 2]
    }
    fn p90(v: &[f64]) -> f64 {
        v[v.len() * 9 / 10]
    }
}

/// The chain with `matching` on every `every`-th pair of the first 16 s of `table1`.
fn run(matching: MatchingConfig, every: u64) -> Transfer {
    let config = Presets::builtin().get("table1").unwrap();
    let mut sim = Simulator::new(config.clone()).unwrap();
    let mut detector = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
    let mut chain = VisionChain::new(matching, EstimatorConfig::default()).unwrap();
    let mut chained = 0;
    let mut brute_force = 0;
    let mut first = None;
    let mut images = render::blank_pair(&sim);
    let mut history: HashMap<(usize, u64), SimFrame> = HashMap::new();
    let (mut errors, mut located, mut position_errors, mut true_f_errors) =
        (Vec::new(), 0, Vec::new(), Vec::new());
    let mut k = 0u64;
    while let Some(step) = sim.step() {
        k += 1;
        if !k.is_multiple_of(every) || k > 480 {
            continue;
        }
        for frame in &step.frames {
            history.insert((frame.uav.index(), frame.seq), *frame);
        }
        let lens = sim.distortion();
        let inputs = render::inputs(&mut sim, &step, &mut images, &mut detector, false, lens);
        let result = chain.process(&inputs[0], &inputs[1]).unwrap();
        if let ChainOutcome::Located(located_target) = result.outcome {
            let matching::Located { past, filtered, .. } = *located_target;
            located += 1;
            let per_uav = [0, 1].map(|i| past.iter().filter(|m| m.uav.index() == i).count());
            if first.is_none() && per_uav.iter().all(|n| *n > 0) {
                first = Some((k, per_uav));
            }
            let target = Point3::from(step.frames[0].target);
            for m in past {
                chained += m.chained.iter().all(|c| *c) as usize;
                brute_force += (0..2).filter(|&s| !m.chained[s] && !m.guided[s]).count();
                let then = history[&(m.uav.index(), m.seq)];
                let truth = then.view.project(&target).unwrap();
                let e = ((m.pixel[0] - truth[0]).powi(2) + (m.pixel[1] - truth[1]).powi(2)).sqrt();
                // The transfer through the *true* F's isolates the method from F estimation.
                let det = [inputs[0].detection.unwrap(), inputs[1].detection.unwrap()];
                let (fl, fr) = (
                    step.frames[0].view.fundamental_to(&then.view).unwrap(),
                    step.frames[1].view.fundamental_to(&then.view).unwrap(),
                );
                let loose = MatchingConfig {
                    min_line_angle_deg: 0.0,
                    border_px: -1e9,
                    ..Default::default()
                };
                let bounds = matching::epipolar::ImageBounds {
                    intrinsics: &sim.intrinsics(),
                    distortion: &shared_types::lens::Distortion::NONE,
                    width: 640,
                    height: 480,
                };
                if let Ok(p) =
                    matching::epipolar::transfer_point(&fl, det[0], &fr, det[1], &bounds, &loose)
                {
                    true_f_errors
                        .push(((p[0] - truth[0]).powi(2) + (p[1] - truth[1]).powi(2)).sqrt());
                }
                errors.push(e);
            }
            if let Ok(f) = filtered {
                position_errors.push((f.estimate.position - target).norm());
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    position_errors.sort_by(f64::total_cmp);
    true_f_errors.sort_by(f64::total_cmp);
    Transfer {
        located,
        errors,
        true_f_errors,
        position_errors,
        chained,
        brute_force,
        first,
    }
}

fn report(label: &str, t: &Transfer) {
    eprintln!(
        "{label}: {} geolocations, {} past points ({} carried by tracking, {} sides by brute force): transfer error median {:.3} px (through the true F: {:.3} px), p90 {:.3} px; 3-D error median {:.3} m",
        t.located,
        t.errors.len(),
        t.chained,
        t.brute_force,
        Transfer::median(&t.errors),
        Transfer::median(&t.true_f_errors),
        Transfer::p90(&t.errors),
        Transfer::median(&t.position_errors),
    );
}

#[test]
fn epipolar_transfer_lands_on_the_current_target_in_past_images() {
    let t = run(MatchingConfig::default(), 4);
    report("default (tracking between ORB frames), every 4th pair", &t);
    assert!(t.located >= 60, "only {} geolocations", t.located);
    // The method itself is exact: through the true F's the point lands on the truth.
    let true_f_median = Transfer::median(&t.true_f_errors);
    assert!(
        true_f_median < 0.5,
        "transfer through the true F: median {true_f_median} px"
    );
    // Issue #4's target: a median of 1.5 px with the estimated F's. Measured 0.48 px
    // with the default `ground_plane` F and guided matching (docs/matching.md); the
    // 5-point E measured 4.2 px here.
    let median = Transfer::median(&t.errors);
    assert!(median <= 1.5, "median transfer error {median} px");
    // 4 frames apart, with `track_refresh_frames` = 6, nearly every pair is a
    // refresh: this run measures the ORB path; the next test the tracked one.
}

/// Issue #15: tracking between ORB frames must not cost transfer accuracy. The same
/// pairs, every 2nd, with tracking and with ORB plus a fresh fit on every frame.
#[test]
fn tracking_between_orb_frames_keeps_the_transfer_accuracy() {
    let tracked = run(MatchingConfig::default(), 2);
    let fresh = run(
        MatchingConfig {
            track_between_orb: false,
            ..MatchingConfig::default()
        },
        2,
    );
    report("tracking, every 2nd pair", &tracked);
    report("ORB and a fresh fit on every frame, every 2nd pair", &fresh);
    assert_eq!(fresh.chained, 0);
    assert!(tracked.chained > 0);
    let (a, b) = (
        Transfer::median(&tracked.errors),
        Transfer::median(&fresh.errors),
    );
    assert!(
        a <= 1.25 * b + 0.05,
        "tracking: median {a:.3} px against {b:.3} px"
    );
    // A newly selected keyframe is guided through a past image both were matched
    // with: brute force is the exception (the first matchings after warm-up).
    assert!(
        tracked.brute_force * 20 < 2 * tracked.errors.len(),
        "{} brute-force sides of {} past points",
        tracked.brute_force,
        tracked.errors.len()
    );
    assert!(
        tracked.located as f64 >= 0.9 * fresh.located as f64,
        "{} against {} geolocations",
        tracked.located,
        fresh.located
    );
}

/// While the ring is short of the N − 1 past images per UAV the baseline constraint
/// selects, a pair is matched with `min_past_images` of them: the first set comes
/// sooner, carries fewer, and its transfers are as good.
#[test]
fn a_short_ring_is_matched_with_min_past_images() {
    let with = |min_past_images| MatchingConfig {
        min_past_images,
        ..MatchingConfig::default()
    };
    let full = run(with(3), 2);
    let short = run(with(1), 2);
    report("three past images per UAV from the first set", &full);
    report("one past image per UAV from the first set", &short);
    let (Some((k_full, n_full)), Some((k_short, n_short))) = (full.first, short.first) else {
        panic!("no set located");
    };
    eprintln!("first set: step {k_full} with {n_full:?} past images, against step {k_short} with {n_short:?}");
    assert_eq!(n_full, [3, 3]);
    assert!(n_short.iter().all(|n| (1..3).contains(n)), "{n_short:?}");
    assert!(k_short < k_full, "step {k_short} against {k_full}");
    assert!(short.located > full.located);
    let median = Transfer::median(&short.errors);
    assert!(median <= 1.5, "median transfer error {median} px");
}

/// A pair whose target a camera did not find (under a bridge) still carries the other
/// vehicles into its past images (`MatchOutcome::TargetUnseen`, `others_unseen`): on
/// every 8th pair of `table1` after the warm-up the target's detections are withheld
/// and given as another vehicle's in both images instead; it is paired across the
/// views and its transfers land on its true projections in the past images as the
/// target's own do.
#[test]
fn a_pair_without_the_target_carries_the_other_vehicles_into_its_past_images() {
    use matching::MatchOutcome;
    use shared_types::messages::{Candidate, DetectionMsg};
    let config = Presets::builtin().get("table1").unwrap();
    let mut sim = Simulator::new(config.clone()).unwrap();
    let mut detector = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
    let mut chain =
        VisionChain::new(MatchingConfig::default(), EstimatorConfig::default()).unwrap();
    let mut images = render::blank_pair(&sim);
    let mut history: HashMap<(usize, u64), SimFrame> = HashMap::new();
    let (mut unseen, mut paired, mut errors) = (0, 0, Vec::new());
    let mut k = 0u64;
    while let Some(step) = sim.step() {
        k += 1;
        if !k.is_multiple_of(2) || k > 480 {
            continue;
        }
        for frame in &step.frames {
            history.insert((frame.uav.index(), frame.seq), *frame);
        }
        let lens = sim.distortion();
        let inputs = render::inputs(&mut sim, &step, &mut images, &mut detector, false, lens);
        let [(l, _), (r, _)] = chain.observe_pair([&inputs[0], &inputs[1]]).unwrap();
        let mut observed = [l, r];
        let mut metas = [inputs[0].meta(), inputs[1].meta()];
        let hide = k > 160 && k.is_multiple_of(16);
        if hide {
            for meta in &mut metas {
                let Some(centre) = meta.detection.take() else {
                    continue;
                };
                let mut d = DetectionMsg::default();
                d.candidates[0] = Candidate {
                    centre,
                    bbox: [centre[0] - 8.0, centre[1] - 8.0, 16.0, 16.0],
                    bgr: [30, 30, 200],
                    ..Candidate::default()
                };
                d.candidate_count = 1;
                meta.others = matching::frame::Others::of(&d);
            }
        }
        let mut timing = matching::ChainTiming::default();
        let outcome = chain
            .match_current(
                [&metas[0], &metas[1]],
                &mut observed,
                &mut timing,
                &mut Vec::new(),
            )
            .unwrap();
        match outcome {
            MatchOutcome::Matched(set) => {
                assert!(!hide);
                chain.others([&metas[0], &metas[1]], &set);
            }
            MatchOutcome::TargetUnseen(u) => {
                assert!(hide);
                unseen += 1;
                assert!(u.set.past.iter().all(|m| m.pixel[0].is_nan()));
                let out = chain.others_unseen([&metas[0], &metas[1]], &u);
                let target = Point3::from(step.frames[0].target);
                for other in &out.targets {
                    paired += 1;
                    for (m, p) in u.set.past.iter().zip(&other.past) {
                        let Some(p) = p else { continue };
                        let truth = history[&(m.uav.index(), m.seq)]
                            .view
                            .project(&target)
                            .unwrap();
                        errors.push(((p[0] - truth[0]).powi(2) + (p[1] - truth[1]).powi(2)).sqrt());
                    }
                }
            }
            _ => assert!(!hide || k < 200, "pair {k}"),
        }
        chain.admit([&metas[0], &metas[1]], &mut observed).unwrap();
    }
    errors.sort_by(f64::total_cmp);
    eprintln!(
        "{unseen} pairs without the target, {paired} vehicles paired, {} past points: median {:.3} px",
        errors.len(),
        errors.get(errors.len() / 2).copied().unwrap_or(f64::NAN)
    );
    assert!(unseen >= 15, "{unseen} pairs without the target");
    // Paired as another vehicle on nearly every such pair (19 of 20 measured).
    assert!(paired * 10 >= unseen * 9, "{paired} of {unseen} paired");
    assert!(errors.len() >= 4 * paired, "{} past points", errors.len());
    let median = errors[errors.len() / 2];
    assert!(median <= 1.5, "median transfer error {median} px");
}
