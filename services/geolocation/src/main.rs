//! `dualgeo-geolocation`: the geolocation service shell. Wakes when matching publishes
//! an observation set, runs the paper's consistency filter (eq. 29–32) and the
//! altitude/regression iteration, and publishes an [`EstimateMsg`]. `[estimator] method`
//! selects `temporal` (default), `paper` or `joint`: the temporal filter carries both
//! biases and the target across sets (it recognises reused keyframes by their frame
//! sequence numbers).
//!
//! Restart (issue #13): after every published estimate the service checkpoints the
//! filter and the last estimate's pair and time to `<state-dir>/geolocation.ckpt`
//! (`shared_types::checkpoint`, written after the publish so it never delays one). A
//! restarted service resumes from it; a set not newer than the last estimate published
//! before the restart is dropped (`stale_sets`), so estimates stay in time order.
//!
//! Histograms (µs): `transport`, `wait`, `compute`, `checkpoint` (write of the state
//! file), and `end_to_end` (frame capture → estimate published). Counters: `sets`,
//! `estimates`, `sets_lost`, `bad_input`, `rejected.<reason>`, `resumed`,
//! `checkpoint_refused`, `checkpoint_failed`, `stale_sets`, `estimates_late` (published
//! more than a frame period after the pair's moment; `shared_types::deadline`),
//! `segments` (the stream jumped, a looped recording starting over: the filter and the
//! tracks started over, as for a new stream; a set of an earlier segment is
//! `stale_sets`), `sets_refused` (matching refused the pair as two vehicles: the
//! filter's prediction is published, its rays untaken) and `target_on_track` (the
//! other vehicles of the pair say the target's detections are another tracked
//! vehicle's: the same; `geolocation::target_identity`), `target_in_doubt` (right
//! after a gap in the sets, they put it in doubt: the same).
//!
//! Several targets (`[tracks]`, on by default): the set's other vehicles are located
//! with the target's yaw biases and tracked (`geolocation::others_message`, its
//! counters); the confirmed tracks ride in the estimate message. They are
//! checkpointed with the filter: a restarted service keeps their ids.

use anyhow::{Context, Result};
use clap::Parser;
use geolocation::geolocator::Geolocator;
use geolocation::set_message::{is_stale, segment_step, Resume, SegmentStep, CHECKPOINT_KIND};
use geolocation::tracks::{TrackConfig, Tracks};
use geolocation::{EstimatorConfig, EstimatorMethod, TemporalEstimator};
use shared_types::checkpoint;
use shared_types::clock::{elapsed_us, monotonic_ns};
use shared_types::deadline::{Deadlines, Verdict};
use shared_types::messages::{EstimateMsg, ObservationSetMsg};
use shared_types::service_names::Topic;
use shared_types::shell::{
    self, apply_realtime, init_tracing, load_section, serve, Permanent, SeqGaps, ServiceArgs,
    StatsSaver,
};
use shared_types::stats::StageStats;
use shared_types::transport::{Endpoint, Stage};

#[derive(Parser)]
#[command(about = "dualgeo geolocation service (started by `dualgeo run`)")]
struct Args {
    #[command(flatten)]
    service: ServiceArgs,
}

/// The checkpoint left by a previous incarnation, if there is one to trust.
fn resume(
    path: Option<&std::path::Path>,
    config: &EstimatorConfig,
    temporal: &mut Option<TemporalEstimator>,
    tracks: &mut Tracks,
    track_config: TrackConfig,
    stats: &mut StageStats,
) -> Option<(u64, f64, u32)> {
    let found = match checkpoint::read::<Resume>(path?, CHECKPOINT_KIND) {
        Ok(found) => found?,
        Err(e) => {
            stats.count("checkpoint_refused", 1);
            tracing::warn!("checkpoint ignored, starting fresh: {e}");
            return None;
        }
    };
    if let (Some(t), Some(snap)) = (temporal.as_mut(), &found.filter) {
        match TemporalEstimator::restore(*config, snap) {
            Ok(f) => *t = f,
            Err(e) => {
                stats.count("checkpoint_refused", 1);
                tracing::warn!("filter state ignored, starting fresh: {e}");
            }
        }
    }
    if let Some(snap) = &found.tracks {
        match Tracks::restore(track_config, snap) {
            Ok(t) => *tracks = t,
            Err(e) => {
                stats.count("checkpoint_refused", 1);
                tracing::warn!("tracks ignored, starting fresh: {e}");
                // Fresh tracks, but no id given twice.
                tracks.keep_ids_below(snap.next_id);
            }
        }
    }
    stats.count("resumed", 1);
    tracing::info!(
        pair = found.last_pair_seq,
        t_s = found.last_t_s,
        "resumed from the checkpoint"
    );
    Some((found.last_pair_seq, found.last_t_s, found.segment))
}

/// Exits with [`shell::EXIT_PERMANENT`] when the input or configuration was refused
/// (the supervisor does not restart that), 1 on any other failure.
fn main() -> std::process::ExitCode {
    shell::exit_code(run())
}

