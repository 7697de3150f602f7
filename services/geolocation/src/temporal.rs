//! Beyond the paper (issue #7): the yaw biases and the target carried across
//! geolocations by an iterated extended Kalman filter, so accuracy accumulates over time
//! instead of depending on one 8-image window. Design note: docs/temporal.md.
//!
//! State s = (x, y, z, v_x, v_y, δψ_L, δψ_R):
//! - the target follows a constant-velocity model in x, y (white acceleration σ_a) and a
//!   random walk in z;
//! - each bias is a random walk whose rate matches a configurable drift (eq. 34 drifts
//!   0.2°/s).
//!
//! Measurements are the rays of a geolocation's observation set, with the residual of
//! the joint estimator (`joint.rs`):
//!
//! - The current pair's pose noise is new every frame, so its two images get six
//!   pose-error states each for one update, marginalised after it. (With that noise
//!   in the ray's covariance C_k instead, as in the joint estimator, C_k is evaluated
//!   at the estimate while the residual scales with 1/depth: the update then prefers
//!   a target further from the cameras, and the altitude sat ~1.4 m low with
//!   horizontal GPS noise alone. docs/temporal.md, "The altitude offset".)
//! - A past keyframe is reused by many consecutive geolocations with *one* pose error.
//!   Its largest baseline, the information that separates the biases from a target
//!   displacement, comes at its last uses. Each keyframe in the window therefore gets
//!   its own six pose-error states (x, y, z, yaw, pitch, roll), with the noise model's
//!   σ's as prior. Its rays depend on them, and its reuse is not counted as new
//!   evidence. The states are marginalised when the keyframe leaves the window. This is
//!   the idea of the MSCKF, applied to keyframe poses.
//!
//! Rays are gated by their Mahalanobis distance (χ², two degrees of freedom, 99.9 %). After a bias step (an AHRS re-initialisation) the
//! innovations stay large. Three such geolocations in a row re-open the bias and
//! position covariances, and the filter re-converges.
//!
//! The filter never reads truth. Cost: ~0.2 ms per geolocation with 8 images (the
//! state has 7 + 8 per keyframe + 12 entries during an update).

use crate::joint::{reproject, Theta};
use crate::{Estimate, EstimatorConfig, EstimatorError, Observation};
use nalgebra::{DMatrix, DVector, Matrix4, Point3};
use shared_types::conventions::Uav;

/// χ²(2) at 99.9 %: a ray further than this from the prediction is rejected.
const GATE: f64 = 13.8;
/// Weight of the newest geolocation in the running mean of each UAV's whitened
/// current-ray innovation.
const DRIFT_ALPHA: f64 = 0.1;
/// χ²(2) at 99.99 %: a running mean this far from zero (in units of its own σ under a
/// consistent filter) means a persistent offset: a bias step.
const DRIFT_GATE: f64 = 18.4;
/// Geolocations after a re-opening before another can happen.
const REOPEN_HOLD: usize = 20;

/// Identifies an image across geolocations: (UAV, frame sequence number).
pub type ImageId = (Uav, u64);

/// How far an estimate can be trusted (issue #23): `track.csv`'s `quality`, MCAP's
/// and the report's. Its accuracy is always the filter's covariance; this says why it
/// is what it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quality {
    /// The yaw biases are not yet known well (1σ above `converged_bias_sigma_deg`):
    /// after the start or a re-opening. The stated accuracy is large and honest.
    #[default]
    Converging = 0,
    /// The current pair's rays were taken and the biases are known.
    Tracking = 1,
    /// No ray of the current pair was taken (gated out, or none usable): the estimate
    /// is the filter's prediction, its covariance grows with time.
    Coasting = 2,
}

impl Quality {
    pub fn name(self) -> &'static str {
        match self {
            Quality::Converging => "converging",
            Quality::Tracking => "tracking",
            Quality::Coasting => "coasting",
        }
    }

    pub fn from_index(i: u64) -> Option<Self> {
        [Quality::Converging, Quality::Tracking, Quality::Coasting]
            .get(i as usize)
            .copied()
    }
}

/// What the filter adds to an [`Estimate`].
#[derive(Debug, Clone, PartialEq)]
pub struct TemporalEstimate {
    pub estimate: Estimate,
    /// Target velocity (v_x, v_y), m/s.
    pub velocity: [f64; 2],
    /// 1σ of v_x and v_y from the filter's covariance, m/s.
    pub velocity_std_mps: [f64; 2],
    /// Rays used in this update and rays gated out.
    pub rays_used: usize,
    pub rays_rejected: usize,
    /// The covariance was re-opened at this update (bias step suspected).
    pub reopened: bool,
    pub quality: Quality,
}

/// The filter's tuning (in `EstimatorConfig`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TemporalConfig {
    /// σ of the target's horizontal acceleration, m/s².
    pub acceleration_sigma_mps2: f64,
    /// Random-walk σ of the target altitude, m/√s.
    pub altitude_walk_m_per_sqrt_s: f64,
    /// Random-walk σ of each bias, °/√s (matches a drift of this many °/s over 1 s).
    pub bias_drift_deg_per_sqrt_s: f64,
    /// σ of the first state: position (m), velocity (m/s) and biases (°). The
    /// position starts at the first window's estimate; the biases start at **zero**
    /// with this σ, as wide as a real AHRS's yaw error before any correction (not at
    /// one window's estimate: on an unseen scene that was 60–80° off, and the filter
    /// trusted it).
    pub initial_position_sigma_m: f64,
    pub initial_velocity_sigma_mps: f64,
    pub initial_bias_sigma_deg: f64,
    /// The estimate is `converging` while either bias's 1σ is above this, degrees.
    pub converged_bias_sigma_deg: f64,
    /// Added to the bias σ when the covariance is re-opened, degrees.
    pub reopen_bias_sigma_deg: f64,
    /// σ of a past image's pixel, which comes from the epipolar transfer, not from the
    /// detector (measured: median 4 px; docs/matching.md): the part that changes from
    /// one geolocation to the next ...
    pub transfer_sigma_px: f64,
    /// ... and the part a keyframe keeps across its reuses (its E estimates resemble
    /// each other), carried as two states per keyframe.
    pub transfer_offset_sigma_px: f64,
}

