//! The temporal filter's start hypotheses (issue #23): where the current pair's rays
//! meet under a hypothesis's biases, what that point depends on, and where the bias
//! grid has to be split because the point does not move linearly with the biases.
//!
//! Why: each start hypothesis (`hypotheses.rs`) is one linearised filter whose
//! position prior is the current pair's meeting point. That point moves with the
//! biases, so its covariance and its covariance with the biases are what the biases'
//! and the pair's errors make of it (first order, plus the second-order spread where
//! the point curves). Started instead with an independent 15 m position σ, a
//! hypothesis read its position prior as knowledge of the biases: on exact synthetic
//! rays from cameras 45° off nadir its bias σ fell from 15° to 2.7° in half a second
//! with errors of 10° and 15°, and it stayed 130–170 m off while stating 16 m
//! (docs/temporal.md, "Cameras that look ahead").
//!
//! Pure functions over plain data (nalgebra); `temporal.rs` builds the filters.

use crate::hypotheses::{bias_grid, BiasStart};
use crate::Observation;
use nalgebra::{Matrix3, Point3, Vector2, Vector3};

/// A start hypothesis is split where its meeting point's second-order term at ±1σ of a
/// bias exceeds this share of its position spread (`split_where_curved`). Nadir
/// cameras stay below 0.15 over the default grid's 15° components; on exact synthetic
/// rays 45° off nadir 0.2 left 4 % of the estimates beyond 3σ, 0.1 0.4 %, 0.05 0.1 %
/// at twice the hypotheses.
pub(crate) const CURVED: f64 = 0.1;
/// How many times a start hypothesis may be split (3 × 3 each time: 15°, 5°, 1.7°).
pub(crate) const MAX_SPLITS: usize = 2;

/// What one current image's errors are, as the filter models them.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ImageNoise {
    /// σ's of the white pose error (x, y, z metres; yaw, pitch, roll radians).
    pub white: [f64; 6],
    /// The UAV's correlated pose-error block: its first state index and σ's.
    pub correlated: Option<(usize, [f64; 6])>,
    /// σ of the detected pixel, pixels.
    pub sigma_px: f64,
}

/// One source of the meeting point's error.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Source {
    /// ∂point/∂source at the hypothesis.
    pub slope: Vector3<f64>,
    /// Half the second difference over ±σ: how far the point at ±1σ strays from the
    /// line through the point at the hypothesis (zero when it does not exist).
    pub curve: Vector3<f64>,
    pub sigma: f64,
    /// The filter state the source is, if it is one (a bias, a correlated pose error).
    pub state: Option<usize>,
    /// Whether the point exists at ±1σ of this source.
    pub exists: bool,
}

/// The current pair's meeting point under one hypothesis's biases, and its sources.
#[derive(Debug, Clone)]
pub(crate) struct MeetingPrior {
    pub point: Point3<f64>,
    /// The two biases first, then each image's pose-error components and pixel.
    pub sources: Vec<Source>,
}

impl MeetingPrior {
    /// The point's mean squared error about `point`: first-order spread plus the
    /// second-order terms (a source x ~ N(0, σ²) moving the point by `slope` x +
    /// `curve` (x/σ)² shifts its mean by `curve` and spreads it by 2 `curve` `curve`ᵀ
    /// about that mean, 3 `curve` `curve`ᵀ about `point`), plus `floor_m`² per axis.
    pub fn covariance(&self, floor_m: f64) -> Matrix3<f64> {
        let mut c = Matrix3::identity() * floor_m * floor_m;
        for s in &self.sources {
            c += s.slope * s.slope.transpose() * s.sigma * s.sigma
                + 3.0 * s.curve * s.curve.transpose();
        }
        c
    }

    /// The point's first-order spread, metres: √(Σ |slope|² σ²).
    pub fn spread_m(&self) -> f64 {
        self.sources
            .iter()
            .map(|s| s.slope.norm_squared() * s.sigma * s.sigma)
            .sum::<f64>()
            .sqrt()
    }

