//! `track.csv`, written as the run goes (issue #13): one row per valid estimate,
//! flushed at least every [`FLUSH_EVERY`], so a day-long run holds no estimate in
//! memory and a killed supervisor leaves the track up to its last flush. The GeoJSON,
//! the accuracy and the path plot are made from the file at the end
//! ([`read_back`]).
//!
//! Columns: t_s, pair_seq, x_m, y_m, z_m, lat_deg, lon_deg, alt_m (empty without a
//! geodetic origin), yaw_bias_left_deg, yaw_bias_right_deg, images_used, iterations,
//! h_acc_m, v_acc_m (1σ horizontal and vertical accuracy), quality (`converging`: the
//! yaw biases are not yet known and the accuracy says so; `tracking`; `coasting`: no
//! ray of the current pair was taken, the estimate is the filter's prediction),
//! track_id (0: the target; from 1: the other vehicles' confirmed tracks, one row each
//! per pair after the target's, with the target's yaw biases, which they share (empty
//! when the target's estimate of that pair was rejected), and images_used and
//! iterations 0).

use acquisition::recording::Origin;
use anyhow::{Context, Result};
use shared_types::messages::{EstimateMsg, EstimateStatus};
use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub const FLUSH_EVERY: Duration = Duration::from_millis(500);

const HEADER: [&str; 16] = [
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
    "quality",
    "track_id",
];

