//! Optimal assignment between two sets (detections across the two views, estimates to
//! tracks, truth to tracks in the scorer), with `pathfinding`'s Kuhn–Munkres (O(n³)).
//! Either side may be the larger; the crate wants the rows to be the smaller side and
//! integer weights, so this transposes and scales costs by 10⁶ (differences below 10⁻⁶
//! tie), each clamped to 10¹² so that the crate's sums cannot overflow whatever the
//! caller's units.

use pathfinding::matrix::Matrix;
use pathfinding::prelude::{kuhn_munkres, kuhn_munkres_min};

const SCALE: f64 = 1e6;
/// Largest scaled cost or weight: sums over a million entries stay far inside i64.
const MAX_SCALED: f64 = 1e12;

/// The row→column assignment of least total cost: every row of the smaller side gets
/// a column. `cost[r][c]` must be finite and ≥ 0; rows all the same length.
pub fn min_cost(cost: &[Vec<f64>]) -> Vec<Option<usize>> {
    solve(
        cost,
        |c| (c * SCALE).round().clamp(0.0, MAX_SCALED) as i64,
        |m| kuhn_munkres_min(m).1,
    )
}

/// The row→column assignment of greatest total weight (counts).
pub fn max_weight(weight: &[Vec<u64>]) -> Vec<Option<usize>> {
    solve(
        weight,
        |w| w.min(MAX_SCALED as u64) as i64,
        |m| kuhn_munkres(m).1,
    )
}

fn solve<T: Copy>(
    table: &[Vec<T>],
    to_int: impl Fn(T) -> i64,
    run: impl Fn(&Matrix<i64>) -> Vec<usize>,
) -> Vec<Option<usize>> {
    let rows = table.len();
    let columns = table.first().map_or(0, Vec::len);
    if rows == 0 || columns == 0 {
        return vec![None; rows];
    }
    if rows <= columns {
        let m = Matrix::from_fn(rows, columns, |(r, c)| to_int(table[r][c]));
        run(&m).into_iter().map(Some).collect()
    } else {
        let m = Matrix::from_fn(columns, rows, |(c, r)| to_int(table[r][c]));
        let mut out = vec![None; rows];
        for (c, r) in run(&m).into_iter().enumerate() {
            out[r] = Some(c);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every assignment of the smaller side, by brute force (small sizes).
    fn brute_min(cost: &[Vec<f64>]) -> f64 {
        fn go(cost: &[Vec<f64>], r: usize, used: &mut Vec<bool>, best: &mut f64, acc: f64) {
            if r == cost.len() {
                *best = best.min(acc);
                return;
            }
            for c in 0..used.len() {
                if !used[c] {
                    used[c] = true;
                    go(cost, r + 1, used, best, acc + cost[r][c]);
                    used[c] = false;
                }
            }
        }
        let mut best = f64::INFINITY;
        go(cost, 0, &mut vec![false; cost[0].len()], &mut best, 0.0);
        best
    }

    fn total(cost: &[Vec<f64>], a: &[Option<usize>]) -> f64 {
        a.iter()
            .enumerate()
            .filter_map(|(r, c)| c.map(|c| cost[r][c]))
            .sum()
    }

    #[test]
    fn the_least_cost_is_found_whichever_side_is_larger() {
        // A fixed linear congruential sequence (Knuth's MMIX constants).
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((state >> 33) % 10_000) as f64 / 1000.0
        };
        for (rows, columns) in [(1, 1), (2, 3), (3, 3), (4, 2), (5, 5), (3, 6)] {
            let cost: Vec<Vec<f64>> = (0..rows)
                .map(|_| (0..columns).map(|_| next()).collect())
                .collect();
            let a = min_cost(&cost);
            assert_eq!(a.len(), rows);
            assert_eq!(a.iter().flatten().count(), rows.min(columns));
            let mut seen: Vec<_> = a.iter().flatten().collect();
            seen.sort();
            seen.dedup();
            assert_eq!(seen.len(), rows.min(columns), "a column used twice");
            let expected = if rows <= columns {
                brute_min(&cost)
            } else {
                let t: Vec<Vec<f64>> = (0..columns)
                    .map(|c| (0..rows).map(|r| cost[r][c]).collect())
                    .collect();
                brute_min(&t)
            };
            assert!(
                (total(&cost, &a) - expected).abs() < 1e-5,
                "{rows}x{columns}"
            );
        }
    }

    /// Costs far beyond any metric's are clamped, not overflowed.
    #[test]
    fn huge_costs_do_not_overflow() {
        let a = min_cost(&[vec![1e20, 1.0], vec![1.0, f64::MAX]]);
        assert_eq!(a, vec![Some(1), Some(0)]);
        assert_eq!(max_weight(&[vec![u64::MAX, 0]]), vec![Some(0)]);
    }

    #[test]
    fn weights_are_maximised_and_empty_sides_give_nothing() {
        let w = vec![vec![5, 0], vec![4, 1], vec![0, 3]];
        assert_eq!(max_weight(&w), vec![Some(0), None, Some(1)]);
        assert_eq!(min_cost(&[]), Vec::<Option<usize>>::new());
        assert_eq!(min_cost(&[vec![], vec![]]), vec![None, None]);
    }
}