    /// How far the point curves within ±1σ of the biases: the larger of the two
    /// biases' `curve` as a share of [`Self::spread_m`]; infinite where the point at
    /// ±1σ does not exist (the rays no longer meet in front of both cameras).
    pub fn curvature(&self) -> f64 {
        let spread = self.spread_m().max(f64::MIN_POSITIVE);
        self.sources[..2]
            .iter()
            .map(|s| {
                if s.exists {
                    s.curve.norm() / spread
                } else {
                    f64::INFINITY
                }
            })
            .fold(0.0, f64::max)
    }
}

/// Where the current pair's rays meet with the biases `bias` and, per image, the pose
/// error `e` (measured = true + e, as the filter's residual) and pixel offset `px`
/// removed. `None` when they do not meet in front of both cameras.
fn meet(
    current: [&Observation; 2],
    bias: [f64; 2],
    e: [[f64; 6]; 2],
    px: [[f64; 2]; 2],
    min_angle_rad: f64,
) -> Option<Point3<f64>> {
    let ray = |i: usize| {
        let o = current[i];
        let mut moved = *o;
        let (position, att) = o.pose_without_error(bias, &e[i]);
        moved.position = position;
        moved.attitude = att;
        moved.pixel += Vector2::new(px[i][0], px[i][1]);
        let direction = crate::ground_model::PreparedRay::new(&moved).direction(att.yaw);
        (moved.position, direction)
    };
    let ((ol, dl), (or, dr)) = (ray(0), ray(1));
    crate::altitude::ray_pair_midpoint(ol, dl, or, dr, min_angle_rad)
        .ok()
        .map(|m| m.midpoint)
}

/// The current pair's meeting point under the biases `bias` (radians, each with σ
/// `bias_sigma`, states 5 and 6) and its sources: the two biases, each image's pose
/// error (white, and its UAV's correlated block when there is one) and pixel noise.
/// `None` when the rays do not meet in front of both cameras, or a slope is not finite.
pub(crate) fn meeting_prior(
    current: [&Observation; 2],
    bias: [f64; 2],
    bias_sigma: f64,
    noise: [ImageNoise; 2],
    min_angle_rad: f64,
) -> Option<MeetingPrior> {
    const NO_POSE: [[f64; 6]; 2] = [[0.0; 6]; 2];
    const NO_PIXEL: [[f64; 2]; 2] = [[0.0; 2]; 2];
    let point = meet(current, bias, NO_POSE, NO_PIXEL, min_angle_rad)?;
    // Slope by central differences at `step`; curve from the points at ±σ.
    let source = |f: &dyn Fn(f64) -> Option<Point3<f64>>, step: f64, sigma: f64, state| {
        let slope = (f(step)? - f(-step)?) / (2.0 * step);
        let (curve, exists) = match (f(sigma), f(-sigma)) {
            (Some(a), Some(b)) => (((a - point) + (b - point)) / 2.0, true),
            _ => (Vector3::zeros(), false),
        };
        Some(Source {
            slope,
            curve,
            sigma,
            state,
            exists,
        })
    };
    let mut sources = Vec::with_capacity(2 + 2 * 14);
    for k in 0..2 {
        let f = |h: f64| {
            let mut b = bias;
            b[k] += h;
            meet(current, b, NO_POSE, NO_PIXEL, min_angle_rad)
        };
        sources.push(source(&f, 1e-5, bias_sigma, Some(5 + k))?);
    }
    for (i, n) in noise.iter().enumerate() {
        for j in 0..6 {
            let f = |h: f64| {
                let mut e = NO_POSE;
                e[i][j] = h;
                meet(current, bias, e, NO_PIXEL, min_angle_rad)
            };
            let step = if j < 3 { 1e-3 } else { 1e-5 };
            sources.push(source(&f, step, n.white[j], None)?);
            if let Some((g, sigma)) = n.correlated {
                sources.push(source(&f, step, sigma[j], Some(g + j))?);
            }
        }
        for j in 0..2 {
            let f = |h: f64| {
                let mut px = NO_PIXEL;
                px[i][j] = h;
                meet(current, bias, NO_POSE, px, min_angle_rad)
            };
            sources.push(source(&f, 1e-2, n.sigma_px, None)?);
        }
    }
    sources
        .iter()
        .all(|s| s.slope.iter().chain(s.curve.iter()).all(|v| v.is_finite()) && s.sigma.is_finite())
        .then_some(MeetingPrior { point, sources })
}

