//! The temporal filter's state as plain data (issue #13): what the geolocation service
//! checkpoints after every estimate, so that a restarted service resumes the track and
//! both yaw biases instead of re-warming them from nothing.
//!
//! Restoring checks everything it is given (dimensions, finite values, a symmetric
//! covariance with a non-negative diagonal): a snapshot that fails is refused, and the
//! filter starts fresh. After a restore, the first update predicts across the time the
//! service was down (the constant-velocity model and the bias random walk of
//! `temporal.rs`), so the covariance, hence h_acc, grows with what was lost.
//!
//! While the start's bias hypotheses are still open (`hypotheses.rs`, the first
//! seconds of a track, longer where the rays could fit several) the snapshot holds
//! the leading one only, its covariance widened by how far the others' means lie
//! (Σ wᵢ dᵢ dᵢᵀ over the core states, dᵢ the mean's distance from the leader's): a
//! service restarted then resumes that hypothesis alone, and states at least the
//! spread the bank stated (a leader alone with its own covariance knows nothing of
//! the hypotheses it outlived).

use crate::hypotheses::{weights, Hypothesis};
use crate::temporal::{ImageId, TemporalEstimator, CORE, REOPEN_HOLD, SLOT};
use crate::{EstimatorConfig, EstimatorError};
use nalgebra::{DMatrix, DVector, Vector2};
use shared_types::conventions::Uav;

/// [`TemporalEstimator`]'s state; `core` is `None` before the first update.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TemporalSnapshot {
    pub core: Option<FilterState>,
    /// Keyframe slots: (UAV index, frame sequence number).
    pub slots: Vec<(u8, u64)>,
    pub drift: [[f64; 2]; 2],
    pub since_reopen: u64,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FilterState {
    pub t_s: f64,
    pub state: Vec<f64>,
    /// Column-major, `state.len()`².
    pub covariance: Vec<f64>,
}

fn invalid(why: &str) -> EstimatorError {
    EstimatorError::Config(format!("temporal snapshot refused: {why}"))
}

impl TemporalEstimator {
    pub fn snapshot(&self) -> TemporalSnapshot {
        let Some(leader) = self.bank.first() else {
            return TemporalSnapshot {
                core: None,
                slots: Vec::new(),
                drift: [[0.0; 2]; 2],
                since_reopen: REOPEN_HOLD as u64,
            };
        };
        let (t, s, p) = &leader.state;
        let mut p = p.clone();
        if self.bank.len() > 1 {
            let w = weights(&self.bank.iter().map(|h| h.log_weight).collect::<Vec<_>>());
            // Core rows only: hypotheses may differ in their keyframe slots.
            let leader_core = s.rows(0, CORE);
            let mut spread = DMatrix::<f64>::zeros(CORE, CORE);
            for (h, w) in self.bank.iter().zip(w) {
                let d = h.state.1.rows(0, CORE) - leader_core;
                spread += &d * d.transpose() * w;
            }
            let mut block = p.view_mut((0, 0), (CORE, CORE));
            block += spread;
        }
        TemporalSnapshot {
            core: Some(FilterState {
                t_s: *t,
                state: s.iter().copied().collect(),
                covariance: p.as_slice().to_vec(),
            }),
            slots: leader
                .slots
                .iter()
                .map(|(uav, seq)| (uav.index() as u8, *seq))
                .collect(),
            drift: leader.drift.map(|d| [d.x, d.y]),
            since_reopen: leader.since_reopen as u64,
        }
    }

