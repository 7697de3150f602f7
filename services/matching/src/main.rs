//! `dualgeo-matching`: the matching service shell.
//!
//! - On a frame: ORB on the pixels in place (a `Mat` over the shared-memory sample), the
//!   left and right frames of a pair in parallel (the left on a thread of rayon's
//!   persistent pool); the sample is released as soon as its features exist.
//! - On a detection: once both frames of a pair have features and both detections are
//!   in, corresponding-point matching against the keyframe rings (Section 2.3), an
//!   [`ObservationSetMsg`] to geolocation, then the pair is offered to the rings.
//!
//! A slow matching stage keeps only the newest pair: older queued frames are dropped
//! and counted (`frames_dropped`).
//!
//! Restart (issue #13): with `--state-dir`, every admitted keyframe and the rings' index
//! are checkpointed ([`matching::ring_store`]) after the pair's set is published; a
//! restarted service refills its rings from them (`keyframes_restored`) and can match
//! the first complete pair it sees.
//!
//! Histograms (µs): `transport`, `wait`, `orb`, `match`, `compute` (orb + match of one
//! pair), `checkpoint` (keyframe files and index). Counters: `frames`, `pairs`, `sets`,
//! `frames_lost` (sequence gaps), `frames_dropped`, `no_detection`, `warming_up`,
//! `past_rejected.<reason>`, `essential_fallback` (past images whose F came from the
//! 5-point E because the dominant plane was not level), and the adaptations of
//! [`matching::ChainCounts`]: `retried_looser_ratio`, `retry_rescued`,
//! `fast_threshold_lowered`, `keypoints_outside_lens`, `detections_outside_lens`;
//! `keyframes_restored`, `checkpoint_refused`, `checkpoint_failed`.

use anyhow::{Context, Result};
use clap::Parser;
use detection::frame_view::frame_mat;
use geolocation::EstimatorConfig;
use matching::features::{Features, OrbExtractor};
use matching::ring_store::RingStore;
use matching::{
    extract_undistorted, ChainCounts, FrameInput, FrameMeta, MatchOutcome, MatchingConfig,
    VisionChain,
};
use shared_types::clock::{elapsed_us, monotonic_ns};
use shared_types::conventions::{Intrinsics, Uav};
use shared_types::lens::Distortion;
use shared_types::messages::{DetectionMsg, FrameHeader, ObservationSetMsg, MAX_OBSERVATIONS};
use shared_types::service_names::Topic;
use shared_types::shell::{
    init_tracing, load_section, serve, SeqGaps, ServiceArgs, StatsSaver, Wake,
};
use shared_types::stats::StageStats;
use shared_types::transport::{Endpoint, FrameSubscriber, Stage};
use std::collections::BTreeMap;
use std::sync::Arc;

#[derive(Parser)]
#[command(about = "dualgeo matching service (started by `dualgeo run`)")]
struct Args {
    #[command(flatten)]
    service: ServiceArgs,
}

/// Pairs older than this many sequence numbers behind the newest are abandoned.
const MAX_PENDING_PAIRS: u64 = 4;

#[derive(Default)]
struct Pending {
    frames: [Option<(FrameHeader, Arc<Features>)>; 2],
    detections: [Option<DetectionMsg>; 2],
    orb_us: u64,
}

struct Matcher {
    /// Left frames finished with (processed, dropped or lost), not yet acknowledged to
    /// acquisition: one acknowledgement per pair, for `--rate max` flow control.
    acks: u64,
    chain: VisionChain,
    worker_orb: OrbExtractor,
    pending: BTreeMap<u64, Pending>,
    stats: StageStats,
    gaps: [SeqGaps; 2],
    /// Where the rings are checkpointed, and what was admitted since the last save.
    store: Option<RingStore>,
    unsaved: [bool; 2],
}

/// Features of the left frame from the pool thread, with its counts.
type LeftFeatures = (FrameHeader, Arc<Features>, ChainCounts);

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

fn meta(header: &FrameHeader, detection: &DetectionMsg) -> FrameMeta {
    let [fx, fy, cx, cy] = header.intrinsics;
    FrameMeta {
        seq: header.seq,
        t_s: header.t_s,
        pose: header.pose,
        detection: (detection.found == 1).then_some(detection.centre),
        intrinsics: Intrinsics::new(fx, fy, cx, cy),
        distortion: Distortion(header.distortion),
        width: header.width,
        height: header.height,
    }
}

