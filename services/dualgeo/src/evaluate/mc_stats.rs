//! The Monte Carlo's figures (issue #23): what one run's estimates say against truth,
//! and what a scene's runs say together. Pure functions over plain records.

use serde::{Deserialize, Serialize};

/// One estimate against truth (truth for scoring only).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EstimateRow {
    pub t_s: f64,
    /// Estimate − truth, ENU metres.
    pub err: [f64; 3],
    /// The stated covariance of x, y: (σ_xx, σ_xy, σ_yy), m².
    pub cov_xy: [f64; 3],
    /// The stated 1σ of z, m.
    pub v_acc: f64,
    /// Yaw-bias estimate − truth, degrees (wrapped).
    pub bias_err_deg: [f64; 2],
    /// The target was in both images (a detection to estimate from).
    pub visible: bool,
    /// The filter's quality state (`geolocation::Quality` as its index).
    pub quality: u8,
    /// An estimate of a look-alike ([`crate::score::look_alike::of_a_look_alike`]).
    #[serde(default)]
    pub look_alike: bool,
}

impl EstimateRow {
    /// √(σ_x² + σ_y²): MAVLink's h_acc.
    pub fn h_acc(&self) -> f64 {
        (self.cov_xy[0] + self.cov_xy[2]).max(0.0).sqrt()
    }

    pub fn h_err(&self) -> f64 {
        self.err[0].hypot(self.err[1])
    }

    /// Normalised estimation error squared over x, y, z (3 degrees of freedom), with
    /// the stated x-y covariance and σ_z (their cross terms are not published).
    pub fn nees(&self) -> Option<f64> {
        let [a, b, c] = self.cov_xy;
        let det = a * c - b * b;
        if !(det > 0.0 && self.v_acc > 0.0) {
            return None;
        }
        let [x, y, z] = self.err;
        let xy = (c * x * x - 2.0 * b * x * y + a * y * y) / det;
        Some(xy + (z / self.v_acc).powi(2))
    }

    /// Beyond three times the stated accuracy, horizontally or vertically.
    pub fn gross(&self) -> bool {
        self.h_err() > 3.0 * self.h_acc() || self.err[2].abs() > 3.0 * self.v_acc
    }
}

/// One run of one scene under one seed.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RunRecord {
    pub seed: u64,
    /// Pairs after the warm-up with the target in both images, and those located.
    pub visible_after_warm_up: usize,
    pub located_after_warm_up: usize,
    /// Estimates made while the target was not in both images (after the warm-up):
    /// something else was taken for it.
    pub located_not_visible: usize,
    pub estimates: Vec<EstimateRow>,
}

impl RunRecord {
    /// Estimates of a look-alike, from the first estimate.
    pub fn look_alike_estimates(&self) -> usize {
        self.estimates.iter().filter(|e| e.look_alike).count()
    }
}

/// Mean absolute value.
fn mae(v: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for x in v {
        s += x.abs();
        n += 1;
    }
    if n == 0 {
        f64::NAN
    } else {
        s / n as f64
    }
}

/// The `q` quantile (nearest rank) of finite values; NaN when there are none.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let k = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[k - 1]
}

impl RunRecord {
    fn after(&self, warm_up_s: f64) -> impl Iterator<Item = &EstimateRow> {
        self.estimates.iter().filter(move |e| e.t_s >= warm_up_s)
    }

    /// MAE x, y, z and horizontal after the warm-up.
    pub fn mae_after(&self, warm_up_s: f64) -> [f64; 4] {
        [
            mae(self.after(warm_up_s).map(|e| e.err[0])),
            mae(self.after(warm_up_s).map(|e| e.err[1])),
            mae(self.after(warm_up_s).map(|e| e.err[2])),
            mae(self.after(warm_up_s).map(|e| e.h_err())),
        ]
    }

