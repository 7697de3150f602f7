//! The whole chain in one process: from the current stereo pair (frames, measured
//! poses, detections) and each UAV's keyframe ring to an estimate. It runs
//! corresponding-point matching (Section 2.3), the consistency filter (eq. 29–32) and
//! the altitude/regression iteration (Sections 2.1–2.2). The geolocation service, the
//! tests and the evaluation harness all call [`VisionChain::process`].

mod anchors;
mod fresh_fit;
mod landing;
mod others;
mod past;
mod refresh;
mod target_pair;

use anchors::{Guide, KeyframeId, Prior, PriorKey};
pub use landing::LandingReport;
pub use others::{OtherPixels, OthersOutcome};
use past::{match_past, Job, PastResult};
use refresh::Refresher;
pub use refresh::{RefreshJob, RefreshResult};

use crate::config::MatchingConfig;
use crate::epipolar::MatchReject;
pub use crate::frame::{extract_undistorted, ChainCounts, ChainError, FrameInput, FrameMeta};
use crate::frame_tracking::{FrameTracker, Observed};
use crate::ground_plane::PlaneModel;
use crate::ring::{Keyframe, KeyframeRing};
use geolocation::telemetry_noise::TelemetryNoise;
use geolocation::{
    geolocate, geolocate_filtered, Estimate, EstimatorConfig, EstimatorError, FilteredEstimate,
    Observation,
};
use nalgebra::{Matrix3, Vector2};
use shared_types::conventions::{Intrinsics, Uav};
use shared_types::messages::{PoseNoise, PoseSample};
use std::collections::{BTreeMap, VecDeque};
use std::time::Instant;

/// The observation set of one pair: what the geolocation stage estimates from.
#[derive(Debug, Clone, PartialEq)]
pub struct MatchedSet {
    /// The current left and right images with their detections.
    pub current: [Observation; 2],
    /// Past images that got a corresponding point (same order as `past`).
    pub past_observations: Vec<Observation>,
    pub past: Vec<PastMatch>,
    /// When the pair was mended (`target_pair`): the side, and its detection's ideal
    /// pixel before (another vehicle, which the other-vehicle pairing lists in place
    /// of the candidate taken for the target).
    pub mended: Option<(usize, [f64; 2])>,
}

/// Matching's answer for one pair.
#[derive(Debug)]
pub enum MatchOutcome {
    NoDetection,
    NotEnoughHistory {
        past: [usize; 2],
    },
    Matched(Box<MatchedSet>),
    /// The two current detections are two vehicles and could not be mended
    /// (`chain::target_pair`): no set to estimate from; the current observations, so
    /// that the service can say so downstream (a refused set: the filter coasts).
    TargetPairMismatch(Box<[Observation; 2]>),
    /// A current image has no target detection but both show other vehicles: the
    /// past images fitted without it, for the other vehicles
    /// ([`VisionChain::others_unseen`]).
    TargetUnseen(Box<UnseenSet>),
}

/// A pair without the target in a current image, its past images fitted all the
/// same: `set` has the images (the target's pixels (0, 0), unknown) and every past
/// image whose two fits held (the matches' `pixel` NaN).
#[derive(Debug, Clone, PartialEq)]
pub struct UnseenSet {
    pub set: MatchedSet,
    /// The ground homographies from the current left image to the current right one
    /// through each past image both sides were fitted to (`H_R⁻¹ · H_L`), the most
    /// inliers first (as `ground_homographies` for a matched pair).
    pub left_to_right: Vec<Matrix3<f64>>,
}

/// `H_R⁻¹ · H_L` of each past image with both homographies, the most inliers first
/// ([`most_inliers_first`]).
fn left_to_right_through(fits: Vec<(usize, [Option<Matrix3<f64>>; 2])>) -> Vec<Matrix3<f64>> {
    most_inliers_first(
        fits.into_iter()
            .filter_map(|(inliers, [hl, hr])| Some((inliers, hr?.try_inverse()? * hl?)))
            .collect(),
    )
}

/// The homographies of `all` (inlier count, homography), the most inliers first.
/// Stable, then reversed: of equal counts the last comes first (as `max_by_key`
/// picks), and a replay repeats.
pub(super) fn most_inliers_first(mut all: Vec<(usize, Matrix3<f64>)>) -> Vec<Matrix3<f64>> {
    all.sort_by_key(|(inliers, _)| *inliers);
    all.reverse();
    all.into_iter().map(|(_, h)| h).collect()
}