impl Default for TemporalConfig {
    fn default() -> Self {
        Self {
            acceleration_sigma_mps2: 1.5,
            altitude_walk_m_per_sqrt_s: 0.3,
            bias_drift_deg_per_sqrt_s: 0.2,
            initial_position_sigma_m: 15.0,
            initial_velocity_sigma_mps: 8.0,
            initial_bias_sigma_deg: 45.0,
            converged_bias_sigma_deg: 3.0,
            reopen_bias_sigma_deg: 15.0,
            transfer_sigma_px: 4.0,
            transfer_offset_sigma_px: 6.0,
        }
    }
}

impl TemporalConfig {
    pub fn validate(&self) -> Result<(), EstimatorError> {
        let all = [
            self.acceleration_sigma_mps2,
            self.altitude_walk_m_per_sqrt_s,
            self.bias_drift_deg_per_sqrt_s,
            self.initial_position_sigma_m,
            self.initial_velocity_sigma_mps,
            self.initial_bias_sigma_deg,
            self.converged_bias_sigma_deg,
            self.reopen_bias_sigma_deg,
            self.transfer_sigma_px,
            self.transfer_offset_sigma_px,
        ];
        if all.iter().all(|v| v.is_finite() && *v > 0.0) {
            Ok(())
        } else {
            Err(EstimatorError::Config(format!(
                "[estimator.temporal] σ's must be finite and > 0, got {self:?}"
            )))
        }
    }
}

/// The filter. Feed it every geolocation's observation set in time order.
#[derive(Debug, Clone)]
pub struct TemporalEstimator {
    pub(crate) config: EstimatorConfig,
    /// (time, state, covariance): 7 core states then 8 per keyframe slot.
    pub(crate) state: Option<(f64, DVector<f64>, DMatrix<f64>)>,
    pub(crate) slots: Vec<ImageId>,
    /// Running mean of each UAV's whitened current-ray innovation (zero-mean when the
    /// filter's model holds).
    pub(crate) drift: [nalgebra::Vector2<f64>; 2],
    /// Geolocations since the last re-opening.
    pub(crate) since_reopen: usize,
    /// Before the start: the last plausible window estimates (t, position).
    pub(crate) start_candidates: Vec<(f64, Point3<f64>)>,
}

/// Window estimates that must agree before the filter starts.
const START_CONSENSUS: usize = 3;
/// How far a target can drive between two of them, m/s (the agreement's allowance).
const START_MAX_SPEED_MPS: f64 = 20.0;

/// Core states: x, y, z, v_x, v_y, δψ_L, δψ_R ...
const CORE: usize = 7;
/// ... then, when either UAV's noise model has a correlated error, each UAV's
/// correlated pose error (x, y, z, yaw, pitch, roll; zero with zero variance for the
/// components that are white), starting at these indices.
const GM: [usize; 2] = [CORE, CORE + 6];
/// States per keyframe: pose error (x, y, z, yaw, pitch, roll) and the offset (u, v)
/// its epipolar transfer shares across reuses.
pub(crate) const SLOT: usize = 8;

fn theta(s: &DVector<f64>) -> Theta {
    Theta::new(s[0], s[1], s[2], s[5], s[6])
}

/// One ray and where its pose error lives.
struct Ray {
    obs: Observation,
    /// Index of the first of the image's six pose-error states. Every ray has them:
    /// a keyframe's persist while it is in the window, the current pair's live for one
    /// update (their pose noise is new every frame) and are marginalised after it.
    slot: usize,
    /// Index of the keyframe's transfer offset (u, v) states; the current pair has none.
    offset: Option<usize>,
    /// The current pair's correlated pose error: its UAV's block, added to `slot`'s.
    /// (A keyframe's slot starts from that block and holds the whole error.)
    gm: Option<usize>,
    /// σ of what remains of the pixel once the pose error is a state: the transfer's
    /// per-geolocation part for a keyframe, the detector's σ for the current pair.
    sigma_px: f64,
}

/// Residual of a ray with the image's pose error `e` (measured = true + e) removed and
/// its transfer offset `offset` (pixels) added.
fn ray_residual(
    o: &Observation,
    th: &Theta,
    e: &[f64],
    offset: Option<[f64; 2]>,
) -> Option<nalgebra::Vector2<f64>> {
    let bias = th[3 + o.uav.index()];
    let mut att = o.attitude.corrected_for_yaw_bias(bias);
    att.yaw -= e[3];
    att.pitch -= e[4];
    att.roll -= e[5];
    let pos = [
        o.position.x - e[0],
        o.position.y - e[1],
        o.position.z - e[2],
    ];
    let p = Point3::new(th[0], th[1], th[2]);
    let [du, dv] = offset.unwrap_or([0.0; 2]);
    Some(reproject(o, pos, att, &p)? - o.pixel + nalgebra::Vector2::new(du, dv))
}

impl TemporalEstimator {
    pub fn new(config: EstimatorConfig) -> Result<Self, EstimatorError> {
        config.validate()?;
        config.temporal.validate()?;
        Ok(Self {
            config,
            state: None,
            slots: Vec::new(),
            drift: [nalgebra::Vector2::zeros(); 2],
            since_reopen: REOPEN_HOLD,
            start_candidates: Vec::new(),
        })
    }

    /// Forgets everything (a new stream, or time went backwards).
    pub fn reset(&mut self) {
        self.state = None;
        self.slots.clear();
        self.drift = [nalgebra::Vector2::zeros(); 2];
        self.since_reopen = REOPEN_HOLD;
        self.start_candidates.clear();
    }