    pub fn bias_mae_after(&self, warm_up_s: f64) -> [f64; 2] {
        [
            mae(self.after(warm_up_s).map(|e| e.bias_err_deg[0])),
            mae(self.after(warm_up_s).map(|e| e.bias_err_deg[1])),
        ]
    }

    /// Seconds from the first pair until the 3-D error stays within `limit_m` for the
    /// rest of the run (the time of the first estimate of that final stretch); `None`
    /// when the last estimate is still outside or there is none.
    pub fn time_to_trust(&self, limit_m: f64) -> Option<f64> {
        let mut start = None;
        for e in &self.estimates {
            let d = (e.err[0].powi(2) + e.err[1].powi(2) + e.err[2].powi(2)).sqrt();
            if d <= limit_m {
                start.get_or_insert(e.t_s);
            } else {
                start = None;
            }
        }
        start
    }

    pub fn first_estimate_s(&self) -> Option<f64> {
        self.estimates.first().map(|e| e.t_s)
    }

    /// The first time h_acc is at most `limit_m`.
    pub fn h_acc_within_s(&self, limit_m: f64) -> Option<f64> {
        self.estimates
            .iter()
            .find(|e| e.h_acc() <= limit_m)
            .map(|e| e.t_s)
    }

    /// Mean vertical error (estimate − truth) after the warm-up; NaN when none.
    pub fn mean_z_after(&self, warm_up_s: f64) -> f64 {
        let (s, n) = self
            .after(warm_up_s)
            .fold((0.0, 0usize), |(s, n), e| (s + e.err[2], n + 1));
        if n == 0 {
            f64::NAN
        } else {
            s / n as f64
        }
    }

    /// Shares (%) of estimates inside h_acc and inside v_acc, from the first estimate.
    pub fn within_shares(&self) -> [f64; 2] {
        let (h, v, _) = shares_inside(&self.estimates);
        [h, v]
    }
}

/// Shares (%) of `rows` whose horizontal (vertical) error is within the stated h_acc
/// (v_acc), and their count; NaN shares when there are none.
fn shares_inside<'a>(rows: impl IntoIterator<Item = &'a EstimateRow>) -> (f64, f64, usize) {
    let (mut h, mut v, mut n) = (0usize, 0usize, 0usize);
    for e in rows {
        n += 1;
        h += usize::from(e.h_err() <= e.h_acc());
        v += usize::from(e.err[2].abs() <= e.v_acc);
    }
    if n == 0 {
        return (f64::NAN, f64::NAN, 0);
    }
    let share = |k: usize| 100.0 * k as f64 / n as f64;
    (share(h), share(v), n)
}

/// A scene's runs together: the Monte Carlo table's row.
#[derive(Debug, Clone, Serialize)]
pub struct SceneSummary {
    pub runs: usize,
    pub estimates: usize,
    /// Per-run MAE after the warm-up (x, y, z, horizontal): median, 90th percentile.
    pub mae_median: [f64; 4],
    pub mae_p90: [f64; 4],
    /// The run with the largest horizontal MAE after the warm-up: (seed, its MAE x, y, z).
    pub worst: (u64, [f64; 3]),
    /// Median of the per-run bias MAE, degrees.
    pub bias_mae_median: [f64; 2],
    pub located_pct: f64,
    pub located_not_visible: usize,
    /// Estimates of a look-alike, from the first estimate, and the runs with any.
    pub look_alike_estimates: usize,
    pub look_alike_runs: usize,
    /// Pooled over runs and estimates, from the first estimate.
    pub within_h_acc_pct: f64,
    pub within_v_acc_pct: f64,
    pub gross_pct: f64,
    /// Mean NEES (3 dof) pooled, and the two-sided 95 % region of the mean over
    /// `runs` independent runs (χ²(3·runs)/runs).
    pub mean_nees: f64,
    pub nees_bounds: [f64; 2],
    /// Mean vertical error (estimate − truth) after the warm-up, pooled, and its
    /// standard error over runs (the spread of the runs' own means / √runs): under
    /// correlated navigation errors each run's altitude carries its GPS's metres, and
    /// a mean over 8 runs cannot show a 0.3 m offset.
    pub mean_z_err_m: f64,
    pub mean_z_err_se_m: f64,
    /// Median over runs of the time-to-trust (error stays within 2 m), and the worst;
    /// runs that never got there count as infinite.
    pub time_to_trust_median_s: f64,
    pub time_to_trust_worst_s: f64,
    pub first_estimate_median_s: f64,
    /// Median over runs of the first time h_acc ≤ 2 m.
    pub h_acc_2m_median_s: f64,
    /// Per-run share inside h_acc and v_acc, (seed, h %, v %).
    pub per_run_within: Vec<(u64, f64, f64)>,
    /// Share inside h_acc and v_acc (%) and the count per [`AGE_BINS_S`] bin.
    pub within_by_age: Vec<(f64, f64, usize)>,
}