/// The consistency filter and the iteration on a matched set (filtered), and the
/// iteration on every image (unfiltered, Table 1's "before filtering").
pub fn estimate_matched(set: &MatchedSet, estimator: &EstimatorConfig) -> Located {
    let filtered = geolocate_filtered(
        &set.current[0],
        &set.current[1],
        &set.past_observations,
        estimator,
    );
    let mut all = set.current.to_vec();
    all.extend_from_slice(&set.past_observations);
    let unfiltered = geolocate(&all, estimator);
    Located {
        filtered,
        unfiltered,
        past: set.past.clone(),
    }
}

/// A past image that got a corresponding point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PastMatch {
    pub uav: Uav,
    pub seq: u64,
    /// The past image's capture time, seconds (the stream's clock).
    pub t_s: f64,
    /// p_n: the current target position's pixel in that past image.
    pub pixel: [f64; 2],
    pub inliers: [usize; 2],
    /// F_Ln and F_Rn (x_pastᵀ F x_current = 0): diagnostics, and the transfer of the
    /// other vehicles of the pair into this image (`others.rs`).
    pub fundamental: [nalgebra::Matrix3<f64>; 2],
    /// Which model gave each F (`ground_plane` method only).
    pub models: [Option<PlaneModel>; 2],
    /// The rotation from each current camera (left, right) to this past one, from its
    /// level plane's decomposition (`PairGeometry::rotation`).
    pub rotations: [Option<nalgebra::Matrix3<f64>>; 2],
    /// Whether each side was matched guided by a prior (else brute force).
    pub guided: [bool; 2],
    /// Whether each side's homography was carried by frame-to-frame tracking from an
    /// earlier fit instead of fitted on this frame (`frame_tracking.rs`).
    pub chained: [bool; 2],
}

#[derive(Debug)]
pub enum ChainOutcome {
    /// A current frame had no detection.
    NoDetection,
    /// A ring does not yet hold N − 1 past images far enough apart.
    NotEnoughHistory { past: [usize; 2] },
    /// The past images matched; estimates with and without the consistency filter.
    Located(Box<Located>),
    /// The two current detections are two vehicles (`chain::target_pair`): no set.
    TargetPairMismatch,
}

#[derive(Debug)]
pub struct Located {
    /// The paper's method: consistency filter (eq. 29–32), then the iteration.
    pub filtered: Result<FilteredEstimate, EstimatorError>,
    /// The iteration on every matched image, no filter (Table 1's "before filtering").
    pub unfiltered: Result<Estimate, EstimatorError>,
    pub past: Vec<PastMatch>,
}

/// One timed step of matching a past image (`--trace`): `past` (the whole job),
/// `match` (Hamming matching), `F` (a fundamental-matrix fit) and `transfer` (the
/// epipolar-line intersection), against the keyframe `keyframe` of UAV `uav`, on
/// CLOCK_MONOTONIC.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Step {
    pub name: &'static str,
    pub uav: u8,
    pub keyframe: u64,
    pub start_ns: u64,
    pub end_ns: u64,
}

impl Step {
    /// A step of `uav` and keyframe `keyframe` from `start_ns` to now.
    pub(crate) fn since(name: &'static str, uav: Uav, keyframe: u64, start_ns: u64) -> Self {
        Step {
            name,
            uav: uav.index() as u8,
            keyframe,
            start_ns,
            end_ns: shared_types::clock::monotonic_ns(),
        }
    }
}

/// Wall time of each step on the calling thread, microseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ChainTiming {
    /// ORB (or frame-to-frame tracking) on the current left and right frames, and ORB
    /// run late on a tracked frame the pair turned out to need.
    pub orb_us: f64,
    /// Ratio-tested Hamming matching, current vs past (2 × (2N − 2) matchings).
    pub matching_us: f64,
    /// F_Ln and F_Rn estimation.
    pub fundamental_us: f64,
    /// Epipolar-line intersections.
    pub transfer_us: f64,
    /// Consistency filter and the altitude/regression iteration (filtered estimate only).
    pub estimate_us: f64,
    /// Refreshes run on the calling thread during this pair ([`VisionChain::process`]
    /// without [`VisionChain::refresh_on_thread`]): in the service that is the refresh
    /// thread's work, not the pair's, so it is not in `orb_us` nor in the total.
    pub refresh_us: f64,
}

