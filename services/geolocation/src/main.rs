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
//! `checkpoint_refused`, `checkpoint_failed`, `stale_sets`.

use anyhow::{Context, Result};
use clap::Parser;
use geolocation::{
    estimate_set, EstimatorConfig, EstimatorMethod, ImageId, Observation, TemporalEstimator,
    TemporalSnapshot,
};
use serde::{Deserialize, Serialize};
use shared_types::checkpoint;
use shared_types::clock::{elapsed_us, monotonic_ns};
use shared_types::messages::{EstimateMsg, EstimateStatus, ObservationSetMsg};
use shared_types::service_names::Topic;
use shared_types::shell::{init_tracing, load_section, serve, SeqGaps, ServiceArgs, StatsSaver};
use shared_types::stats::StageStats;
use shared_types::transport::{Endpoint, Stage};

#[derive(Parser)]
#[command(about = "dualgeo geolocation service (started by `dualgeo run`)")]
struct Args {
    #[command(flatten)]
    service: ServiceArgs,
}

/// The checkpoint's kind tag (`shared_types::checkpoint`).
const CHECKPOINT_KIND: u32 = 2;

/// What a restarted geolocation service resumes from.
#[derive(Serialize, Deserialize)]
struct Resume {
    /// Pair and stream time of the last estimate published.
    last_pair_seq: u64,
    last_t_s: f64,
    /// The temporal filter (`None` for the per-window methods, which keep no state).
    filter: Option<TemporalSnapshot>,
}

/// The checkpoint left by a previous incarnation, if there is one to trust.
fn resume(
    path: Option<&std::path::Path>,
    config: &EstimatorConfig,
    temporal: &mut Option<TemporalEstimator>,
    stats: &mut StageStats,
) -> Option<(u64, f64)> {
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
    stats.count("resumed", 1);
    tracing::info!(
        pair = found.last_pair_seq,
        t_s = found.last_t_s,
        "resumed from the checkpoint"
    );
    Some((found.last_pair_seq, found.last_t_s))
}

/// No NaN leaves this service: an estimate with a non-finite value is a rejection.
fn finite(msg: &EstimateMsg) -> bool {
    msg.position
        .iter()
        .chain(&msg.yaw_bias_deg)
        .chain(&msg.covariance)
        .all(|v| v.is_finite())
        && msg.altitude_std_error_m.is_finite()
}

/// The estimate of one observation set, or why there is none.
fn estimate(
    set: &ObservationSetMsg,
    config: &EstimatorConfig,
    temporal: Option<&mut TemporalEstimator>,
    stats: &mut StageStats,
) -> EstimateMsg {
    let mut msg = EstimateMsg {
        pair_seq: set.pair_seq,
        capture_ns: set.capture_ns,
        t_s: set.t_s,
        ..Default::default()
    };
    let observations: Result<Vec<Observation>, _> = set
        .entries()
        .iter()
        .enumerate()
        .map(|(i, e)| Observation::from_entry(e, i))
        .collect();
    let observations = match observations {
        Ok(o) if o.len() >= 2 && set.count as usize == o.len() => o,
        Ok(_) => {
            stats.count("bad_input", 1);
            tracing::warn!(
                pair = set.pair_seq,
                count = set.count,
                "observation set count is invalid"
            );
            msg.status = EstimateStatus::BadInput as u32;
            return msg;
        }
        Err(e) => {
            stats.count("bad_input", 1);
            tracing::warn!(pair = set.pair_seq, "observation set rejected: {e}");
            msg.status = EstimateStatus::BadInput as u32;
            return msg;
        }
    };
    let past: Vec<(ImageId, Observation)> = set.entries()[2..]
        .iter()
        .zip(&observations[2..])
        .map(|(entry, o)| ((o.uav, entry.frame_seq), *o))
        .collect();
    let current = [&observations[0], &observations[1]];
    let result = estimate_set(set.t_s, current, &past, config, temporal).map(|e| {
        if e.reopened {
            stats.count("temporal_reopened", 1);
            tracing::info!(
                pair = set.pair_seq,
                "bias step suspected: covariance re-opened"
            );
        }
        if e.velocity.is_some() {
            stats.count("temporal_rays_rejected", e.rays_rejected as u64);
        }
        e.estimate
    });
    match result {
        Ok(e) => {
            stats.count("estimates", 1);
            msg.position = [e.position.x, e.position.y, e.position.z];
            msg.yaw_bias_deg = [e.yaw_bias[0].to_degrees(), e.yaw_bias[1].to_degrees()];
            for (i, v) in e.covariance.transpose().iter().enumerate() {
                msg.covariance[i] = *v;
            }
            msg.altitude_std_error_m = e.altitude_std_error_m;
            msg.images_used = e.images_used as u32;
            msg.iterations = e.iterations as u32;
            msg.converged = e.converged as u32;
        }
        Err(e) => {
            stats.count(&format!("rejected.{}", e.kind()), 1);
            tracing::debug!(pair = set.pair_seq, "no estimate: {e}");
            msg.status = EstimateStatus::Rejected as u32;
        }
    }
    msg
}

fn main() -> Result<()> {
    let args = Args::parse();
    init_tracing("geolocation");
    let config: EstimatorConfig = load_section(args.service.config.as_deref(), "estimator")?;
    config.validate().context("[estimator] configuration")?;
    let endpoint = Endpoint::new(&args.service.run_id, "geolocation")?;
    let subscriber = endpoint.subscriber::<ObservationSetMsg>(Topic::Observations)?;
    let publisher = endpoint.publisher::<EstimateMsg>(Topic::Estimates)?;
    let wake_supervisor = endpoint.notifier(Stage::Supervisor)?;
    let listener = endpoint.listener(Stage::Geolocation)?;
    let mut stats = StageStats::new("geolocation");
    let mut gaps = SeqGaps::default();
    let mut temporal = match config.method {
        EstimatorMethod::Temporal => Some(TemporalEstimator::new(config)?),
        _ => None,
    };
    let state_path = args.service.state_file("geolocation.ckpt");
    let mut last = resume(state_path.as_deref(), &config, &mut temporal, &mut stats);
    let mut saver = StatsSaver::new(&args.service);
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
            stats.record("wait", elapsed_us(set.published_ns, start));
            stats.count("sets", 1);
            stats.count("sets_lost", gaps.see(set.set_seq));
            if matches!(last, Some((_, t)) if set.t_s <= t) {
                stats.count("stale_sets", 1);
                continue;
            }
            let mut msg = estimate(set, &config, temporal.as_mut(), &mut stats);
            drop(sample);
            if msg.status == EstimateStatus::Ok as u32 && !finite(&msg) {
                stats.count("rejected.non_finite", 1);
                msg.status = EstimateStatus::Rejected as u32;
            }
            let done = monotonic_ns();
            stats.record("compute", elapsed_us(start, done));
            msg.published_ns = monotonic_ns();
            stats.record("end_to_end", elapsed_us(msg.capture_ns, msg.published_ns));
            publisher.send_copy(msg).context("publish estimate")?;
            wake_supervisor.notify().context("wake supervisor")?;
            last = Some((msg.pair_seq, msg.t_s));
            if let Some(path) = &state_path {
                let state = Resume {
                    last_pair_seq: msg.pair_seq,
                    last_t_s: msg.t_s,
                    filter: temporal.as_ref().map(TemporalEstimator::snapshot),
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
        Ok(true)
    })?;
    let path = saver.finish(&stats)?;
    tracing::info!(?stop, stats = %path.display(), "geolocation stopped");
    Ok(())
}