/// Trust means the 3-D error stays within this, metres.
pub const TRUST_M: f64 = 2.0;

/// The calibration's age bins: seconds since a run's first estimate, [from, to). The
/// pooled share inside h_acc / v_acc can be right on average while the filter is
/// over-confident while it converges and cautious afterwards; these bins show which.
pub const AGE_BINS_S: [(f64, f64); 4] =
    [(0.0, 3.0), (3.0, 6.0), (6.0, 10.0), (10.0, f64::INFINITY)];

/// Shares (%) inside h_acc and inside v_acc, and the count, of the estimates made
/// [from, to) seconds after their run's first estimate, pooled over runs.
pub fn within_by_age(runs: &[RunRecord], (from, to): (f64, f64)) -> (f64, f64, usize) {
    shares_inside(runs.iter().flat_map(|r| {
        let t0 = r.estimates.first().map_or(0.0, |e| e.t_s);
        r.estimates.iter().filter(move |e| {
            let age = e.t_s - t0;
            age >= from && age < to
        })
    }))
}

pub fn summarise(runs: &[RunRecord], warm_up_s: f64) -> SceneSummary {
    let maes: Vec<[f64; 4]> = runs.iter().map(|r| r.mae_after(warm_up_s)).collect();
    let column = |i: usize| maes.iter().map(|m| m[i]).collect::<Vec<f64>>();
    let mae_median = [0, 1, 2, 3].map(|i| quantile(&column(i), 0.5));
    let mae_p90 = [0, 1, 2, 3].map(|i| quantile(&column(i), 0.9));
    let worst = runs
        .iter()
        .zip(&maes)
        .filter(|(_, m)| m[3].is_finite())
        .max_by(|a, b| a.1[3].total_cmp(&b.1[3]))
        .map_or((0, [f64::NAN; 3]), |(r, m)| (r.seed, [m[0], m[1], m[2]]));
    let biases: Vec<[f64; 2]> = runs.iter().map(|r| r.bias_mae_after(warm_up_s)).collect();
    let bias_mae_median =
        [0, 1].map(|i| quantile(&biases.iter().map(|b| b[i]).collect::<Vec<_>>(), 0.5));
    let all: Vec<&EstimateRow> = runs.iter().flat_map(|r| &r.estimates).collect();
    let n = all.len();
    let pct = |k: usize| {
        if n == 0 {
            f64::NAN
        } else {
            100.0 * k as f64 / n as f64
        }
    };
    let within = shares_inside(all.iter().copied());
    let nees: Vec<f64> = all.iter().filter_map(|e| e.nees()).collect();
    let mean_nees = if nees.is_empty() {
        f64::NAN
    } else {
        nees.iter().sum::<f64>() / nees.len() as f64
    };
    let k = runs.len().max(1) as f64;
    let dof = 3.0 * k;
    let nees_bounds = [chi2_quantile(0.025, dof) / k, chi2_quantile(0.975, dof) / k];
    let after: Vec<&EstimateRow> = runs.iter().flat_map(|r| r.after(warm_up_s)).collect();
    let mean_z_err_m = if after.is_empty() {
        f64::NAN
    } else {
        after.iter().map(|e| e.err[2]).sum::<f64>() / after.len() as f64
    };
    let run_means: Vec<f64> = runs
        .iter()
        .map(|r| r.mean_z_after(warm_up_s))
        .filter(|m| !m.is_nan())
        .collect();
    let mean_z_err_se_m = if run_means.len() < 2 {
        f64::NAN
    } else {
        let m = run_means.iter().sum::<f64>() / run_means.len() as f64;
        let var =
            run_means.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (run_means.len() - 1) as f64;
        (var / run_means.len() as f64).sqrt()
    };
    let times = |f: &dyn Fn(&RunRecord) -> Option<f64>| -> Vec<f64> {
        runs.iter().map(|r| f(r).unwrap_or(f64::INFINITY)).collect()
    };
    let trust = times(&|r| r.time_to_trust(TRUST_M));
    let median_incl_inf = |v: &[f64]| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v.get(v.len().saturating_sub(1) / 2)
            .copied()
            .unwrap_or(f64::NAN)
    };
    let visible: usize = runs.iter().map(|r| r.visible_after_warm_up).sum();
    let located: usize = runs.iter().map(|r| r.located_after_warm_up).sum();
    SceneSummary {
        runs: runs.len(),
        estimates: n,
        mae_median,
        mae_p90,
        worst,
        bias_mae_median,
        located_pct: if visible == 0 {
            f64::NAN
        } else {
            100.0 * located as f64 / visible as f64
        },
        located_not_visible: runs.iter().map(|r| r.located_not_visible).sum(),
        look_alike_estimates: runs.iter().map(RunRecord::look_alike_estimates).sum(),
        look_alike_runs: runs.iter().filter(|r| r.look_alike_estimates() > 0).count(),
        within_h_acc_pct: within.0,
        within_v_acc_pct: within.1,
        gross_pct: pct(all.iter().filter(|e| e.gross()).count()),
        mean_nees,
        nees_bounds,
        mean_z_err_m,
        mean_z_err_se_m,
        time_to_trust_median_s: median_incl_inf(&trust),
        time_to_trust_worst_s: trust.iter().copied().fold(f64::NAN, f64::max),
        first_estimate_median_s: median_incl_inf(&times(&|r| r.first_estimate_s())),
        h_acc_2m_median_s: median_incl_inf(&times(&|r| r.h_acc_within_s(TRUST_M))),
        per_run_within: runs
            .iter()
            .map(|r| {
                let [h, v] = r.within_shares();
                (r.seed, h, v)
            })
            .collect(),
        within_by_age: AGE_BINS_S
            .iter()
            .map(|&bin| within_by_age(runs, bin))
            .collect(),
    }
}