    /// A filter with `config` in the state of `snapshot`, or why the snapshot cannot
    /// be trusted.
    pub fn restore(
        config: EstimatorConfig,
        snapshot: &TemporalSnapshot,
    ) -> Result<Self, EstimatorError> {
        let mut filter = Self::new(config)?;
        let slots: Vec<ImageId> = snapshot
            .slots
            .iter()
            .map(|&(uav, seq)| match uav {
                0 => Ok((Uav::Left, seq)),
                1 => Ok((Uav::Right, seq)),
                _ => Err(invalid("a slot names no UAV")),
            })
            .collect::<Result<_, _>>()?;
        let n = filter.core_len() + SLOT * slots.len();
        if let Some(core) = &snapshot.core {
            if core.state.len() != n || core.covariance.len() != n * n {
                return Err(invalid("dimensions do not match the keyframe slots"));
            }
            let finite = core.t_s.is_finite()
                && core
                    .state
                    .iter()
                    .chain(&core.covariance)
                    .all(|v| v.is_finite());
            if !finite {
                return Err(invalid("a value is not finite"));
            }
            let p = DMatrix::from_column_slice(n, n, &core.covariance);
            let symmetric = (0..n).all(|i| {
                p[(i, i)] >= 0.0
                    && (0..i)
                        .all(|j| (p[(i, j)] - p[(j, i)]).abs() <= 1e-9 * (1.0 + p[(i, j)].abs()))
            });
            if !symmetric {
                return Err(invalid(
                    "the covariance is not symmetric with a non-negative diagonal",
                ));
            }
            if !snapshot.drift.iter().flatten().all(|v| v.is_finite()) {
                return Err(invalid("the drift monitor is not finite"));
            }
            filter.bank = vec![Hypothesis {
                log_weight: 0.0,
                state: (core.t_s, DVector::from_column_slice(&core.state), p),
                slots,
                drift: snapshot.drift.map(|d| Vector2::new(d[0], d[1])),
                since_reopen: usize::try_from(snapshot.since_reopen).unwrap_or(usize::MAX),
                lost_since_s: None,
            }];
        } else if !slots.is_empty() {
            return Err(invalid("keyframe slots without a state"));
        }
        Ok(filter)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::SyntheticScenario;
    use crate::PastImage;
    use rand::SeedableRng;

    /// Feeds `filter` synthetic trials from `t` for `seconds`; returns the last estimate.
    fn feed(
        filter: &mut TemporalEstimator,
        rng: &mut rand::rngs::StdRng,
        t0: f64,
        seconds: f64,
        next_id: &mut u64,
    ) -> Option<crate::TemporalEstimate> {
        let scenario = SyntheticScenario::default();
        let mut last = None;
        let mut t = t0;
        while t < t0 + seconds {
            if let Ok(trial) = scenario.trial(t, 4, rng) {
                let o = &trial.observations;
                let past: Vec<PastImage> = o[2..]
                    .iter()
                    .map(|ob| {
                        *next_id += 1;
                        PastImage {
                            id: (ob.uav, *next_id),
                            t_s: t,
                            observation: *ob,
                            rotation_from: [None; 2],
                        }
                    })
                    .collect();
                let window = crate::geolocate(o, &EstimatorConfig::default()).ok();
                if let Ok(e) = filter.update(t, [&o[0], &o[1]], &past, window.as_ref()) {
                    last = Some(e);
                }
            }
            t += 0.1;
        }
        last
    }

    #[test]
    fn a_restored_filter_continues_exactly_like_the_original() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let mut original = TemporalEstimator::new(EstimatorConfig::default()).unwrap();
        let mut id = 0;
        feed(&mut original, &mut rng, 5.0, 10.0, &mut id).unwrap();
        // One hypothesis left: the snapshot holds all there is (with several it holds
        // the leader, widened: `a_restore_while_the_bank_is_open_keeps_its_spread`).
        assert_eq!(original.hypotheses(), 1);
        let snap = original.snapshot();
        // Through the checkpoint file's encoding, as the service does.
        let bytes = shared_types::checkpoint::encode(1, &snap).unwrap();
        let decoded: TemporalSnapshot = shared_types::checkpoint::decode(1, &bytes).unwrap();
        assert_eq!(decoded, snap);
        let mut restored =
            TemporalEstimator::restore(EstimatorConfig::default(), &decoded).unwrap();
        let (mut rng_a, mut rng_b) = (rng.clone(), rng);
        let (mut id_a, mut id_b) = (id, id);
        let a = feed(&mut original, &mut rng_a, 15.0, 2.0, &mut id_a).unwrap();
        let b = feed(&mut restored, &mut rng_b, 15.0, 2.0, &mut id_b).unwrap();
        assert_eq!(a, b);
    }

