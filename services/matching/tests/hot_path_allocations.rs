//! Allocations on the per-frame path in steady state (issue #24 item 4), counted by
//! a counting global allocator (`shared_types::alloc_count`) on a rendered flight of
//! the `default` preset, each stage called as its service calls it:
//!
//! - detection: `TrackedDetector::detect_gated` on each frame;
//! - matching: `Intake::extract` (tracking) and `Intake::next_set` (matching with the
//!   past images from the tracked points, admissions) on each pair, the refreshes on
//!   their own thread (not counted: off the per-frame path);
//! - geolocation: `estimate_message` with the temporal filter on each set.
//!
//! Only the calling thread's Rust allocations are counted (OpenCV's C++ allocations
//! never reach Rust's allocator). Counted after an 8 s warm-up (the rings full, the
//! filter converged), over the next 4 s. The target is none: detection meets it and
//! is held to it; matching and geolocation do not yet, and are held to ceilings (the
//! figures below with a margin) so that the counts can only fall.

#[path = "support/render.rs"]
mod render;

use acquisition::sim::{Presets, Simulator};
use detection::camera_swing::CameraView;
use detection::{ColourBlobConfig, ColourBlobDetector, TrackedDetector};
use geolocation::set_message::estimate_message;
use geolocation::{EstimatorConfig, TemporalEstimator};
use matching::intake::Intake;
use matching::MatchingConfig;
use opencv::prelude::*;
use shared_types::alloc_count::{count_allocations, Allocations, CountingAllocator};
use shared_types::messages::{DetectionMsg, FrameHeader, PixelFormat};
use shared_types::stats::StageStats;

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

const WARM_UP_PAIRS: u64 = 240;
const COUNTED_PAIRS: u64 = 120;

/// Per stage: allocations per call (sorted), and the largest single allocation.
#[derive(Default)]
struct Tally {
    per_call: Vec<u64>,
    bytes: Vec<u64>,
    largest: u64,
}

impl Tally {
    fn add(&mut self, a: Allocations) {
        self.per_call.push(a.count);
        self.bytes.push(a.bytes);
        self.largest = self.largest.max(a.largest);
    }

    fn report(&mut self, stage: &str) -> (u64, u64) {
        self.per_call.sort_unstable();
        self.bytes.sort_unstable();
        let n = self.per_call.len();
        let (median, max) = (self.per_call[n / 2], self.per_call[n - 1]);
        eprintln!(
            "{stage}: {n} calls, allocations per call median {median}, max {max}; bytes median {}, max {}; largest one {} bytes",
            self.bytes[n / 2],
            self.bytes[n - 1],
            self.largest
        );
        (median, max)
    }
}

#[test]
fn the_per_frame_path_allocates_no_more_than_its_ceiling() {
    // The allocator is installed and counts (else every stage would show none).
    let (v, a) = count_allocations(|| vec![7u8; 100]);
    assert_eq!((a.count, a.bytes, v.len()), (1, 100, 100));
    let mut config = Presets::builtin().get("default").unwrap();
    config.duration_s = (WARM_UP_PAIRS + COUNTED_PAIRS) as f64 / 30.0 + 0.5;
    let mut sim = Simulator::new(config).unwrap();
    let mut finder = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
    let mut detector = TrackedDetector::new(ColourBlobConfig::default()).unwrap();
    let estimator = EstimatorConfig::default();
    let mut intake = Intake::new(MatchingConfig::default(), estimator).unwrap();
    intake.chain.refresh_on_thread(true).unwrap();
    let mut temporal = TemporalEstimator::new(estimator).unwrap();
    let mut stats = StageStats::new("geolocation");
    let mut images = render::blank_pair(&sim);
    let [mut detection, mut matching, mut geolocation] = [(); 3].map(|_| Tally::default());
    let mut estimates = 0;
    for k in 0..WARM_UP_PAIRS + COUNTED_PAIRS {
        let Some(step) = sim.step() else { break };
        let lens = sim.distortion();
        let inputs = render::inputs(&mut sim, &step, &mut images, &mut finder, false, lens);
        let counted = k >= WARM_UP_PAIRS;
        let headers = inputs.iter().enumerate().map(|(uav, f)| FrameHeader {
            seq: f.seq,
            capture_ns: 1_000_000 + f.seq * 33_333_333,
            t_s: f.t_s,
            uav: uav as u8,
            pixel_format: PixelFormat::Bgr8 as u32,
            width: f.width,
            height: f.height,
            stride: 3 * f.width,
            pose: f.pose,
            intrinsics: [
                f.intrinsics.fx,
                f.intrinsics.fy,
                f.intrinsics.cx,
                f.intrinsics.cy,
            ],
            distortion: f.distortion.0,
            ..Default::default()
        });
        let headers: Vec<FrameHeader> = headers.collect();
        let mut found = [None, None];
        for uav in 0..2 {
            let image = inputs[uav].image;
            let f = &inputs[uav];
            let view = CameraView::new(&f.pose, f.intrinsics, f.distortion);
            let (d, a) = count_allocations(|| {
                detector.detect_gated(uav, headers[uav].t_s, image, None, view)
            });
            found[uav] = d.unwrap();
            if counted {
                detection.add(a);
            }
        }
        let pixels = [
            images[0].data_bytes().unwrap(),
            images[1].data_bytes().unwrap(),
        ];
        let (set, a) = count_allocations(|| {
            intake.extract([Some((headers[0], pixels[0])), Some((headers[1], pixels[1]))]);
            for (uav, d) in found.iter().enumerate() {
                intake.on_detection(DetectionMsg {
                    seq: headers[uav].seq,
                    uav: uav as u8,
                    found: d.is_some() as u8,
                    centre: d.map_or([0.0; 2], |d| d.centre),
                    ..Default::default()
                });
            }
            intake.next_set()
        });
        if counted {
            matching.add(a);
        }
        let Some(set) = set else { continue };
        let (msg, a) = count_allocations(|| {
            estimate_message(&set, &estimator, Some(&mut temporal), &mut stats)
        });
        if counted {
            geolocation.add(a);
            estimates += (msg.status == 0) as u32;
        }
    }
    assert!(
        estimates as u64 > COUNTED_PAIRS * 3 / 4,
        "{estimates} estimates"
    );
    // (stage, median, max) allocations per call. Detection meets the target (none);
    // matching measured median 69, max 216 (87 KB; the tracker's per-frame point
    // lists, the landing's seeds, the per-pair answer's lists), geolocation 1 070 /
    // 1 600 (2.4 MB: the temporal filter's dynamically sized matrices, built afresh
    // per update, per hypothesis: with the start's tempered weights,
    // `likelihood_temper` 0.3, two hypotheses are still open over these 4 s on this
    // flight, where Bayes' weights had closed the bank to one: 566 / 615).
    // Ceilings: today's figures with about 30 % margin.
    let ceilings = [
        ("detection", 0, 0),
        ("matching", 90, 280),
        ("geolocation", 1400, 2100),
    ];
    for ((stage, median_max, max_max), tally) in
        ceilings
            .into_iter()
            .zip([&mut detection, &mut matching, &mut geolocation])
    {
        let (median, max) = tally.report(stage);
        assert!(
            median <= median_max,
            "{stage}: median {median} allocations per call"
        );
        assert!(max <= max_max, "{stage}: {max} allocations in one call");
    }
}
