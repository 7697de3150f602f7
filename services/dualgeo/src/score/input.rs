//! What `dualgeo score` reads: a recording's truth (every vehicle's from
//! truth_targets.csv, else the one target's from truth.csv) and a run's track.csv,
//! turned into one [`Frame`] per stereo pair. Evaluation only.

use super::metrics::{Frame, Object};
use acquisition::recording::{read_targets_truth, Recording, TRUTH_TARGETS_FILE};
use anyhow::{bail, Context, Result};
use shared_types::conventions::Uav;
use std::collections::BTreeMap;
use std::path::Path;

/// A track.csv row as the scorer needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackRow {
    pub t_s: f64,
    /// 0 when the file has no `track_id` column (one target).
    pub track_id: u32,
    pub p: [f64; 3],
    /// Left, right, degrees, when the file has them.
    pub yaw_bias_deg: Option<[f64; 2]>,
    /// The stated horizontal accuracy (1σ, metres), when the file has it.
    pub h_acc_m: Option<f64>,
    /// The stated vertical accuracy (1σ, metres), when the file has it.
    pub v_acc_m: Option<f64>,
}

/// Reads a track.csv by its column names (`t_s`, `x_m`, `y_m`, `z_m`; `track_id`,
/// `yaw_bias_left_deg`, `yaw_bias_right_deg`, `h_acc_m`, `v_acc_m` when present), so files
/// written before and after `track_id` read alike.
pub fn read_track(path: &Path) -> Result<Vec<TrackRow>> {
    let mut r = csv::Reader::from_path(path).with_context(|| format!("open {}", path.display()))?;
    let headers = r
        .headers()
        .with_context(|| format!("read {}", path.display()))?
        .clone();
    let column = |name: &str| headers.iter().position(|h| h == name);
    let required = |name: &str| {
        column(name).with_context(|| format!("{}: no `{name}` column", path.display()))
    };
    let (t, x, y, z) = (
        required("t_s")?,
        required("x_m")?,
        required("y_m")?,
        required("z_m")?,
    );
    let id = column("track_id");
    let bias = column("yaw_bias_left_deg").zip(column("yaw_bias_right_deg"));
    let h_acc = column("h_acc_m");
    let v_acc = column("v_acc_m");
    let mut rows = Vec::new();
    for (i, record) in r.records().enumerate() {
        let line = i + 2;
        let record = record.with_context(|| format!("{}: line {line}", path.display()))?;
        let number = |c: usize| -> Result<f64> {
            let text = record.get(c).unwrap_or("");
            let v: f64 = text.parse().with_context(|| {
                format!(
                    "{}: line {line}, column {}: \"{text}\" is not a number",
                    path.display(),
                    &headers[c]
                )
            })?;
            if !v.is_finite() {
                bail!(
                    "{}: line {line}, column {}: not finite",
                    path.display(),
                    &headers[c]
                );
            }
            Ok(v)
        };
        let track_id = match id {
            Some(c) => {
                let text = record.get(c).unwrap_or("");
                text.parse().with_context(|| {
                    format!(
                        "{}: line {line}: \"{text}\" is not a track id",
                        path.display()
                    )
                })?
            }
            None => 0,
        };
        // Empty on a row without them (another vehicle's, when the target's estimate
        // of its pair was rejected).
        let present = |c: usize| record.get(c).is_some_and(|t| !t.is_empty());
        let yaw_bias_deg = match bias {
            Some((l, r)) if present(l) || present(r) => Some([number(l)?, number(r)?]),
            _ => None,
        };
        let stated = |col: Option<usize>| -> Result<Option<f64>> {
            match col {
                Some(c) if present(c) => Ok(Some(number(c)?)),
                _ => Ok(None),
            }
        };
        let (h_acc_m, v_acc_m) = (stated(h_acc)?, stated(v_acc)?);
        rows.push(TrackRow {
            t_s: number(t)?,
            track_id,
            p: [number(x)?, number(y)?, number(z)?],
            yaw_bias_deg,
            h_acc_m,
            v_acc_m,
        });
    }
    Ok(rows)
}