pub fn geodetic(origin: &Origin, p: &[f64; 3]) -> (f64, f64, f64) {
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
pub fn one_sigma(e: &EstimateMsg) -> Option<(f64, f64)> {
    let h = (e.covariance[0] + e.covariance[5]).sqrt();
    let v = e.altitude_std_error_m;
    (h.is_finite() && v.is_finite()).then_some((h, v))
}

/// The lat_deg, lon_deg, alt_m cells of position `p` (empty without an origin).
fn geodetic_cells(origin: Option<&Origin>, p: &[f64; 3]) -> [String; 3] {
    match origin.map(|o| geodetic(o, p)) {
        Some((lat, lon, alt)) => [
            format!("{lat:.8}"),
            format!("{lon:.8}"),
            format!("{alt:.3}"),
        ],
        None => Default::default(),
    }
}

pub struct TrackWriter {
    path: PathBuf,
    w: csv::Writer<File>,
    origin: Option<Origin>,
    last_flush: Instant,
    /// Valid estimates written.
    pub rows: u64,
}

impl TrackWriter {
    pub fn create(path: &Path, origin: Option<Origin>) -> Result<Self> {
        let mut w =
            csv::Writer::from_path(path).with_context(|| format!("create {}", path.display()))?;
        w.write_record(HEADER)?;
        w.flush()?;
        Ok(Self {
            path: path.to_path_buf(),
            w,
            origin,
            last_flush: Instant::now(),
            rows: 0,
        })
    }

    /// Writes the target's row if `e` is a valid estimate, and a row per other track
    /// it carries (those come with a rejected target estimate too).
    pub fn push(&mut self, e: &EstimateMsg) -> Result<()> {
        if e.status == EstimateStatus::Ok as u32 {
            self.push_target(e)?;
        }
        self.push_tracks(e)?;
        if self.last_flush.elapsed() >= FLUSH_EVERY {
            self.flush()?;
        }
        Ok(())
    }

    fn push_target(&mut self, e: &EstimateMsg) -> Result<()> {
        let [lat, lon, alt] = geodetic_cells(self.origin.as_ref(), &e.position);
        let sigma = one_sigma(e);
        self.w
            .write_record([
                format!("{:.6}", e.t_s),
                e.pair_seq.to_string(),
                format!("{:.3}", e.position[0]),
                format!("{:.3}", e.position[1]),
                format!("{:.3}", e.position[2]),
                lat,
                lon,
                alt,
                format!("{:.3}", e.yaw_bias_deg[0]),
                format!("{:.3}", e.yaw_bias_deg[1]),
                e.images_used.to_string(),
                e.iterations.to_string(),
                sigma.map_or(String::new(), |(h, _)| format!("{h:.3}")),
                sigma.map_or(String::new(), |(_, v)| format!("{v:.3}")),
                geolocation::Quality::from_index(e.quality)
                    .map_or("unknown", |q| q.name())
                    .to_string(),
                "0".to_string(),
            ])
            .with_context(|| format!("write {}", self.path.display()))?;
        self.rows += 1;
        Ok(())
    }

    fn push_tracks(&mut self, e: &EstimateMsg) -> Result<()> {
        // The shared biases are the target's estimate's: unknown on a pair whose
        // target estimate was rejected (its tracks then coast).
        let bias = |k: usize| {
            if e.status == EstimateStatus::Ok as u32 {
                format!("{:.3}", e.yaw_bias_deg[k])
            } else {
                String::new()
            }
        };
        for t in e.tracks() {
            let [lat, lon, alt] = geodetic_cells(self.origin.as_ref(), &t.position);
            let h = (t.covariance_xy[0] + t.covariance_xy[3]).max(0.0).sqrt();
            self.w
                .write_record([
                    format!("{:.6}", e.t_s),
                    e.pair_seq.to_string(),
                    format!("{:.3}", t.position[0]),
                    format!("{:.3}", t.position[1]),
                    format!("{:.3}", t.position[2]),
                    lat,
                    lon,
                    alt,
                    bias(0),
                    bias(1),
                    "0".to_string(),
                    "0".to_string(),
                    format!("{h:.3}"),
                    format!("{:.3}", t.altitude_std_error_m),
                    geolocation::Quality::from_index(u64::from(t.quality))
                        .map_or("unknown", |q| q.name())
                        .to_string(),
                    t.id.to_string(),
                ])
                .with_context(|| format!("write {}", self.path.display()))?;
        }
        Ok(())
    }

    pub fn flush(&mut self) -> Result<()> {
        self.last_flush = Instant::now();
        self.w
            .flush()
            .with_context(|| format!("write {}", self.path.display()))
    }
}

/// The target's valid estimates in a track file (track_id 0; every row of a file
/// written before the column), with what the file keeps of them (time, pair,
/// position, biases; the rest default), for the end-of-run outputs.
pub fn read_back(path: &Path) -> Result<Vec<EstimateMsg>> {
    let mut r = csv::Reader::from_path(path).with_context(|| format!("read {}", path.display()))?;
    let mut out = Vec::new();
    for (i, row) in r.records().enumerate() {
        let row = row.with_context(|| format!("{} row {}", path.display(), i + 2))?;
        if row.get(15).is_some_and(|id| !id.is_empty() && id != "0") {
            continue;
        }
        let f = |k: usize| -> Result<f64> {
            row.get(k)
                .and_then(|v| v.parse::<f64>().ok())
                .with_context(|| format!("{} row {} column {}", path.display(), i + 2, k + 1))
        };
        out.push(EstimateMsg {
            t_s: f(0)?,
            pair_seq: row.get(1).and_then(|v| v.parse().ok()).unwrap_or(0),
            position: [f(2)?, f(3)?, f(4)?],
            yaw_bias_deg: [f(8)?, f(9)?],
            status: EstimateStatus::Ok as u32,
            ..Default::default()
        });
    }
    Ok(out)
}

/// The other vehicles' tracks in a track file (track_id ≥ 1): per id, its positions
/// (x, y, z, ENU metres) in file order.
pub fn read_other_tracks(path: &Path) -> Result<std::collections::BTreeMap<u32, Vec<[f64; 3]>>> {
    let mut r = csv::Reader::from_path(path).with_context(|| format!("read {}", path.display()))?;
    let mut out: std::collections::BTreeMap<u32, Vec<[f64; 3]>> = Default::default();
    for (i, row) in r.records().enumerate() {
        let row = row.with_context(|| format!("{} row {}", path.display(), i + 2))?;
        let Some(id) = row.get(15).and_then(|v| v.parse::<u32>().ok()) else {
            continue;
        };
        if id == 0 {
            continue;
        }
        let f = |k: usize| -> Result<f64> {
            row.get(k)
                .and_then(|v| v.parse::<f64>().ok())
                .with_context(|| format!("{} row {} column {}", path.display(), i + 2, k + 1))
        };
        out.entry(id).or_default().push([f(2)?, f(3)?, f(4)?]);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_stream_to_disk_and_read_back() {
        let dir = std::env::temp_dir().join(format!("dualgeo-track-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("track.csv");
        let mut w = TrackWriter::create(&path, None).unwrap();
        let mut e = EstimateMsg {
            t_s: 1.5,
            pair_seq: 45,
            position: [1.0, -2.0, 3.25],
            yaw_bias_deg: [20.5, -3.0],
            status: EstimateStatus::Ok as u32,
            ..Default::default()
        };
        w.push(&e).unwrap();
        e.status = EstimateStatus::Rejected as u32;
        w.push(&e).unwrap();
        w.flush().unwrap();
        // On disk before the writer is finished with.
        let back = read_back(&path).unwrap();
        assert_eq!(back.len(), 1);
        assert_eq!((back[0].t_s, back[0].pair_seq), (1.5, 45));
        assert_eq!(back[0].position, [1.0, -2.0, 3.25]);
        assert_eq!(back[0].yaw_bias_deg, [20.5, -3.0]);
        assert_eq!(w.rows, 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Another vehicle's track is a row of its own with its id; the end-of-run outputs
    /// read the target's rows only.
    #[test]
    fn other_tracks_get_rows_of_their_own() {
        let dir = std::env::temp_dir().join(format!("dualgeo-tracks-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("track.csv");
        let mut w = TrackWriter::create(&path, None).unwrap();
        let mut e = EstimateMsg {
            t_s: 2.0,
            pair_seq: 60,
            position: [1.0, 2.0, 13.5],
            yaw_bias_deg: [20.0, -20.0],
            status: EstimateStatus::Ok as u32,
            track_count: 1,
            ..Default::default()
        };
        e.tracks[0] = shared_types::messages::TrackEstimate {
            id: 3,
            quality: 2,
            position: [9.0, 8.0, 13.0],
            covariance_xy: [0.09, 0.0, 0.0, 0.16],
            altitude_std_error_m: 0.5,
            velocity_mps: [1.0, 0.0],
        };
        w.push(&e).unwrap();
        w.flush().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let rows: Vec<&str> = text.lines().collect();
        assert!(rows[0].ends_with(",quality,track_id"));
        assert!(rows[1].ends_with(",converging,0"), "{}", rows[1]);
        assert_eq!(
            rows[2],
            "2.000000,60,9.000,8.000,13.000,,,,20.000,-20.000,0,0,0.500,0.500,coasting,3"
        );
        let back = read_back(&path).unwrap();
        assert_eq!(back.len(), 1);
        assert_eq!(back[0].position, [1.0, 2.0, 13.5]);
        let others = read_other_tracks(&path).unwrap();
        assert_eq!(others.len(), 1);
        assert_eq!(others[&3], vec![[9.0, 8.0, 13.0]]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