impl ChainTiming {
    pub fn total_us(&self) -> f64 {
        self.orb_us + self.matching_us + self.fundamental_us + self.transfer_us + self.estimate_us
    }
}

#[derive(Debug)]
pub struct ChainResult {
    pub outcome: ChainOutcome,
    /// Past images that gave no point, with the reason.
    pub rejections: Vec<(Uav, u64, MatchReject)>,
    pub timing: ChainTiming,
}

pub struct VisionChain {
    counts: ChainCounts,
    /// The timed steps of the last `match_current` (for `--trace`).
    steps: Vec<Step>,
    config: MatchingConfig,
    estimator: EstimatorConfig,
    /// Each UAV's frame-to-frame tracker and ORB extractor.
    trackers: [FrameTracker; 2],
    pub(crate) rings: [KeyframeRing; 2],
    /// Each UAV's measured position smoothed over time, (t, position): the baseline
    /// constraint's ruler.
    pub(crate) smoothed: [Option<(f64, nalgebra::Point3<f64>)>; 2],
    /// Guided-matching priors: the last ground homography from each current side to
    /// each keyframe.
    priors: BTreeMap<PriorKey, Prior>,
    /// Past images whose fit failed on a current side's last ORB frame, with the
    /// tracking epoch that frame began and the reason: not retried before the side's
    /// next ORB frame.
    failed: BTreeMap<PriorKey, (u64, MatchReject)>,
    /// Per keyframe (UAV, seq): the ground homographies from it to the past images it
    /// was matched with as a current frame, so that a current frame with a prior for
    /// one of those can be guided to it without brute force.
    links: BTreeMap<KeyframeId, Vec<(KeyframeId, Matrix3<f64>)>>,
    /// ORB and matching of refreshed frames, off the per-pair path (`refresh.rs`).
    refresher: Refresher,
    /// Frames the landed refreshes got admitted to the rings, per UAV, since the last
    /// [`VisionChain::admit`].
    landed_admissions: [bool; 2],
    /// What the last refreshes did ([`VisionChain::take_landings`]).
    landings: VecDeque<LandingReport>,
    /// The stream segment (`FrameHeader::segment`) the trackers and rings are of.
    pub(crate) segment: u32,
    /// The target's residual under the ground homography from the current left image
    /// to the right one on the last pair that had one, px: the shift the other
    /// vehicles are paired with on a pair without the target (`others.rs`).
    last_target_shift: Option<[f64; 2]>,
    /// The white noise of each UAV's pose samples over the frames given to
    /// [`VisionChain::match_current`] (`geolocation::telemetry_noise`; every set
    /// carries it, [`VisionChain::pose_noise`]).
    telemetry: TelemetryNoise,
}

fn micros(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e6
}

impl VisionChain {
    pub fn new(config: MatchingConfig, estimator: EstimatorConfig) -> Result<Self, ChainError> {
        config.validate().map_err(ChainError::Config)?;
        estimator
            .validate()
            .map_err(|e| ChainError::Config(e.to_string()))?;
        let ring = || KeyframeRing::new(config.ring_capacity, config.keyframe_spacing_m);
        Ok(Self {
            counts: ChainCounts::default(),
            steps: Vec::new(),
            trackers: [
                FrameTracker::new(&config, Uav::Left)?,
                FrameTracker::new(&config, Uav::Right)?,
            ],
            rings: [ring(), ring()],
            smoothed: [None, None],
            priors: BTreeMap::new(),
            failed: BTreeMap::new(),
            links: BTreeMap::new(),
            refresher: Refresher::inline(&config)?,
            landed_admissions: [false; 2],
            landings: VecDeque::new(),
            segment: 0,
            last_target_shift: None,
            telemetry: TelemetryNoise::new(),
            config,
            estimator,
        })
    }

    /// The stream segment the chain's state is of.
    pub fn segment(&self) -> u32 {
        self.segment
    }