/// Everything the scorer compares.
#[derive(Debug, Clone, PartialEq)]
pub struct Loaded {
    /// One per stereo pair from the run's first estimate (after the warm-up) to the
    /// recording's end.
    pub frames: Vec<Frame>,
    /// |estimated − true| yaw bias, left and right, degrees: one per scored pair with
    /// an estimate (the biases are shared by every track of a pair).
    pub bias_errors_deg: Vec<[f64; 2]>,
    /// Which truth file described the vehicles.
    pub truth_file: &'static str,
    /// track.csv rows at no pair of the recording (within half a frame period), and
    /// rows of a track already seen at their pair (the one nearest the pair's time is
    /// kept).
    pub unpaired_rows: u64,
}

impl Loaded {
    /// The mean of [`Loaded::bias_errors_deg`], left and right; `None` without any.
    pub fn yaw_bias_mae_deg(&self) -> Option<[f64; 2]> {
        let n = self.bias_errors_deg.len();
        (n > 0).then(|| {
            let sum = self
                .bias_errors_deg
                .iter()
                .fold([0.0, 0.0], |a, e| [a[0] + e[0], a[1] + e[1]]);
            sum.map(|s| s / n as f64)
        })
    }
}

fn wrap_deg(d: f64) -> f64 {
    (d + 180.0).rem_euclid(360.0) - 180.0
}

/// The index of the pair time in `times` (ascending) nearest `t_s`, if within
/// `half_period` of it: the pair a track.csv row belongs to.
pub fn nearest_pair(times: &[f64], t_s: f64, half_period: f64) -> Option<usize> {
    let i = times.partition_point(|t| *t < t_s);
    [i.checked_sub(1), Some(i)]
        .into_iter()
        .flatten()
        .filter(|&j| j < times.len())
        .min_by(|&a, &b| (times[a] - t_s).abs().total_cmp(&(times[b] - t_s).abs()))
        .filter(|&j| (times[j] - t_s).abs() < half_period)
}

/// A vehicle in one image: id, point, whether the image shows it.
type Seen = (u32, [f64; 3], bool);