impl Matcher {
    /// Takes the newest frame of each UAV (older ones are dropped) and computes ORB.
    fn on_frames(&mut self, subscribers: &[FrameSubscriber; 2], wake: Wake) -> Result<()> {
        let mut newest = [None, None];
        let mut first = true;
        for (uav, subscriber) in subscribers.iter().enumerate() {
            while let Some(sample) = subscriber.receive().context("receive frame")? {
                let header = sample.user_header();
                if first {
                    if let Some(us) = wake.hop_us(header.published_ns) {
                        self.stats.record("transport", us);
                    }
                    first = false;
                }
                self.stats.count("frames", 1);
                self.stats
                    .count("frames_lost", self.gaps[uav].see(header.seq));
                if newest[uav].replace(sample).is_some() {
                    self.stats.count("frames_dropped", 1);
                }
            }
        }
        let start = monotonic_ns();
        for sample in newest.iter().flatten() {
            self.stats
                .record("wait", elapsed_us(sample.user_header().published_ns, start));
        }
        // Plain (header, bytes) views: the samples themselves stay on this thread.
        let views = newest
            .each_ref()
            .map(|s| s.as_ref().map(|s| (*s.user_header(), s.payload())));
        let [left, right] = views;
        let (chain, worker_orb) = (&mut self.chain, &mut self.worker_orb);
        let extract_right =
            |chain: &mut VisionChain| -> Result<Option<(FrameHeader, Arc<Features>)>> {
                let Some((header, payload)) = right else {
                    return Ok(None);
                };
                let mat = frame_mat(&header, payload)?;
                Ok(Some((header, chain.extract(&input(&header, &mat))?)))
            };
        let extract_left = |orb: &mut OrbExtractor| -> Result<Option<LeftFeatures>> {
            let Some((header, payload)) = left else {
                return Ok(None);
            };
            let mat = frame_mat(&header, payload)?;
            let (features, counts) = extract_undistorted(orb, &input(&header, &mat))?;
            Ok(Some((header, Arc::new(features), counts)))
        };
        // Left on a pool thread, right on this one. The pool's threads live as long as
        // the process: OpenCV 4.6 keeps per-thread data (cv::TLSDataContainer, from
        // parallel_for_) of every thread that ever called it, so a thread per pair
        // leaked ~15 KB/s (heaptrack; issue #13).
        let (l, r) = if left.is_some() && right.is_some() {
            let mut l = None;
            let r = rayon::in_place_scope(|scope| {
                scope.spawn(|_| l = Some(extract_left(worker_orb)));
                extract_right(chain)
            });
            (
                l.unwrap_or_else(|| Err(anyhow::anyhow!("the left ORB task did not run"))),
                r,
            )
        } else {
            (extract_left(worker_orb), extract_right(chain))
        };
        drop(newest);
        let orb_us = elapsed_us(start, monotonic_ns());
        let l = l.map(|found| {
            found.map(|(header, features, counts)| {
                self.chain.add_counts(&counts);
                (header, features)
            })
        });
        for (uav, result) in [l, r].into_iter().enumerate() {
            match result {
                Ok(Some((header, features))) => {
                    let slot = self.pending.entry(header.seq).or_default();
                    slot.frames[uav] = Some((header, features));
                    slot.orb_us += orb_us;
                    self.stats.record("orb", orb_us);
                }
                Ok(None) => {}
                Err(e) => {
                    tracing::warn!(uav, "frame rejected: {e:#}");
                    self.stats.count("bad_frames", 1);
                }
            }
        }
        Ok(())
    }

    fn on_detections(
        &mut self,
        subscriber: &shared_types::transport::MsgSubscriber<DetectionMsg>,
    ) -> Result<()> {
        while let Some(sample) = subscriber.receive().context("receive detection")? {
            let d = *sample.payload();
            if d.uav > 1 {
                self.stats.count("bad_detections", 1);
                continue;
            }
            self.pending.entry(d.seq).or_default().detections[d.uav as usize] = Some(d);
        }
        Ok(())
    }

