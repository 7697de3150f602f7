//! `dualgeo-detection`: the detection service shell. Wakes when acquisition publishes a
//! frame, reads the pixels in place (a `Mat` header over the shared-memory sample),
//! runs the configured detector and publishes a [`DetectionMsg`] per frame.
//!
//! Histograms (µs): `transport` (frame publish → this stage woke, first frame of a
//! wake-up), `wait` (frame publish → processing starts), `compute` (detection).
//! Counters: `frames`, `found`, `frames_lost` (sequence gaps: overwritten while busy),
//! `bad_frames`, `window_looks` / `window_misses` (frames searched first in a window
//! around the track, and those that then needed the whole frame), `exposure_retries`
//! (frames looked at again with the exposure-scaled
//! brightness floor), `partial_view_dropped` (detections of a partly hidden target,
//! dropped by the per-camera track of [`TrackedDetector`]), `gated_out` (frames where
//! a blob of the target's colour lay outside the gate of the geolocation filter's
//! prediction and none inside: a look-alike not taken for the target; the service
//! subscribes to the estimates for it, `detection::prediction_gate`), `reacquired`
//! (detections after a camera found nothing in its gates for `reacquire_after_s`),
//! `swings_followed` (frames whose measured camera swing beyond its attitude noise
//! moved the track's hint, `detection::camera_swing`),
//! `track_kept` (frames where a coasting filter's gate favoured another blob too
//! little to leave the image track's, `detection::tracked::KEEP_TRACK`),
//! `gated_frames` (frames detected with a gate), `frames_late` (started after the
//! frame's deadline, one frame period after its moment: `shared_types::deadline`) and
//! `frames_shed` (late with a newer frame of the same UAV waiting: skipped, no message),
//! `segments` (the stream jumped, a looped recording starting over: every camera's
//! tracks and the filter's predictions were forgotten).
//! With `[detection] kind = "yolo"` (`detection::learned`): `model_runs`,
//! `model_found`, `tracked`, `track_lost`, and the histogram `model` (µs per model run,
//! on its own thread). With `kind = "motion"` (`detection::motion`): `movers` (blobs
//! moving against the ground, summed over frames), `no_ground` (frames whose ground
//! motion was not measured), `acquired`, `track_lost` and `held` (frames whose target
//! was its patch from the last frame it moved in). With `[detection] candidates`
//! (default; the colour detector adds every blob of another vivid colour and every
//! white vehicle, `[detection.others]`): `candidates` (other objects published beside the target, summed over
//! frames), `candidates_overflow` (left out for room) and `candidates_failed`.

use anyhow::{Context, Result};
use clap::Parser;
use detection::camera_swing::CameraView;
use detection::config::{DetectionConfig, DetectorKind};
use detection::frame_view::frame_mat;
use detection::learned::LearnedDetector;
use detection::motion::MotionDetector;
use detection::other_colours::OtherColours;
use detection::prediction_gate::{gate_for, FrameGeometry, RecentPredictions, TargetPrediction};
use detection::TrackedDetector;
use shared_types::clock::{elapsed_us, monotonic_ns};
use shared_types::conventions::Intrinsics;
use shared_types::conventions::Uav;
use shared_types::deadline::{drain_with_lookahead, Deadlines, Verdict};
use shared_types::lens::Distortion;
use shared_types::messages::FrameHeader;
use shared_types::messages::{DetectionMsg, EstimateMsg};
use shared_types::service_names::Topic;
use shared_types::shell::{
    self, apply_realtime, init_tracing, load_section, serve, Permanent, SeqGaps, ServiceArgs,
    StatsSaver,
};
use shared_types::stats::StageStats;
use shared_types::transport::{Endpoint, MsgPublisher, Stage};

#[derive(Parser)]
#[command(about = "dualgeo detection service (started by `dualgeo run`)")]
struct Args {
    #[command(flatten)]
    service: ServiceArgs,
}

/// Exits with [`shell::EXIT_PERMANENT`] when the input or configuration was refused
/// (the supervisor does not restart that), 1 on any other failure.
fn main() -> std::process::ExitCode {
    shell::exit_code(run())
}

