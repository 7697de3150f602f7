//! What `dualgeo run` leaves in `--out`:
//!
//! - `track.csv`: one row per estimate, written as the run goes (`track.rs`).
//! - `track.geojson`: the target's track and every other vehicle's as WGS84 LineStrings
//!   ([lon, lat, alt]; one feature each, property `track_id`) when the source has an
//!   origin, made from track.csv at the end.
//! - `path.png`: the estimated path against truth, when truth exists.
//! - `latency/<row>.hgrm` and `latency.png`: the latency percentile distributions.
//! - `report.json`: exactly `frames_in`, `pairs_in`, `estimates_out`, `frames_dropped`,
//!   `accuracy` (null without truth), `latency_us`, `throughput_hz`, `restarts` (per
//!   service), `pairs_lost_in_restarts` and `recovery_ms` (death seen → estimates
//!   resumed: count, p50, p99, max; null without restarts).
//! - `counters.json`: every stage's counters (drops by cause, rejections by reason),
//!   with `supervisor.restarts.<service>`, `supervisor.pairs_lost_in_restarts` and,
//!   when some were, `supervisor.estimates_lost` (published by geolocation, never
//!   received: a queue overflowed).
//! - `soak.csv`, `soak.png`: memory, descriptors and latency per `--sample-every-s`
//!   (`soak.rs`), with the flatness verdict printed.
//! - `restarts.csv`: one row per death (service, incarnation, status, and the
//!   CLOCK_MONOTONIC times it was seen, restarted, and estimates resumed).
//! - `stats/` (each stage's raw histograms) and `stream/` (what the live simulator
//!   streamed: telemetry.csv, truth.csv).

use super::accuracy::{accuracy, pair_with_truth, Accuracy};
use super::collect::Collected;
use super::latency::{self, Gathered, LatencyReport};
use super::plots;
use super::track::{geodetic, read_back, read_other_tracks};
use super::RunArgs;
use acquisition::flight::FlightMeta;
use acquisition::recording::Origin;
use anyhow::{Context, Result};
use serde::Serialize;
use shared_types::messages::EstimateMsg;
use std::path::{Path, PathBuf};

#[derive(Serialize)]
struct Report {
    frames_in: u64,
    pairs_in: u64,
    estimates_out: u64,
    frames_dropped: u64,
    accuracy: Option<Accuracy>,
    latency_us: LatencyReport,
    throughput_hz: f64,
    restarts: std::collections::BTreeMap<String, u64>,
    pairs_lost_in_restarts: u64,
    recovery_ms: Option<Recovery>,
}

#[derive(Serialize)]
struct Recovery {
    count: usize,
    /// Deaths after which no estimate came before the run ended.
    unrecovered: usize,
    p50: f64,
    p99: f64,
    max: f64,
}

fn recovery(c: &Collected) -> Option<Recovery> {
    let restarts = &c.supervision.restarts;
    if restarts.is_empty() {
        return None;
    }
    let mut ms: Vec<f64> = restarts.iter().filter_map(|r| r.recovery_ms()).collect();
    ms.sort_by(f64::total_cmp);
    let pick = |q: f64| {
        ms.get(((ms.len() as f64 * q).ceil() as usize).saturating_sub(1))
            .copied()
            .unwrap_or(f64::NAN)
    };
    Some(Recovery {
        count: restarts.len(),
        unrecovered: restarts.len() - ms.len(),
        p50: pick(0.5),
        p99: pick(0.99),
        max: ms.last().copied().unwrap_or(f64::NAN),
    })
}

fn write_restarts_csv(path: &Path, c: &Collected) -> Result<()> {
    let mut w =
        csv::Writer::from_path(path).with_context(|| format!("create {}", path.display()))?;
    w.write_record([
        "service",
        "incarnation",
        "status",
        "died_ns",
        "restarted_ns",
        "resumed_ns",
        "recovery_ms",
        "pairs_lost",
    ])?;
    let opt = |v: Option<u64>| v.map_or(String::new(), |v| v.to_string());
    for r in &c.supervision.restarts {
        w.write_record([
            r.service.to_string(),
            r.incarnation.to_string(),
            r.status.clone(),
            r.died_ns.to_string(),
            opt(r.restarted_ns),
            opt(r.resumed_ns),
            r.recovery_ms().map_or(String::new(), |v| format!("{v:.1}")),
            r.pairs_lost().to_string(),
        ])?;
    }
    w.flush()
        .with_context(|| format!("write {}", path.display()))?;
    Ok(())
}