    /// Whether the filter may start from `window` at `t_s`: the window estimate must be
    /// plausible (below both current cameras, both biases within twice the start's
    /// σ, at least 45°) and agree with the previous [`START_CONSENSUS`] − 1 plausible ones (within
    /// twice the start's position σ plus what a target can drive in between). One
    /// set that pairs the target in one camera with a look-alike in the other gives a
    /// window estimate hundreds of metres off (`suite_traffic`); the filter started
    /// there with σ 15 m and never came back.
    fn agree_on_start(
        &mut self,
        t_s: f64,
        current: [&Observation; 2],
        window: &Estimate,
    ) -> Result<(), EstimatorError> {
        let tc = self.config.temporal;
        let p = window.position;
        let bias_limit = (2.0 * tc.initial_bias_sigma_deg).max(45.0).to_radians();
        let plausible = p.iter().all(|v| v.is_finite())
            && window.yaw_bias.iter().all(|b| b.abs() <= bias_limit)
            && current.iter().all(|o| p.z < o.position.z);
        if !plausible {
            return Err(EstimatorError::NotStarted {
                reason: "implausible window estimate",
            });
        }
        self.start_candidates.push((t_s, p));
        if self.start_candidates.len() > START_CONSENSUS {
            self.start_candidates.remove(0);
        }
        let tolerance =
            |dt: f64| 2.0 * tc.initial_position_sigma_m + START_MAX_SPEED_MPS * dt.abs();
        let agree = self.start_candidates.iter().all(|(ti, pi)| {
            self.start_candidates
                .iter()
                .all(|(tj, pj)| (pi - pj).norm() <= tolerance(ti - tj))
        });
        match (self.start_candidates.len() == START_CONSENSUS, agree) {
            (true, true) => Ok(()),
            (_, false) => {
                // Keep the newest: the others disagree with it or with each other.
                self.start_candidates
                    .drain(..self.start_candidates.len() - 1);
                Err(EstimatorError::NotStarted {
                    reason: "window estimates disagree",
                })
            }
            (false, true) => Err(EstimatorError::NotStarted {
                reason: "waiting for agreeing window estimates",
            }),
        }
    }

    /// σ's of the white part of one image's pose error (x, y, z, yaw, pitch, roll):
    /// all of it under the paper's model, the jitter where an error is correlated.
    fn pose_sigmas(&self, uav: Uav) -> [f64; 6] {
        let n = self.config.noise(uav);
        let pos = |s: f64| {
            if n.position_tau_s > 0.0 {
                n.position_jitter_m
            } else {
                s
            }
        };
        let att = |s: f64| {
            if n.attitude_tau_s > 0.0 {
                n.attitude_jitter_deg.to_radians()
            } else {
                s.to_radians()
            }
        };
        [
            pos(n.sigma_position_m[0]),
            pos(n.sigma_position_m[1]),
            pos(n.sigma_position_m[2]),
            att(n.sigma_yaw_deg),
            att(n.sigma_pitch_deg),
            att(n.sigma_roll_deg),
        ]
    }

    /// Length of the core state (before the keyframe slots).
    pub(crate) fn core_len(&self) -> usize {
        let correlated =
            self.config.noise_left.is_correlated() || self.config.noise_right.is_correlated();
        if correlated {
            CORE + 12
        } else {
            CORE
        }
    }

    /// First index of `uav`'s correlated pose-error block, if the state has one.
    fn gm_block(&self, uav: Uav) -> Option<usize> {
        (self.core_len() > CORE).then_some(GM[uav.index()])
    }

    /// (stationary σ, time constant) of each component of one UAV's correlated pose
    /// error; σ 0 where the error is white.
    fn correlated(&self, uav: Uav) -> [(f64, f64); 6] {
        let n = self.config.noise(uav);
        let pos = |s: f64| {
            (
                if n.position_tau_s > 0.0 { s } else { 0.0 },
                n.position_tau_s,
            )
        };
        let att = |s: f64| {
            let on = n.attitude_tau_s > 0.0;
            (if on { s.to_radians() } else { 0.0 }, n.attitude_tau_s)
        };
        [
            pos(n.sigma_position_m[0]),
            pos(n.sigma_position_m[1]),
            pos(n.sigma_position_m[2]),
            att(n.sigma_yaw_deg),
            att(n.sigma_pitch_deg),
            att(n.sigma_roll_deg),
        ]
    }

    /// Residual, its measurement covariance and its Jacobian over the whole state.
    fn linearise(
        &self,
        ray: &Ray,
        s: &DVector<f64>,
    ) -> Option<(nalgebra::Vector2<f64>, nalgebra::Matrix2<f64>, DMatrix<f64>)> {
        let th = theta(s);
        let e: Vec<f64> = (0..6)
            .map(|k| s[ray.slot + k] + ray.gm.map_or(0.0, |g| s[g + k]))
            .collect();
        let offset = ray.offset.map(|j| [s[j], s[j + 1]]);
        let r0 = ray_residual(&ray.obs, &th, &e, offset)?;
        let c = nalgebra::Matrix2::identity() * ray.sigma_px.powi(2);
        let mut h = DMatrix::<f64>::zeros(2, s.len());
        for (col, k) in [(0usize, 0usize), (1, 1), (2, 2), (5, 3), (6, 4)] {
            let step = if k < 3 { 1e-4 } else { 1e-7 };
            let mut t = th;
            t[k] += step;
            let d = (ray_residual(&ray.obs, &t, &e, offset)? - r0) / step;
            h.view_mut((0, col), (2, 1)).copy_from(&d);
        }
        if let Some(j) = ray.offset {
            // The transfer offset enters the residual with unit slope.
            h[(0, j)] = 1.0;
            h[(1, j + 1)] = 1.0;
        }
        for k in 0..6 {
            let step = if k < 3 { 1e-4 } else { 1e-7 };
            let mut ek = e.clone();
            ek[k] += step;
            let d = (ray_residual(&ray.obs, &th, &ek, offset)? - r0) / step;
            h.view_mut((0, ray.slot + k), (2, 1)).copy_from(&d);
            if let Some(g) = ray.gm {
                h.view_mut((0, g + k), (2, 1)).copy_from(&d);
            }
        }
        Some((r0, c, h))
    }

