//! The temporal filter's start as a Gaussian sum over the two yaw biases (issue #23).
//!
//! Why: at the start the biases are known only to a real AHRS's ±45°, and with the
//! cameras far above the target the data of the first seconds leave a long, curved
//! valley of near-equal fits (the target shifted along the UAVs' baseline with the two
//! biases turned opposite ways). One extended Kalman filter linearised at one point of
//! that valley slid along it and, its covariance computed there, claimed a few metres
//! while 30–140 m off (250 m up: on exact synthetic rays with keyframes reused as the
//! chain reuses them, 17 % of estimates beyond 3σ, NEES 133; `suite_high_hd` seed 1
//! of the Monte Carlo: the altitude 17 m low for the whole run).
//!
//! What: the N(0, σ₀²) bias prior is split into a grid of `bias_hypotheses` per axis
//! (7, the default: σ₀/7 = 6.4° each, 12.9° apart; 3: means −30°, 0°, +30° per UAV,
//! each with σ₀/3 = 15°), each one a whole filter
//! (the same keyframe slots, its own state). Each starts where the current pair's two
//! rays meet under its own biases, with that point's own covariance, and a component
//! whose point curves within it is split into a finer grid while the bank has room
//! (`start_prior.rs`). Every update weighs each hypothesis by the
//! likelihood of its innovations raised to `likelihood_temper` (0.3 by default: a
//! tempered likelihood, as successive updates share their past images' errors; 1 is
//! Bayes' rule; docs/temporal.md "Tempered hypothesis weights"); one far behind the
//! leader is dropped, two that have come together are
//! merged (moments matched), so the bank is one filter again within a few seconds. Until then the estimate is the leader's, its covariance the mixture's
//! spread about it: the stated accuracy includes the hypotheses still open. This is
//! the Gaussian-sum filter of Alspach and Sorenson (1972), used only where the
//! posterior is far from one Gaussian.
//!
//! `[estimator.temporal] bias_hypotheses` sets the grid (7, the default: a 15°
//! component was still linearised across a curved fit, docs/temporal.md "A finer start
//! grid"; 1 is one filter started at the window estimate, as before issue #23's last
//! step). The
//! honest mixture stays `converging` longer than one overconfident filter did, so
//! detection gates with `converging` estimates too, the biases' σ widening the gate
//! (`detection::prediction_gate`; docs/temporal.md).
//!
//! Pure functions over plain data (nalgebra); `temporal.rs` runs the filters.

use crate::observation::ImageId;
use nalgebra::{DMatrix, DVector, Vector2};

/// A hypothesis whose weight is this far below the leader's (natural log, ~1e-4) is dropped.
const PRUNE_LOG_WEIGHT: f64 = 9.0;
/// Two hypotheses are merged when their core states differ by less than this squared
/// Mahalanobis distance under the sum of their covariances. Measured on exact synthetic
/// rays (24 seeds, 100 m and 250 m up): 0.1–0.6 gives the same calibration; 4 merged
/// hypotheses that had not yet agreed (NEES 2.6 → 14 at 100 m).
const MERGE_D2: f64 = 0.5;

/// One hypothesis: a whole filter state and its weight.
#[derive(Debug, Clone)]
pub(crate) struct Hypothesis {
    /// Natural log of the weight, up to a constant shared by the bank.
    pub(crate) log_weight: f64,
    /// (time, state, covariance): the core states then 8 per keyframe slot.
    pub(crate) state: (f64, DVector<f64>, DMatrix<f64>),
    pub(crate) slots: Vec<ImageId>,
    /// Running mean of each UAV's whitened current-ray innovation (zero-mean when the
    /// filter's model holds).
    pub(crate) drift: [Vector2<f64>; 2],
    /// Geolocations since the last re-opening.
    pub(crate) since_reopen: usize,
    /// Time both UAVs' running means started drifting (the filter coasting on them);
    /// `None` while either agrees. Not checkpointed: a restart counts afresh.
    pub(crate) lost_since_s: Option<f64>,
}

/// A start's bias hypothesis: mean (radians), σ (radians) and prior log weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct BiasStart {
    pub(crate) mean: [f64; 2],
    pub(crate) sigma: f64,
    pub(crate) log_weight: f64,
}

