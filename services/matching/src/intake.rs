//! The matching service's intake, without the transport: frames (a header and the
//! pixels, as they lie in shared memory) and detections arrive in any order, a pair is
//! complete when both frames have features and both detections are in, and the newest
//! complete pair is matched against the keyframe rings into an [`ObservationSetMsg`].
//! Every header field is untrusted (the fuzz target `frames` feeds it arbitrary bytes):
//! a bad frame or detection is counted and dropped.
//!
//! The service shell (`main.rs`) receives the samples, calls [`Intake::extract`] with
//! plain `(header, bytes)` views, [`Intake::on_detection`] per detection and
//! [`Intake::next_set`] until it returns `None`.

use crate::chain::{MatchOutcome, MatchedSet, OthersOutcome};
use crate::frame::{ChainCounts, FrameInput, FrameMeta, Others};
use crate::frame_tracking::{FrameTracker, Observed, TrackReport};
use crate::ring_store::RingStore;
use crate::set_message::{matched_set, refused_set, unseen_set, unseen_set_with_others, SetHeader};
use crate::{ChainTiming, MatchingConfig, VisionChain};
use anyhow::Result;
use detection::frame_view::frame_mat;
use geolocation::EstimatorConfig;
use shared_types::clock::{elapsed_us, monotonic_ns};
use shared_types::conventions::{Intrinsics, Uav};
use shared_types::deadline::{Deadlines, Verdict};
use shared_types::lens::Distortion;
use shared_types::messages::{DetectionMsg, FrameHeader, ObservationSetMsg, MAX_OBSERVATIONS};
use shared_types::stats::StageStats;
use shared_types::trace::Tracer;
use std::collections::BTreeMap;

/// Pairs older than this many sequence numbers behind the newest are abandoned.
const MAX_PENDING_PAIRS: u64 = 4;

/// A frame's header and its pixels, borrowed from a shared-memory sample.
pub type FrameView<'a> = (FrameHeader, &'a [u8]);

#[derive(Default)]
struct Pending {
    frames: [Option<(FrameHeader, Observed)>; 2],
    detections: [Option<DetectionMsg>; 2],
    orb_us: u64,
}

pub struct Intake {
    /// Left frames finished with (processed, dropped or lost), not yet acknowledged to
    /// acquisition: one acknowledgement per pair, for `--rate max` flow control.
    pub acks: u64,
    pub chain: VisionChain,
    pending: BTreeMap<u64, Pending>,
    pub stats: StageStats,
    /// Per-frame spans (`--trace`; off by default).
    pub trace: Tracer,
    /// Where the rings are checkpointed, and what was admitted since the last save.
    store: Option<RingStore>,
    unsaved: [bool; 2],
    /// The pairs' deadlines (off until the shell turns them on: the evaluation and
    /// `--rate max` have no clock to be late against).
    pub deadlines: Deadlines<1>,
}

/// One frame observed (tracked, and ORB where wanted), with its counts.
type Seen = (FrameHeader, Observed, ChainCounts, TrackReport);

/// A frame's pixels with what its header says (no detection yet: ORB does not need it).
fn input<'a>(header: &FrameHeader, mat: &'a opencv::core::Mat) -> FrameInput<'a> {
    let [fx, fy, cx, cy] = header.intrinsics;
    FrameInput {
        seq: header.seq,
        t_s: header.t_s,
        pose: header.pose,
        image: mat,
        detection: None,
        intrinsics: Intrinsics::new(fx, fy, cx, cy),
        distortion: Distortion(header.distortion),
        width: header.width,
        height: header.height,
    }
}

/// What a frame's header says, without a detection.
fn frame_meta(header: &FrameHeader) -> FrameMeta {
    let [fx, fy, cx, cy] = header.intrinsics;
    FrameMeta {
        seq: header.seq,
        t_s: header.t_s,
        pose: header.pose,
        detection: None,
        intrinsics: Intrinsics::new(fx, fy, cx, cy),
        distortion: Distortion(header.distortion),
        width: header.width,
        height: header.height,
        others: Others::default(),
    }
}

fn meta(header: &FrameHeader, detection: &DetectionMsg) -> FrameMeta {
    FrameMeta {
        detection: (detection.found == 1).then_some(detection.centre),
        others: Others::of(detection),
        ..frame_meta(header)
    }
}