    /// The stream jumped to `segment` (a looped recording starting over): the
    /// trackers, rings, priors and refreshes start over, as for a new stream. The old
    /// keyframes show a world that is gone: their fits would fail (past images outside
    /// the image) or, worse, pair the target with whatever lies there. A refresh in
    /// flight is waited for and dropped; the refresh thread and the buffers stay.
    /// Counts not yet taken are kept. Every field that holds what was seen is
    /// emptied here: `e2e_pipeline`'s second pass repeating the first byte for byte
    /// checks that none is forgotten.
    pub fn start_over(&mut self, segment: u32) -> Result<(), ChainError> {
        self.refresher.start_over()?;
        for tracker in &mut self.trackers {
            tracker.start_over();
        }
        self.rings = [(); 2]
            .map(|_| KeyframeRing::new(self.config.ring_capacity, self.config.keyframe_spacing_m));
        self.smoothed = [None, None];
        self.telemetry = TelemetryNoise::new();
        self.priors.clear();
        self.failed.clear();
        self.links.clear();
        self.steps.clear();
        self.landed_admissions = [false; 2];
        self.landings.clear();
        self.last_target_shift = None;
        self.segment = segment;
        Ok(())
    }

    /// Runs the refreshes on a thread of their own (the service); `fixed`: they land
    /// on the frame `refresh_landing_frames` after theirs, waiting if late (a replay at
    /// `--rate max`, which then repeats exactly), else on the first frame after they
    /// finish (live). Without this call they run on the calling thread and land as
    /// with `fixed` (the evaluation, tests).
    pub fn refresh_on_thread(&mut self, fixed: bool) -> Result<(), ChainError> {
        self.refresher.start_thread(&self.config, fixed)
    }

    pub fn rings(&self) -> &[KeyframeRing; 2] {
        &self.rings
    }

    /// The trackers, for a caller that observes both UAVs' frames on two threads
    /// (call [`VisionChain::before_frame`] for both before and
    /// [`VisionChain::after_observe`] for both after, as
    /// [`VisionChain::observe_pair`] does).
    pub fn trackers_mut(&mut self) -> &mut [FrameTracker; 2] {
        &mut self.trackers
    }

    /// The smoothed position `track` would give `uav` at this frame.
    fn predicted_baseline(
        &self,
        uav: Uav,
        t_s: f64,
        p: nalgebra::Point3<f64>,
    ) -> nalgebra::Point3<f64> {
        smoothed_next(
            self.smoothed[uav.index()],
            t_s,
            p,
            self.config.baseline_smoothing_s,
        )
        .1
    }

    /// Adds counts from work done outside the chain (the service's second ORB thread).
    pub fn add_counts(&mut self, c: &ChainCounts) {
        self.counts += *c;
    }

    /// The timed steps of the last past-image matching (`--trace`).
    pub fn steps(&self) -> &[Step] {
        &self.steps
    }

    /// The counts since the last call, and zero.
    pub fn take_counts(&mut self) -> ChainCounts {
        std::mem::take(&mut self.counts)
    }

    /// Locates the target of the current pair, then offers both frames to the rings.
    pub fn process(
        &mut self,
        left: &FrameInput,
        right: &FrameInput,
    ) -> Result<ChainResult, ChainError> {
        let mut timing = ChainTiming::default();
        let t = Instant::now();
        let [(l, _), (r, _)] = self.observe_pair([left, right])?;
        let mut observed = [l, r];
        timing.refresh_us = self.refresher.take_inline_us();
        timing.orb_us = (micros(t) - timing.refresh_us).max(0.0);
        let (left, right) = (left.meta(), right.meta());
        let mut rejections = Vec::new();
        let matched =
            self.match_current([&left, &right], &mut observed, &mut timing, &mut rejections)?;
        let outcome = match matched {
            MatchOutcome::NoDetection | MatchOutcome::TargetUnseen(_) => ChainOutcome::NoDetection,
            MatchOutcome::NotEnoughHistory { past } => ChainOutcome::NotEnoughHistory { past },
            MatchOutcome::TargetPairMismatch(_) => ChainOutcome::TargetPairMismatch,
            MatchOutcome::Matched(set) => {
                let t = Instant::now();
                let located = estimate_matched(&set, &self.estimator);
                timing.estimate_us = micros(t);
                ChainOutcome::Located(Box::new(located))
            }
        };
        self.admit([&left, &right], &mut observed)?;
        Ok(ChainResult {
            outcome,
            rejections,
            timing,
        })
    }