    /// Adds one geolocation at `t_s`: `current` is the current (left, right) pair, `past`
    /// the past images with their ids. `window` is the per-window estimate of the same
    /// set (paper's or joint), used only to start the filter.
    pub fn update(
        &mut self,
        t_s: f64,
        current: [&Observation; 2],
        past: &[(ImageId, Observation)],
        window: Option<&Estimate>,
    ) -> Result<TemporalEstimate, EstimatorError> {
        if !t_s.is_finite() {
            return Err(EstimatorError::NonFinite {
                index: 0,
                what: "time",
            });
        }
        for (i, o) in current.iter().enumerate() {
            o.validate(i)?;
        }
        for (i, (_, o)) in past.iter().enumerate() {
            o.validate(i + 2)?;
        }
        if matches!(self.state, Some((t0, _, _)) if t_s < t0) {
            self.reset();
        }
        let tc = self.config.temporal;
        let (t0, mut s, mut p) = match self.state.take() {
            Some(x) => x,
            None => {
                // Start from the window estimate (never from truth), once several agree.
                let w = window.ok_or(EstimatorError::TooFewImages {
                    needed: 3,
                    left: 1,
                    right: 1,
                })?;
                self.agree_on_start(t_s, current, w)?;
                self.start_candidates.clear();
                self.slots.clear();
                let mut s = DVector::zeros(self.core_len());
                s[0] = w.position.x;
                s[1] = w.position.y;
                s[2] = w.position.z;
                let (sp, sv, sb) = (
                    tc.initial_position_sigma_m,
                    tc.initial_velocity_sigma_mps,
                    tc.initial_bias_sigma_deg.to_radians(),
                );
                let mut p = DMatrix::zeros(s.len(), s.len());
                for (i, v) in [sp, sp, sp, sv, sv, sb, sb].into_iter().enumerate() {
                    p[(i, i)] = v * v;
                }
                for uav in [Uav::Left, Uav::Right] {
                    let Some(g) = self.gm_block(uav) else {
                        continue;
                    };
                    for (k, (sigma, _)) in self.correlated(uav).into_iter().enumerate() {
                        p[(g + k, g + k)] = sigma * sigma;
                    }
                }
                (t_s, s, p)
            }
        };
        // Predict the core: constant velocity (white acceleration), random walks for z
        // and the biases. Keyframe pose errors do not change.
        let dt = t_s - t0;
        if dt > 0.0 {
            let n = s.len();
            let mut f = DMatrix::<f64>::identity(n, n);
            f[(0, 3)] = dt;
            f[(1, 4)] = dt;
            let qa = tc.acceleration_sigma_mps2.powi(2);
            let mut q = DMatrix::<f64>::zeros(n, n);
            for (pos, vel) in [(0, 3), (1, 4)] {
                q[(pos, pos)] = qa * dt.powi(3) / 3.0;
                q[(pos, vel)] = qa * dt.powi(2) / 2.0;
                q[(vel, pos)] = qa * dt.powi(2) / 2.0;
                q[(vel, vel)] = qa * dt;
            }
            q[(2, 2)] = tc.altitude_walk_m_per_sqrt_s.powi(2) * dt;
            let qb = tc.bias_drift_deg_per_sqrt_s.to_radians().powi(2) * dt;
            q[(5, 5)] = qb;
            q[(6, 6)] = qb;
            // Correlated pose errors: first-order Gauss–Markov, exact discretisation.
            for uav in [Uav::Left, Uav::Right] {
                let Some(g) = self.gm_block(uav) else {
                    continue;
                };
                for (k, (sigma, tau)) in self.correlated(uav).into_iter().enumerate() {
                    if sigma > 0.0 {
                        let i = g + k;
                        let rho = (-dt / tau).exp();
                        f[(i, i)] = rho;
                        q[(i, i)] = sigma * sigma * (1.0 - rho * rho);
                    }
                }
            }
            s = &f * s;
            p = &f * p * f.transpose() + q;
        }

        // Keyframe slots: marginalise those that left the window, add the new ones.
        let ids: Vec<ImageId> = past.iter().map(|(id, _)| *id).collect();
        let core = self.core_len();
        let keep: Vec<usize> = (0..core)
            .chain(
                self.slots
                    .iter()
                    .enumerate()
                    .filter(|(_, id)| ids.contains(id))
                    .flat_map(|(k, _)| core + SLOT * k..core + SLOT * (k + 1)),
            )
            .collect();
        if keep.len() != s.len() {
            s = DVector::from_iterator(keep.len(), keep.iter().map(|&i| s[i]));
            p = DMatrix::from_fn(keep.len(), keep.len(), |r, c| p[(keep[r], keep[c])]);
            self.slots.retain(|id| ids.contains(id));
        }
        for (id, _) in past {
            if !self.slots.contains(id) {
                let sig = self.pose_sigmas(id.0);
                let n = s.len();
                s = s.resize_vertically(n + SLOT, 0.0);
                p = p.resize(n + SLOT, n + SLOT, 0.0);
                // Its pose error is its UAV's correlated error (as it is now: the
                // keyframe is a second or two old, short beside the time constants)
                // plus its own white part.
                if let Some(g) = self.gm_block(id.0) {
                    for j in 0..6 {
                        s[n + j] = s[g + j];
                        for c in 0..n {
                            p[(n + j, c)] = p[(g + j, c)];
                            p[(c, n + j)] = p[(c, g + j)];
                        }
                    }
                    for j in 0..6 {
                        for k in 0..6 {
                            p[(n + j, n + k)] = p[(g + j, g + k)];
                        }
                    }
                }
                for j in 0..6 {
                    p[(n + j, n + j)] += sig[j].max(1e-6).powi(2);
                }
                let offset = tc.transfer_offset_sigma_px.powi(2);
                p[(n + 6, n + 6)] = offset;
                p[(n + 7, n + 7)] = offset;
                self.slots.push(*id);
            }
        }
        // The current pair's pose errors: six states per image for this update only
        // (marginalised after it). With their pose noise in the covariance instead,
        // evaluated at the estimate, the reprojection residual's 1/depth scale made
        // the update prefer a target further from the cameras: the altitude sat
        // ~1.4 m low with horizontal GPS noise alone (docs/temporal.md).
        let kept = s.len();
        let mut rays: Vec<Ray> = Vec::with_capacity(2 + past.len());
        for o in current {
            let sig = self.pose_sigmas(o.uav);
            let n = s.len();
            s = s.resize_vertically(n + 6, 0.0);
            p = p.resize(n + 6, n + 6, 0.0);
            for j in 0..6 {
                p[(n + j, n + j)] = sig[j].max(1e-6).powi(2);
            }
            rays.push(Ray {
                obs: *o,
                slot: n,
                offset: None,
                gm: self.gm_block(o.uav),
                sigma_px: self.config.noise(o.uav).sigma_pixel_px,
            });
        }
        for (id, o) in past {
            let Some(k) = self.slots.iter().position(|x| x == id) else {
                continue;
            };
            rays.push(Ray {
                obs: *o,
                slot: core + SLOT * k,
                offset: Some(core + SLOT * k + 6),
                gm: None,
                sigma_px: tc.transfer_sigma_px,
            });
        }

        // Gate at the prediction; follow each UAV's current-ray innovation over time.
        let mut accepted = Vec::new();
        for (i, ray) in rays.iter().enumerate() {
            let Some((r, c, h)) = self.linearise(ray, &s) else {
                continue;
            };
            let sk = &h * &p * h.transpose() + DMatrix::from_column_slice(2, 2, c.as_slice());
            let Some(chol) = sk.clone().cholesky() else {
                continue;
            };
            let rv = DVector::from_column_slice(r.as_slice());
            let whitened = chol
                .l()
                .solve_lower_triangular(&rv)
                .unwrap_or_else(|| rv.clone());
            let d2 = whitened.norm_squared();
            if i < 2 {
                let w2 = nalgebra::Vector2::new(whitened[0], whitened[1]);
                let uav = ray.obs.uav.index();
                self.drift[uav] += DRIFT_ALPHA * (w2 - self.drift[uav]);
            }
            if d2 <= GATE {
                accepted.push(i);
            }
        }
        self.since_reopen += 1;
        let drift_var = DRIFT_ALPHA / (2.0 - DRIFT_ALPHA);
        let drifting = self
            .drift
            .iter()
            .any(|m| m.norm_squared() / drift_var > DRIFT_GATE);
        let mut reopened = false;
        if drifting && self.since_reopen >= REOPEN_HOLD {
            // A bias step: forget what we believed about the biases and the position.
            let sb = tc.reopen_bias_sigma_deg.to_radians().powi(2);
            let sp = tc.initial_position_sigma_m.powi(2);
            p[(5, 5)] += sb;
            p[(6, 6)] += sb;
            for i in 0..3 {
                p[(i, i)] += sp;
            }
            // Keyframes taken before the step carry the old bias: let their yaw errors
            // take up the difference instead of pulling the new bias back.
            for k in 0..self.slots.len() {
                p[(core + SLOT * k + 3, core + SLOT * k + 3)] += sb;
            }
            self.drift = [nalgebra::Vector2::zeros(); 2];
            self.since_reopen = 0;
            reopened = true;
            // Against the widened prediction every ray of this geolocation is plausible.
            accepted = (0..rays.len()).collect();
        }

        // Iterated EKF update over every accepted ray at once.
        let n = s.len();
        let s_prior = s.clone();
        let mut s_iter = s.clone();
        let mut gain_h = None;
        for _ in 0..3 {
            let m = accepted.len() * 2;
            if m == 0 {
                break;
            }
            let mut h = DMatrix::<f64>::zeros(m, n);
            let mut r = DVector::<f64>::zeros(m);
            let mut rc = DMatrix::<f64>::zeros(m, m);
            let mut ok = true;
            for (row, &i) in accepted.iter().enumerate() {
                let Some((rk, ck, hk)) = self.linearise(&rays[i], &s_iter) else {
                    ok = false;
                    break;
                };
                // IEKF: linearise at s_iter; innovation relative to the prior.
                let lin = DVector::from_column_slice(rk.as_slice()) + &hk * (&s_prior - &s_iter);
                r.rows_mut(2 * row, 2).copy_from(&lin);
                h.view_mut((2 * row, 0), (2, n)).copy_from(&hk);
                rc.view_mut((2 * row, 2 * row), (2, 2)).copy_from(&ck);
            }
            if !ok {
                break;
            }
            let sm = &h * &p * h.transpose() + rc;
            let Some(sinv) = sm.try_inverse() else { break };
            let k = &p * h.transpose() * sinv;
            s_iter = &s_prior - &k * r;
            gain_h = Some((k, h));
        }
        if let Some((k, h)) = gain_h {
            let i_kh = DMatrix::<f64>::identity(n, n) - &k * h;
            let pn = &i_kh * &p;
            p = (&pn + pn.transpose()) * 0.5;
            s = s_iter;
        }
        // Marginalise the current pair's pose errors.
        let s = s.rows(0, kept).into_owned();
        let p = p.view((0, 0), (kept, kept)).into_owned();
        if !s.iter().all(|v| v.is_finite()) || !p.iter().all(|v| v.is_finite()) {
            self.reset();
            return Err(EstimatorError::NonFiniteResult {
                what: "temporal state",
            });
        }
        let bias_known =
            (5..7).all(|i| p[(i, i)].max(0.0).sqrt() <= tc.converged_bias_sigma_deg.to_radians());
        let current_taken = accepted.iter().any(|&i| i < 2);
        let quality = match (bias_known, current_taken) {
            (false, _) => Quality::Converging,
            (true, true) => Quality::Tracking,
            (true, false) => Quality::Coasting,
        };
        let idx = [0, 1, 5, 6];
        let covariance = Matrix4::from_fn(|r, c| p[(idx[r], idx[c])]);
        let out = TemporalEstimate {
            estimate: Estimate {
                position: Point3::new(s[0], s[1], s[2]),
                yaw_bias: [s[5], s[6]],
                covariance,
                altitude_std_error_m: p[(2, 2)].max(0.0).sqrt(),
                iterations: 1,
                converged: true,
                images_used: accepted.len(),
            },
            velocity: [s[3], s[4]],
            velocity_std_mps: [p[(3, 3)].max(0.0).sqrt(), p[(4, 4)].max(0.0).sqrt()],
            rays_used: accepted.len(),
            rays_rejected: rays.len() - accepted.len(),
            reopened,
            quality,
        };
        self.state = Some((t_s, s, p));
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::SyntheticScenario;
    use rand::SeedableRng;
    use shared_types::nav_noise::{BiasModel, NavNoise};

    /// Runs the filter over a synthetic flight; returns (t, estimate, truth target, true biases).
    fn fly(
        scenario: &SyntheticScenario,
        seconds: f64,
        seed: u64,
    ) -> Vec<(f64, TemporalEstimate, Point3<f64>, [f64; 2])> {
        fly_with(scenario, EstimatorConfig::default(), 4, seconds, seed)
    }

    /// `fly` with a configuration and `n` images per UAV (1: the current pair only).
    fn fly_with(
        scenario: &SyntheticScenario,
        config: EstimatorConfig,
        n: usize,
        seconds: f64,
        seed: u64,
    ) -> Vec<(f64, TemporalEstimate, Point3<f64>, [f64; 2])> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let mut filter = TemporalEstimator::new(config).unwrap();
        let mut out = Vec::new();
        let dt = 1.0 / 10.0;
        let mut next_id = 0u64;
        let mut t = 5.0;
        while t < seconds {
            let Ok(trial) = scenario.trial(t, n.max(2), &mut rng) else {
                t += dt;
                continue;
            };
            let o = &trial.observations;
            // The generator draws new noise for every past image of every trial, so each
            // is a distinct image: give it a distinct id.
            let past: Vec<(ImageId, Observation)> = o[2..]
                .iter()
                .filter(|_| n > 1)
                .map(|ob| {
                    next_id += 1;
                    ((ob.uav, next_id), *ob)
                })
                .collect();
            let window = crate::geolocate(o, &EstimatorConfig::default()).ok();
            if let Ok(e) = filter.update(t, [&o[0], &o[1]], &past, window.as_ref()) {
                out.push((t, e, trial.target, trial.yaw_bias));
            }
            t += dt;
        }
        out
    }