fn run() -> Result<()> {
    let args = Args::parse();
    init_tracing("detection");
    apply_realtime(args.service.config.as_deref(), "detection")
        .map_err(|e| Permanent::new("[realtime]", e))?;
    let config: DetectionConfig = load_section(args.service.config.as_deref(), "detection")?;
    let gate_config = config.colour.gate;
    let candidates = config.candidates;
    // Other vehicles' colours: with the colour detector only (a mover is any colour).
    let others = match config.kind {
        DetectorKind::Colour if candidates => Some(
            OtherColours::new(config.others.clone(), &config.colour.hue_ranges)
                .map_err(|e| Permanent::new("[detection.others]", e))?,
        ),
        _ => None,
    };
    let detector = Chosen::new(config, args.service.flow_controlled)
        .map_err(|e| Permanent::new("[detection] configuration", e))?;
    let endpoint = Endpoint::new(&args.service.run_id, "detection")?;
    let frames = [
        endpoint.frame_subscriber(Uav::Left)?,
        endpoint.frame_subscriber(Uav::Right)?,
    ];
    let publisher = endpoint.publisher::<DetectionMsg>(Topic::Detections)?;
    let estimates = endpoint.subscriber::<EstimateMsg>(Topic::Estimates)?;
    let wake_matching = endpoint.notifier(Stage::Matching)?;
    let listener = endpoint.listener(Stage::Detection)?;
    let mut stage = Detecting {
        detector,
        candidates,
        others,
        found_all: Vec::new(),
        predictions: RecentPredictions::default(),
        segments: [None; 2],
        gate_config,
        stats: StageStats::new("detection"),
        trace: args.service.tracer("detection"),
        deadlines: Deadlines::new(args.service.flow_controlled),
    };
    let mut gaps = [SeqGaps::default(); 2];
    let mut saver = StatsSaver::new(&args.service);
    tracing::info!(
        run = endpoint.run_id(),
        incarnation = args.service.incarnation,
        "detection ready"
    );

    let stop = serve(&listener, |wake| -> Result<bool> {
        let mut first = true;
        while let Some(e) = estimates.receive().context("receive estimate")? {
            stage
                .predictions
                .push(e.pair_seq, TargetPrediction::from_estimate(e.payload()));
        }
        for (uav, subscriber) in frames.iter().enumerate() {
            // A late frame with a newer one behind it is shed (shared_types::deadline).
            // At most two samples are borrowed at once (FRAME_MAX_BORROWED).
            drain_with_lookahead(
                || subscriber.receive().context("receive frame"),
                |sample, superseded| {
                    let header = sample.user_header();
                    if first {
                        if let Some(us) = wake.hop_us(header.published_ns) {
                            stage.stats.record("transport", us);
                        }
                        first = false;
                    }
                    stage.stats.count("frames", 1);
                    stage.stats.count("frames_lost", gaps[uav].see(header.seq));
                    stage.deadlines.see(uav, header.t_s);
                    let view = (*header, sample.payload());
                    stage.handle(uav, view, superseded, &publisher)?;
                    drop(sample);
                    wake_matching.notify().context("wake matching")?;
                    Ok(())
                },
            )?;
        }
        saver.tick(&stage.stats);
        stage.trace.maybe_flush();
        Ok(true)
    })?;
    let Detecting { stats, trace, .. } = &mut stage;
    trace.flush();
    let path = saver.finish(stats)?;
    tracing::info!(?stop, stats = %path.display(), "detection stopped");
    Ok(())
}

/// The detector `[detection] kind` chose.
enum Chosen {
    Colour(Box<TrackedDetector>),
    Learned(Box<LearnedDetector>),
    Motion(Box<MotionDetector>),
}

impl Chosen {
    /// `camera`'s stream jumped (a new segment): its tracks start over.
    fn start_over(&mut self, camera: usize) {
        match self {
            Chosen::Colour(d) => d.start_over(camera),
            Chosen::Learned(d) => d.start_over(camera),
            Chosen::Motion(d) => d.start_over(camera),
        }
    }

