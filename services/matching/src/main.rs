//! `dualgeo-matching`: the matching service shell.
//!
//! - On a frame: a refresh due lands, then KLT tracking on the pixels in place (a `Mat`
//!   over the shared-memory sample), the left and right frames of a pair in parallel
//!   (the left on a thread of rayon's persistent pool); a frame that needs a refresh
//!   hands its grey copy to the refresh thread (ORB, matching with past images,
//!   admissions; `--flow-controlled`: refreshes land on fixed frames). The sample is
//!   released when tracking is done.
//! - On a detection: once both frames of a pair are tracked and both detections are
//!   in, corresponding-point matching against the keyframe rings (Section 2.3) from
//!   the tracked points, and an [`ObservationSetMsg`] to geolocation.
//!
//! A slow matching stage keeps only the newest pair: older queued frames are dropped
//! and counted (`frames_dropped`), on time or not (the tracker steps over a skipped
//! frame; tracking the older one would only delay the newer). A pair matched more than
//! a frame period after its moment is counted `pairs_late` (`shared_types::deadline`;
//! none with `--flow-controlled`).
//!
//! Restart (issue #13): with `--state-dir`, every admitted keyframe and the rings' index
//! are checkpointed ([`matching::ring_store`]) after the pair's set is published; a
//! restarted service refills its rings from them (`keyframes_restored`) and can match
//! the first complete pair it sees.
//!
//! Histograms (µs): `transport`, `wait`, `track` (`orb` with tracking off), `match`,
//! `compute` (track + match of one pair), `checkpoint` (keyframe files and index),
//! `refresh` (the refresh thread's work per job), `refresh_wait` (a pair waiting for a
//! refresh at `--rate max`); `refresh_late` counts frames from a refresh's frame to
//! the one it landed on. Counters: `frames`, `pairs`, `sets`,
//! `frames_lost` (sequence gaps), `frames_dropped`, `no_detection` (a pair without the
//! target in a view: its set is published marked `TARGET_UNSEEN`, for the other
//! vehicles' tracks), `warming_up`,
//! `past_rejected.<reason>` (`awaiting_refresh`: nothing tracked to that past image
//! yet), `refreshes`, `refresh_not_followed`, `refresh_failed`, `essential_fallback`
//! (past images whose F came from the 5-point E because the dominant plane was not
//! level), and the adaptations of
//! [`matching::ChainCounts`]: `retried_looser_ratio`, `retry_rescued`,
//! `fast_threshold_lowered`, `keypoints_outside_lens`, `detections_outside_lens`,
//! `rectified_frames` (ORB on a tilted camera's straight-down view, `matching::rectify`),
//! `target_pair_repaired`, `target_pair_mismatch`, `target_pair_unchecked` and
//! `target_pair_past_dropped` (the target's two views checked against each other,
//! `matching::chain::target_pair`);
//! `keyframes_restored`, `checkpoint_refused`, `checkpoint_failed`; `segments` (the
//! stream jumped, a looped recording starting over: trackers, rings and refreshes
//! started over; a pair of the old segment completed later is `pairs_abandoned`);
//! `bad_frames`,
//! `bad_detections` and `match_failed` (untrusted input dropped: a pair is lost, the
//! service goes on). The pairing and matching logic is [`matching::intake`]; this
//! file only moves samples.

use anyhow::{Context, Result};
use clap::Parser;
use geolocation::EstimatorConfig;
use matching::intake::Intake;
use matching::MatchingConfig;
use shared_types::clock::{elapsed_us, monotonic_ns};
use shared_types::conventions::Uav;
use shared_types::deadline::Deadlines;
use shared_types::messages::{DetectionMsg, ObservationSetMsg};
use shared_types::service_names::Topic;
use shared_types::shell::{
    self, apply_realtime, init_tracing, load_section, serve, Permanent, SeqGaps, ServiceArgs,
    StatsSaver, Wake,
};
use shared_types::transport::{Endpoint, FrameSubscriber, Stage};

#[derive(Parser)]
#[command(about = "dualgeo matching service (started by `dualgeo run`)")]
struct Args {
    #[command(flatten)]
    service: ServiceArgs,
}

/// Receives the newest frame of each UAV (older ones are dropped and counted) and
/// hands them to the intake for ORB.
fn on_frames(
    intake: &mut Intake,
    gaps: &mut [SeqGaps; 2],
    subscribers: &[FrameSubscriber; 2],
    wake: Wake,
) -> Result<()> {
    let mut newest = [None, None];
    let mut first = true;
    for (uav, subscriber) in subscribers.iter().enumerate() {
        while let Some(sample) = subscriber.receive().context("receive frame")? {
            let header = sample.user_header();
            if first {
                if let Some(us) = wake.hop_us(header.published_ns) {
                    intake.stats.record("transport", us);
                }
                first = false;
            }
            intake.stats.count("frames", 1);
            intake.stats.count("frames_lost", gaps[uav].see(header.seq));
            if newest[uav].replace(sample).is_some() {
                intake.stats.count("frames_dropped", 1);
            }
        }
    }
    let start = monotonic_ns();
    for sample in newest.iter().flatten() {
        intake
            .stats
            .record("wait", elapsed_us(sample.user_header().published_ns, start));
    }
    // Plain (header, bytes) views: the samples themselves stay on this thread and are
    // released as soon as their features exist.
    intake.extract(
        newest
            .each_ref()
            .map(|s| s.as_ref().map(|s| (*s.user_header(), s.payload()))),
    );
    Ok(())
}

/// Exits with [`shell::EXIT_PERMANENT`] when the input or configuration was refused
/// (the supervisor does not restart that), 1 on any other failure.
fn main() -> std::process::ExitCode {
    shell::exit_code(run())
}

fn run() -> Result<()> {
    let args = Args::parse();
    init_tracing("matching");
    let path = args.service.config.as_deref();
    apply_realtime(path, "matching").map_err(|e| Permanent::new("[realtime]", e))?;
    let config: MatchingConfig = load_section(path, "matching")?;
    let estimator: EstimatorConfig = load_section(path, "estimator")?;
    let mut intake = Intake::new(config.clone(), estimator)
        .map_err(|e| Permanent::new("[matching] configuration", e))?;
    intake.trace = args.service.tracer("matching");
    intake.deadlines = Deadlines::new(args.service.flow_controlled);
    if let Some(dir) = &args.service.state_dir {
        intake.restore(dir, config, estimator)?;
    }
    // Keyframe work (ORB, matching with past images, admissions) on its own thread.
    intake
        .chain
        .refresh_on_thread(args.service.flow_controlled)
        .context("start the refresh thread")?;
    let mut gaps = [SeqGaps::default(); 2];
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
        on_frames(&mut intake, &mut gaps, &frames, wake)?;
        while let Some(sample) = detections.receive().context("receive detection")? {
            intake.on_detection(*sample.payload());
        }
        while let Some(mut set) = intake.next_set() {
            set.set_seq = next_set_seq;
            next_set_seq += 1;
            set.published_ns = monotonic_ns();
            publisher.send_copy(set).context("publish observations")?;
            wake_geolocation.notify().context("wake geolocation")?;
            intake.stats.count("sets", 1);
        }
        for _ in 0..std::mem::take(&mut intake.acks) {
            ack_acquisition.notify().context("acknowledge a pair")?;
        }
        intake.checkpoint();
        saver.tick(&intake.stats);
        intake.trace.maybe_flush();
        Ok(true)
    })?;
    intake.trace.flush();
    let path = saver.finish(&intake.stats)?;
    tracing::info!(?stop, stats = %path.display(), "matching stopped");
    Ok(())
}