    /// Issue #23: with the current pair's pose noise in its covariance the altitude sat
    /// ~1.4 m low under horizontal GPS noise alone (the covariance, held at the
    /// iterate, shrank with depth); with their pose errors as states it does not.
    /// The smallest case: current pair only, biases known, 12 seeds of 20 s.
    #[test]
    fn horizontal_gps_noise_leaves_no_altitude_offset() {
        let scenario = SyntheticScenario {
            noise: NavNoise {
                sigma_position_m: [3.0, 3.0, 0.0],
                ..NavNoise::NONE
            },
            bias: BiasModel::Eq34 {
                delta0_deg: 0.0,
                rate_deg_s: 0.0,
            },
            ..Default::default()
        };
        let mut config = EstimatorConfig::default();
        let mut noise = crate::NoiseModel::isotropic(3.0, 0.001, 0.1);
        noise.sigma_position_m[2] = 0.001;
        config.noise_left = noise;
        config.noise_right = noise;
        config.temporal.initial_bias_sigma_deg = 0.001;
        config.temporal.bias_drift_deg_per_sqrt_s = 0.0001;
        let (mut sum, mut inside, mut n) = (0.0, 0usize, 0usize);
        for seed in 0..12 {
            for (t, e, truth, _) in fly_with(&scenario, config, 1, 25.0, 100 + seed) {
                if t >= 15.0 {
                    let dz = e.estimate.position.z - truth.z;
                    sum += dz;
                    inside += usize::from(dz.abs() <= e.estimate.altitude_std_error_m);
                    n += 1;
                }
            }
        }
        assert!(n > 1000, "{n}");
        let mean = sum / n as f64;
        let share = inside as f64 / n as f64;
        // Before: −1.36 m and 14 % inside v_acc. The mean's standard error over 12
        // seeds is ~0.15 m.
        assert!(mean.abs() < 0.45, "mean vertical error {mean:.2} m");
        assert!(share > 0.55, "inside v_acc {share:.2}");
    }