    /// Restarted while the start's hypotheses are open, the filter resumes the leader
    /// with the others' spread added to its core covariance, not the leader's own.
    #[test]
    fn a_restore_while_the_bank_is_open_keeps_its_spread() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut filter = TemporalEstimator::new(EstimatorConfig::default()).unwrap();
        let mut id = 0;
        feed(&mut filter, &mut rng, 5.0, 0.5, &mut id).unwrap();
        assert!(filter.hypotheses() > 1, "the bank has closed already");
        let own = filter.bank[0].state.2.clone();
        let restored =
            TemporalEstimator::restore(EstimatorConfig::default(), &filter.snapshot()).unwrap();
        assert_eq!(restored.hypotheses(), 1);
        let p = &restored.bank[0].state.2;
        let h2 = |m: &DMatrix<f64>| m[(0, 0)] + m[(1, 1)];
        assert!(
            h2(p) > h2(&own),
            "{} vs the leader's own {}",
            h2(p),
            h2(&own)
        );
        // Widened by a positive semi-definite spread: every variance at least its own.
        assert!((0..p.nrows()).all(|i| p[(i, i)] >= own[(i, i)]));
    }

    #[test]
    fn a_gap_after_restore_widens_the_covariance() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(6);
        let mut filter = TemporalEstimator::new(EstimatorConfig::default()).unwrap();
        let mut id = 0;
        let before = feed(&mut filter, &mut rng, 5.0, 10.0, &mut id).unwrap();
        let mut restored =
            TemporalEstimator::restore(EstimatorConfig::default(), &filter.snapshot()).unwrap();
        // Down for 3 s: the first estimate after it carries the prediction's growth.
        let after = feed(&mut restored, &mut rng, 18.0, 0.1, &mut id).unwrap();
        let h = |e: &crate::TemporalEstimate| {
            e.estimate.covariance[(0, 0)] + e.estimate.covariance[(1, 1)]
        };
        assert!(h(&after) > h(&before), "{} vs {}", h(&after), h(&before));
        let b = |e: &crate::TemporalEstimate| e.estimate.yaw_bias;
        for uav in 0..2 {
            assert!((b(&after)[uav] - b(&before)[uav]).abs() < 1.0_f64.to_radians());
        }
    }

    #[test]
    fn bad_snapshots_are_refused() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut filter = TemporalEstimator::new(EstimatorConfig::default()).unwrap();
        let mut id = 0;
        feed(&mut filter, &mut rng, 5.0, 3.0, &mut id).unwrap();
        let good = filter.snapshot();
        let config = EstimatorConfig::default();
        let mut s = good.clone();
        s.slots.push((0, 1));
        assert!(TemporalEstimator::restore(config, &s).is_err());
        let mut s = good.clone();
        s.slots[0].0 = 2;
        assert!(TemporalEstimator::restore(config, &s).is_err());
        let mut s = good.clone();
        s.core.as_mut().unwrap().state[0] = f64::NAN;
        assert!(TemporalEstimator::restore(config, &s).is_err());
        let mut s = good.clone();
        s.core.as_mut().unwrap().covariance[1] += 1.0;
        assert!(TemporalEstimator::restore(config, &s).is_err());
        let mut s = good.clone();
        s.drift[0][0] = f64::INFINITY;
        assert!(TemporalEstimator::restore(config, &s).is_err());
        assert!(TemporalEstimator::restore(config, &good).is_ok());
        let empty = TemporalEstimator::new(config).unwrap().snapshot();
        assert!(TemporalEstimator::restore(config, &empty).is_ok());
    }
}