/// The start grid `grid`, its most curved components split first: while a component
/// whose `curvature` is above [`CURVED`] is at most [`MAX_SPLITS`] deep and the bank
/// stays within `cap`, it is replaced by the 3 × 3 grid that covers it with components
/// a third as wide (`bias_grid`, their weights summing to its weight).
///
/// Why: the meeting point as a linear function of the biases holds only where it moves
/// nearly linearly with them. Nadir cameras' rays meet at points that do. Two cameras
/// looking 45° ahead meet at points that run away along their lines of sight as
/// opposite biases turn them parallel: 100 m up and 70 m apart, the component at (30°,
/// −30°) has 18 m/° at its mean, and the point at its ±1σ is ~900 m from the line. On
/// exact synthetic rays the fixed 3 × 3 grid left 14 % of the estimates beyond 3σ
/// there (a fixed 7 × 7 grid 0.5 %); splitting only where the point curves spends the
/// extra hypotheses where they are needed.
pub(crate) fn split_where_curved(
    grid: Vec<BiasStart>,
    cap: usize,
    curvature: impl Fn(&BiasStart) -> f64,
) -> Vec<BiasStart> {
    if grid.len() + 8 > cap {
        // No room for a split (the default 7 × 7 grid fills the cap): skip the
        // curvature, ~80 ray-pair solves a component.
        return grid;
    }
    let mut bank: Vec<(BiasStart, usize, f64)> = grid
        .into_iter()
        .map(|g| {
            let c = curvature(&g);
            (g, 0, c)
        })
        .collect();
    while bank.len() + 8 <= cap {
        let Some((i, _)) = bank
            .iter()
            .enumerate()
            .filter(|(_, (_, depth, c))| *depth < MAX_SPLITS && *c > CURVED)
            .max_by(|a, b| a.1 .2.total_cmp(&b.1 .2))
        else {
            break;
        };
        let (g, depth, _) = bank.swap_remove(i);
        let sub = bias_grid(3, g.sigma);
        let total = sub.iter().map(|c| c.log_weight.exp()).sum::<f64>().ln();
        for c in sub {
            let child = BiasStart {
                mean: [g.mean[0] + c.mean[0], g.mean[1] + c.mean[1]],
                sigma: c.sigma,
                log_weight: g.log_weight + c.log_weight - total,
            };
            let c = curvature(&child);
            bank.push((child, depth + 1, c));
        }
    }
    bank.into_iter().map(|(g, ..)| g).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::SyntheticScenario;
    use rand::SeedableRng;

    fn noise() -> [ImageNoise; 2] {
        let n = ImageNoise {
            white: [
                3.0,
                3.0,
                3.0,
                2f64.to_radians(),
                2f64.to_radians(),
                2f64.to_radians(),
            ],
            correlated: None,
            sigma_px: 1.0,
        };
        [n, n]
    }

    /// The current pair of a noise-free flight at `t_s`, with its true biases.
    fn pair(sc: &SyntheticScenario, t_s: f64) -> ([Observation; 2], [f64; 2], Point3<f64>) {
        let trial = sc
            .trial(t_s, 1, &mut rand::rngs::StdRng::seed_from_u64(1))
            .unwrap();
        (
            [trial.observations[0], trial.observations[1]],
            trial.yaw_bias,
            trial.target,
        )
    }

    fn exact(sc: SyntheticScenario) -> SyntheticScenario {
        SyntheticScenario {
            noise: crate::synthetic::NavNoise::isotropic(0.0, 0.0),
            ..sc
        }
    }

    /// At the true biases the rays meet at the target; the slopes match a finite
    /// change of a bias, and a bias's covariance with the point is its slope × σ².
    #[test]
    fn the_meeting_point_and_its_slopes_are_the_geometry() {
        for tilt in [0.0, 45.0] {
            let sc = exact(SyntheticScenario {
                camera_tilt_deg: tilt,
                trail_m: 100.0 * f64::tan(tilt.to_radians()),
                ..Default::default()
            });
            let (obs, bias, target) = pair(&sc, 3.0);
            let prior = meeting_prior([&obs[0], &obs[1]], bias, 0.1, noise(), 1e-3).unwrap();
            assert!((prior.point - target).norm() < 1e-6, "tilt {tilt}");
            let step = 0.2f64.to_radians();
            let moved = meet(
                [&obs[0], &obs[1]],
                [bias[0] + step, bias[1]],
                [[0.0; 6]; 2],
                [[0.0; 2]; 2],
                1e-3,
            )
            .unwrap();
            let predicted = prior.point + prior.sources[0].slope * step;
            assert!(
                (moved - predicted).norm() < 0.05 * (moved - prior.point).norm(),
                "tilt {tilt}: {moved} against {predicted}"
            );
            assert_eq!(prior.sources[0].state, Some(5));
            assert_eq!(prior.sources[1].state, Some(6));
            assert_eq!(prior.sources.len(), 2 + 2 * 8);
            let c = prior.covariance(0.0);
            assert!(c.iter().all(|v| v.is_finite()) && c[(2, 2)] > 0.0);
        }
    }

    /// On noisy pairs (σ_pos 3 m, σ_att 2°, 80 m up and 40 m apart, where one pair's
    /// altitude is worth ±11–15 m) at the true biases, the meeting point's stated
    /// covariance is its error's: mean NEES over 4 000 pairs within χ²(3)'s 99 % region
    /// for that many (2.9–3.1), the altitude's error / σ rms within 5 % of 1.
    #[test]
    fn the_meeting_points_covariance_is_its_error() {
        let sc = SyntheticScenario {
            altitude_agl_m: 80.0,
            uav_separation_m: 40.0,
            ..Default::default()
        };
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let (mut z2, mut nees, mut n) = (0.0, 0.0, 0);
        for i in 0..4000 {
            let trial = sc.trial(3.0 + 0.01 * f64::from(i), 1, &mut rng).unwrap();
            let obs = [trial.observations[0], trial.observations[1]];
            let p = meeting_prior([&obs[0], &obs[1]], trial.yaw_bias, 1e-9, noise(), 1e-3)
                .expect("the rays meet");
            let c = p.covariance(0.0);
            let d = p.point - trial.target;
            z2 += d.z * d.z / c[(2, 2)];
            nees += (d.transpose() * c.try_inverse().unwrap() * d)[(0, 0)];
            n += 1;
        }
        let (rms, nees) = ((z2 / f64::from(n)).sqrt(), nees / f64::from(n));
        eprintln!("z error / σ rms {rms:.3}, mean NEES {nees:.2} over {n} pairs");
        assert!((2.9..=3.1).contains(&nees), "mean NEES {nees:.2}");
        assert!((rms - 1.0).abs() < 0.05, "z rms {rms:.3}");
    }

    /// Nadir cameras' meeting points barely curve over the default grid's 15°
    /// components, so the grid stays 3 × 3; cameras 45° ahead of nadir split it where
    /// opposite biases turn their rays parallel, never beyond the cap, the weights
    /// still summing to the grid's.
    #[test]
    fn the_grid_is_split_only_where_the_meeting_point_curves() {
        let sigma0 = 45f64.to_radians();
        for (tilt, split) in [(0.0, false), (45.0, true)] {
            let sc = exact(SyntheticScenario {
                camera_tilt_deg: tilt,
                trail_m: 100.0 * f64::tan(tilt.to_radians()),
                ..Default::default()
            });
            let (obs, ..) = pair(&sc, 3.0);
            let curvature = |g: &BiasStart| {
                meeting_prior([&obs[0], &obs[1]], g.mean, g.sigma, noise(), 1e-3)
                    .map_or(f64::INFINITY, |p| p.curvature())
            };
            let grid = bias_grid(3, sigma0);
            let mass = |g: &[BiasStart]| g.iter().map(|c| c.log_weight.exp()).sum::<f64>();
            let before = mass(&grid);
            for cap in [9, 49, 81] {
                let bank = split_where_curved(grid.clone(), cap, curvature);
                assert!(
                    bank.len() <= cap.max(9),
                    "tilt {tilt}, cap {cap}: {}",
                    bank.len()
                );
                assert_eq!(bank.len() > 9, split && cap > 9, "tilt {tilt}, cap {cap}");
                assert!((mass(&bank) - before).abs() < 1e-9 * before);
            }
        }
    }
}