    /// Issue #23 item 7: a GPS error that stays (here a constant 2–3 m per UAV, as a
    /// consumer GPS over 20 s) cannot be averaged away. Told that its position error
    /// is correlated (τ 120 s), the filter keeps h_acc honest and its errors inside
    /// 3 h_acc; told it is white, it claims decimetres and is metres off.
    #[test]
    fn a_gps_error_that_stays_is_not_averaged_away() {
        let scenario = SyntheticScenario {
            noise: NavNoise::NONE,
            sigma_pixel_px: 0.5,
            ..Default::default()
        };
        let offsets = [
            nalgebra::Vector3::new(2.5, -2.0, 1.0),
            nalgebra::Vector3::new(-1.5, -3.0, -2.0),
        ];
        let run = |config: EstimatorConfig| {
            let mut rng = rand::rngs::StdRng::seed_from_u64(21);
            let mut filter = TemporalEstimator::new(config).unwrap();
            let mut out = Vec::new();
            let mut t = 5.0;
            while t < 25.0 {
                let mut trial = scenario.trial(t, 4, &mut rng).unwrap();
                for o in &mut trial.observations {
                    o.position += offsets[o.uav.index()];
                }
                let o = &trial.observations;
                // Keyframes every 1.25 s: the same image keeps its id across updates.
                let k = (t / 1.25).floor() as u64;
                let past: Vec<(ImageId, Observation)> = o[2..]
                    .iter()
                    .enumerate()
                    .map(|(i, ob)| ((ob.uav, 1000 * k + i as u64), *ob))
                    .collect();
                let window = crate::geolocate(o, &config).ok();
                if let Ok(e) = filter.update(t, [&o[0], &o[1]], &past, window.as_ref()) {
                    if t >= 15.0 {
                        let d = e.estimate.position - trial.target;
                        let h_acc =
                            (e.estimate.covariance[(0, 0)] + e.estimate.covariance[(1, 1)]).sqrt();
                        out.push((d.x.hypot(d.y), h_acc));
                    }
                }
                t += 0.1;
            }
            out
        };
        let mut correlated = EstimatorConfig::default();
        for noise in [&mut correlated.noise_left, &mut correlated.noise_right] {
            *noise = crate::NoiseModel::isotropic(3.0, 0.05, 0.5);
            noise.position_tau_s = 120.0;
            noise.position_jitter_m = 0.05;
        }
        let mut white = correlated;
        for noise in [&mut white.noise_left, &mut white.noise_right] {
            noise.position_tau_s = 0.0;
        }
        let honest = run(correlated);
        let naive = run(white);
        assert!(honest.len() > 50 && naive.len() > 50);
        let mean = |v: &[(f64, f64)], f: fn(&(f64, f64)) -> f64| {
            v.iter().map(f).sum::<f64>() / v.len() as f64
        };
        // The white model: overconfident (its h_acc far below its error).
        assert!(
            mean(&naive, |x| x.1) < 0.5 * mean(&naive, |x| x.0),
            "white h_acc {:.2} vs error {:.2}",
            mean(&naive, |x| x.1),
            mean(&naive, |x| x.0)
        );
        // The correlated model: h_acc at the GPS error's scale, errors within 3 h_acc.
        assert!(
            mean(&honest, |x| x.1) > 1.5,
            "{:.2}",
            mean(&honest, |x| x.1)
        );
        assert!(
            honest.iter().all(|(err, acc)| *err <= 3.0 * acc),
            "{:?}",
            honest.iter().map(|x| x.0 / x.1).fold(0.0, f64::max)
        );
    }