/// Reads `recording`'s truth and `track` and pairs them. Pairs before the run's first
/// estimate + `warm_up_s` are left out.
pub fn load(recording: &Path, track: &Path, warm_up_s: f64) -> Result<Loaded> {
    let rec = Recording::open(recording)
        .with_context(|| format!("open the recording {}", recording.display()))?;
    let Some(truth) = rec.truth.as_ref() else {
        bail!(
            "{} has no truth.csv: there is nothing to score against",
            recording.display()
        );
    };
    // Each image's vehicles, by (uav, frame).
    let mut seen: BTreeMap<(Uav, u64), Vec<Seen>> = BTreeMap::new();
    let targets_path = recording.join(TRUTH_TARGETS_FILE);
    let truth_file = if targets_path.is_file() {
        for row in read_targets_truth(&targets_path)? {
            seen.entry((row.uav, row.frame)).or_default().push((
                row.target_id,
                row.target,
                row.target_px.is_some(),
            ));
        }
        TRUTH_TARGETS_FILE
    } else {
        for row in truth {
            seen.entry((row.uav, row.frame)).or_default().push((
                0,
                row.target,
                row.target_px.is_some(),
            ));
        }
        "truth.csv"
    };
    let half_period = 0.5 / rec.meta.frame_rate_hz;
    let pairs = rec.pairs();
    let times: Vec<f64> = pairs.iter().map(|p| rec.telemetry[p.left].t_s).collect();
    let mut estimates: Vec<Vec<TrackRow>> = vec![Vec::new(); pairs.len()];
    let mut unpaired_rows = 0;
    for row in read_track(track)? {
        match nearest_pair(&times, row.t_s, half_period) {
            Some(j) => estimates[j].push(row),
            None => unpaired_rows += 1,
        }
    }
    // One estimate per track and pair: the row nearest the pair's time.
    for (k, rows) in estimates.iter_mut().enumerate() {
        let before = rows.len();
        rows.sort_by(|a, b| {
            a.track_id.cmp(&b.track_id).then(
                (a.t_s - times[k])
                    .abs()
                    .total_cmp(&(b.t_s - times[k]).abs()),
            )
        });
        rows.dedup_by_key(|r| r.track_id);
        unpaired_rows += (before - rows.len()) as u64;
    }
    let Some(first) = estimates.iter().position(|e| !e.is_empty()) else {
        bail!(
            "{} has no estimate at any pair of the recording",
            track.display()
        );
    };
    let start = times[first] + warm_up_s;
    let bias =
        |index: usize| wrap_deg(rec.telemetry[index].pose.yaw_deg - truth[index].pose.yaw_deg);
    let mut frames = Vec::new();
    let mut bias_errors_deg = Vec::new();
    for (k, pair) in pairs.iter().enumerate().skip(first) {
        if times[k] < start {
            continue;
        }
        let (l, r) = (&rec.telemetry[pair.left], &rec.telemetry[pair.right]);
        let empty = Vec::new();
        let left = seen.get(&(Uav::Left, l.frame)).unwrap_or(&empty);
        let right = seen.get(&(Uav::Right, r.frame)).unwrap_or(&empty);
        let mut frame = Frame {
            t_s: times[k],
            ..Frame::default()
        };
        for &(id, p, in_left) in left {
            let in_right = right.iter().any(|&(rid, _, shown)| rid == id && shown);
            if in_left && in_right {
                frame.truth.push(Object {
                    id,
                    p,
                    h_acc_m: None,
                    v_acc_m: None,
                });
            } else {
                frame.dont_care.push(p);
            }
        }
        for &(id, p, _) in right {
            if !left.iter().any(|&(lid, _, _)| lid == id) {
                frame.dont_care.push(p);
            }
        }
        frame.estimates = estimates[k]
            .iter()
            .map(|e| Object {
                id: e.track_id,
                p: e.p,
                h_acc_m: e.h_acc_m,
                v_acc_m: e.v_acc_m,
            })
            .collect();
        if let Some([bl, br]) = estimates[k].iter().find_map(|e| e.yaw_bias_deg) {
            bias_errors_deg.push([
                wrap_deg(bl - bias(pair.left)).abs(),
                wrap_deg(br - bias(pair.right)).abs(),
            ]);
        }
        frames.push(frame);
    }
    Ok(Loaded {
        frames,
        bias_errors_deg,
        truth_file,
        unpaired_rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_track_file_reads_with_or_without_track_ids() {
        let dir = tempfile::tempdir().unwrap();
        let old = dir.path().join("old.csv");
        std::fs::write(
            &old,
            "t_s,pair_seq,x_m,y_m,z_m,yaw_bias_left_deg,yaw_bias_right_deg\n0.5,15,1,2,3,4,5\n",
        )
        .unwrap();
        let rows = read_track(&old).unwrap();
        assert_eq!(rows[0].track_id, 0);
        assert_eq!(rows[0].p, [1.0, 2.0, 3.0]);
        assert_eq!(rows[0].yaw_bias_deg, Some([4.0, 5.0]));
        let new = dir.path().join("new.csv");
        std::fs::write(&new, "track_id,t_s,x_m,y_m,z_m\n3,0.5,1,2,3\n").unwrap();
        let rows = read_track(&new).unwrap();
        assert_eq!((rows[0].track_id, rows[0].yaw_bias_deg), (3, None));
        std::fs::write(&new, "t_s,x_m,y_m,z_m\n0.5,1,x,3\n").unwrap();
        let e = format!("{:#}", read_track(&new).unwrap_err());
        assert!(e.contains("line 2") && e.contains("y_m"), "{e}");
        std::fs::write(&new, "t_s,x_m,y_m\n").unwrap();
        let e = format!("{:#}", read_track(&new).unwrap_err());
        assert!(e.contains("z_m"), "{e}");
    }
}