impl Intake {
    pub fn new(config: MatchingConfig, estimator: EstimatorConfig) -> Result<Self> {
        config.validate().map_err(anyhow::Error::msg)?;
        if config.images_per_uav * 2 > MAX_OBSERVATIONS {
            anyhow::bail!(
                "[matching] images_per_uav must be at most {}",
                MAX_OBSERVATIONS / 2
            );
        }
        Ok(Self {
            acks: 0,
            chain: VisionChain::new(config, estimator)?,
            pending: BTreeMap::new(),
            stats: StageStats::new("matching"),
            trace: Tracer::off(),
            store: None,
            unsaved: [false; 2],
            deadlines: Deadlines::new(true),
        })
    }

    /// Refills the rings from `<state_dir>/matching` and checkpoints there from now on.
    /// A store that cannot be trusted is counted and the rings start empty.
    pub fn restore(
        &mut self,
        state_dir: &std::path::Path,
        config: MatchingConfig,
        estimator: EstimatorConfig,
    ) -> Result<()> {
        let mut store = RingStore::open(state_dir)?;
        let start = monotonic_ns();
        match store.restore(&mut self.chain) {
            Ok(n) => {
                self.stats.count("keyframes_restored", n as u64);
                if n > 0 {
                    tracing::info!(
                        keyframes = n,
                        ms = elapsed_us(start, monotonic_ns()) as f64 / 1e3,
                        "keyframe rings restored"
                    );
                }
            }
            Err(e) => {
                self.stats.count("checkpoint_refused", 1);
                tracing::warn!("keyframe rings not restored, rebuilding them: {e}");
                self.chain = VisionChain::new(config, estimator)?;
            }
        }
        self.store = Some(store);
        Ok(())
    }

    /// The newest frame of each UAV observed (left on a pool thread, right on this
    /// one): tracked from the UAV's previous frame, with ORB where the chain foresees
    /// the pair needs it (`frame_tracking.rs`), then waiting in the pending pairs for
    /// their detections. A frame the header does not describe is counted
    /// (`bad_frames`) and dropped.
    pub fn extract(&mut self, views: [Option<FrameView>; 2]) {
        let start = monotonic_ns();
        let [left, right] = views;
        // The stream jumped (a looped recording started over): the chain starts over
        // before the new segment's first frame is tracked.
        let newest_segment = [&left, &right]
            .into_iter()
            .flatten()
            .map(|(h, _)| h.segment)
            .max();
        if let Some(segment) = newest_segment.filter(|s| *s > self.chain.segment()) {
            self.start_segment(segment);
        }
        // A refresh due on these frames lands first (and may wait for its thread at
        // `--rate max`: counted in `refresh_wait`).
        for (uav, view) in [(Uav::Left, &left), (Uav::Right, &right)] {
            if let Some((h, _)) = view {
                if let Err(e) = self.chain.before_frame(uav, h.seq) {
                    tracing::warn!(?uav, "refresh not landed: {e}");
                    self.stats.count("refresh_failed", 1);
                }
            }
        }
        let [left_tracker, right_tracker] = self.chain.trackers_mut();
        let observe = |tracker: &mut FrameTracker, view: Option<FrameView>| {
            let Some((header, payload)) = view else {
                return Ok(None);
            };
            let mat = frame_mat(&header, payload)?;
            let (observed, counts, report) = tracker.observe(&input(&header, &mat))?;
            anyhow::Ok(Some((header, observed, counts, report)))
        };
        // Left on a pool thread, right on this one. The pool's threads live as long as
        // the process: OpenCV 4.6 keeps per-thread data (cv::TLSDataContainer, from
        // parallel_for_) of every thread that ever called it, so a thread per pair
        // leaked ~15 KB/s (heaptrack; issue #13).
        let (l, r): (Result<Option<Seen>>, Result<Option<Seen>>) =
            if left.is_some() && right.is_some() {
                let mut l = None;
                let r = rayon::in_place_scope(|scope| {
                    scope.spawn(|_| l = Some(observe(left_tracker, left)));
                    observe(right_tracker, right)
                });
                (
                    l.unwrap_or_else(|| Err(anyhow::anyhow!("the left ORB task did not run"))),
                    r,
                )
            } else {
                (observe(left_tracker, left), observe(right_tracker, right))
            };
        let orb_end = monotonic_ns();
        let orb_us = elapsed_us(start, orb_end);
        for (uav, result) in [l, r].into_iter().enumerate() {
            match result {
                Ok(Some((header, mut observed, counts, report))) => {
                    self.chain.add_counts(&counts);
                    let side = [Uav::Left, Uav::Right][uav];
                    let frame = frame_meta(&header);
                    if let Err(e) = self.chain.after_observe(side, &frame, &mut observed) {
                        tracing::warn!(uav, "refresh not asked for: {e}");
                        self.stats.count("refresh_failed", 1);
                    }
                    let name = if report.orb { "orb" } else { "track" };
                    self.stats.count(
                        if report.orb {
                            "orb_frames"
                        } else {
                            "tracked_only_frames"
                        },
                        1,
                    );
                    if report.lost {
                        self.stats.count("track_lost", 1);
                    }
                    let slot = self.pending.entry(header.seq).or_default();
                    slot.frames[uav] = Some((header, observed));
                    slot.orb_us += orb_us;
                    self.stats.record(name, orb_us);
                    let uav = Some(header.uav);
                    self.trace
                        .span("wait", header.seq, uav, header.published_ns, start);
                    self.trace.span(name, header.seq, uav, start, orb_end);
                }
                Ok(None) => {}
                Err(e) => {
                    tracing::warn!(uav, "frame rejected: {e:#}");
                    self.stats.count("bad_frames", 1);
                }
            }
        }
        self.record_landings();
    }