fn run() -> Result<()> {
    let args = Args::parse();
    init_tracing("geolocation");
    apply_realtime(args.service.config.as_deref(), "geolocation")
        .map_err(|e| Permanent::new("[realtime]", e))?;
    let config: EstimatorConfig = load_section(args.service.config.as_deref(), "estimator")?;
    config
        .validate()
        .map_err(|e| Permanent::new("[estimator] configuration", e))?;
    let track_config: TrackConfig = load_section(args.service.config.as_deref(), "tracks")?;
    let mut tracks =
        Tracks::new(track_config).map_err(|e| Permanent::new("[tracks] configuration", e))?;
    let endpoint = Endpoint::new(&args.service.run_id, "geolocation")?;
    let subscriber = endpoint.subscriber::<ObservationSetMsg>(Topic::Observations)?;
    let publisher = endpoint.publisher::<EstimateMsg>(Topic::Estimates)?;
    let wake_supervisor = endpoint.notifier(Stage::Supervisor)?;
    let listener = endpoint.listener(Stage::Geolocation)?;
    let mut stats = StageStats::new("geolocation");
    let mut gaps = SeqGaps::default();
    // Every set is estimated, late or not: the filter's update is well under a
    // millisecond and a skipped set's information would be lost for every later
    // estimate. Late ones are counted (`estimates_late`).
    let mut deadlines = Deadlines::<1>::new(args.service.flow_controlled);
    let mut temporal = match config.method {
        EstimatorMethod::Temporal => Some(TemporalEstimator::new(config)?),
        _ => None,
    };
    let state_path = args.service.state_file("geolocation.ckpt");
    let mut last = resume(
        state_path.as_deref(),
        &config,
        &mut temporal,
        &mut tracks,
        track_config,
        &mut stats,
    );
    let mut geolocator = Geolocator::new(config, track_config, temporal, tracks);
    let mut saver = StatsSaver::new(&args.service);
    let mut trace = args.service.tracer("geolocation");
    tracing::info!(run = endpoint.run_id(), method = ?config.method, incarnation = args.service.incarnation, "geolocation ready");

    let stop = serve(&listener, |wake| -> Result<bool> {
        let mut first = true;
        while let Some(sample) = subscriber.receive().context("receive observations")? {
            let set = sample.payload();
            if first {
                if let Some(us) = wake.hop_us(set.published_ns) {
                    stats.record("transport", us);
                }
                first = false;
            }
            let start = monotonic_ns();
            let (set_pair, set_published, set_segment) =
                (set.pair_seq, set.published_ns, set.segment);
            stats.record("wait", elapsed_us(set.published_ns, start));
            stats.count("sets", 1);
            stats.count("sets_lost", gaps.see(set.set_seq));
            let step = segment_step(set.segment, last.map(|(_, _, s)| s));
            if step == SegmentStep::Old || is_stale(set.t_s, last.map(|(_, t, _)| t)) {
                stats.count("stale_sets", 1);
                continue;
            }
            if step == SegmentStep::New {
                geolocator.start_over();
                stats.count("segments", 1);
            }
            let unseen = set.refused == ObservationSetMsg::TARGET_UNSEEN;
            let mut msg = geolocator.estimate(set, &mut stats);
            drop(sample);
            // A pair without the target and without a track to report says nothing:
            // nothing is published (nor checkpointed, nor timed). It was seen all the
            // same: a new segment it started is not started again by the next set.
            if unseen && msg.track_count == 0 {
                last = Some((msg.pair_seq, msg.t_s, set_segment));
                continue;
            }
            let done = monotonic_ns();
            stats.record("compute", elapsed_us(start, done));
            msg.published_ns = monotonic_ns();
            stats.record("end_to_end", elapsed_us(msg.capture_ns, msg.published_ns));
            deadlines.see(0, msg.t_s);
            if deadlines.verdict(0, msg.capture_ns, msg.published_ns, false) == Verdict::Late {
                stats.count("estimates_late", 1);
            }
            trace.span("wait", set_pair, None, set_published, start);
            trace.span("estimate", set_pair, None, start, done);
            trace.span(
                "end_to_end",
                msg.pair_seq,
                None,
                msg.capture_ns,
                msg.published_ns,
            );
            publisher.send_copy(msg).context("publish estimate")?;
            // Against the supervisor's count of those it received: `estimates_lost`.
            stats.count("published", 1);
            wake_supervisor.notify().context("wake supervisor")?;
            last = Some((msg.pair_seq, msg.t_s, set_segment));
            if let Some(path) = &state_path {
                let state = Resume {
                    last_pair_seq: msg.pair_seq,
                    last_t_s: msg.t_s,
                    segment: set_segment,
                    filter: geolocator
                        .temporal
                        .as_ref()
                        .map(TemporalEstimator::snapshot),
                    tracks: track_config.enabled.then(|| geolocator.tracks.snapshot()),
                };
                let t0 = monotonic_ns();
                match checkpoint::write(path, CHECKPOINT_KIND, &state) {
                    Ok(()) => stats.record("checkpoint", elapsed_us(t0, monotonic_ns())),
                    Err(e) => {
                        stats.count("checkpoint_failed", 1);
                        tracing::warn!("checkpoint not written: {e}");
                    }
                }
            }
        }
        saver.tick(&stats);
        trace.maybe_flush();
        Ok(true)
    })?;
    trace.flush();
    let path = saver.finish(&stats)?;
    tracing::info!(?stop, stats = %path.display(), "geolocation stopped");
    Ok(())
}