    /// Issue #23: a first set that pairs the target with a look-alike gives a window
    /// estimate far off; the filter does not start there, and starts once three
    /// window estimates agree.
    #[test]
    fn the_filter_starts_only_from_agreeing_window_estimates() {
        let scenario = SyntheticScenario::default();
        let mut rng = rand::rngs::StdRng::seed_from_u64(4);
        let mut f = TemporalEstimator::new(EstimatorConfig::default()).unwrap();
        let trial = |t: f64, rng: &mut rand::rngs::StdRng| scenario.trial(t, 4, rng).unwrap();
        let mut tr = trial(5.0, &mut rng);
        let o = tr.observations.clone();
        let mut window = crate::geolocate(&o, &EstimatorConfig::default()).unwrap();
        // Implausible: a target above the cameras.
        window.position.z = o[0].position.z + 10.0;
        let e = f.update(5.0, [&o[0], &o[1]], &[], Some(&window));
        assert!(matches!(e, Err(EstimatorError::NotStarted { .. })), "{e:?}");
        // A wrong (mismatched) window 200 m off, then good ones: no start until three
        // good ones agree, and the start is near the target.
        window.position = tr.target + nalgebra::Vector3::new(200.0, 0.0, -300.0);
        assert!(f.update(5.1, [&o[0], &o[1]], &[], Some(&window)).is_err());
        let mut started = None;
        for k in 0..4 {
            let t = 5.2 + 0.1 * k as f64;
            tr = trial(t, &mut rng);
            let o = &tr.observations;
            let w = crate::geolocate(o, &EstimatorConfig::default()).unwrap();
            if let Ok(e) = f.update(t, [&o[0], &o[1]], &[], Some(&w)) {
                started = Some((k, e));
                break;
            }
        }
        let (k, e) = started.expect("started");
        assert_eq!(k, 2, "the third agreeing window starts it");
        assert!((e.estimate.position - tr.target).norm() < 30.0);
    }

    /// Issue #23 item 8: on exact synthetic rays with the noise the filter is told (the
    /// paper's Table 2: σ_att 2°, σ_pos 3 m, eq. (34) biases with δψ0 = 20°), its
    /// stated covariance is honest from the first estimate: the mean normalised error
    /// squared over x, y (their 2×2 covariance) and z (v_acc) lies in the 95 % region
    /// of χ² with 3 degrees of freedom per run (errors within a run are correlated, so
    /// a run counts once), and no more than 1 % of estimates are beyond 3σ.
    #[test]
    fn nees_is_within_its_chi2_region_on_exact_rays_with_the_stated_noise() {
        let scenario = SyntheticScenario::default();
        let runs = 12;
        let (mut sum, mut n, mut gross) = (0.0, 0usize, 0usize);
        for seed in 0..runs {
            for (_, e, truth, _) in fly(&scenario, 25.0, 300 + seed) {
                let d = e.estimate.position - truth;
                let c = e.estimate.covariance.fixed_view::<2, 2>(0, 0).into_owned();
                let Some(ci) = c.try_inverse() else {
                    panic!("singular horizontal covariance {c}")
                };
                let h = nalgebra::Vector2::new(d.x, d.y);
                let v = e.estimate.altitude_std_error_m;
                let nees_h = (h.transpose() * ci * h)[(0, 0)];
                sum += nees_h + (d.z / v).powi(2);
                let h_acc = (c[(0, 0)] + c[(1, 1)]).sqrt();
                gross += usize::from(h.norm() > 3.0 * h_acc || d.z.abs() > 3.0 * v);
                n += 1;
            }
        }
        assert!(n > 1000, "{n}");
        let mean = sum / n as f64;
        // χ²(36) at 2.5 % and 97.5 %: 21.34 and 54.44, over 12 runs.
        let region = (21.34 / runs as f64, 54.44 / runs as f64);
        eprintln!(
            "mean NEES {mean:.2} (region {:.2}–{:.2}), gross {gross} of {n}",
            region.0, region.1
        );
        assert!(
            (region.0..=region.1).contains(&mean),
            "mean NEES {mean:.2} outside {region:?}"
        );
        assert!(gross * 100 <= n, "{gross} of {n} beyond 3σ");
    }

