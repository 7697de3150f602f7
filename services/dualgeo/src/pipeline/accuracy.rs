//! Accuracy against truth, for the report: evaluation only. The truth and telemetry
//! files are read here, after the run, never by a stage.
//!
//! An estimate at pair time t is compared with the truth row of the left image at t
//! (|Δt| < half a frame period): the target point (x, y, z), and the yaw biases of
//! both UAVs' current images (telemetry yaw − true yaw, wrapped; truth.csv's definition).

use acquisition::recording::{read_telemetry, read_truth, TelemetryRow, TruthRow};
use anyhow::Result;
use geolocation::evaluation::ErrorStats;
use serde::Serialize;
use shared_types::conventions::Uav;
use shared_types::messages::{EstimateMsg, EstimateStatus};
use std::path::Path;

#[derive(Debug, Clone, Copy, Serialize)]
pub struct Xyz {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

#[derive(Debug, Clone, Copy, Serialize)]
pub struct LeftRight {
    pub left: f64,
    pub right: f64,
}

/// `accuracy` of report.json.
#[derive(Debug, Serialize)]
pub struct Accuracy {
    pub mae_m: Xyz,
    pub std_m: Xyz,
    pub max_m: Xyz,
    pub yaw_bias_mae_deg: LeftRight,
}

/// Per-image truth: (t_s, true target, bias in degrees) for one UAV, in time order.
struct Track {
    rows: Vec<(f64, [f64; 3], f64)>,
}

impl Track {
    fn at(&self, t: f64, tolerance: f64) -> Option<([f64; 3], f64)> {
        let i = self.rows.partition_point(|r| r.0 < t);
        [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|j| self.rows.get(j))
            .filter(|r| (r.0 - t).abs() < tolerance)
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
            .map(|r| (r.1, r.2))
    }
}

fn wrap_deg(d: f64) -> f64 {
    let w = (d + 180.0).rem_euclid(360.0) - 180.0;
    if w == -180.0 {
        180.0
    } else {
        w
    }
}

fn tracks(telemetry: &[TelemetryRow], truth: &[TruthRow]) -> [Track; 2] {
    [Uav::Left, Uav::Right].map(|uav| {
        let mut rows: Vec<(f64, [f64; 3], f64)> = truth
            .iter()
            .zip(telemetry)
            .filter(|(t, _)| t.uav == uav)
            .map(|(t, m)| (t.t_s, t.target, wrap_deg(m.pose.yaw_deg - t.pose.yaw_deg)))
            .collect();
        rows.sort_by(|a, b| a.0.total_cmp(&b.0));
        Track { rows }
    })
}

/// The truth of every valid estimate, in order: (estimate, true target, true biases).
pub type Paired = Vec<(EstimateMsg, [f64; 3], [f64; 2])>;

/// Pairs estimates with truth from `dir`'s telemetry.csv and truth.csv. `None` when
/// there is no truth.
pub fn pair_with_truth(
    dir: &Path,
    estimates: &[EstimateMsg],
    frame_rate_hz: f64,
) -> Result<Option<Paired>> {
    let truth_path = dir.join("truth.csv");
    if !truth_path.is_file() {
        return Ok(None);
    }
    let telemetry: Vec<TelemetryRow> = read_telemetry(&dir.join("telemetry.csv"))?
        .into_iter()
        .map(|(_, r)| r)
        .collect();
    let truth: Vec<TruthRow> = read_truth(&truth_path)?
        .into_iter()
        .map(|(_, r)| r)
        .collect();
    if telemetry.len() != truth.len() {
        anyhow::bail!(
            "{}: {} rows but telemetry.csv has {}",
            truth_path.display(),
            truth.len(),
            telemetry.len()
        );
    }
    let [left, right] = tracks(&telemetry, &truth);
    let tolerance = 0.5 / frame_rate_hz;
    let paired = estimates
        .iter()
        .filter(|e| e.status == EstimateStatus::Ok as u32)
        .filter_map(|e| {
            let (target, bias_l) = left.at(e.t_s, tolerance)?;
            let (_, bias_r) = right.at(e.t_s, tolerance)?;
            Some((*e, target, [bias_l, bias_r]))
        })
        .collect();
    Ok(Some(paired))
}

pub fn accuracy(paired: &Paired) -> Option<Accuracy> {
    if paired.is_empty() {
        return None;
    }
    let axis = |i: usize| -> ErrorStats {
        let errors: Vec<f64> = paired
            .iter()
            .map(|(e, t, _)| e.position[i] - t[i])
            .collect();
        ErrorStats::from_errors(&errors)
    };
    let bias = |i: usize| -> f64 {
        let errors: Vec<f64> = paired
            .iter()
            .map(|(e, _, b)| wrap_deg(e.yaw_bias_deg[i] - b[i]))
            .collect();
        ErrorStats::from_errors(&errors).mae
    };
    let (x, y, z) = (axis(0), axis(1), axis(2));
    Some(Accuracy {
        mae_m: Xyz {
            x: x.mae,
            y: y.mae,
            z: z.mae,
        },
        std_m: Xyz {
            x: x.std,
            y: y.std,
            z: z.std,
        },
        max_m: Xyz {
            x: x.max,
            y: y.max,
            z: z.max,
        },
        yaw_bias_mae_deg: LeftRight {
            left: bias(0),
            right: bias(1),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_truth_within_half_a_period() {
        let t = Track {
            rows: vec![
                (0.0, [0.0; 3], 1.0),
                (0.1, [1.0; 3], 2.0),
                (0.2, [2.0; 3], 3.0),
            ],
        };
        assert_eq!(t.at(0.11, 0.05).unwrap().1, 2.0);
        assert_eq!(t.at(0.19, 0.05).unwrap().1, 3.0);
        assert!(t.at(0.35, 0.05).is_none());
        assert_eq!(wrap_deg(350.0), -10.0);
        assert_eq!(wrap_deg(-180.0), 180.0);
    }
}
