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
//! `gated_frames` (frames detected with a gate).

use anyhow::{Context, Result};
use clap::Parser;
use detection::frame_view::frame_mat;
use detection::prediction_gate::{gate_for, FrameGeometry, RecentPredictions, TargetPrediction};
use detection::{ColourBlobConfig, TrackedDetector};
use shared_types::clock::{elapsed_us, monotonic_ns};
use shared_types::conventions::Intrinsics;
use shared_types::conventions::Uav;
use shared_types::lens::Distortion;
use shared_types::messages::{DetectionMsg, EstimateMsg};
use shared_types::service_names::Topic;
use shared_types::shell::{
    apply_realtime, init_tracing, load_section, serve, SeqGaps, ServiceArgs, StatsSaver,
};
use shared_types::stats::StageStats;
use shared_types::transport::{Endpoint, Stage};

#[derive(Parser)]
#[command(about = "dualgeo detection service (started by `dualgeo run`)")]
struct Args {
    #[command(flatten)]
    service: ServiceArgs,
}

fn main() -> Result<()> {
    let args = Args::parse();
    init_tracing("detection");
    apply_realtime(args.service.config.as_deref(), "detection")?;
    let config: ColourBlobConfig = load_section(args.service.config.as_deref(), "detection")?;
    let gate_config = config.gate;
    let mut detector = TrackedDetector::new(config).context("detector configuration")?;
    let endpoint = Endpoint::new(&args.service.run_id, "detection")?;
    let frames = [
        endpoint.frame_subscriber(Uav::Left)?,
        endpoint.frame_subscriber(Uav::Right)?,
    ];
    let publisher = endpoint.publisher::<DetectionMsg>(Topic::Detections)?;
    let estimates = endpoint.subscriber::<EstimateMsg>(Topic::Estimates)?;
    let mut predictions = RecentPredictions::default();
    let wake_matching = endpoint.notifier(Stage::Matching)?;
    let listener = endpoint.listener(Stage::Detection)?;
    let mut stats = StageStats::new("detection");
    let mut gaps = [SeqGaps::default(); 2];
    let mut saver = StatsSaver::new(&args.service);
    let mut trace = args.service.tracer("detection");
    tracing::info!(
        run = endpoint.run_id(),
        incarnation = args.service.incarnation,
        "detection ready"
    );

    let stop = serve(&listener, |wake| -> Result<bool> {
        let mut first = true;
        while let Some(e) = estimates.receive().context("receive estimate")? {
            predictions.push(e.pair_seq, TargetPrediction::from_estimate(e.payload()));
        }
        for (uav, subscriber) in frames.iter().enumerate() {
            while let Some(sample) = subscriber.receive().context("receive frame")? {
                let header = *sample.user_header();
                if first {
                    if let Some(us) = wake.hop_us(header.published_ns) {
                        stats.record("transport", us);
                    }
                    first = false;
                }
                let start = monotonic_ns();
                stats.record("wait", elapsed_us(header.published_ns, start));
                stats.count("frames", 1);
                stats.count("frames_lost", gaps[uav].see(header.seq));
                let found = match frame_mat(&header, sample.payload()) {
                    Ok(mat) => match detector.detect_gated(
                        uav,
                        header.t_s,
                        &mat,
                        gate_of(&predictions, &header, &gate_config, &mut stats),
                    ) {
                        Ok(d) => d,
                        Err(e) => {
                            tracing::warn!(seq = header.seq, uav, "detector failed: {e}");
                            stats.count("bad_frames", 1);
                            None
                        }
                    },
                    Err(e) => {
                        tracing::warn!(seq = header.seq, uav, "frame rejected: {e}");
                        stats.count("bad_frames", 1);
                        None
                    }
                };
                drop(sample);
                let mut msg = DetectionMsg {
                    seq: header.seq,
                    capture_ns: header.capture_ns,
                    t_s: header.t_s,
                    uav: header.uav,
                    ..Default::default()
                };
                let counts = detector.take_counts();
                stats.count("exposure_retries", counts.exposure_retries);
                stats.count("partial_view_dropped", counts.partial_view_dropped);
                stats.count("window_looks", counts.window_looks);
                stats.count("window_misses", counts.window_misses);
                stats.count("gated_out", counts.gated_out);
                stats.count("reacquired", counts.reacquired);
                if let Some(d) = found {
                    stats.count("found", 1);
                    msg.found = 1;
                    msg.bbox = d.bbox;
                    msg.centre = d.centre;
                    msg.confidence = d.confidence as f64;
                }
                let done = monotonic_ns();
                stats.record("compute", elapsed_us(start, done));
                let uav_id = Some(header.uav);
                trace.span("wait", header.seq, uav_id, header.published_ns, start);
                trace.span("detect", header.seq, uav_id, start, done);
                msg.published_ns = monotonic_ns();
                publisher.send_copy(msg).context("publish detection")?;
                wake_matching.notify().context("wake matching")?;
            }
        }
        saver.tick(&stats);
        trace.maybe_flush();
        Ok(true)
    })?;
    trace.flush();
    let path = saver.finish(&stats)?;
    tracing::info!(?stop, stats = %path.display(), "detection stopped");
    Ok(())
}

/// The gate of this frame from the estimate [`detection::prediction_gate::ESTIMATE_LAG_PAIRS`]
/// pairs back, if the filter was tracking then (counted `gated_frames`).
fn gate_of(
    predictions: &RecentPredictions,
    header: &shared_types::messages::FrameHeader,
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
