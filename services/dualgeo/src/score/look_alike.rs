//! Estimates of a look-alike (issue #23's `suite_traffic` target: none): the target's
//! estimate horizontally nearer a car coloured like the target than the target, and
//! more than [`LOOK_ALIKE_MIN_M`] from it. The Monte Carlo scores its in-process runs
//! with [`of_a_look_alike`]; [`target_on_look_alike`] scores a `dualgeo run` output
//! against a recording's truth_targets.csv the same way. Evaluation only.

use super::input::{nearest_pair, read_track};
use acquisition::recording::{read_targets_truth, Recording, TRUTH_TARGETS_FILE};
use anyhow::{Context, Result};
use shared_types::conventions::Uav;
use std::collections::BTreeMap;
use std::path::Path;

/// An estimate this near the target is the target's, whatever else is near.
pub const LOOK_ALIKE_MIN_M: f64 = 2.0;

/// Whether an estimate at `estimate` is one of the look-alikes at `look_alikes`
/// rather than the target at `target` (ENU, one origin).
pub fn of_a_look_alike(
    estimate: [f64; 3],
    target: [f64; 3],
    look_alikes: impl IntoIterator<Item = [f64; 3]>,
) -> bool {
    let h = |a: [f64; 3], b: [f64; 3]| (a[0] - b[0]).hypot(a[1] - b[1]);
    let to_target = h(estimate, target);
    to_target > LOOK_ALIKE_MIN_M && look_alikes.into_iter().any(|l| h(estimate, l) < to_target)
}

/// How many of the target's estimates (track 0 of `track`, from the first) are of a
/// look-alike, the vehicles being where `recording`'s truth_targets.csv puts them at
/// the estimate's pair (the left image's row), whether the cameras show them or not.
/// `look_alike_ids` are the truth_targets.csv ids of the cars coloured like the target
/// (the recording does not say which they are; the scene does). Rows at no pair of
/// the recording (over half a frame period off) are not counted.
pub fn target_on_look_alike(recording: &Path, track: &Path, look_alike_ids: &[u32]) -> Result<u64> {
    if look_alike_ids.is_empty() {
        return Ok(0);
    }
    let rec = Recording::open(recording)
        .with_context(|| format!("open the recording {}", recording.display()))?;
    let targets = recording.join(TRUTH_TARGETS_FILE);
    // Every vehicle's point per left image.
    let mut at: BTreeMap<u64, BTreeMap<u32, [f64; 3]>> = BTreeMap::new();
    for row in read_targets_truth(&targets)
        .with_context(|| format!("read {}", targets.display()))?
        .into_iter()
        .filter(|r| r.uav == Uav::Left)
    {
        at.entry(row.frame)
            .or_default()
            .insert(row.target_id, row.target);
    }
    let half_period = 0.5 / rec.meta.frame_rate_hz;
    let (times, frames): (Vec<f64>, Vec<u64>) = rec
        .pairs()
        .iter()
        .map(|p| {
            let left = &rec.telemetry[p.left];
            (left.t_s, left.frame)
        })
        .unzip();
    let mut count = 0;
    for row in read_track(track)?.into_iter().filter(|r| r.track_id == 0) {
        let nearest = nearest_pair(&times, row.t_s, half_period);
        let Some(vehicles) = nearest.and_then(|j| at.get(&frames[j])) else {
            continue;
        };
        let Some(&target) = vehicles.get(&0) else {
            continue;
        };
        let look_alikes = look_alike_ids
            .iter()
            .filter_map(|id| vehicles.get(id).copied());
        count += of_a_look_alike(row.p, target, look_alikes) as u64;
    }
    Ok(count)
}

#[cfg(test)]
mod tests {
    use super::*;
    use acquisition::recording::ImageEncoding;
    use acquisition::sim::{record, Presets, Simulator};

    #[test]
    fn an_estimate_nearer_a_look_alike_than_the_target_is_of_the_look_alike() {
        let target = [0.0, 0.0, 13.5];
        let look_alike = [20.0, 3.5, 13.5];
        // On the target, or near it with the look-alike beside: the target's.
        assert!(!of_a_look_alike([0.5, 0.5, 13.0], target, [look_alike]));
        assert!(!of_a_look_alike(
            [1.5, 1.0, 13.0],
            target,
            [[1.0, 3.5, 13.5]]
        ));
        // Nearer the look-alike and over 2 m from the target: the look-alike's.
        assert!(of_a_look_alike([18.0, 3.0, 13.0], target, [look_alike]));
        // Far from both, nearer the target: a bad estimate, not a look-alike's.
        assert!(!of_a_look_alike([-9.0, 0.0, 13.0], target, [look_alike]));
        assert!(!of_a_look_alike([18.0, 3.0, 13.0], target, []));
    }

    /// A short `suite_traffic` recording (the red car 60 m behind the target): a track-0
    /// row on the red car is counted, one on the target, another track's row on the
    /// red car and a row at no pair are not.
    #[test]
    fn the_targets_rows_on_a_look_alike_are_counted_against_the_recording() {
        let mut config = Presets::builtin().get("suite_traffic").expect("preset");
        config.duration_s = 0.2;
        let dir = tempfile::tempdir().expect("temp dir");
        let rec = dir.path().join("rec");
        let mut sim = Simulator::new(config).expect("simulator");
        record(
            &mut sim,
            "suite_traffic",
            &rec,
            ImageEncoding::Jpeg { quality: 80 },
            |_, _| {},
        )
        .expect("record");
        let rows = read_targets_truth(&rec.join(TRUTH_TARGETS_FILE)).expect("truth");
        let at = |frame: u64, id: u32| {
            let r = rows
                .iter()
                .find(|r| r.uav == Uav::Left && r.frame == frame && r.target_id == id)
                .expect("a row");
            (r.t_s, r.target)
        };
        let line = |track: u32, (t, p): (f64, [f64; 3])| {
            format!("{track},{t},{},{},{}\n", p[0], p[1], p[2])
        };
        let (t1, red1) = at(1, 1);
        let text = String::from("track_id,t_s,x_m,y_m,z_m\n")
            + &line(0, at(0, 0))
            + &line(0, (t1, red1))
            + &line(1, at(2, 1))
            + &line(0, (t1 + 10.0, red1));
        let track = dir.path().join("track.csv");
        std::fs::write(&track, text).expect("write track");
        assert_eq!(target_on_look_alike(&rec, &track, &[1]).expect("scored"), 1);
        assert_eq!(target_on_look_alike(&rec, &track, &[]).expect("scored"), 0);
    }
}