/// Where truth lives, the frame rate and the geodetic origin of the run's source.
pub(super) fn source_facts(
    args: &RunArgs,
    stream_dir: &Path,
) -> Result<(PathBuf, f64, Option<Origin>)> {
    if args.source == "sim" {
        let config = args.scenario.config()?;
        Ok((
            stream_dir.to_path_buf(),
            config.frame_rate_hz,
            config.origin,
        ))
    } else if args.source.ends_with(".toml") {
        // A flight: its truth.csv and telemetry.csv (evaluation only, format v1) sit
        // beside it; without them the report has no accuracy block.
        let path = Path::new(&args.source);
        let meta = FlightMeta::read(path).map_err(anyhow::Error::msg)?;
        let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        Ok((dir, meta.frame_rate_hz, Some(meta.origin)))
    } else {
        // The whole recording is checked by the reader acquisition uses (metadata,
        // every CSV row, the image files' presence) before any process starts: a
        // recording it refuses is an error here, not an acquisition that exits and is
        // restarted.
        let dir = PathBuf::from(&args.source);
        let meta = acquisition::recording::Recording::open(&dir)
            .with_context(|| format!("--source {}", dir.display()))?
            .meta;
        Ok((dir, meta.frame_rate_hz, meta.origin))
    }
}

/// The geoid height a source states (a flight's `geoid_height_m`), 0 for the others.
pub(super) fn source_geoid_height(args: &RunArgs) -> Result<f64> {
    if args.source.ends_with(".toml") {
        let meta = FlightMeta::read(Path::new(&args.source)).map_err(anyhow::Error::msg)?;
        return Ok(meta.geoid_height_m);
    }
    Ok(0.0)
}

fn frames_dropped(g: &Gathered) -> u64 {
    super::latency::frames_dropped_of(|stage, name| g.counter(stage, name))
}

/// The target's track and every other vehicle's as WGS84 LineStrings, one feature
/// each (`track_id` 0 the target).
fn write_geojson(
    path: &Path,
    estimates: &[EstimateMsg],
    others: &std::collections::BTreeMap<u32, Vec<[f64; 3]>>,
    origin: &Origin,
) -> Result<()> {
    use geojson::{Feature, FeatureCollection, Geometry, Value};
    let feature = |id: u32, name: String, points: &mut dyn Iterator<Item = [f64; 3]>| {
        let line: Vec<Vec<f64>> = points
            .map(|p| {
                let (lat, lon, alt) = geodetic(origin, &p);
                vec![lon, lat, alt]
            })
            .collect();
        let mut props = geojson::JsonObject::new();
        props.insert("name".into(), name.into());
        props.insert("track_id".into(), id.into());
        props.insert("estimates".into(), line.len().into());
        // A LineString needs two positions: a one-estimate track is a Point.
        let geometry = match line.as_slice() {
            [one] => Value::Point(one.clone()),
            _ => Value::LineString(line),
        };
        Feature {
            geometry: Some(Geometry::new(geometry)),
            properties: Some(props),
            ..Default::default()
        }
    };
    let mut features = vec![feature(
        0,
        "dualgeo target track".into(),
        &mut estimates.iter().map(|e| e.position),
    )];
    for (id, points) in others {
        features.push(feature(
            *id,
            format!("dualgeo vehicle {id}"),
            &mut points.iter().copied(),
        ));
    }
    let collection = FeatureCollection {
        features,
        bbox: None,
        foreign_members: None,
    };
    std::fs::write(path, collection.to_string())
        .with_context(|| format!("write {}", path.display()))
}