/// The χ²(k) quantile at probability `p` (Wilson–Hilferty: within 1 % for k ≥ 12, the
/// region of four runs or more; 16 % low at the 2.5 % point for k = 3).
pub fn chi2_quantile(p: f64, k: f64) -> f64 {
    let z = normal_quantile(p);
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).powi(3)
}

/// The standard normal quantile (Acklam's rational approximation, |error| < 1.2e-9).
fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383_577_518_672_69e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A kept run read back is the run flown, to the bit (serde_json's
    /// `float_roundtrip`): without it one value in a few thousand parsed one ULP off,
    /// and a report from kept runs differed in its JSON's last digits from the one
    /// that flew them.
    #[test]
    fn a_kept_run_reads_back_to_the_bits_written() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let rows: Vec<EstimateRow> = (0..5000)
            .map(|_| {
                let mut r = row(rng.random::<f64>() * 20.0, [0.0; 3], 1.0);
                r.err = [0; 3].map(|_| rng.random::<f64>() * 10.0 - 5.0);
                r.cov_xy = [0; 3].map(|_| rng.random::<f64>() * 3.0);
                r.v_acc = rng.random::<f64>();
                r
            })
            .collect();
        let text = serde_json::to_string(&rows).expect("serialise");
        let back: Vec<EstimateRow> = serde_json::from_str(&text).expect("parse");
        let bits = |rs: &[EstimateRow]| -> Vec<u64> {
            rs.iter()
                .flat_map(|r| {
                    [
                        r.t_s,
                        r.err[0],
                        r.err[1],
                        r.err[2],
                        r.cov_xy[0],
                        r.cov_xy[1],
                        r.cov_xy[2],
                        r.v_acc,
                    ]
                })
                .map(f64::to_bits)
                .collect()
        };
        let (written, read) = (bits(&rows), bits(&back));
        let off = written.iter().zip(&read).filter(|(w, r)| w != r).count();
        assert_eq!(
            off,
            0,
            "{off} of {} values read back as other bits",
            written.len()
        );
    }

    fn row(t_s: f64, err: [f64; 3], sigma: f64) -> EstimateRow {
        EstimateRow {
            t_s,
            err,
            cov_xy: [sigma * sigma, 0.0, sigma * sigma],
            v_acc: sigma,
            bias_err_deg: [0.0, 0.0],
            visible: true,
            quality: 1,
            look_alike: false,
        }
    }

    /// Runs whose altitudes are each a few metres off (a correlated GPS error) give a
    /// mean vertical error with a standard error of the runs' spread / √runs; white
    /// errors within runs give one near zero.
    #[test]
    fn the_mean_vertical_errors_standard_error_is_over_runs() {
        let run = |seed: u64, z: f64| RunRecord {
            seed,
            estimates: (0..100)
                .map(|i| row(10.0 + i as f64 * 0.1, [0.0, 0.0, z], 1.0))
                .collect(),
            ..Default::default()
        };
        let s = summarise(&[run(1, 3.0), run(2, -1.0), run(3, 1.0)], 10.0);
        // Means +3, −1, +1: mean +1, sample σ 2, standard error 2/√3.
        assert!((s.mean_z_err_m - 1.0).abs() < 1e-9);
        assert!((s.mean_z_err_se_m - 2.0 / 3f64.sqrt()).abs() < 1e-9);
        let same = summarise(&[run(1, 0.2), run(2, 0.2)], 10.0);
        assert!(same.mean_z_err_se_m.abs() < 1e-9);
        assert!(summarise(&[run(1, 0.2)], 10.0).mean_z_err_se_m.is_nan());
    }

    #[test]
    fn chi2_quantiles_match_tables() {
        // χ²(12): 4.404 at 2.5 %, 23.337 at 97.5 %; χ²(60): 40.48 and 83.30.
        assert!((chi2_quantile(0.025, 12.0) - 4.404).abs() < 0.044);
        assert!((chi2_quantile(0.975, 12.0) - 23.337).abs() < 0.23);
        assert!((chi2_quantile(0.025, 60.0) - 40.48).abs() < 0.2);
        assert!((chi2_quantile(0.975, 60.0) - 83.30).abs() < 0.3);
    }

    #[test]
    fn a_calibrated_gaussian_scores_as_calibrated() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let n = Normal::new(0.0, 2.0).unwrap();
        let runs: Vec<RunRecord> = (0..20)
            .map(|seed| RunRecord {
                seed,
                estimates: (0..200)
                    .map(|i| {
                        let err = [n.sample(&mut rng), n.sample(&mut rng), n.sample(&mut rng)];
                        // Stated: σ_x = σ_y = σ_z = 2 m, so h_acc = 2√2.
                        row(i as f64 * 0.1, err, 2.0)
                    })
                    .collect(),
                ..Default::default()
            })
            .collect();
        let s = summarise(&runs, 10.0);
        // A circular Gaussian puts 1 − e⁻¹ = 63 % inside √2 σ; |z| inside σ: 68 %.
        assert!(
            (s.within_h_acc_pct - 63.2).abs() < 2.0,
            "{}",
            s.within_h_acc_pct
        );
        assert!(
            (s.within_v_acc_pct - 68.3).abs() < 2.0,
            "{}",
            s.within_v_acc_pct
        );
        assert!((s.mean_nees - 3.0).abs() < 0.1, "{}", s.mean_nees);
        assert!(s.nees_bounds[0] < 3.0 && 3.0 < s.nees_bounds[1]);
        assert!(s.gross_pct < 2.0);
        assert!(s.mean_z_err_m.abs() < 0.1);
        // An overconfident filter (stated σ a third of the truth) is caught.
        let liar: Vec<RunRecord> = runs
            .iter()
            .map(|r| RunRecord {
                estimates: r
                    .estimates
                    .iter()
                    .map(|e| row(e.t_s, e.err, 2.0 / 3.0))
                    .collect(),
                ..r.clone()
            })
            .collect();
        let s = summarise(&liar, 10.0);
        assert!(s.mean_nees > 20.0 && s.gross_pct > 10.0 && s.within_v_acc_pct < 40.0);
    }

    /// A filter that states 1 m throughout while its errors shrink from 3 m to 0.3 m is
    /// calibrated on average only: the age bins show it over-confident first and
    /// cautious later, counted from each run's own first estimate.
    #[test]
    fn calibration_by_age_counts_from_each_runs_first_estimate() {
        let run = |seed: u64, t0: f64| RunRecord {
            seed,
            estimates: (0..200)
                .map(|i| {
                    // Steps of 1/8 s from a start that is a binary fraction: every
                    // age is exact, so the bins' edges fall where written.
                    let age = i as f64 * 0.125;
                    let e = if age < 6.0 { 3.0 } else { 0.3 };
                    row(t0 + age, [e, 0.0, e], 1.0)
                })
                .collect(),
            ..Default::default()
        };
        let runs = [run(1, 2.0), run(2, 7.5)];
        let s = summarise(&runs, 10.0);
        let bins = &s.within_by_age;
        assert_eq!(bins.len(), AGE_BINS_S.len());
        // h_acc = √2 m: 3 m is outside, 0.3 m inside; v_acc 1 m the same.
        assert_eq!((bins[0].0, bins[0].1, bins[0].2), (0.0, 0.0, 48));
        assert_eq!((bins[1].0, bins[1].1, bins[1].2), (0.0, 0.0, 48));
        assert_eq!((bins[2].0, bins[2].1, bins[2].2), (100.0, 100.0, 64));
        assert_eq!((bins[3].0, bins[3].1, bins[3].2), (100.0, 100.0, 240));
        assert!((runs[0].mean_z_after(10.0) - 0.3).abs() < 1e-12);
        assert!(RunRecord::default().mean_z_after(10.0).is_nan());
        assert!(within_by_age(&[], AGE_BINS_S[0]).0.is_nan());
    }

    #[test]
    fn time_to_trust_is_the_start_of_the_last_good_stretch() {
        let r = RunRecord {
            estimates: vec![
                row(1.0, [0.5, 0.0, 0.0], 1.0),
                row(2.0, [5.0, 0.0, 0.0], 1.0),
                row(3.0, [1.0, 0.0, 0.0], 1.0),
                row(4.0, [0.0, 1.0, 1.0], 1.0),
            ],
            ..Default::default()
        };
        assert_eq!(r.time_to_trust(2.0), Some(3.0));
        assert_eq!(r.first_estimate_s(), Some(1.0));
        let never = RunRecord {
            estimates: vec![row(1.0, [0.0, 0.0, 9.0], 1.0)],
            ..Default::default()
        };
        assert_eq!(never.time_to_trust(2.0), None);
    }
}