/// The grid that covers the prior N(0, σ₀²) per bias with `per_axis` × `per_axis`
/// components of σ = σ₀ / per_axis, 2σ apart (the outer ones' 1σ reaching ±σ₀),
/// weighted by the prior at their means (its variance less theirs). Narrow components
/// are what matters: each is linearised where it is. `per_axis` 1 is the single filter
/// at zero with σ₀.
pub(crate) fn bias_grid(per_axis: usize, sigma0: f64) -> Vec<BiasStart> {
    let n = per_axis.max(1);
    let sigma = sigma0 / n as f64;
    let spread = (sigma0 * sigma0 - sigma * sigma).max(f64::MIN_POSITIVE);
    let at = |k: usize| (k as f64 - (n - 1) as f64 / 2.0) * 2.0 * sigma;
    let mut grid = Vec::with_capacity(n * n);
    for i in 0..n {
        for j in 0..n {
            let mean = [at(i), at(j)];
            let log_weight = if n == 1 {
                0.0
            } else {
                -0.5 * (mean[0] * mean[0] + mean[1] * mean[1]) / spread
            };
            grid.push(BiasStart {
                mean,
                sigma,
                log_weight,
            });
        }
    }
    grid
}

/// Drops hypotheses far behind the leader, merges those that have come together and
/// sorts the bank leader first. `core` is the number of core states compared.
pub(crate) fn prune_and_merge(bank: &mut Vec<Hypothesis>, core: usize) {
    let Some(max) = bank.iter().map(|h| h.log_weight).reduce(f64::max) else {
        return;
    };
    bank.retain(|h| h.log_weight > max - PRUNE_LOG_WEIGHT);
    for h in bank.iter_mut() {
        // Keep the numbers near zero: only differences matter.
        h.log_weight -= max;
    }
    bank.sort_by(|a, b| b.log_weight.total_cmp(&a.log_weight));
    let mut i = 0;
    while i < bank.len() {
        let mut j = i + 1;
        while j < bank.len() {
            if close(&bank[i], &bank[j], core) {
                let other = bank.remove(j);
                merge_into(&mut bank[i], &other);
            } else {
                j += 1;
            }
        }
        i += 1;
    }
}

fn close(a: &Hypothesis, b: &Hypothesis, core: usize) -> bool {
    let (sa, pa) = (&a.state.1, &a.state.2);
    let (sb, pb) = (&b.state.1, &b.state.2);
    if sa.len() != sb.len() || a.slots != b.slots {
        return false;
    }
    let d = (sb - sa).rows(0, core).into_owned();
    let c = (pa + pb).view((0, 0), (core, core)).into_owned();
    c.cholesky()
        .map(|ch| d.dot(&ch.solve(&d)) < MERGE_D2)
        .unwrap_or(false)
}

/// Moment matching of two hypotheses with the same layout into `into` (the heavier;
/// its drift monitor and re-opening count are kept).
fn merge_into(into: &mut Hypothesis, other: &Hypothesis) {
    let (la, lb) = (into.log_weight, other.log_weight);
    let m = la.max(lb);
    let (a, b) = ((la - m).exp(), (lb - m).exp());
    let (wa, wb) = (a / (a + b), b / (a + b));
    let (sa, pa) = (&into.state.1, &into.state.2);
    let (sb, pb) = (&other.state.1, &other.state.2);
    let mean = sa * wa + sb * wb;
    let (da, db) = (sa - &mean, sb - &mean);
    let cov = (pa + &da * da.transpose()) * wa + (pb + &db * db.transpose()) * wb;
    into.state.1 = mean;
    into.state.2 = (&cov + cov.transpose()) * 0.5;
    into.log_weight = m + (a + b).ln();
}

/// Normalised weights of `log_weights` (the leader's is the largest).
pub(crate) fn weights(log_weights: &[f64]) -> Vec<f64> {
    let max = log_weights
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    let w: Vec<f64> = log_weights.iter().map(|l| (l - max).exp()).collect();
    let total: f64 = w.iter().sum();
    w.iter().map(|v| v / total).collect()
}