    /// Starts the chain over for stream segment `segment` (counted `segments`); the
    /// emptied rings are checkpointed, so a restart does not bring the old ones back.
    fn start_segment(&mut self, segment: u32) {
        match self.chain.start_over(segment) {
            Ok(()) => {
                self.stats.count("segments", 1);
                self.unsaved = [true; 2];
            }
            Err(e) => {
                tracing::warn!(segment, "the chain did not start over: {e}");
                self.stats.count("match_failed", 1);
            }
        }
    }

    /// The refreshes that landed: `refresh` (the thread's work, µs), `refresh_late`
    /// (frames from the one it was taken on to the one it landed on), `refresh_wait`
    /// (a pair waiting for it at `--rate max`), and the trace's refresh lane.
    fn record_landings(&mut self) {
        for l in self.chain.take_landings() {
            let work = l.steps.iter().find(|s| s.name == "refresh");
            if let Some(w) = work {
                self.stats
                    .record("refresh", elapsed_us(w.start_ns, w.end_ns));
            }
            self.stats
                .record("refresh_late", l.landed_seq.saturating_sub(l.taken_seq));
            if l.waited_us > 0 {
                self.stats.record("refresh_wait", l.waited_us);
            }
            if !self.trace.is_on() {
                continue;
            }
            let uav = Some(l.uav.index() as u8);
            self.trace.span(
                "refresh_queued",
                l.taken_seq,
                uav,
                l.submitted_ns,
                work.map_or(l.finished_ns, |w| w.start_ns),
            );
            for st in &l.steps {
                let name = match st.name {
                    "refresh" => "refresh",
                    "orb" => "refresh_orb",
                    "match" => "refresh_match",
                    "F" => "refresh_F",
                    _ => "refresh_other",
                };
                let kf = (st.name != "refresh" && st.name != "orb").then_some(st.keyframe);
                self.trace
                    .past_span(name, l.taken_seq, Some(st.uav), kf, st.start_ns, st.end_ns);
            }
        }
    }

    /// A detection waits in its pair; one naming no UAV is counted and dropped.
    pub fn on_detection(&mut self, d: DetectionMsg) {
        if d.uav > 1 {
            self.stats.count("bad_detections", 1);
            return;
        }
        self.pending.entry(d.seq).or_default().detections[d.uav as usize] = Some(d);
    }