    /// Updates each UAV's smoothed position with the current pair. GPS noise (σ 3 m per
    /// axis) would otherwise decide which frames count as T_re apart: the difference of
    /// two raw fixes has σ ≈ 4 m per axis against T_re = 8 m. An exponential average
    /// with time constant `baseline_smoothing_s` cuts that to ~1 m. Its lag is the same
    /// for every frame, so distances between smoothed positions stay right.
    /// Both UAVs' pose-sample noise up to the last pair matched (as each set carries
    /// it: `chords` 0 where not measured yet).
    pub fn pose_noise(&self) -> [PoseNoise; 2] {
        self.telemetry.to_msg()
    }

    fn track(&mut self, frames: [&FrameMeta; 2]) {
        let tau = self.config.baseline_smoothing_s;
        for uav in [Uav::Left, Uav::Right] {
            let f = frames[uav.index()];
            self.telemetry.add(uav, f.t_s, &f.pose);
            let slot = &mut self.smoothed[uav.index()];
            *slot = Some(smoothed_next(*slot, f.t_s, f.pose.position(), tau));
        }
    }

    fn baseline_position(&self, uav: Uav, frame: &FrameMeta) -> nalgebra::Point3<f64> {
        self.smoothed[uav.index()].map_or(frame.pose.position(), |(_, p)| p)
    }

    /// Offers the current pair to the keyframe rings (the baseline constraint decides)
    /// when it has ORB features (tracking off; while tracking, a refresh admits frames
    /// when it lands). Returns, per UAV, whether a frame was admitted since the last
    /// call, by either.
    pub fn admit(
        &mut self,
        frames: [&FrameMeta; 2],
        observed: &mut [Observed; 2],
    ) -> Result<[bool; 2], ChainError> {
        let mut admitted = std::mem::take(&mut self.landed_admissions);
        for uav in [Uav::Left, Uav::Right] {
            let frame = frames[uav.index()];
            let Some(features) = observed[uav.index()].features.clone() else {
                continue;
            };
            let baseline_position = self.baseline_position(uav, frame);
            if !self.rings[uav.index()].would_admit(&baseline_position) {
                continue;
            }
            // The ground homographies fitted on this very frame: its links.
            let links: Vec<(KeyframeId, Matrix3<f64>)> = self
                .priors
                .iter()
                .filter(|((side, _, _), p)| *side == uav.index() && p.t_s == frame.t_s)
                .map(|((_, kf_uav, kf_seq), p)| ((*kf_uav, *kf_seq), p.homography))
                .collect();
            if !links.is_empty() {
                self.links.insert((uav.index(), frame.seq), links);
            }
            admitted[uav.index()] |= self.rings[uav.index()].offer(Keyframe {
                seq: frame.seq,
                t_s: frame.t_s,
                pose: frame.pose,
                baseline_position,
                intrinsics: frame.intrinsics,
                distortion: frame.distortion,
                width: frame.width,
                height: frame.height,
                features,
            });
        }
        Ok(admitted)
    }