/// The mixture's second moment about `about`: Σ wᵢ (Pᵢ + (μᵢ − a)(μᵢ − a)ᵀ). With `about`
/// the leader's mean this is the covariance of the leader's estimate under the whole
/// mixture: its own uncertainty plus how far the other hypotheses lie.
pub(crate) fn spread_about<const N: usize>(
    about: &nalgebra::SVector<f64, N>,
    members: &[(f64, nalgebra::SVector<f64, N>, nalgebra::SMatrix<f64, N, N>)],
) -> nalgebra::SMatrix<f64, N, N> {
    members.iter().fold(
        nalgebra::SMatrix::<f64, N, N>::zeros(),
        |acc, (w, mu, p)| {
            let d = mu - about;
            acc + (p + d * d.transpose()) * *w
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hypothesis(log_weight: f64, mean: &[f64], sigma: f64) -> Hypothesis {
        let n = mean.len();
        Hypothesis {
            log_weight,
            state: (
                0.0,
                DVector::from_column_slice(mean),
                DMatrix::identity(n, n) * sigma * sigma,
            ),
            slots: Vec::new(),
            drift: [Vector2::zeros(); 2],
            since_reopen: 0,
            lost_since_s: None,
        }
    }

    #[test]
    fn the_grid_covers_the_prior_with_narrower_components() {
        let sigma0 = 45f64.to_radians();
        let grid = bias_grid(3, sigma0);
        assert_eq!(grid.len(), 9);
        let w = weights(&grid.iter().map(|g| g.log_weight).collect::<Vec<_>>());
        for axis in 0..2 {
            let mean: f64 = grid.iter().zip(&w).map(|(g, w)| w * g.mean[axis]).sum();
            assert!(mean.abs() < 1e-12);
            // The outer components' 1σ reach the prior's 1σ: ±45°.
            let reach = grid
                .iter()
                .map(|g| g.mean[axis].abs() + g.sigma)
                .fold(0.0, f64::max);
            assert!((reach - sigma0).abs() < 1e-12, "{}°", reach.to_degrees());
        }
        // σ 15°, 30° apart, the centre heaviest.
        assert!(grid.iter().all(|g| (g.sigma - sigma0 / 3.0).abs() < 1e-12));
        assert_eq!(grid[4].mean, [0.0, 0.0]);
        assert!(grid.iter().all(|g| g.log_weight <= grid[4].log_weight));
        let one = bias_grid(1, sigma0);
        assert_eq!(
            one,
            vec![BiasStart {
                mean: [0.0, 0.0],
                sigma: sigma0,
                log_weight: 0.0
            }]
        );
    }

    #[test]
    fn far_behind_hypotheses_are_dropped_and_close_ones_merged() {
        let mut bank = vec![
            hypothesis(-20.0, &[100.0, 0.0], 1.0),
            hypothesis(0.0, &[0.0, 0.0], 1.0),
            hypothesis(-0.5, &[0.2, 0.0], 1.0),
            hypothesis(-1.0, &[10.0, 0.0], 1.0),
        ];
        prune_and_merge(&mut bank, 2);
        // The 100 m one is ~e⁻²⁰ behind: dropped. 0 and 0.2 (d² = 0.02) merged, 10 kept.
        assert_eq!(bank.len(), 2);
        let leader = &bank[0];
        assert!(leader.state.1[0] > 0.0 && leader.state.1[0] < 0.1);
        // The merged covariance holds both and their spread.
        assert!(leader.state.2[(0, 0)] > 1.0);
        assert!(leader.log_weight > 0.0);
        assert!((bank[1].state.1[0] - 10.0).abs() < 1e-12);
    }

    #[test]
    fn the_spread_about_the_leader_includes_the_others_distance() {
        let about = nalgebra::Vector2::new(0.0, 0.0);
        let p = nalgebra::Matrix2::identity();
        let members = [
            (0.75, about, p),
            (0.25, nalgebra::Vector2::new(4.0, 0.0), p),
        ];
        let c = spread_about(&about, &members);
        assert!((c[(0, 0)] - (1.0 + 0.25 * 16.0)).abs() < 1e-12);
        assert!((c[(1, 1)] - 1.0).abs() < 1e-12);
    }
}