    #[test]
    fn biases_converge_over_time_on_noisy_data() {
        let scenario = SyntheticScenario::default();
        let run = fly(&scenario, 40.0, 11);
        let late: Vec<_> = run.iter().filter(|(t, ..)| *t > 25.0).collect();
        assert!(late.len() > 50);
        let bias_mae = late
            .iter()
            .map(|(_, e, _, b)| {
                ((e.estimate.yaw_bias[0] - b[0]).abs() + (e.estimate.yaw_bias[1] - b[1]).abs())
                    / 2.0
            })
            .sum::<f64>()
            / late.len() as f64;
        let early: Vec<_> = run.iter().filter(|(t, ..)| *t < 7.0).collect();
        let early_mae = early
            .iter()
            .map(|(_, e, _, b)| {
                ((e.estimate.yaw_bias[0] - b[0]).abs() + (e.estimate.yaw_bias[1] - b[1]).abs())
                    / 2.0
            })
            .sum::<f64>()
            / early.len().max(1) as f64;
        // The paper's per-window estimate on the same kind of data, for comparison.
        let mut rng = rand::rngs::StdRng::seed_from_u64(12);
        let mut window_errors = Vec::new();
        for i in 0..200 {
            let trial = scenario
                .trial(25.0 + i as f64 * 0.075, 4, &mut rng)
                .unwrap();
            if let Ok(e) = crate::geolocate(&trial.observations, &EstimatorConfig::default()) {
                window_errors.push(
                    ((e.yaw_bias[0] - trial.yaw_bias[0]).abs()
                        + (e.yaw_bias[1] - trial.yaw_bias[1]).abs())
                        / 2.0,
                );
            }
        }
        let window_mae = window_errors.iter().sum::<f64>() / window_errors.len() as f64;
        eprintln!(
            "bias MAE: temporal early {:.2}°, late {:.2}°; per-window {:.2}°",
            early_mae.to_degrees(),
            bias_mae.to_degrees(),
            window_mae.to_degrees()
        );
        assert!(
            bias_mae.to_degrees() < 3.0,
            "late bias MAE {:.2}°",
            bias_mae.to_degrees()
        );
        assert!(bias_mae < 0.5 * window_mae, "no better than one window");
    }

    /// Issue #23: an unseen scene started the filter 60–80° off and it claimed ±1.3 m
    /// while 10–50 m wrong. With biases far from zero, the start must say it does not
    /// know (large h_acc, `converging`) and never be confidently wrong on the way.
    #[test]
    fn a_large_wrong_bias_converges_without_a_confident_wrong_estimate() {
        for (seed, (left_deg, right_deg)) in [(21, (40.0, -35.0)), (22, (-30.0, 38.0))] {
            let scenario = SyntheticScenario {
                bias: BiasModel::Constant {
                    left_deg,
                    right_deg,
                },
                ..SyntheticScenario::default()
            };
            let run = fly(&scenario, 35.0, seed);
            assert!(run.len() > 200);
            let h_acc = |e: &TemporalEstimate| {
                (e.estimate.covariance[(0, 0)] + e.estimate.covariance[(1, 1)]).sqrt()
            };
            let mut gross = 0;
            for (t, e, truth, _) in &run {
                let d = e.estimate.position - truth;
                let h = d.x.hypot(d.y);
                if h > 3.0 * h_acc(e) {
                    gross += 1;
                    eprintln!("t {t:.1}: {h:.1} m off, h_acc {:.2} m", h_acc(e));
                }
            }
            assert!(
                gross * 100 <= run.len(),
                "{gross} of {} estimates beyond 3 h_acc",
                run.len()
            );
            assert_eq!(run[0].1.quality, Quality::Converging);
            let late: Vec<_> = run.iter().filter(|(t, ..)| *t > 25.0).collect();
            let bias_err = late
                .iter()
                .map(|(_, e, _, b)| {
                    (0..2)
                        .map(|i| (e.estimate.yaw_bias[i] - b[i]).abs())
                        .sum::<f64>()
                        / 2.0
                })
                .sum::<f64>()
                / late.len() as f64;
            assert!(
                bias_err.to_degrees() < 3.0,
                "late bias error {:.2}°",
                bias_err.to_degrees()
            );
            assert!(late
                .iter()
                .all(|(_, e, ..)| e.quality != Quality::Converging));
        }
    }

    #[test]
    fn time_going_backwards_resets_and_nan_is_rejected() {
        let scenario = SyntheticScenario {
            bias: BiasModel::Constant {
                left_deg: 5.0,
                right_deg: -5.0,
            },
            ..SyntheticScenario::default()
        };
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        let trial = scenario.trial(10.0, 4, &mut rng).unwrap();
        let o = &trial.observations;
        let window = crate::geolocate(o, &EstimatorConfig::default()).unwrap();
        let mut f = TemporalEstimator::new(EstimatorConfig::default()).unwrap();
        assert!(
            f.update(10.0, [&o[0], &o[1]], &[], None).is_err(),
            "cannot start without a window estimate"
        );
        // It starts once three window estimates agree.
        for t in [10.0, 10.1] {
            let e = f.update(t, [&o[0], &o[1]], &[], Some(&window));
            assert!(matches!(e, Err(EstimatorError::NotStarted { .. })), "{e:?}");
        }
        f.update(10.2, [&o[0], &o[1]], &[], Some(&window)).unwrap();
        assert!(f.update(f64::NAN, [&o[0], &o[1]], &[], None).is_err());
        // Earlier time: a new stream; without a window estimate it cannot restart.
        assert!(f.update(5.0, [&o[0], &o[1]], &[], None).is_err());
    }
}