    /// Matches the newest complete pair; abandons older and stale ones. A pair whose
    /// matching fails is counted (`match_failed`) and dropped.
    pub fn next_set(&mut self) -> Option<ObservationSetMsg> {
        let complete = self.pending.iter().rev().find_map(|(seq, p)| {
            (p.frames.iter().all(Option::is_some) && p.detections.iter().all(Option::is_some))
                .then_some(*seq)
        });
        let newest = self.pending.keys().next_back().copied().unwrap_or(0);
        let cutoff = complete.unwrap_or(newest.saturating_sub(MAX_PENDING_PAIRS));
        let stale: Vec<u64> = self.pending.range(..cutoff).map(|(s, _)| *s).collect();
        for s in stale {
            if let Some(p) = self.pending.remove(&s) {
                self.stats.count("pairs_abandoned", 1);
                self.acks += p.frames[0].is_some() as u64;
            }
        }
        let seq = complete?;
        let pair = self.pending.remove(&seq)?;
        let [Some((hl, ol)), Some((hr, or))] = pair.frames else {
            return None;
        };
        let (Some(dl), Some(dr)) = (pair.detections[0], pair.detections[1]) else {
            return None;
        };
        self.acks += 1;
        // A pair of the segment before the jump, completed late: the chain has started
        // over, and its frames must not enter the new rings.
        if hl.segment < self.chain.segment() {
            self.stats.count("pairs_abandoned", 1);
            return None;
        }
        self.stats.count("pairs", 1);
        let start = monotonic_ns();
        // Only the newest complete pair is ever matched (older ones were abandoned
        // above), so a late pair has nothing newer to yield to: matched, counted.
        self.deadlines.see(0, hl.t_s);
        let moment = hl.capture_ns.min(hr.capture_ns);
        if self.deadlines.verdict(0, moment, start, false) == Verdict::Late {
            self.stats.count("pairs_late", 1);
        }
        let (ml, mr) = (meta(&hl, &dl), meta(&hr, &dr));
        let mut observed = [ol, or];
        let mut timing = ChainTiming::default();
        let mut rejections = Vec::new();
        let outcome =
            match self
                .chain
                .match_current([&ml, &mr], &mut observed, &mut timing, &mut rejections)
            {
                Ok(outcome) => outcome,
                Err(e) => {
                    // OpenCV refusing a frame the header described wrongly: that pair
                    // is lost, the service goes on.
                    self.stats.count("match_failed", 1);
                    tracing::warn!(pair = seq, "matching failed: {e}");
                    return None;
                }
            };
        for (_, _, reason) in &rejections {
            self.stats
                .count(&format!("past_rejected.{}", reason.kind()), 1);
        }
        let c = self.chain.take_counts();
        for (name, n) in [
            ("retried_looser_ratio", c.retried_looser_ratio),
            ("retry_rescued", c.retry_rescued),
            ("fast_threshold_lowered", c.fast_threshold_lowered),
            ("keypoints_outside_lens", c.keypoints_outside_lens),
            ("rectified_frames", c.rectified_frames),
            ("detections_outside_lens", c.detections_outside_lens),
            ("chained_sides", c.chained_sides),
            ("refreshes", c.refreshes),
            ("refresh_not_followed", c.refresh_not_followed),
            ("refresh_failed", c.refresh_failed),
            ("target_pair_repaired", c.target_pair_repaired),
            ("target_pair_mismatch", c.target_pair_mismatch),
            ("target_pair_unchecked", c.target_pair_unchecked),
            ("target_pair_past_dropped", c.target_pair_past_dropped),
        ] {
            if n > 0 {
                self.stats.count(name, n);
            }
        }
        let header = SetHeader {
            pair_seq: seq,
            capture_ns: hl.capture_ns.min(hr.capture_ns),
            t_s: hl.t_s,
            rejected_past: rejections.len() as u32,
            segment: hl.segment,
            frames: [(hl.seq, hl.t_s), (hr.seq, hr.t_s)],
            pose_noise: self.chain.pose_noise(),
        };
        let set = match outcome {
            MatchOutcome::NoDetection => {
                self.stats.count("no_detection", 1);
                Some(unseen_set(&header))
            }
            // The other vehicles of a pair without the target, through its past
            // images (`chain/others.rs`).
            MatchOutcome::TargetUnseen(unseen) => {
                self.stats.count("no_detection", 1);
                let others = self.chain.others_unseen([&ml, &mr], &unseen);
                self.count_others(&others);
                let msg = unseen_set_with_others(&header, &unseen, &others);
                if msg.other_count > 0 {
                    self.stats
                        .count("others_unseen", u64::from(msg.other_count));
                }
                Some(msg)
            }
            MatchOutcome::NotEnoughHistory { .. } => {
                self.stats.count("warming_up", 1);
                None
            }
            // Counted `target_pair_mismatch` with the chain's counts above. The set
            // holds the current images only and is marked refused: geolocation
            // publishes the filter's prediction for it, which keeps the detectors'
            // gates (a coasting one takes the blob nearest the prediction) until both
            // cameras are on one vehicle again. Without it a camera that had taken
            // another car kept it, and every later pair was refused (`multi_town`
            // seed 3: 163 pairs, 7 s).
            MatchOutcome::TargetPairMismatch(current) => Some(refused_set(&header, &current)),
            MatchOutcome::Matched(m) => {
                let fallbacks = m
                    .past
                    .iter()
                    .flat_map(|p| p.models)
                    .filter(|model| {
                        *model == Some(crate::ground_plane::PlaneModel::EssentialFallback)
                    })
                    .count();
                if fallbacks > 0 {
                    self.stats.count("essential_fallback", fallbacks as u64);
                }
                let others = self.others([&ml, &mr], &m);
                let msg = matched_set(&header, &m, &others);
                if msg.others_dropped > 0 {
                    self.stats
                        .count("others_dropped", u64::from(msg.others_dropped));
                }
                if msg.other_count > 0 {
                    self.stats.count("others", u64::from(msg.other_count));
                }
                Some(msg)
            }
        };
        let admitted = match self.chain.admit([&ml, &mr], &mut observed) {
            Ok(admitted) => admitted,
            Err(e) => {
                self.stats.count("match_failed", 1);
                tracing::warn!(pair = seq, "admission failed: {e}");
                [false; 2]
            }
        };
        self.unsaved = [self.unsaved[0] | admitted[0], self.unsaved[1] | admitted[1]];
        let end = monotonic_ns();
        let match_us = elapsed_us(start, end);
        if self.trace.is_on() {
            self.trace.span("match_pair", seq, None, start, end);
            for st in self.chain.steps() {
                let (uav, kf) = (Some(st.uav), Some(st.keyframe));
                self.trace
                    .past_span(st.name, seq, uav, kf, st.start_ns, st.end_ns);
            }
        }
        self.stats.record("match", match_us);
        self.stats.record("compute", pair.orb_us / 2 + match_us);
        set
    }