    /// Matches the newest complete pair; abandons older and stale ones.
    fn next_set(&mut self) -> Result<Option<ObservationSetMsg>> {
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
        let Some(seq) = complete else { return Ok(None) };
        let Some(pair) = self.pending.remove(&seq) else {
            return Ok(None);
        };
        let (Some((hl, fl)), Some((hr, fr)), Some(dl), Some(dr)) = (
            pair.frames[0].clone(),
            pair.frames[1].clone(),
            pair.detections[0],
            pair.detections[1],
        ) else {
            return Ok(None);
        };
        self.stats.count("pairs", 1);
        self.acks += 1;
        let start = monotonic_ns();
        let (ml, mr) = (meta(&hl, &dl), meta(&hr, &dr));
        let features = [fl, fr];
        let mut timing = matching::ChainTiming::default();
        let mut rejections = Vec::new();
        let outcome =
            self.chain
                .match_current([&ml, &mr], &features, &mut timing, &mut rejections)?;
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
            ("detections_outside_lens", c.detections_outside_lens),
        ] {
            if n > 0 {
                self.stats.count(name, n);
            }
        }
        let set = match outcome {
            MatchOutcome::NoDetection => {
                self.stats.count("no_detection", 1);
                None
            }
            MatchOutcome::NotEnoughHistory { .. } => {
                self.stats.count("warming_up", 1);
                None
            }
            MatchOutcome::Matched(m) => {
                let fallbacks = m
                    .past
                    .iter()
                    .flat_map(|p| p.models)
                    .filter(|model| {
                        *model == Some(matching::ground_plane::PlaneModel::EssentialFallback)
                    })
                    .count();
                if fallbacks > 0 {
                    self.stats.count("essential_fallback", fallbacks as u64);
                }
                let mut msg = ObservationSetMsg {
                    pair_seq: seq,
                    capture_ns: hl.capture_ns.min(hr.capture_ns),
                    t_s: hl.t_s,
                    rejected_past: rejections.len() as u32,
                    ..Default::default()
                };
                let seqs = [hl.seq, hr.seq]
                    .into_iter()
                    .chain(m.past.iter().map(|p| p.seq));
                let all = m.current.iter().chain(&m.past_observations).zip(seqs);
                for (slot, (o, seq)) in msg.entries.iter_mut().zip(all).take(MAX_OBSERVATIONS) {
                    *slot = o.to_entry();
                    slot.frame_seq = seq;
                    msg.count += 1;
                }
                Some(msg)
            }
        };
        let admitted = self.chain.admit([&ml, &mr], &features);
        self.unsaved = [self.unsaved[0] | admitted[0], self.unsaved[1] | admitted[1]];
        let match_us = elapsed_us(start, monotonic_ns());
        self.stats.record("match", match_us);
        self.stats.record("compute", pair.orb_us / 2 + match_us);
        Ok(set)
    }

    /// Saves newly admitted keyframes (called after the sets are published).
    fn checkpoint(&mut self) {
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

fn main() -> Result<()> {
    let args = Args::parse();
    init_tracing("matching");
    let path = args.service.config.as_deref();
    let config: MatchingConfig = load_section(path, "matching")?;
    let estimator: EstimatorConfig = load_section(path, "estimator")?;
    if config.images_per_uav * 2 > MAX_OBSERVATIONS {
        anyhow::bail!(
            "[matching] images_per_uav must be at most {}",
            MAX_OBSERVATIONS / 2
        );
    }
    let worker_orb = OrbExtractor::new(&config)?;
    let mut matcher = Matcher {
        acks: 0,
        chain: VisionChain::new(config.clone(), estimator)?,
        worker_orb,
        pending: BTreeMap::new(),
        stats: StageStats::new("matching"),
        gaps: [SeqGaps::default(); 2],
        store: None,
        unsaved: [false; 2],
    };
    if let Some(dir) = &args.service.state_dir {
        let mut store = RingStore::open(dir)?;
        let start = monotonic_ns();
        match store.restore(&mut matcher.chain) {
            Ok(n) => {
                matcher.stats.count("keyframes_restored", n as u64);
                if n > 0 {
                    tracing::info!(
                        keyframes = n,
                        ms = elapsed_us(start, monotonic_ns()) as f64 / 1e3,
                        "keyframe rings restored"
                    );
                }
            }
            Err(e) => {
                matcher.stats.count("checkpoint_refused", 1);
                tracing::warn!("keyframe rings not restored, rebuilding them: {e}");
                matcher.chain = VisionChain::new(config.clone(), estimator)?;
            }
        }
        matcher.store = Some(store);
    }
    let mut saver = StatsSaver::new(&args.service);
    let endpoint = Endpoint::new(&args.service.run_id, "matching")?;
    let frames = [
        endpoint.frame_subscriber(Uav::Left)?,
        endpoint.frame_subscriber(Uav::Right)?,
    ];
    let detections = endpoint.subscriber::<DetectionMsg>(Topic::Detections)?;
    let publisher = endpoint.publisher::<ObservationSetMsg>(Topic::Observations)?;
    let wake_geolocation = endpoint.notifier(Stage::Geolocation)?;
    let ack_acquisition = endpoint.notifier(Stage::Acquisition)?;
    let listener = endpoint.listener(Stage::Matching)?;
    tracing::info!(run = endpoint.run_id(), "matching ready");
    let mut next_set_seq = 0u64;

    let stop = serve(&listener, |wake| -> Result<bool> {
        matcher.on_frames(&frames, wake)?;
        matcher.on_detections(&detections)?;
        while let Some(mut set) = matcher.next_set()? {
            set.set_seq = next_set_seq;
            next_set_seq += 1;
            set.published_ns = monotonic_ns();
            publisher.send_copy(set).context("publish observations")?;
            wake_geolocation.notify().context("wake geolocation")?;
            matcher.stats.count("sets", 1);
        }
        for _ in 0..std::mem::take(&mut matcher.acks) {
            ack_acquisition.notify().context("acknowledge a pair")?;
        }
        matcher.checkpoint();
        saver.tick(&matcher.stats);
        Ok(true)
    })?;
    let path = saver.finish(&matcher.stats)?;
    tracing::info!(?stop, stats = %path.display(), "matching stopped");
    Ok(())
}