    fn new(config: DetectionConfig, flow_controlled: bool) -> Result<Self, detection::DetectError> {
        Ok(match (config.kind, config.yolo) {
            (DetectorKind::Yolo, Some(yolo)) => {
                Chosen::Learned(Box::new(LearnedDetector::new(yolo, flow_controlled)?))
            }
            (DetectorKind::Motion, _) => {
                Chosen::Motion(Box::new(MotionDetector::new(config.motion)?))
            }
            _ => Chosen::Colour(Box::new(TrackedDetector::new(config.colour)?)),
        })
    }
}

/// The service's state between wake-ups.
struct Detecting {
    detector: Chosen,
    /// `[detection] candidates`: publish every other object found.
    candidates: bool,
    /// `[detection.others]`: blobs of the other vehicles' colours.
    others: Option<OtherColours>,
    /// Everything the detector found in the frame (reused).
    found_all: Vec<detection::Detection>,
    predictions: RecentPredictions,
    /// Per camera: the stream segment of its last frame.
    segments: [Option<u32>; 2],
    gate_config: detection::prediction_gate::GateConfig,
    stats: StageStats,
    trace: shared_types::trace::Tracer,
    deadlines: Deadlines<2>,
}

impl Detecting {
    /// Detects in one frame of `uav` and publishes the result, or sheds the frame
    /// (`frames_shed`, no message) when it is past its deadline and `superseded` by a
    /// newer frame of the same UAV; a late frame with nothing newer is detected and
    /// counted `frames_late`.
    fn handle(
        &mut self,
        uav: usize,
        (header, payload): (FrameHeader, &[u8]),
        superseded: bool,
        publisher: &MsgPublisher<DetectionMsg>,
    ) -> Result<()> {
        let start = monotonic_ns();
        let uav_id = Some(header.uav);
        self.stats
            .record("wait", elapsed_us(header.published_ns, start));
        self.trace
            .span("wait", header.seq, uav_id, header.published_ns, start);
        match self
            .deadlines
            .verdict(uav, header.capture_ns, start, superseded)
        {
            Verdict::Shed => {
                self.stats.count("frames_shed", 1);
                return Ok(());
            }
            Verdict::Late => self.stats.count("frames_late", 1),
            Verdict::OnTime => {}
        }
        // The stream jumped (a looped recording started over): this camera's tracks
        // and the filter's predictions speak of a world that is gone.
        if self.segments[uav].is_some_and(|s| s != header.segment) {
            self.detector.start_over(uav);
            if self.predictions.start_segment(header.seq) {
                self.stats.count("segments", 1);
            }
        }
        self.segments[uav] = Some(header.segment);
        let stats = &mut self.stats;
        let mat = frame_mat(&header, payload);
        let detected = mat.as_ref().map(|mat| match &mut self.detector {
            Chosen::Colour(d) => d.detect_gated(
                uav,
                header.t_s,
                mat,
                gate_of(&self.predictions, &header, &self.gate_config, stats),
                view_of(&header),
            ),
            // The learned detector is not gated by the filter's prediction yet.
            Chosen::Learned(d) => d.detect(uav, mat),
            Chosen::Motion(d) => d.detect(
                uav,
                mat,
                gate_of(&self.predictions, &header, &self.gate_config, stats),
            ),
        });
        let detector_ok = matches!(detected, Ok(Ok(_)));
        let found = match detected {
            Ok(Ok(d)) => d,
            Ok(Err(e)) => {
                tracing::warn!(seq = header.seq, uav, "detector failed: {e}");
                stats.count("bad_frames", 1);
                None
            }
            Err(e) => {
                tracing::warn!(seq = header.seq, uav, "frame rejected: {e}");
                stats.count("bad_frames", 1);
                None
            }
        };
        let mut msg = DetectionMsg {
            seq: header.seq,
            capture_ns: header.capture_ns,
            t_s: header.t_s,
            uav: header.uav,
            ..Default::default()
        };
        match &mut self.detector {
            Chosen::Colour(d) => {
                let counts = d.take_counts();
                stats.count("exposure_retries", counts.exposure_retries);
                stats.count("partial_view_dropped", counts.partial_view_dropped);
                stats.count("window_looks", counts.window_looks);
                stats.count("window_misses", counts.window_misses);
                stats.count("gated_out", counts.gated_out);
                stats.count("reacquired", counts.reacquired);
                stats.count("swings_followed", counts.swings_followed);
                stats.count("track_kept", counts.track_kept);
            }
            Chosen::Learned(d) => {
                let counts = d.take_counts();
                stats.count("model_runs", counts.model_runs);
                stats.count("model_found", counts.model_found);
                stats.count("tracked", counts.tracked);
                stats.count("track_lost", counts.track_lost);
                if let Some(mean) = counts.model_us.checked_div(counts.model_runs) {
                    stats.record("model", mean);
                }
            }
            Chosen::Motion(d) => {
                let counts = d.take_counts();
                stats.count("movers", counts.movers);
                stats.count("no_ground", counts.no_ground);
                stats.count("acquired", counts.acquired);
                stats.count("track_lost", counts.track_lost);
                stats.count("held", counts.held);
            }
        }
        if let Some(d) = found {
            stats.count("found", 1);
            msg.found = 1;
            msg.bbox = d.bbox;
            msg.centre = d.centre;
            msg.confidence = d.confidence as f64;
        }
        // A frame the detector failed on has no candidates either.
        if let (true, true, Ok(mat)) = (self.candidates, detector_ok, &mat) {
            self.publish_candidates(&mut msg, mat);
        }
        let done = monotonic_ns();
        self.stats.record("compute", elapsed_us(start, done));
        self.trace.span("detect", header.seq, uav_id, start, done);
        msg.published_ns = monotonic_ns();
        publisher.send_copy(msg).context("publish detection")?;
        Ok(())
    }
}

