//! The refresh thread (issue #24): keyframe work moved off the per-pair path must not
//! change what a replay at `--rate max` gives. The same rendered frames go through a
//! chain whose refreshes run on the calling thread (the evaluation's) and through one
//! whose refreshes run on their own thread and land on fixed frames (the service's at
//! `--rate max`): every pair's past points must be bit-identical, refreshes must land
//! exactly `refresh_landing_frames` after their frame, and pairs must be located.

#[path = "support/render.rs"]
mod render;

use acquisition::sim::{Presets, Simulator};
use detection::{ColourBlobConfig, ColourBlobDetector};
use geolocation::EstimatorConfig;
use matching::{ChainOutcome, MatchingConfig, VisionChain};

/// Per pair: the past points (UAV, keyframe seq, pixel bits), or `None` if the pair
/// was not located; and the landings (UAV, frame taken on, frame landed on).
type Answers = (Vec<Option<Vec<(u8, u64, [u64; 2])>>>, Vec<(u8, u64, u64)>);

fn run(on_thread: bool, pairs: u64) -> Answers {
    let mut config = Presets::builtin().get("default").unwrap();
    config.duration_s = pairs as f64 / 30.0 + 0.5;
    let mut sim = Simulator::new(config).unwrap();
    let mut detector = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
    let mut chain =
        VisionChain::new(MatchingConfig::default(), EstimatorConfig::default()).expect("chain");
    if on_thread {
        chain.refresh_on_thread(true).expect("refresh thread");
    }
    let mut images = render::blank_pair(&sim);
    let (mut answers, mut landings) = (Vec::new(), Vec::new());
    for _ in 0..pairs {
        let Some(step) = sim.step() else { break };
        let lens = sim.distortion();
        let inputs = render::inputs(&mut sim, &step, &mut images, &mut detector, false, lens);
        let result = chain.process(&inputs[0], &inputs[1]).expect("chain");
        answers.push(match result.outcome {
            ChainOutcome::Located(l) => Some(
                l.past
                    .iter()
                    .map(|m| {
                        let bits = [m.pixel[0].to_bits(), m.pixel[1].to_bits()];
                        (m.uav.index() as u8, m.seq, bits)
                    })
                    .collect(),
            ),
            _ => None,
        });
        for l in chain.take_landings() {
            landings.push((l.uav.index() as u8, l.taken_seq, l.landed_seq));
        }
    }
    (answers, landings)
}

#[test]
fn refreshes_on_their_own_thread_give_a_replay_the_same_answers() {
    let pairs = 240;
    let (inline, inline_landings) = run(false, pairs);
    let (threaded, threaded_landings) = run(true, pairs);
    let located = inline.iter().filter(|a| a.is_some()).count();
    let points: usize = inline.iter().flatten().map(Vec::len).sum();
    eprintln!(
        "{located} of {pairs} pairs located, {points} past points, {} refreshes",
        inline_landings.len()
    );
    assert!(located > pairs as usize / 2, "{located} of {pairs} located");
    assert!(points > located * 4, "{points} past points");
    let landing_frames = MatchingConfig::default().refresh_landing_frames as u64;
    assert!(
        inline_landings
            .iter()
            .all(|(_, taken, landed)| landed - taken == landing_frames),
        "every refresh lands {landing_frames} frames late: {inline_landings:?}"
    );
    assert_eq!(inline_landings, threaded_landings);
    for (i, (a, b)) in inline.iter().zip(&threaded).enumerate() {
        assert_eq!(a, b, "pair {i}");
    }
}