pub fn write_all(
    args: &RunArgs,
    out: &Path,
    stats_dir: &Path,
    stream_dir: &Path,
    c: &Collected,
) -> Result<()> {
    let mut supervisor = c.stats.clone();
    for (service, n) in c.supervision.counts() {
        supervisor.count(&format!("restarts.{service}"), n);
    }
    supervisor.count("pairs_lost_in_restarts", c.supervision.pairs_lost());
    let mut gathered = Gathered::load(stats_dir, &supervisor)?;
    // Estimates geolocation published that the supervisor never received (its queue
    // overflowed while it was starved): track.csv lacks them.
    let lost = gathered
        .counter("geolocation", "published")
        .saturating_sub(c.messages);
    if lost > 0 {
        eprintln!("{lost} estimates published by geolocation never reached the outputs (the supervisor fell behind)");
        if let Some(s) = gathered.stages.get_mut("supervisor") {
            s.count("estimates_lost", lost);
        }
    }
    let (truth_dir, frame_rate_hz, origin) = source_facts(args, stream_dir)?;
    let ok = read_back(&out.join("track.csv"))?;
    let others = read_other_tracks(&out.join("track.csv"))?;
    match &origin {
        Some(o) => write_geojson(&out.join("track.geojson"), &ok, &others, o)?,
        None => eprintln!("the source has no geodetic origin: track.geojson not written"),
    }
    let paired = pair_with_truth(&truth_dir, &ok, frame_rate_hz)?;
    let acc = paired.as_ref().and_then(accuracy);
    if let Some(p) = &paired {
        let est: Vec<[f64; 2]> = p
            .iter()
            .map(|(e, _, _)| [e.position[0], e.position[1]])
            .collect();
        let truth: Vec<[f64; 2]> = p.iter().map(|(_, t, _)| [t[0], t[1]]).collect();
        if !est.is_empty() {
            plots::path_against_truth(&out.join("path.png"), &est, &truth)?;
        }
    }
    let rows = latency::write_hgrm(&gathered, &out.join("latency"))?;
    if !rows.is_empty() {
        plots::latency_percentiles(&out.join("latency.png"), &rows)?;
    }
    let secs = (c.end_ns.saturating_sub(c.start_ns)) as f64 * 1e-9;
    let report = Report {
        frames_in: gathered.counter("acquisition", "frames_in"),
        pairs_in: gathered.counter("acquisition", "pairs_in"),
        estimates_out: ok.len() as u64,
        frames_dropped: frames_dropped(&gathered),
        accuracy: acc,
        latency_us: latency::report(&gathered),
        throughput_hz: if secs > 0.0 {
            ok.len() as f64 / secs
        } else {
            0.0
        },
        restarts: c.supervision.counts(),
        pairs_lost_in_restarts: c.supervision.pairs_lost(),
        recovery_ms: recovery(c),
    };
    write_restarts_csv(&out.join("restarts.csv"), c)?;
    let samples = &c.sampler.samples;
    if !samples.is_empty() {
        plots::soak(&out.join("soak.png"), samples)?;
    }
    let json = serde_json::to_string_pretty(&report)?;
    std::fs::write(out.join("report.json"), &json).context("write report.json")?;
    std::fs::write(
        out.join("counters.json"),
        serde_json::to_string_pretty(&gathered.counters())?,
    )
    .context("write counters.json")?;

    println!("{}", latency::table(&gathered));
    println!(
        "frames in {}, pairs in {}, estimates out {}, frames dropped {}, throughput {:.1} estimates/s over {:.1} s{}",
        report.frames_in,
        report.pairs_in,
        report.estimates_out,
        report.frames_dropped,
        report.throughput_hz,
        secs,
        if c.interrupted { " (stopped by signal)" } else { "" }
    );
    match &report.accuracy {
        Some(a) => println!(
            "accuracy vs truth (m): MAE x {:.3} y {:.3} z {:.3} | STD x {:.3} y {:.3} z {:.3} | MAX x {:.3} y {:.3} z {:.3}\nyaw-bias MAE (deg): left {:.2} right {:.2}",
            a.mae_m.x, a.mae_m.y, a.mae_m.z, a.std_m.x, a.std_m.y, a.std_m.z, a.max_m.x, a.max_m.y, a.max_m.z,
            a.yaw_bias_mae_deg.left, a.yaw_bias_mae_deg.right
        ),
        None => println!("accuracy: no truth for this source"),
    }
    if let Some(r) = &report.recovery_ms {
        println!(
            "restarts {} ({}), pairs lost in restarts {}, estimates resumed after p50 {:.0} ms, p99 {:.0} ms, max {:.0} ms{}",
            r.count,
            report
                .restarts
                .iter()
                .filter(|(_, n)| **n > 0)
                .map(|(s, n)| format!("{s} {n}"))
                .collect::<Vec<_>>()
                .join(", "),
            report.pairs_lost_in_restarts,
            r.p50,
            r.p99,
            r.max,
            if r.unrecovered > 0 {
                format!(" ({} without an estimate before the end)", r.unrecovered)
            } else {
                String::new()
            }
        );
    }
    if !samples.is_empty() {
        for line in super::soak::verdict(samples, args.soak_warm_up_s) {
            println!("{line}");
        }
    }
    let bad = gathered.counter("acquisition", "bad_frames");
    if bad > 0 {
        println!("{bad} pair(s) skipped for unreadable images (see the acquisition log above)");
    }
    println!("outputs in {}", out.display());
    Ok(())
}