impl Detecting {
    /// Puts every other object the detector found in `mat` into `msg` (counted
    /// `candidates`, and `candidates_overflow` beyond the message's room). A failure
    /// leaves the message without candidates (counted `candidates_failed`).
    fn publish_candidates(&mut self, msg: &mut DetectionMsg, mat: &opencv::core::Mat) {
        let found = &mut self.found_all;
        found.clear();
        let listed = match &mut self.detector {
            Chosen::Colour(d) => d
                .candidates(mat, found)
                .and_then(|()| match &mut self.others {
                    Some(o) => o.find(mat, found),
                    None => Ok(()),
                }),
            Chosen::Motion(d) => {
                found.extend(d.last_movers().iter().map(|m| m.as_detection()));
                Ok(())
            }
            // The model's other boxes are not kept yet.
            Chosen::Learned(_) => Ok(()),
        };
        match listed.and_then(|()| detection::candidates::fill(msg, found, mat)) {
            Ok(dropped) => {
                self.stats
                    .count("candidates", u64::from(msg.candidate_count));
                self.stats.count("candidates_overflow", u64::from(dropped));
            }
            Err(e) => {
                tracing::warn!(seq = msg.seq, "candidates not listed: {e}");
                msg.candidate_count = 0;
                self.stats.count("candidates_failed", 1);
            }
        }
    }
}

/// The frame's measured camera (its swings move the image track's hint).
fn view_of(header: &FrameHeader) -> Option<CameraView> {
    let [fx, fy, cx, cy] = header.intrinsics;
    CameraView::new(
        &header.pose,
        Intrinsics::new(fx, fy, cx, cy),
        Distortion(header.distortion),
    )
}

/// The gate of this frame from the estimate [`detection::prediction_gate::ESTIMATE_LAG_PAIRS`]
/// pairs back, if the filter was tracking then (counted `gated_frames`).
fn gate_of(
    predictions: &RecentPredictions,
    header: &FrameHeader,
    config: &detection::prediction_gate::GateConfig,
    stats: &mut StageStats,
) -> Option<detection::prediction_gate::Gate> {
    let prediction = predictions.for_pair(header.seq)?;
    let [fx, fy, cx, cy] = header.intrinsics;
    let frame = FrameGeometry {
        t_s: header.t_s,
        uav: header.uav as usize,
        pose: header.pose,
        intrinsics: Intrinsics::new(fx, fy, cx, cy),
        distortion: Distortion(header.distortion),
        width: header.width,
    };
    let gate = gate_for(&prediction, &frame, config);
    if gate.is_some() {
        stats.count("gated_frames", 1);
    }
    gate
}