    /// Section 2.3 for the current pair: the corresponding point of the current target
    /// in each selected past image. Adds the matching, F/E and transfer times to
    /// `timing` and every rejected past image to `rejections`.
    pub fn match_current(
        &mut self,
        current: [&FrameMeta; 2],
        observed: &mut [Observed; 2],
        timing: &mut ChainTiming,
        rejections: &mut Vec<(Uav, u64, MatchReject)>,
    ) -> Result<MatchOutcome, ChainError> {
        self.steps.clear();
        self.track(current);
        // The detector works on the recorded pixels; the geometry needs the ideal
        // pinhole ones (the keypoints were undistorted the same way).
        let undistorted = |f: &FrameMeta| {
            let [u, v] = f.detection?;
            f.distortion.undistort_pixel(&f.intrinsics, u, v)
        };
        let detections = match (undistorted(current[0]), undistorted(current[1])) {
            (Some(pl), Some(pr)) => Some([pl, pr]),
            _ => {
                let lost = current
                    .iter()
                    .filter(|f| f.detection.is_some() && undistorted(f).is_none())
                    .count();
                self.counts.detections_outside_lens += lost as u64;
                // Without the target the past images are still fitted when both
                // current images show other vehicles: they are located through them
                // (`TargetUnseen`).
                let others_on_both = current.iter().all(|f| !f.others.as_slice().is_empty());
                if !(self.config.others_when_unseen && others_on_both) {
                    return Ok(MatchOutcome::NoDetection);
                }
                None
            }
        };
        let wanted = self.config.images_per_uav - 1;
        let positions =
            [Uav::Left, Uav::Right].map(|uav| self.baseline_position(uav, current[uav.index()]));
        let rings = &self.rings;
        let selected: [Vec<&Keyframe>; 2] = [Uav::Left, Uav::Right].map(|uav| {
            let frame = current[uav.index()];
            rings[uav.index()].select(&positions[uav.index()], frame.seq, wanted)
        });
        // Warming up: matched once every UAV has `min_past_images` of them.
        if selected
            .iter()
            .any(|s| s.len() < self.config.past_images_needed())
        {
            if detections.is_none() {
                return Ok(MatchOutcome::NoDetection);
            }
            return Ok(MatchOutcome::NotEnoughHistory {
                past: [selected[0].len(), selected[1].len()],
            });
        }

        let observation =
            |uav: Uav, pose: &PoseSample, pixel: [f64; 2], intrinsics: Intrinsics| Observation {
                uav,
                position: pose.position(),
                attitude: pose.attitude(),
                mount: pose.mount.mount(),
                pixel: Vector2::new(pixel[0], pixel[1]),
                intrinsics,
            };
        // Without the target its pixels are unknown: (0, 0), never read
        // (`TargetUnseen`).
        let pixels = detections.unwrap_or([[0.0; 2]; 2]);
        let current_obs = [Uav::Left, Uav::Right].map(|uav| {
            let f = current[uav.index()];
            observation(uav, &f.pose, pixels[uav.index()], f.intrinsics)
        });

        // Every selected past image is independent: split them over
        // `match_threads` threads, keep their order.
        let jobs: Vec<(Uav, &Keyframe)> = [Uav::Left, Uav::Right]
            .into_iter()
            .flat_map(|uav| selected[uav.index()].iter().map(move |kf| (uav, *kf)))
            .collect();
        let metas = [*current[0], *current[1]];
        let guides: Vec<[Guide; 2]> = jobs
            .iter()
            .map(|(uav, kf)| {
                [0, 1].map(|side| {
                    self.guide(
                        side,
                        *uav,
                        kf.seq,
                        &metas[side],
                        observed[side].motion.as_ref(),
                    )
                })
            })
            .collect();
        let features = [observed[0].features.clone(), observed[1].features.clone()];
        let config = &self.config;
        let features = &features;
        let run = |chunk: &[Job]| -> Vec<PastResult> {
            let mut neighbours = Vec::with_capacity(config.orb_features as usize);
            chunk
                .iter()
                .map(|((uav, kf), prior)| {
                    // Same fit, same draws, whichever pool thread runs it.
                    if let Err(e) = crate::robust_fit::seed_cv_rng(&[
                        uav.index() as u64,
                        kf.seq,
                        metas[0].seq,
                        metas[1].seq,
                    ]) {
                        tracing::warn!("cv RNG not seeded: {e}");
                    }
                    match_past(
                        config,
                        *uav,
                        kf,
                        &metas,
                        detections,
                        features,
                        prior,
                        &mut neighbours,
                    )
                })
                .collect()
        };
        let work: Vec<_> = jobs.iter().copied().zip(guides).collect();
        let threads = self.config.match_threads.clamp(1, work.len().max(1));
        let per_thread = work.len().div_ceil(threads);
        let results: Vec<PastResult> = if threads > 1 {
            // On rayon's persistent pool, never a thread per call: OpenCV keeps
            // per-thread data of every thread that called it (issue #13's leak).
            let chunks: Vec<&[_]> = work.chunks(per_thread).collect();
            let mut parts: Vec<Vec<PastResult>> = chunks.iter().map(|_| Vec::new()).collect();
            let run = &run;
            rayon::in_place_scope(|scope| {
                let (first, rest) = parts.split_at_mut(1);
                for (slot, chunk) in rest.iter_mut().zip(&chunks[1..]) {
                    scope.spawn(move |_| *slot = run(chunk));
                }
                if let (Some(slot), Some(chunk)) = (first.first_mut(), chunks.first()) {
                    *slot = run(chunk);
                }
            });
            parts.into_iter().flatten().collect()
        } else {
            run(&work)
        };

        let mut past = Vec::new();
        let mut past_obs = Vec::new();
        let mut new_priors: Vec<(PriorKey, f64, Matrix3<f64>)> = Vec::new();
        // Without the target: each fitted past image's (fewer side's inliers, both
        // sides' ground homographies), for pairing the other vehicles.
        let mut unseen_ground: Vec<(usize, [Option<Matrix3<f64>>; 2])> = Vec::new();
        let mut counts = ChainCounts::default();
        let mut steps = Vec::new();
        for ((uav, kf), r) in jobs.iter().zip(results) {
            steps.extend_from_slice(&r.steps);
            let retried = r.retried.iter().filter(|x| **x).count() as u64;
            counts.retried_looser_ratio += retried;
            if r.result.is_ok() {
                counts.retry_rescued += retried;
            }
            let t = r.timing;
            timing.matching_us += t.matching_us;
            timing.fundamental_us += t.fundamental_us;
            timing.transfer_us += t.transfer_us;
            // A side without a new homography (a failed fit) keeps its old prior, which
            // ages out; a tracked side keeps its anchor.
            for (side, h) in r.homographies.iter().enumerate() {
                if let Some(homography) = h {
                    let key = (side, uav.index(), kf.seq);
                    new_priors.push((key, metas[side].t_s, *homography));
                }
            }
            if let Ok(m) = &r.result {
                counts.chained_sides += m.chained.iter().filter(|c| **c).count() as u64;
            }
            match r.result {
                Ok(m) => {
                    let pixel = if detections.is_some() {
                        m.pixel
                    } else {
                        [0.0; 2]
                    };
                    past_obs.push(observation(*uav, &kf.pose, pixel, kf.intrinsics));
                    if detections.is_none() {
                        unseen_ground.push((m.inliers[0].min(m.inliers[1]), r.homographies));
                    }
                    past.push(m);
                }
                Err(reason) => rejections.push((*uav, kf.seq, reason)),
            }
        }

        self.counts += counts;
        self.steps = steps;
        // A pair without the target leaves the priors as they were, so that the
        // target's own matching after it is what it was without such pairs.
        if detections.is_none() {
            new_priors.clear();
        }
        for (key, t_s, homography) in new_priors {
            self.priors
                .entry(key)
                .and_modify(|p| {
                    p.t_s = t_s;
                    p.homography = homography;
                })
                .or_insert_with(|| Prior::new(t_s, homography));
        }
        // Forget keyframes the rings have evicted.
        let rings = &self.rings;
        self.priors
            .retain(|&(_, uav, seq), _| rings[uav].iter().any(|kf| kf.seq == seq));
        self.failed
            .retain(|&(_, uav, seq), _| rings[uav].iter().any(|kf| kf.seq == seq));
        self.links
            .retain(|&(uav, seq), _| rings[uav].iter().any(|kf| kf.seq == seq));

        let mut set = MatchedSet {
            current: current_obs,
            past_observations: past_obs,
            past,
            mended: None,
        };
        if detections.is_none() {
            return Ok(MatchOutcome::TargetUnseen(Box::new(UnseenSet {
                left_to_right: left_to_right_through(unseen_ground),
                set,
            })));
        }
        if self.config.target_pair_gate_mrad > 0.0 {
            match self.check_target_pair(current, &mut set) {
                target_pair::PairCheck::Consistent => {}
                target_pair::PairCheck::Unchecked => self.counts.target_pair_unchecked += 1,
                target_pair::PairCheck::Repaired { past_dropped, .. } => {
                    self.counts.target_pair_repaired += 1;
                    self.counts.target_pair_past_dropped += past_dropped as u64;
                }
                target_pair::PairCheck::Mismatch => {
                    self.counts.target_pair_mismatch += 1;
                    return Ok(MatchOutcome::TargetPairMismatch(Box::new(set.current)));
                }
            }
        }
        Ok(MatchOutcome::Matched(Box::new(set)))
    }
}

/// One step of the exponential smoothing of a UAV's measured position (see
/// `VisionChain::track`): the slot after a frame at `t_s` measured at `p`.
fn smoothed_next(
    slot: Option<(f64, nalgebra::Point3<f64>)>,
    t_s: f64,
    p: nalgebra::Point3<f64>,
    tau: f64,
) -> (f64, nalgebra::Point3<f64>) {
    match slot {
        Some((t0, s)) if t_s > t0 && tau > 0.0 => {
            let a = 1.0 - (-(t_s - t0) / tau).exp();
            (t_s, s + (p - s) * a)
        }
        Some((t0, s)) if t_s <= t0 && t_s > t0 - 1.0 => (t0, s),
        _ => (t_s, p),
    }
}
