//! `dualgeo-geolocation`: the geolocation service shell. Wakes when matching publishes
//! an observation set, runs the paper's consistency filter (eq. 29–32) and the
//! altitude/regression iteration, and publishes an [`EstimateMsg`]. `[estimator] method`
//! selects `paper` (default), `joint`, or `temporal`: the temporal filter carries both
//! biases and the target across sets (it recognises reused keyframes by their frame
//! sequence numbers).
//!
//! Histograms (µs): `transport`, `wait`, `compute`, and `end_to_end` (frame capture →
//! estimate published). Counters: `sets`, `estimates`, `sets_lost`, `bad_input`,
//! `rejected.<reason>`.

use anyhow::{Context, Result};
use clap::Parser;
use geolocation::{
    estimate_set, EstimatorConfig, EstimatorMethod, ImageId, Observation, TemporalEstimator,
};
use shared_types::clock::{elapsed_us, monotonic_ns};
use shared_types::messages::{EstimateMsg, EstimateStatus, ObservationSetMsg};
use shared_types::service_names::Topic;
use shared_types::shell::{init_tracing, load_section, serve, SeqGaps, ServiceArgs};
use shared_types::stats::StageStats;
use shared_types::transport::{Endpoint, Stage};

#[derive(Parser)]
#[command(about = "dualgeo geolocation service (started by `dualgeo run`)")]
struct Args {
    #[command(flatten)]
    service: ServiceArgs,
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
    tracing::info!(run = endpoint.run_id(), method = ?config.method, "geolocation ready");

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
            let mut msg = estimate(set, &config, temporal.as_mut(), &mut stats);
            drop(sample);
            let done = monotonic_ns();
            stats.record("compute", elapsed_us(start, done));
            msg.published_ns = monotonic_ns();
            stats.record("end_to_end", elapsed_us(msg.capture_ns, msg.published_ns));
            publisher.send_copy(msg).context("publish estimate")?;
            wake_supervisor.notify().context("wake supervisor")?;
        }
        Ok(true)
    })?;
    let path = stats.save(&args.service.stats_dir)?;
    tracing::info!(?stop, stats = %path.display(), "geolocation stopped");
    Ok(())
}