    /// The other vehicles paired across the pair (counted `others_unpaired`,
    /// `others_no_geometry`; `others` and `others_dropped` once in the message).
    fn others(&mut self, current: [&FrameMeta; 2], matched: &MatchedSet) -> OthersOutcome {
        let outcome = self.chain.others(current, matched);
        self.count_others(&outcome);
        outcome
    }

    /// Counts `others_no_geometry` and `others_unpaired`.
    fn count_others(&mut self, outcome: &OthersOutcome) {
        if outcome.no_geometry {
            self.stats.count("others_no_geometry", 1);
        }
        if outcome.unpaired > 0 {
            self.stats.count("others_unpaired", outcome.unpaired as u64);
        }
    }

    /// Saves newly admitted keyframes (called after the sets are published).
    pub fn checkpoint(&mut self) {
        let Some(store) = self.store.as_mut() else {
            return;
        };
        let unsaved = std::mem::take(&mut self.unsaved);
        if !unsaved.iter().any(|u| *u) {
            return;
        }
        let start = monotonic_ns();
        match store.save(&self.chain, unsaved) {
            Ok(()) => self
                .stats
                .record("checkpoint", elapsed_us(start, monotonic_ns())),
            Err(e) => {
                self.stats.count("checkpoint_failed", 1);
                tracing::warn!("keyframes not checkpointed: {e}");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shared_types::messages::PixelFormat;

    fn intake() -> Intake {
        Intake::new(MatchingConfig::default(), EstimatorConfig::default()).unwrap()
    }

    fn header(seq: u64) -> FrameHeader {
        FrameHeader {
            seq,
            pixel_format: PixelFormat::Bgr8 as u32,
            width: 32,
            height: 24,
            stride: 96,
            pose: shared_types::messages::PoseSample {
                z_m: 100.0,
                ..Default::default()
            },
            intrinsics: [30.0, 30.0, 16.0, 12.0],
            ..Default::default()
        }
    }

    #[test]
    fn a_detection_of_no_uav_is_counted_and_dropped() {
        let mut i = intake();
        i.on_detection(DetectionMsg {
            uav: 7,
            ..Default::default()
        });
        assert_eq!(i.stats.counter("bad_detections"), 1);
        assert!(i.pending.is_empty());
    }

    #[test]
    fn a_frame_its_header_does_not_describe_is_counted_and_dropped() {
        let mut i = intake();
        let pixels = vec![0u8; 10];
        i.extract([Some((header(0), pixels.as_slice())), None]);
        assert_eq!(i.stats.counter("bad_frames"), 1);
        assert!(i.pending.is_empty());
    }

    #[test]
    fn a_pair_with_non_finite_headers_loses_the_pair_not_the_service() {
        let mut i = intake();
        let pixels = vec![90u8; 32 * 24 * 3];
        let mut bad = header(0);
        bad.intrinsics = [f64::NAN; 4];
        bad.pose.yaw_deg = f64::INFINITY;
        i.extract([
            Some((bad, pixels.as_slice())),
            Some((bad, pixels.as_slice())),
        ]);
        for uav in 0..2 {
            i.on_detection(DetectionMsg {
                uav,
                found: 1,
                centre: [f64::NAN, 3.0],
                ..Default::default()
            });
        }
        while i.next_set().is_some() {}
        assert!(i.pending.is_empty(), "the pair was consumed or dropped");
    }
}
