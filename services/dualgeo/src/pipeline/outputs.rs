//! What `dualgeo run` leaves in `--out`:
//!
//! - `track.csv`: one row per estimate: t_s, pair_seq, x_m, y_m, z_m, lat_deg, lon_deg,
//!   alt_m (empty without a geodetic origin), yaw_bias_left_deg, yaw_bias_right_deg,
//!   images_used, iterations, h_acc_m, v_acc_m (1σ horizontal and vertical accuracy).
//! - `track.geojson`: the track as a WGS84 LineString ([lon, lat, alt]) when the source
//!   has an origin.
//! - `path.png`: the estimated path against truth, when truth exists.
//! - `latency/<row>.hgrm` and `latency.png`: the latency percentile distributions.
//! - `report.json`: exactly `frames_in`, `pairs_in`, `estimates_out`, `frames_dropped`,
//!   `accuracy` (null without truth), `latency_us`, `throughput_hz`.
//! - `counters.json`: every stage's counters (drops by cause, rejections by reason).
//! - `stats/` (each stage's raw histograms) and `stream/` (what the live simulator
//!   streamed: telemetry.csv, truth.csv).

use super::accuracy::{accuracy, pair_with_truth, Accuracy};
use super::collect::Collected;
use super::latency::{self, Gathered, LatencyReport};
use super::plots;
use super::RunArgs;
use acquisition::recording::{Origin, RecordingMeta};
use anyhow::{Context, Result};
use serde::Serialize;
use shared_types::messages::{EstimateMsg, EstimateStatus};
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
}

/// Where truth lives, the frame rate and the geodetic origin of the run's source.
fn source_facts(args: &RunArgs, stream_dir: &Path) -> Result<(PathBuf, f64, Option<Origin>)> {
    if args.source == "sim" {
        let config = args.scenario.config()?;
        Ok((
            stream_dir.to_path_buf(),
            config.frame_rate_hz,
            config.origin,
        ))
    } else {
        let dir = PathBuf::from(&args.source);
        let meta = RecordingMeta::read(&dir.join("recording.toml"))?;
        Ok((dir, meta.frame_rate_hz, meta.origin))
    }
}

/// Frames that entered the pipeline (or were due to) and never reached a geolocation
/// attempt: pairs acquisition could not loan (×2), frames overwritten before detection
/// or matching read them, frames matching skipped to stay current, and observation sets
/// geolocation missed (×2).
fn frames_dropped(g: &Gathered) -> u64 {
    2 * g.counter("acquisition", "pairs_dropped")
        + g.counter("detection", "frames_lost")
        + g.counter("matching", "frames_lost")
        + g.counter("matching", "frames_dropped")
        + 2 * g.counter("geolocation", "sets_lost")
}

fn geodetic(origin: &Origin, p: &[f64; 3]) -> (f64, f64, f64) {
    let (lat, lon, alt) = map_3d::enu2geodetic(
        p[0],
        p[1],
        p[2],
        origin.lat_deg.to_radians(),
        origin.lon_deg.to_radians(),
        origin.alt_m,
        map_3d::Ellipsoid::WGS84,
    );
    (lat.to_degrees(), lon.to_degrees(), alt)
}

/// 1σ horizontal and vertical accuracy (MAVLink CAMERA_TRACKING_GEO_STATUS's h_acc and
/// v_acc): √(σ_x² + σ_y²) from the estimate's covariance, and σ_z. `None` when the
/// estimator gave no finite figure.
fn one_sigma(e: &EstimateMsg) -> Option<(f64, f64)> {
    let h = (e.covariance[0] + e.covariance[5]).sqrt();
    let v = e.altitude_std_error_m;
    (h.is_finite() && v.is_finite()).then_some((h, v))
}

fn write_track_csv(path: &Path, estimates: &[&EstimateMsg], origin: Option<&Origin>) -> Result<()> {
    let mut w =
        csv::Writer::from_path(path).with_context(|| format!("create {}", path.display()))?;
    w.write_record([
        "t_s",
        "pair_seq",
        "x_m",
        "y_m",
        "z_m",
        "lat_deg",
        "lon_deg",
        "alt_m",
        "yaw_bias_left_deg",
        "yaw_bias_right_deg",
        "images_used",
        "iterations",
        "h_acc_m",
        "v_acc_m",
    ])?;
    for e in estimates {
        let geo = origin.map(|o| geodetic(o, &e.position));
        let g = |f: fn(&(f64, f64, f64)) -> f64, digits: usize| {
            geo.as_ref()
                .map_or(String::new(), |v| format!("{:.*}", digits, f(v)))
        };
        w.write_record([
            format!("{:.6}", e.t_s),
            e.pair_seq.to_string(),
            format!("{:.3}", e.position[0]),
            format!("{:.3}", e.position[1]),
            format!("{:.3}", e.position[2]),
            g(|v| v.0, 8),
            g(|v| v.1, 8),
            g(|v| v.2, 3),
            format!("{:.3}", e.yaw_bias_deg[0]),
            format!("{:.3}", e.yaw_bias_deg[1]),
            e.images_used.to_string(),
            e.iterations.to_string(),
            one_sigma(e).map_or(String::new(), |(h, _)| format!("{h:.3}")),
            one_sigma(e).map_or(String::new(), |(_, v)| format!("{v:.3}")),
        ])?;
    }
    w.flush()
        .with_context(|| format!("write {}", path.display()))?;
    Ok(())
}

fn write_geojson(path: &Path, estimates: &[&EstimateMsg], origin: &Origin) -> Result<()> {
    use geojson::{Feature, FeatureCollection, Geometry, Value};
    let line: Vec<Vec<f64>> = estimates
        .iter()
        .map(|e| {
            let (lat, lon, alt) = geodetic(origin, &e.position);
            vec![lon, lat, alt]
        })
        .collect();
    let mut props = geojson::JsonObject::new();
    props.insert("name".into(), "dualgeo target track".into());
    props.insert("estimates".into(), estimates.len().into());
    let feature = Feature {
        geometry: Some(Geometry::new(Value::LineString(line))),
        properties: Some(props),
        ..Default::default()
    };
    let collection = FeatureCollection {
        features: vec![feature],
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
    let gathered = Gathered::load(stats_dir, &c.stats)?;
    let (truth_dir, frame_rate_hz, origin) = source_facts(args, stream_dir)?;
    let ok: Vec<&EstimateMsg> = c
        .estimates
        .iter()
        .filter(|e| e.status == EstimateStatus::Ok as u32)
        .collect();

    write_track_csv(&out.join("track.csv"), &ok, origin.as_ref())?;
    match &origin {
        Some(o) => write_geojson(&out.join("track.geojson"), &ok, o)?,
        None => eprintln!("the source has no geodetic origin: track.geojson not written"),
    }
    let paired = pair_with_truth(&truth_dir, &c.estimates, frame_rate_hz)?;
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
    };
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
    let bad = gathered.counter("acquisition", "bad_frames");
    if bad > 0 {
        println!("{bad} pair(s) skipped for unreadable images (see the acquisition log above)");
    }
    println!("outputs in {}", out.display());
    Ok(())
}
