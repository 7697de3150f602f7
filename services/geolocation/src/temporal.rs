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
//! - With correlated (Gauss–Markov) navigation errors each UAV's correlated pose error
//!   is a block of six states; a keyframe's slot starts from it, run back to the
//!   image's capture time. Correlated camera tilts are Schmidt consider states, carried
//!   but never estimated (`considered_tilts`: estimated, they made the filter
//!   overconfident).
//!
//! - Each past image also brings its rotation from the current cameras as the images
//!   measure it (matching's ground-plane homography; `PastImage::rotation_from`): a
//!   residual on the two images' attitudes (`rotation_residual`), which ties the
//!   current image's attitude error to the keyframe's and, across the UAVs, measures
//!   the biases' difference. Beyond the paper: docs/temporal.md "Relative rotations
//!   from the images".
//!
//! Rays are gated by their Mahalanobis distance (χ², two degrees of freedom, 99.9 %).
//! Each UAV's whitened current-ray innovation is followed by a running mean. After a
//! bias step (an AHRS re-initialisation) one UAV's mean leaves its χ² region while the
//! other's stays inside: that bias and the position are re-opened and the filter
//! re-converges. When both leave together neither camera is looking at the predicted
//! target (a look-alike while it hides: the two AHRS do not step together): their
//! rays are refused and the filter coasts; still so after `LOST_AFTER_S`, the target
//! is elsewhere and its position and velocity are re-acquired, the biases kept.
//!
//! With `bias_hypotheses` = 7 (the default) the start is a Gaussian sum over the two
//! yaw biases (`hypotheses.rs`): 49 such filters (3 gives 9, split up to
//! `max_start_hypotheses` where cameras look ahead, `start_prior.rs`) until the data
//! decide between them, then one (docs/temporal.md).
//!
//! The filter never reads truth. Cost: ~0.2 ms per geolocation with 8 images (the
//! state has 7 + 8 per keyframe + 12 entries during an update), times the hypotheses
//! still open.

use crate::hypotheses::{bias_grid, prune_and_merge, spread_about, weights, BiasStart, Hypothesis};
use crate::joint::{reproject, Theta};
use crate::observation::ImagePoseErrors;
use crate::start_agreement::{agree, StartCandidate, START_CONSENSUS};
use crate::start_prior::{meeting_prior, split_where_curved, ImageNoise, MeetingPrior};
use crate::{Estimate, EstimatorConfig, EstimatorError, NoiseModel, Observation, PastImage};
use nalgebra::{DMatrix, DVector, Matrix4, Point3, SMatrix, SVector};
use shared_types::conventions::Uav;

/// χ²(2) at 99.9 %: a ray further than this from the prediction is rejected.
const GATE: f64 = 13.8;
/// Weight of the newest geolocation in the running mean of each UAV's whitened
/// current-ray innovation.
const DRIFT_ALPHA: f64 = 0.1;
/// χ²(2) at 99.99 %: a running mean this far from zero (in units of its own σ under a
/// consistent filter) means a persistent offset: a bias step.
const DRIFT_GATE: f64 = 18.4;
/// χ²(2) at 95 %: a running mean inside this agrees with the prediction.
const DRIFT_AGREES: f64 = 5.99;
/// Geolocations after a re-opening before another can happen.
pub(crate) const REOPEN_HOLD: usize = 20;
/// Seconds both UAVs' rays may drift from the prediction (the filter coasting) before
/// the target is taken to be elsewhere and the position re-acquired. Longer than a
/// look-alike's brief capture while the target is hidden (`suite_traffic` seed 5:
/// 0.93 s), short enough that a target that really moved (a manoeuvre, a replay
/// looping back to its start) is followed again within about a second.
const LOST_AFTER_S: f64 = 1.0;
/// σ added to each axis of a start hypothesis's position (the current pair's meeting
/// point) beyond what the pair's errors make of it, metres: the vehicle's size (the
/// two detections need not be the same spot of it).
const MEETING_FLOOR_M: f64 = 2.0;
/// The most start hypotheses a configuration may ask for: each costs a filter update
/// per geolocation (~0.25 ms with 8 images) until the data drop or merge it.
const MAX_START_HYPOTHESES: usize = 400;

pub use crate::observation::ImageId;

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
    /// The covariance was re-opened at this update (a bias step suspected, or the
    /// target re-acquired after both cameras' rays left the prediction).
    pub reopened: bool,
    pub quality: Quality,
    /// The posterior pose errors of this update's images (the leading hypothesis's).
    pub pose_errors: ImagePoseErrors,
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
    /// Each bias also drifts at a rate the filter estimates (eq. (34): δψ = 0.2 t +
    /// δψ₀; a real AHRS's heading drifts the same way between magnetometer fixes):
    /// the rate's σ at the start and at a re-opening, °/s (0.2, eq. (34)'s rate as
    /// 1σ; docs/temporal.md "The biases' drift": 0.3 gained little more on the tilted
    /// and gimballed cameras and cost the nadir scenes' x more, 0.1 half the gain).
    /// Held at zero for a UAV whose attitude error is correlated (`bias_rate`) ...
    pub initial_bias_rate_sigma_deg_per_s: f64,
    /// ... and its random walk, °/s/√s (a slow change of the drift).
    pub bias_rate_walk_deg_per_s_per_sqrt_s: f64,
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
    /// Bias hypotheses per UAV at the start (`hypotheses.rs`): the start's N(0,
    /// `initial_bias_sigma_deg`²) split into this many per axis (7, the default: 49
    /// filters 12.9° apart with σ 6.4°; 3: 9 filters at −30°, 0°, +30° with σ 15°),
    /// weighed by their innovations, merged once they agree. Any grid makes the start
    /// calibrated 250 m up, where one filter slides along a valley of near-equal fits
    /// (docs/temporal.md); 7 rather than 3 because a 15° component is still linearised
    /// across a curved fit: in the chain's first seconds (8 s runs, 8 seeds, white
    /// errors) gross errors fell 5.9 / 6.5 / 3.5 / 1.8 % → 1.8 / 2.1 / 3.0 / 0.0 % on
    /// `suite_suburban` / `suite_photo_rural` / `suite_wide_lens` / `suite_town`, and
    /// `gimbal` 4.2 → 0.0 % (5: 3.7 / 3.1 / 3.2 / 0.3 %). 1 is one filter started at
    /// the window estimate. The mixture stays `converging` longer than one filter did:
    /// detection gates with `converging` estimates as well.
    pub bias_hypotheses: usize,
    /// At most this many start hypotheses once the grid's curved components are split
    /// (`split_where_curved`); the grid's own `bias_hypotheses`² when smaller.
    pub max_start_hypotheses: usize,
    /// Power (0–1] on each update's likelihood when the start's hypotheses are weighed
    /// (`hypotheses.rs`): 1 is Bayes' rule; below it a tempered likelihood, which
    /// decides between the hypotheses on more evidence, so they stay open (and their
    /// spread in the stated accuracy) longer: the rays of successive updates share
    /// their past images' errors, so each update's own likelihood over-counts what
    /// it knows. 0.3, the default (docs/temporal.md "Tempered hypothesis weights"):
    /// against 1 it took 112 of the 118 estimates beyond 3σ off `gimbal`'s preset
    /// route (seeds 1–3), and the Monte Carlo's share inside h_acc rose on every
    /// white-error scene (pooled 60.8 → 63.6 %, gross 0.23 → 0.18 %; correlated
    /// errors 1.64 → 1.47 % gross).
    pub likelihood_temper: f64,
    /// Where each iteration of the update takes the rays' Jacobians in the target's
    /// x, y (`linearise`). `iterate`: at the iterate, the IEKF's tangent. `midpoint`:
    /// halfway between the prediction and the iterate, the slope averaged over the
    /// update's step (a secant). A ray's sensitivity to the target's altitude is
    /// proportional to its horizontal offset from the camera, and under correlated
    /// camera tilts the iterate's horizontal error moves with the very tilts that make
    /// the residuals, so the tangent there mis-scales the altitude's gain the same way
    /// every update (docs/temporal.md, "Still open" 2). On exact rays, GPS and
    /// attitude Gauss–Markov errors, 48 seeds, mean vertical error after 10 s 100 / 250 m
    /// up: +2.0 / +14.1 m → −0.6 / +3.4 m (inside v_acc 56 / 47 → 62 / 57 %). Under
    /// white errors each update's linearisation error is its own and the tangent is
    /// the better point (30° oblique cameras, 48 seeds: horizontal MAE after 10 s
    /// 1.53 → 1.62 m at the midpoint). `auto`, the default: `midpoint` when either
    /// UAV's error model is correlated (the filter carries a Gauss–Markov block),
    /// `iterate` otherwise.
    pub jacobian_at: JacobianAt,
    /// σ of the images' own measure of a past camera's rotation from a current camera
    /// of the same UAV (matching's ground-plane homography, decomposed; `PastImage::
    /// rotation_from`), degrees: [about either horizontal axis, about the vertical].
    /// The AHRS reads each image's attitude with its own 2° error; the images measure
    /// the rotation between two of them far better, which ties the current camera's
    /// attitude error to its keyframes' (`rotation_residual`). Measured against the
    /// true poses on rendered flights without navigation errors (robust σ, JPEG 95):
    /// nadir 0.15 / 0.06°, 45° gimbal 0.12 / 0.06°, of which a third to a half is
    /// the keyframe's own and comes back at every reuse (its homographies resemble
    /// each other). A keyframe is reused ~30 times, so σ is that of ~30 measurements
    /// sharing that part: √(σ_white² + 30 σ_kept²) (docs/temporal.md "Relative
    /// rotations": at the white σ's the filter claimed ~2× what it knew, NEES 3.5–5.4
    /// and 4 % beyond 3σ on `tilted`). 0 in either turns the measurement off.
    pub rotation_sigma_deg: [f64; 2],
    /// ... and from the other UAV's current camera, 40–120 m away: the plane's
    /// perspective gives its tilt less well (nadir 0.7–1.4° with 0.5–0.8° kept per
    /// keyframe, yaw 0.23°; 45° gimbal 0.24 / 0.29°). This one measures the
    /// difference of the two yaw biases. Under a correlated attitude error the filter
    /// takes 3× these (`CORRELATED_CROSS_ROTATION_INFLATION`: a frame's rotations from
    /// the other UAV go wrong together).
    pub cross_rotation_sigma_deg: [f64; 2],
}

/// Where the update's Jacobians are taken in the target's horizontal position
/// ([`TemporalConfig::jacobian_at`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JacobianAt {
    /// `Midpoint` under a correlated error model, `Iterate` under white errors.
    #[default]
    Auto,
    /// At the iterate (the iterated EKF's tangent).
    Iterate,
    /// Halfway between the prediction and the iterate.
    Midpoint,
}

impl Default for TemporalConfig {
    fn default() -> Self {
        Self {
            acceleration_sigma_mps2: 1.5,
            altitude_walk_m_per_sqrt_s: 0.3,
            bias_drift_deg_per_sqrt_s: 0.2,
            initial_bias_rate_sigma_deg_per_s: 0.2,
            bias_rate_walk_deg_per_s_per_sqrt_s: 0.01,
            initial_position_sigma_m: 15.0,
            initial_velocity_sigma_mps: 8.0,
            initial_bias_sigma_deg: 45.0,
            converged_bias_sigma_deg: 3.0,
            reopen_bias_sigma_deg: 15.0,
            transfer_sigma_px: 4.0,
            transfer_offset_sigma_px: 6.0,
            bias_hypotheses: 7,
            max_start_hypotheses: 49,
            likelihood_temper: 0.3,
            jacobian_at: JacobianAt::Auto,
            rotation_sigma_deg: [0.5, 0.3],
            cross_rotation_sigma_deg: [4.0, 0.8],
        }
    }
}

impl TemporalConfig {
    pub fn validate(&self) -> Result<(), EstimatorError> {
        let all = [
            self.acceleration_sigma_mps2,
            self.altitude_walk_m_per_sqrt_s,
            self.bias_drift_deg_per_sqrt_s,
            self.initial_bias_rate_sigma_deg_per_s,
            self.bias_rate_walk_deg_per_s_per_sqrt_s,
            self.initial_position_sigma_m,
            self.initial_velocity_sigma_mps,
            self.initial_bias_sigma_deg,
            self.converged_bias_sigma_deg,
            self.reopen_bias_sigma_deg,
            self.transfer_sigma_px,
            self.transfer_offset_sigma_px,
        ];
        if !(1..=7).contains(&self.bias_hypotheses) {
            Err(EstimatorError::Config(format!(
                "[estimator.temporal] bias_hypotheses must be 1–7 per UAV, got {}",
                self.bias_hypotheses
            )))
        } else if !(1..=MAX_START_HYPOTHESES).contains(&self.max_start_hypotheses) {
            Err(EstimatorError::Config(format!(
                "[estimator.temporal] max_start_hypotheses must be 1–{MAX_START_HYPOTHESES}, got {}",
                self.max_start_hypotheses
            )))
        } else if !(self.likelihood_temper > 0.0 && self.likelihood_temper <= 1.0) {
            Err(EstimatorError::Config(format!(
                "[estimator.temporal] likelihood_temper must be in (0, 1], got {}",
                self.likelihood_temper
            )))
        } else if !self
            .rotation_sigma_deg
            .iter()
            .chain(&self.cross_rotation_sigma_deg)
            .all(|v| v.is_finite() && *v >= 0.0)
        {
            Err(EstimatorError::Config(format!(
                "[estimator.temporal] rotation σ's must be finite and ≥ 0 (0: off), got {:?} and {:?}",
                self.rotation_sigma_deg, self.cross_rotation_sigma_deg
            )))
        } else if all.iter().all(|v| v.is_finite() && *v > 0.0) {
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
    /// The hypotheses (`hypotheses.rs`), leader first: none before the start, several
    /// while the start's bias hypotheses are open, then one.
    pub(crate) bank: Vec<Hypothesis>,
    /// Before the start: the last sets' candidates (`start_agreement.rs`).
    pub(crate) start_candidates: Vec<StartCandidate>,
    /// The last update's images' pose errors ([`TemporalEstimator::pose_errors_at`]);
    /// not checkpointed (the next update makes them anew).
    pose_errors: Option<ImagePoseErrors>,
}

/// The filter's prediction of the target and its biases at one time
/// ([`TemporalEstimator::predict_target`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetPrior {
    /// (x, y), world ENU, m.
    pub position: [f64; 2],
    /// Its covariance, m².
    pub covariance_xy: nalgebra::Matrix2<f64>,
    /// (δψ_L, δψ_R), radians.
    pub yaw_bias: [f64; 2],
    /// Their covariance, rad².
    pub yaw_bias_covariance: nalgebra::Matrix2<f64>,
}

/// Core states: x, y, z, v_x, v_y, δψ_L, δψ_R ...
pub(crate) const CORE: usize = 9;
/// Index of the left UAV's bias rate (the right's follows): eq. (34)'s drift.
const RATE: usize = 7;

/// (σ at the start and at a re-opening, rad/s; random walk, rad/s/√s) of UAV `uav`'s
/// bias rate. Both zero, the rate held at zero, when that UAV's attitude error is
/// correlated (`attitude_tau_s` > 0): its yaw's Gauss–Markov state already carries a
/// slow wander, and a rate beside it took that wander for a drift and carried it on.
/// Measured in the Monte Carlo under correlated errors (8 seeds): `gimbal` gross
/// errors 4.1 → 16.9 %, NEES 6.7 → 14.8, `suite_high_hd` bias MAE 3.7 → 7.0° with the
/// rate free (docs/temporal.md "The biases' drift").
fn bias_rate(config: &EstimatorConfig, uav: Uav) -> (f64, f64) {
    if config.noise(uav).attitude_tau_s > 0.0 {
        return (0.0, 0.0);
    }
    let tc = config.temporal;
    (
        tc.initial_bias_rate_sigma_deg_per_s.to_radians(),
        tc.bias_rate_walk_deg_per_s_per_sqrt_s.to_radians(),
    )
}

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
    let (position, att) = o.pose_without_error([th[3], th[4]], e);
    let pos = [position.x, position.y, position.z];
    let p = Point3::new(th[0], th[1], th[2]);
    let [du, dv] = offset.unwrap_or([0.0; 2]);
    Some(reproject(o, pos, att, &p)? - o.pixel + nalgebra::Vector2::new(du, dv))
}

/// The images' measure of a past camera's rotation from a current one
/// ([`PastImage::rotation_from`]), between two of the update's rays.
struct RotationPair {
    /// Indices into the update's rays: the current image's and the past image's.
    current: usize,
    past: usize,
    /// `X_past = R X_current`, camera axes.
    measured: nalgebra::Rotation3<f64>,
    /// σ about world x, y, z, radians.
    sigma: nalgebra::Vector3<f64>,
}

/// χ²(3) at 99.9 %: a rotation further than this from the prediction is not taken
/// (a homography fitted on a facade, a decomposition that picked the wrong plane).
const ROTATION_GATE: f64 = 16.27;

/// The rotation left between what the images measure and what the two images'
/// attitudes (their pose errors `e_current`, `e_past` and the biases removed) predict,
/// in world axes: `log(C_past · R · C_currentᵀ)`, zero when they agree (`C` camera →
/// world, `R` the images' `X_past = R X_current`).
fn rotation_residual(
    current: &Observation,
    past: &Observation,
    biases: [f64; 2],
    e_current: &[f64],
    e_past: &[f64],
    measured: &nalgebra::Rotation3<f64>,
) -> nalgebra::Vector3<f64> {
    use shared_types::conventions::camera_to_world;
    let (_, a_current) = current.pose_without_error(biases, e_current);
    let (_, a_past) = past.pose_without_error(biases, e_past);
    let c = camera_to_world(a_current);
    let k = camera_to_world(a_past);
    nalgebra::Rotation3::from_matrix_unchecked(k * measured.matrix() * c.transpose()).scaled_axis()
}

/// [`rotation_residual`] of `m` at state `s`, and its Jacobian (3 × the state): the
/// biases and the two images' attitude errors (the current one's correlated block
/// too), by forward differences.
fn linearise_rotation(
    m: &RotationPair,
    rays: &[Ray],
    s: &DVector<f64>,
) -> (nalgebra::Vector3<f64>, DMatrix<f64>) {
    let (current, past) = (&rays[m.current], &rays[m.past]);
    // The residual with state `bumped` raised by `STEP` (none: at `s` itself), read in
    // place: no copy of the state per column.
    const STEP: f64 = 1e-7;
    let residual = |bumped: Option<usize>| {
        let at = |i: usize| if Some(i) == bumped { s[i] + STEP } else { s[i] };
        let errors = |ray: &Ray| -> [f64; 6] {
            std::array::from_fn(|k| at(ray.slot + k) + ray.gm.map_or(0.0, |g| at(g + k)))
        };
        rotation_residual(
            &current.obs,
            &past.obs,
            [at(5), at(6)],
            &errors(current),
            &errors(past),
            &m.measured,
        )
    };
    let r0 = residual(None);
    // The biases and each image's yaw, pitch and roll errors (the current one's
    // correlated block too): distinct states, each differenced once.
    let attitude = |ray: &Ray| {
        let (slot, gm) = (ray.slot, ray.gm);
        (3..6).flat_map(move |k| std::iter::once(slot + k).chain(gm.map(|g| g + k)))
    };
    let mut h = DMatrix::<f64>::zeros(3, s.len());
    for c in [5, 6]
        .into_iter()
        .chain(attitude(current))
        .chain(attitude(past))
    {
        let d = (residual(Some(c)) - r0) / STEP;
        h.column_mut(c).copy_from(&d);
    }
    (r0, h)
}

/// Under a correlated attitude error, the σ's of a rotation measured from the other
/// UAV's current camera are this many times the configured ones.
///
/// Why: that rotation's error has a heavy tail shared by a frame's past images. On
/// flights without navigation errors (`tilted` with noise and biases at zero, 20 s), the
/// yaw of the rotations from the other UAV is within 0.40° (robust σ) but 3.1 % are
/// beyond 2.4° (up to 12°), and in 23 of 792 frames half or more of them are, together:
/// a current image whose homographies with the other UAV's past images all went wrong
/// (`gimbal` 6 of 698 frames, `suite_town` 0 of 821; the same UAV's rotations in none
/// on the three flights). Under a white attitude error each current image's own 2°
/// state takes up such a frame; under a correlated one its 0.2° jitter cannot, and the
/// yaw biases' difference and, for cameras looking ahead, the range took it. Monte Carlo under
/// correlated errors (8 seeds each, docs/temporal.md "The other UAV's rotations under
/// correlated errors"): `tilted` 14.0 → 1.0 % gross, NEES 7.4 → 2.8, mean altitude
/// error −4.1 → −0.8 m; `suite_traffic` 4.5 → 0.0 %, worst run 18.0 → 6.8 m;
/// `gimbal` 2.5 → 0.2 %; `default` x / y MAE 1.73 / 1.28 → 1.46 / 1.17 m. Holding them
/// off instead cost `suite_traffic` (7.3 % gross); all rotations 3× cost it 3.6 %; a
/// correlation between a frame's rotations (0.7) made `tilted` worse (20.7 %); 2× left
/// `tilted` 4.2 % and `suite_traffic` 4.4 %; a frame-level gate (a current image's
/// rotations from the other UAV dropped when half are far from the prediction) at 1×
/// left `tilted` 17.8 %: those frames do not look wrong at the prediction.
const CORRELATED_CROSS_ROTATION_INFLATION: f64 = 3.0;

/// σ's (about a horizontal axis, about the vertical; degrees) of the rotation measured
/// from the `current` UAV's camera to a past image of the `past` UAV: the configured
/// ones ([`TemporalConfig::rotation_sigma_deg`], `cross_rotation_sigma_deg`), the
/// other UAV's inflated under a correlated attitude error of either UAV
/// ([`CORRELATED_CROSS_ROTATION_INFLATION`]).
fn rotation_sigma_deg(config: &EstimatorConfig, current: Uav, past: Uav) -> [f64; 2] {
    let tc = config.temporal;
    if current == past {
        return tc.rotation_sigma_deg;
    }
    let correlated = [current, past]
        .iter()
        .any(|&u| config.noise(u).attitude_tau_s > 0.0);
    if correlated {
        tc.cross_rotation_sigma_deg
            .map(|s| s * CORRELATED_CROSS_ROTATION_INFLATION)
    } else {
        tc.cross_rotation_sigma_deg
    }
}

/// The measurement noise of `m` (world x, y, z).
fn rotation_noise(m: &RotationPair) -> DMatrix<f64> {
    DMatrix::from_diagonal(&DVector::from_iterator(3, m.sigma.iter().map(|v| v * v)))
}

/// How much wider than for independent innovations the running mean of one UAV's
/// whitened current-ray innovation spreads, when part of that innovation is its
/// correlated pose error (the Gauss–Markov block): the same error from one
/// geolocation to the next, which the mean cannot average away.
///
/// The EWMA `m ← m + α (w − m)` of independent unit innovations has variance
/// α/(2 − α) per axis; of an AR(1) sequence with lag-one correlation `c` it has
/// α/(2 − α) · (1 + βc)/(1 − βc), β = 1 − α. The innovation is a sum: a share `f_k`
/// of its whitened variance is component k of the Gauss–Markov block (correlated
/// from the last geolocation to this one by ρ_k = e^(−Δt/τ_k)), the rest is white.
/// The factor is (1 − Σ f_k) + Σ f_k (1 + βρ_k)/(1 − βρ_k), at least 1. `shares`
/// holds (f_k, ρ_k).
///
/// Without it (the white variance), the drift monitor left its χ² region with
/// nothing wrong under correlated errors: 75 of 116 correlated Monte Carlo runs
/// coasted in ~1 s stretches with both cameras on the target (docs/temporal.md, "The
/// drift monitor under correlated errors").
fn persistence_factor(shares: &[(f64, f64)]) -> f64 {
    let beta = 1.0 - DRIFT_ALPHA;
    let total: f64 = shares.iter().map(|(f, _)| f.max(0.0)).sum();
    let scale = if total > 1.0 { 1.0 / total } else { 1.0 };
    let mut factor = 1.0 - total.min(1.0);
    for &(f, rho) in shares {
        let c = (beta * rho.clamp(0.0, 1.0)).min(1.0 - 1e-9);
        factor += f.max(0.0) * scale * (1.0 + c) / (1.0 - c);
    }
    factor.max(1.0)
}

/// The mixture's second moment about the leader of one quantity, whose mean and
/// covariance `moments` takes from each hypothesis's estimate.
fn spread<const N: usize>(
    weights: &[f64],
    leader: usize,
    outs: &[(TemporalEstimate, bool)],
    moments: impl Fn(&TemporalEstimate) -> (SVector<f64, N>, SMatrix<f64, N, N>),
) -> SMatrix<f64, N, N> {
    let members: Vec<_> = outs
        .iter()
        .zip(weights)
        .map(|((o, _), &w)| {
            let (mean, covariance) = moments(o);
            (w, mean, covariance)
        })
        .collect();
    spread_about(&members[leader].1, &members)
}

impl TemporalEstimator {
    pub fn new(config: EstimatorConfig) -> Result<Self, EstimatorError> {
        config.validate()?;
        config.temporal.validate()?;
        Ok(Self {
            config,
            bank: Vec::new(),
            start_candidates: Vec::new(),
            pose_errors: None,
        })
    }

    /// Forgets everything (a new stream, or time went backwards).
    pub fn reset(&mut self) {
        self.bank.clear();
        self.start_candidates.clear();
        self.pose_errors = None;
    }

    /// What the update at `t_s` (the last one) made of its images' pose errors; `None`
    /// when the last update was at another time, coasted or failed.
    pub fn pose_errors_at(&self, t_s: f64) -> Option<&ImagePoseErrors> {
        self.pose_errors.as_ref().filter(|e| e.t_s == t_s)
    }

    /// What the last update made of its images' pose errors, whenever it was: its
    /// keyframes' errors stay theirs while they are in the window (a pair without the
    /// target, `others_message::add_unseen_tracks`). `None` when it coasted or failed.
    pub fn last_pose_errors(&self) -> Option<&ImagePoseErrors> {
        self.pose_errors.as_ref()
    }

    /// Both UAVs' noise models from now on: the σ's measured from the telemetry
    /// (`telemetry_noise`, raised where the pose samples are noisier than configured).
    /// Only σ's may change: the error model's time constants decide the state's
    /// layout, so a change of them is refused.
    pub fn set_noise(&mut self, left: NoiseModel, right: NoiseModel) -> Result<(), EstimatorError> {
        for (now, new) in [
            (&self.config.noise_left, &left),
            (&self.config.noise_right, &right),
        ] {
            if now.position_tau_s != new.position_tau_s || now.attitude_tau_s != new.attitude_tau_s
            {
                return Err(EstimatorError::Config(
                    "a noise model's time constants cannot change in a running filter".into(),
                ));
            }
        }
        let mut config = self.config;
        config.noise_left = left;
        config.noise_right = right;
        config.validate()?;
        self.config = config;
        Ok(())
    }

    /// Bias hypotheses still open (1 once the start's have been decided, 0 before it).
    pub fn hypotheses(&self) -> usize {
        self.bank.len()
    }

    /// Whether the filter may start at `t_s`: the last [`START_CONSENSUS`] sets must
    /// agree (`start_agreement.rs`): each camera's target ray moving smoothly from set
    /// to set, and the plausible window estimates among them within twice the start's
    /// position σ plus what a target can drive in between. A window estimate is
    /// plausible below both current cameras with both biases within twice the start's
    /// σ (at least 45°); an implausible one, or none, leaves only the rays to agree.
    /// One set that pairs the target in one camera with a look-alike in the other gives
    /// a window estimate hundreds of metres off (`suite_traffic`); the filter started
    /// there with σ 15 m and never came back. Returns the window estimate to start
    /// from, when it is plausible.
    fn agree_on_start<'w>(
        &mut self,
        t_s: f64,
        current: [&Observation; 2],
        window: Option<&'w Estimate>,
    ) -> Result<Option<&'w Estimate>, EstimatorError> {
        let tc = self.config.temporal;
        let bias_limit = (2.0 * tc.initial_bias_sigma_deg).max(45.0).to_radians();
        let window = window.filter(|w| {
            let p = w.position;
            p.iter().all(|v| v.is_finite())
                && w.yaw_bias.iter().all(|b| b.abs() <= bias_limit)
                && current.iter().all(|o| p.z < o.position.z)
        });
        self.start_candidates.push(StartCandidate::new(
            t_s,
            current,
            window.map(|w| w.position),
        ));
        if self.start_candidates.len() > START_CONSENSUS {
            self.start_candidates.remove(0);
        }
        let agreed = agree(&self.start_candidates, tc.initial_position_sigma_m);
        match (self.start_candidates.len() == START_CONSENSUS, agreed) {
            (true, true) => Ok(window),
            (_, false) => {
                // Keep the newest: the others disagree with it or with each other.
                self.start_candidates
                    .drain(..self.start_candidates.len() - 1);
                Err(EstimatorError::NotStarted {
                    reason: "the start's sets disagree",
                })
            }
            (false, true) => Err(EstimatorError::NotStarted {
                reason: "waiting for agreeing sets",
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

    /// Whether the update's Jacobians are taken at the midpoint of its step
    /// ([`TemporalConfig::jacobian_at`]; `auto` follows the correlated block).
    fn midpoint_jacobians(&self) -> bool {
        match self.config.temporal.jacobian_at {
            JacobianAt::Auto => self.core_len() > CORE,
            JacobianAt::Iterate => false,
            JacobianAt::Midpoint => true,
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

    /// The state indices carried as Schmidt "consider" states: the camera tilt (pitch,
    /// roll) errors of a UAV whose attitude error is correlated, in its Gauss–Markov
    /// block and in each of its keyframe slots. Their uncertainty enters every
    /// innovation covariance and every cross-covariance, their estimate is never
    /// updated (it stays at the prior's zero, where every ray is linearised).
    ///
    /// Why: a tilt common to both cameras moves the rays' intersection along the circle
    /// through both cameras and the target (the angle between the rays is kept:
    /// inscribed angle theorem), a curved direction the rays cannot see. An EKF that
    /// estimates the tilts relinearises at a new point of that circle at every update
    /// and gains information along it that the data never gave. Exact rays with a roll
    /// error constant over the run (4°, τ 1000 s) and the biases known: NEES over x, y
    /// 4.3 → 1.9 as consider states; the default Gauss–Markov model (τ 10 s): 5.0 → 2.6
    /// (2 if calibrated; docs/temporal.md). A white tilt is new in every image and has
    /// no such direction: it stays estimated (as consider states it cost 3× the
    /// horizontal MAE).
    fn considered_tilts(&self, slots: &[ImageId]) -> Vec<usize> {
        let core = self.core_len();
        let mut out = Vec::new();
        for uav in [Uav::Left, Uav::Right] {
            if self.config.noise(uav).attitude_tau_s <= 0.0 {
                continue;
            }
            // Pitch and roll: components 4 and 5 of a pose error.
            if let Some(g) = self.gm_block(uav) {
                out.extend([g + 4, g + 5]);
            }
            for (k, id) in slots.iter().enumerate() {
                if id.0 == uav {
                    out.extend([core + SLOT * k + 4, core + SLOT * k + 5]);
                }
            }
        }
        out
    }

    /// The ray's residual at `s`, its measurement covariance and its Jacobian over the
    /// whole state, taken at `s` with the target's x, y moved to `horizontal` when
    /// given ([`JacobianAt`]).
    fn linearise(
        &self,
        ray: &Ray,
        s: &DVector<f64>,
        horizontal: Option<[f64; 2]>,
    ) -> Option<(nalgebra::Vector2<f64>, nalgebra::Matrix2<f64>, DMatrix<f64>)> {
        let mut th = theta(s);
        let e: Vec<f64> = (0..6)
            .map(|k| s[ray.slot + k] + ray.gm.map_or(0.0, |g| s[g + k]))
            .collect();
        let offset = ray.offset.map(|j| [s[j], s[j + 1]]);
        let residual = ray_residual(&ray.obs, &th, &e, offset)?;
        if let Some([x, y]) = horizontal {
            th[0] = x;
            th[1] = y;
        }
        let r0 = match horizontal {
            Some(_) => ray_residual(&ray.obs, &th, &e, offset)?,
            None => residual,
        };
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
        Some((residual, c, h))
    }

    /// Adds one geolocation at `t_s`: `current` is the current (left, right) pair, `past`
    /// the past images with their ids and capture times. `window` is the per-window
    /// estimate of the same set (paper's or joint), used only to start the filter.
    pub fn update(
        &mut self,
        t_s: f64,
        current: [&Observation; 2],
        past: &[PastImage],
        window: Option<&Estimate>,
    ) -> Result<TemporalEstimate, EstimatorError> {
        self.update_or_coast(t_s, current, past, window, false)
    }

    /// The prediction at `t_s` without taking any of the set's rays: its detections
    /// are of another vehicle (`target_identity.rs`). The keyframes stay as they are;
    /// the estimate is `coasting` once the biases are known. `None` before the start.
    pub fn coast(
        &mut self,
        t_s: f64,
        current: [&Observation; 2],
    ) -> Option<Result<TemporalEstimate, EstimatorError>> {
        (!self.bank.is_empty()).then(|| self.update_or_coast(t_s, current, &[], None, true))
    }

    /// The leading hypothesis's prediction at `t_s` (constant velocity and the biases'
    /// walk, as an update predicts; the leader's own covariance, not the mixture's
    /// spread), or `None` before the start or for a time before its state.
    pub fn predict_target(&self, t_s: f64) -> Option<TargetPrior> {
        // The leader as `mixture` picks it (the first of the heaviest).
        let leader = self
            .bank
            .iter()
            .fold(None, |best: Option<&Hypothesis>, h| match best {
                Some(b) if b.log_weight >= h.log_weight => Some(b),
                _ => Some(h),
            })?;
        let (t0, s, p) = &leader.state;
        let dt = t_s - t0;
        if !(dt >= 0.0 && dt.is_finite()) {
            return None;
        }
        let tc = self.config.temporal;
        let qa = tc.acceleration_sigma_mps2.powi(2);
        let qb = tc.bias_drift_deg_per_sqrt_s.to_radians().powi(2) * dt;
        let cov = |r: usize, c: usize| {
            let mut v =
                p[(r, c)] + dt * (p[(r, c + 3)] + p[(r + 3, c)]) + dt * dt * p[(r + 3, c + 3)];
            if r == c {
                v += qa * dt.powi(3) / 3.0;
            }
            v
        };
        let out = TargetPrior {
            position: [s[0] + s[3] * dt, s[1] + s[4] * dt],
            covariance_xy: nalgebra::Matrix2::new(cov(0, 0), cov(0, 1), cov(1, 0), cov(1, 1)),
            yaw_bias: [s[5] + s[RATE] * dt, s[6] + s[RATE + 1] * dt],
            yaw_bias_covariance: {
                let b = |r: usize, c: usize| {
                    p[(r, c)] + dt * (p[(r, c + 2)] + p[(r + 2, c)]) + dt * dt * p[(r + 2, c + 2)]
                };
                nalgebra::Matrix2::new(b(5, 5), b(5, 6), b(6, 5), b(6, 6))
                    + nalgebra::Matrix2::identity() * qb
            },
        };
        let finite = out
            .position
            .iter()
            .chain(&out.yaw_bias)
            .all(|v| v.is_finite())
            && out
                .covariance_xy
                .iter()
                .chain(out.yaw_bias_covariance.iter())
                .all(|v| v.is_finite());
        finite.then_some(out)
    }

    fn update_or_coast(
        &mut self,
        t_s: f64,
        current: [&Observation; 2],
        past: &[PastImage],
        window: Option<&Estimate>,
        coast: bool,
    ) -> Result<TemporalEstimate, EstimatorError> {
        if !t_s.is_finite() {
            return Err(EstimatorError::NonFinite {
                index: 0,
                what: "time",
            });
        }
        // A coasted set's detections are not used (nor checked).
        for (i, o) in current.iter().enumerate().filter(|_| !coast) {
            o.validate(i)?;
        }
        for (i, image) in past.iter().enumerate() {
            image.observation.validate(i + 2)?;
            if !image.t_s.is_finite() {
                return Err(EstimatorError::NonFinite {
                    index: i + 2,
                    what: "capture time",
                });
            }
        }
        if self.bank.iter().any(|h| t_s < h.state.0) {
            self.reset();
        }
        let starting = self.bank.is_empty();
        if starting {
            // Start once several sets agree (never from truth). The window estimate is
            // not needed: each hypothesis starts where the current rays meet under its
            // biases; the paper's window is what fails first when the biases are large
            // and the cameras look ahead (`gimbal`: no start for 19.6 s of a 20 s run,
            // docs/temporal.md "A start without the window").
            // Without a window estimate, not before matching has past images of both
            // UAVs: the current pair alone says nothing of the biases, and a bank
            // started on it alone was 600 m off on `gimbal` seed 8 and never came back.
            let past_of = |uav: Uav| past.iter().any(|p| p.observation.uav == uav);
            if window.is_none() && !(past_of(Uav::Left) && past_of(Uav::Right)) {
                return Err(EstimatorError::NotStarted {
                    reason: "no window estimate and no past image of each UAV",
                });
            }
            let w = self.agree_on_start(t_s, current, window)?;
            self.start_candidates.clear();
            self.bank = self.start(t_s, current, w);
            if self.bank.is_empty() {
                return Err(EstimatorError::NotStarted {
                    reason: "without a window estimate the current rays meet under none of the start's biases",
                });
            }
        }
        let mut kept = Vec::with_capacity(self.bank.len());
        let mut outs = Vec::with_capacity(self.bank.len());
        let mut failure = None;
        for mut h in std::mem::take(&mut self.bank) {
            match self.update_one(&mut h, t_s, current, past, starting, coast) {
                Ok((out, log_likelihood, current_taken)) => {
                    h.log_weight += log_likelihood * self.config.temporal.likelihood_temper;
                    outs.push((out, current_taken));
                    kept.push(h);
                }
                Err(e) => failure = Some(e),
            }
        }
        if kept.is_empty() {
            self.reset();
            return Err(failure.unwrap_or(EstimatorError::NonFiniteResult {
                what: "temporal state",
            }));
        }
        let out = self.mixture(&kept, outs);
        self.pose_errors = (!coast).then(|| out.pose_errors.clone());
        // Hypotheses that agree on the target and both biases are one: their bias
        // rates, observed over many seconds, are left out of the comparison (merging
        // moment-matches them, their spread kept in the covariance).
        prune_and_merge(&mut kept, RATE);
        self.bank = kept;
        Ok(out)
    }

    /// The start's hypotheses (`hypotheses.rs`): each starts where the current pair's
    /// rays meet under its own biases, with that meeting point's covariance
    /// ([`meeting_prior`]), the grid split where that point curves
    /// ([`split_where_curved`]); the window estimate's position with the start's
    /// position σ when they do not meet in front of both cameras (without a window
    /// estimate, that hypothesis is not started). A single filter starts at the window
    /// estimate (none without one).
    fn start(
        &self,
        t_s: f64,
        current: [&Observation; 2],
        window: Option<&Estimate>,
    ) -> Vec<Hypothesis> {
        let tc = self.config.temporal;
        let (sp, sv) = (tc.initial_position_sigma_m, tc.initial_velocity_sigma_mps);
        let min_angle = self.config.min_ray_angle_deg.to_radians();
        let noise = current.map(|o| ImageNoise {
            white: self.pose_sigmas(o.uav),
            correlated: self.gm_block(o.uav).map(|g| {
                let c = self.correlated(o.uav);
                (g, std::array::from_fn(|j| c[j].0))
            }),
            sigma_px: self.config.noise(o.uav).sigma_pixel_px,
        });
        let prior = |g: &BiasStart| meeting_prior(current, g.mean, g.sigma, noise, min_angle);
        let grid = bias_grid(tc.bias_hypotheses, tc.initial_bias_sigma_deg.to_radians());
        let grid = if tc.bias_hypotheses > 1 {
            split_where_curved(grid, tc.max_start_hypotheses, |g| {
                prior(g).map_or(f64::INFINITY, |p| p.curvature())
            })
        } else {
            grid
        };
        grid.into_iter()
            .filter_map(|g| {
                let mut s = DVector::zeros(self.core_len());
                s[5] = g.mean[0];
                s[6] = g.mean[1];
                let mut p = DMatrix::zeros(s.len(), s.len());
                let sr = [Uav::Left, Uav::Right].map(|u| bias_rate(&self.config, u).0);
                for (i, v) in [sp, sp, sp, sv, sv, g.sigma, g.sigma, sr[0], sr[1]]
                    .into_iter()
                    .enumerate()
                {
                    p[(i, i)] = v * v;
                }
                for uav in [Uav::Left, Uav::Right] {
                    let Some(b) = self.gm_block(uav) else {
                        continue;
                    };
                    for (k, (sigma, _)) in self.correlated(uav).into_iter().enumerate() {
                        p[(b + k, b + k)] = sigma * sigma;
                    }
                }
                // A hypothesis starts where the current pair's rays meet under its
                // biases: its position's covariance, and its covariance with the biases
                // and correlated pose errors it moves with, are theirs (`start_prior`).
                // Where they do not meet, at the window estimate with the start's σ
                // (without one, not started).
                // A meeting point above either camera is not one (near-parallel rays
                // turned past each other by the biases).
                let below = |m: &MeetingPrior| current.iter().all(|o| m.point.z < o.position.z);
                let meeting = (tc.bias_hypotheses > 1)
                    .then(|| prior(&g))
                    .flatten()
                    .filter(below);
                let position = match meeting {
                    Some(m) => {
                        p.view_mut((0, 0), (3, 3))
                            .copy_from(&m.covariance(MEETING_FLOOR_M));
                        for source in &m.sources {
                            if let Some(i) = source.state {
                                let c = source.slope * source.sigma * source.sigma;
                                for r in 0..3 {
                                    p[(r, i)] = c[r];
                                    p[(i, r)] = c[r];
                                }
                            }
                        }
                        m.point
                    }
                    None => window?.position,
                };
                s[0] = position.x;
                s[1] = position.y;
                s[2] = position.z;
                Some(Hypothesis {
                    log_weight: g.log_weight,
                    state: (t_s, s, p),
                    slots: Vec::new(),
                    drift: [nalgebra::Vector2::zeros(); 2],
                    since_reopen: REOPEN_HOLD,
                    lost_since_s: None,
                })
            })
            .collect()
    }

    /// The estimate of the bank: the leader's (the heaviest hypothesis), its covariance
    /// the whole mixture's spread about it. `converging` while the mixture's bias σ is
    /// above `converged_bias_sigma_deg`.
    fn mixture(
        &self,
        bank: &[Hypothesis],
        outs: Vec<(TemporalEstimate, bool)>,
    ) -> TemporalEstimate {
        if let [(single, _)] = outs.as_slice() {
            return single.clone();
        }
        let w = weights(&bank.iter().map(|h| h.log_weight).collect::<Vec<_>>());
        let leader = (0..w.len()).fold(0, |best, i| if w[i] > w[best] { i } else { best });
        let (mut out, current_taken) = outs[leader].clone();
        out.estimate.covariance = spread(&w, leader, &outs, |o| {
            let e = &o.estimate;
            let mean =
                SVector::<f64, 4>::new(e.position.x, e.position.y, e.yaw_bias[0], e.yaw_bias[1]);
            (mean, e.covariance)
        });
        let z = spread(&w, leader, &outs, |o| {
            let e = &o.estimate;
            (
                SVector::<f64, 1>::new(e.position.z),
                SMatrix::<f64, 1, 1>::new(e.altitude_std_error_m.powi(2)),
            )
        });
        out.estimate.altitude_std_error_m = z[(0, 0)].max(0.0).sqrt();
        let v = spread(&w, leader, &outs, |o| {
            let variance = SVector::<f64, 2>::from(o.velocity_std_mps.map(|s| s * s));
            (
                SVector::<f64, 2>::from(o.velocity),
                SMatrix::<f64, 2, 2>::from_diagonal(&variance),
            )
        });
        out.velocity_std_mps = [v[(0, 0)].max(0.0).sqrt(), v[(1, 1)].max(0.0).sqrt()];
        let c = &out.estimate.covariance;
        let limit = self.config.temporal.converged_bias_sigma_deg.to_radians();
        let bias_known = (2..4).all(|i| c[(i, i)].max(0.0).sqrt() <= limit);
        out.quality = match (bias_known, current_taken) {
            (false, _) => Quality::Converging,
            (true, true) => Quality::Tracking,
            (true, false) => Quality::Coasting,
        };
        out
    }

    /// One hypothesis's update: its estimate, the log-likelihood of this geolocation's
    /// rays under its prediction (Gaussian over the accepted rays, each gated-out ray
    /// counted at the gate: a robust likelihood) and whether a current ray was taken.
    fn update_one(
        &self,
        hypothesis: &mut Hypothesis,
        t_s: f64,
        current: [&Observation; 2],
        past: &[PastImage],
        starting: bool,
        coast: bool,
    ) -> Result<(TemporalEstimate, f64, bool), EstimatorError> {
        let tc = self.config.temporal;
        let (t0, mut s, mut p) = hypothesis.state.clone();
        // Predict the core: constant velocity (white acceleration), random walks for z
        // and the biases. Keyframe pose errors do not change, but their yaws take the
        // biases' walk (below).
        let dt = t_s - t0;
        let core_len = self.core_len();
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
            // Each bias drifts at its rate (eq. 34), the rate a slow random walk.
            for (uav, u) in [Uav::Left, Uav::Right].into_iter().enumerate() {
                let qr = bias_rate(&self.config, u).1.powi(2);
                let (b, r) = (5 + uav, RATE + uav);
                f[(b, r)] = dt;
                q[(r, r)] = qr * dt;
                q[(b, b)] += qr * dt.powi(3) / 3.0;
                q[(b, r)] = qr * dt.powi(2) / 2.0;
                q[(r, b)] = qr * dt.powi(2) / 2.0;
            }
            // A keyframe's rays are corrected with the *current* bias, but its image
            // was taken under the bias of its capture time: its yaw error state holds
            // the difference, b(t_k) − b(t) plus its own yaw error (measured = true +
            // bias + error). The bias's walk since moves that difference the other
            // way, so the walk's noise enters that UAV's keyframe yaw states with the
            // opposite sign. Left out, the filter took a keyframe reused for 3 s as
            // seeing under today's bias, 0.6° off under eq. (34)'s 0.2°/s drift; 45°
            // off nadir a degree is metres along the line of sight (exact synthetic
            // rays, 12 runs: NEES over 15–20 s 4.5–9.1, now 3.3–4.7; without the drift
            // 2.7–3.4). Nadir flights are as calibrated as before.
            let yaw_slots = |uav: usize| {
                hypothesis
                    .slots
                    .iter()
                    .enumerate()
                    .filter(move |(_, id)| id.0.index() == uav)
                    .map(|(k, _)| core_len + SLOT * k + 3)
            };
            for uav in 0..2 {
                for i in yaw_slots(uav) {
                    // The bias's drift since moves that difference by −rate·dt.
                    f[(i, RATE + uav)] = -dt;
                    q[(5 + uav, i)] = -qb;
                    q[(i, 5 + uav)] = -qb;
                    for j in yaw_slots(uav) {
                        q[(i, j)] = qb;
                    }
                }
            }
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
        // Coasting keeps every keyframe (its `past` is empty).
        let ids: Vec<ImageId> = if coast {
            hypothesis.slots.clone()
        } else {
            past.iter().map(|image| image.id).collect()
        };
        let core = self.core_len();
        let keep: Vec<usize> = (0..core)
            .chain(
                hypothesis
                    .slots
                    .iter()
                    .enumerate()
                    .filter(|(_, id)| ids.contains(id))
                    .flat_map(|(k, _)| core + SLOT * k..core + SLOT * (k + 1)),
            )
            .collect();
        if keep.len() != s.len() {
            s = DVector::from_iterator(keep.len(), keep.iter().map(|&i| s[i]));
            p = DMatrix::from_fn(keep.len(), keep.len(), |r, c| p[(keep[r], keep[c])]);
            hypothesis.slots.retain(|id| ids.contains(id));
        }
        for image in past {
            let id = &image.id;
            if !hypothesis.slots.contains(id) {
                let sig = self.pose_sigmas(id.0);
                let n = s.len();
                s = s.resize_vertically(n + SLOT, 0.0);
                p = p.resize(n + SLOT, n + SLOT, 0.0);
                // Its pose error is its UAV's correlated error when it was taken plus
                // its own white part. The correlated error then, `lag` seconds ago, is
                // the one now run backwards: e(t − lag) = ρ e(t) + w, ρ = e^(−lag/τ),
                // w ~ N(0, σ²(1 − ρ²)) (a stationary Gauss–Markov process is the same
                // run either way). The start's slots are the ones this matters for:
                // the keyframes already in the ring are up to 2–3 s old, and the
                // AHRS's τ is 10 s. Cloned as if taken now, exact rays under the
                // default Gauss–Markov model: NEES 3.3 / 3.1 (x, y / z, 2 / 1 if
                // calibrated) in the first second; with the lag 2.5 / 1.2.
                let lag = (t_s - image.t_s).max(0.0);
                if let Some(g) = self.gm_block(id.0) {
                    let corr = self.correlated(id.0);
                    let rho = corr.map(
                        |(sigma, tau)| {
                            if sigma > 0.0 {
                                (-lag / tau).exp()
                            } else {
                                1.0
                            }
                        },
                    );
                    for j in 0..6 {
                        s[n + j] = rho[j] * s[g + j];
                        for c in 0..n {
                            p[(n + j, c)] = rho[j] * p[(g + j, c)];
                            p[(c, n + j)] = rho[j] * p[(c, g + j)];
                        }
                    }
                    for j in 0..6 {
                        for k in 0..6 {
                            p[(n + j, n + k)] = rho[j] * rho[k] * p[(g + j, g + k)];
                        }
                        p[(n + j, n + j)] += corr[j].0.powi(2) * (1.0 - rho[j] * rho[j]);
                    }
                }
                // Taken `lag` seconds ago under the bias then: b(t − lag) − b(t) =
                // −rate·lag on top of the yaw error (eq. 34's drift).
                {
                    let r = RATE + id.0.index();
                    let yaw = n + 3;
                    s[yaw] -= lag * s[r];
                    for c in 0..n {
                        let v = p[(yaw, c)] - lag * p[(r, c)];
                        p[(yaw, c)] = v;
                        p[(c, yaw)] = v;
                    }
                    // p[(yaw, yaw)] = var(old yaw part) − 2 lag cov(old, r) + lag² var(r)
                    // (the old yaw part's covariance with r is in p[(yaw, r)] now minus
                    // lag·var(r)).
                    let cov_old_r = p[(yaw, r)] + lag * p[(r, r)];
                    p[(yaw, yaw)] += -2.0 * lag * cov_old_r + lag * lag * p[(r, r)];
                }
                for j in 0..6 {
                    p[(n + j, n + j)] += sig[j].max(1e-6).powi(2);
                }
                let offset = tc.transfer_offset_sigma_px.powi(2);
                p[(n + 6, n + 6)] = offset;
                p[(n + 7, n + 7)] = offset;
                hypothesis.slots.push(*id);
            }
        }
        // The current pair's pose errors: six states per image for this update only
        // (marginalised after it). With their pose noise in the covariance instead,
        // evaluated at the estimate, the reprojection residual's 1/depth scale made
        // the update prefer a target further from the cameras: the altitude sat
        // ~1.4 m low with horizontal GPS noise alone (docs/temporal.md).
        let kept = s.len();
        let mut rays: Vec<Ray> = Vec::with_capacity(2 + past.len());
        let current: &[&Observation] = if coast { &[] } else { &current };
        for &o in current {
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
        // The images' measure of each past camera's rotation from the current ones:
        // it ties their attitude errors together (and, across the UAVs, the two
        // biases' difference), whatever the target does.
        let mut rotations: Vec<RotationPair> = Vec::new();
        let current_rays = rays.len();
        for image in past {
            let Some(k) = hypothesis.slots.iter().position(|x| *x == image.id) else {
                continue;
            };
            let o = &image.observation;
            let past_ray = rays.len();
            rays.push(Ray {
                obs: *o,
                slot: core + SLOT * k,
                offset: Some(core + SLOT * k + 6),
                gm: None,
                sigma_px: tc.transfer_sigma_px,
            });
            for (side, v) in image.rotation_from.iter().enumerate() {
                let Some(v) = v else {
                    continue;
                };
                let Some(current_ray) =
                    (0..current_rays).find(|&i| rays[i].obs.uav.index() == side)
                else {
                    continue;
                };
                let current_uav = rays[current_ray].obs.uav;
                let [tilt, yaw] = rotation_sigma_deg(&self.config, current_uav, o.uav);
                if tilt > 0.0 && yaw > 0.0 {
                    rotations.push(RotationPair {
                        current: current_ray,
                        past: past_ray,
                        measured: nalgebra::Rotation3::from_scaled_axis(*v),
                        sigma: nalgebra::Vector3::new(tilt, tilt, yaw).map(f64::to_radians),
                    });
                }
            }
        }

        // Gate at the prediction; follow each UAV's current-ray innovation over time.
        let mut accepted = Vec::new();
        // ln det of each ray's innovation covariance, for the likelihood of those gated out.
        let mut log_det = vec![0.0; rays.len()];
        // Each UAV's persistence factor of its running mean's variance, from its
        // current ray below. A UAV whose ray is not linearised this time keeps its
        // mean as it was; under a correlated model it is then judged at the widest
        // factor (all of the innovation held, ρ = 1), never as if white.
        let mut persistence = [Uav::Left, Uav::Right].map(|uav| {
            if self.gm_block(uav).is_some() {
                persistence_factor(&[(1.0, 1.0)])
            } else {
                1.0
            }
        });
        for (i, ray) in rays.iter().enumerate() {
            let Some((r, c, h)) = self.linearise(ray, &s, None) else {
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
            log_det[i] = 2.0 * chol.l().diagonal().iter().map(|v| v.ln()).sum::<f64>();
            if i < 2 {
                if let Some(g) = ray.gm {
                    let sinv = chol.inverse();
                    let correlated = self.correlated(ray.obs.uav);
                    // A white component (σ 0) has no share.
                    let shares: [(f64, f64); 6] = std::array::from_fn(|k| {
                        let (sigma, tau) = correlated[k];
                        if sigma <= 0.0 {
                            return (0.0, 0.0);
                        }
                        let col = h.column(g + k);
                        let sk_k = col * col.transpose() * p[(g + k, g + k)];
                        ((&sinv * sk_k).trace() / 2.0, (-dt.max(0.0) / tau).exp())
                    });
                    persistence[ray.obs.uav.index()] = persistence_factor(&shares);
                }
                // Each sample enters the running mean at most at the gate's radius
                // (winsorised): one ray far off, a look-alike taken for a frame or two,
                // moved the mean past `DRIFT_GATE` on its own and re-opened that UAV's
                // bias, and the widened filter then took the look-alike's ray and
                // turned the bias 40° (`suite_traffic` seed 3 of the multi-target
                // report: two unchecked pairs at 4.47 s, the target's estimate 10 m off
                // for 2 s, then 3 m off at ±1 m). A persistent offset still trips it,
                // after three geolocations instead of one.
                let w2 = nalgebra::Vector2::new(whitened[0], whitened[1]);
                let w2 = if d2 > GATE {
                    w2 * (GATE / d2).sqrt()
                } else {
                    w2
                };
                let uav = ray.obs.uav.index();
                hypothesis.drift[uav] += DRIFT_ALPHA * (w2 - hypothesis.drift[uav]);
            }
            if d2 <= GATE {
                accepted.push(i);
            }
        }
        // Rotations far from the prediction are not taken (gated like the rays).
        let mut rotation_log_det = vec![0.0; rotations.len()];
        let mut rotations_accepted = Vec::new();
        for (i, m) in rotations.iter().enumerate() {
            let (r, h) = linearise_rotation(m, &rays, &s);
            if !r.iter().chain(h.iter()).all(|v| v.is_finite()) {
                continue;
            }
            let sk = &h * &p * h.transpose() + rotation_noise(m);
            let Some(chol) = sk.cholesky() else {
                continue;
            };
            let rv = DVector::from_column_slice(r.as_slice());
            let d2 = chol
                .l()
                .solve_lower_triangular(&rv)
                .map_or(f64::INFINITY, |w| w.norm_squared());
            rotation_log_det[i] = 2.0 * chol.l().diagonal().iter().map(|v| v.ln()).sum::<f64>();
            if d2 <= ROTATION_GATE {
                rotations_accepted.push(i);
            }
        }
        // A coasted set has no ray: it neither counts towards a re-opening's hold nor
        // moves the drift monitor's decisions (no re-opening, no re-acquisition).
        if !coast {
            hypothesis.since_reopen += 1;
        }
        let drift_var = DRIFT_ALPHA / (2.0 - DRIFT_ALPHA);
        let drift =
            [0, 1].map(|u| hypothesis.drift[u].norm_squared() / (drift_var * persistence[u]));
        // A bias step is one AHRS's: the two UAVs' yaw errors are independent, so both
        // stepping within the same few frames is far less likely than both cameras
        // seeing something other than the predicted target (a look-alike while it is
        // hidden). A UAV's bias is re-opened only when its current rays drift while the
        // other's agree with the prediction (running mean inside χ²(2) at 95 %); when
        // both drift, their rays stay gated out and the filter coasts. Measured on
        // `suite_traffic` seed 5: re-opening both biases let the filter explain the
        // look-alike pair by turning them ±22° the wrong way.
        let stepped = match drift.map(|d| (d > DRIFT_GATE, d <= DRIFT_AGREES)) {
            [(true, _), (_, true)] => Some(0),
            [(_, true), (true, _)] => Some(1),
            _ => None,
        };
        // Both drifting: neither camera is looking at the predicted target. Their rays
        // are not taken until the running means come back (the filter coasts), or for
        // `LOST_AFTER_S`: then the target is elsewhere, and the position and velocity
        // are re-acquired from the rays with the biases kept (below).
        let stepped = stepped.filter(|_| !coast);
        let both_drifting = !coast && drift.iter().all(|d| *d > DRIFT_GATE);
        if coast {
            // No evidence either way: the drifting clock is left as it is.
        } else if both_drifting {
            hypothesis.lost_since_s.get_or_insert(t_s);
        } else {
            hypothesis.lost_since_s = None;
        }
        let lost = !coast
            && hypothesis
                .lost_since_s
                .is_some_and(|since| t_s - since >= LOST_AFTER_S);
        if both_drifting && !lost {
            accepted.clear();
        }
        let mut reopened = false;
        if lost {
            let sp = tc.initial_position_sigma_m.powi(2);
            let sv = tc.initial_velocity_sigma_mps.powi(2);
            for i in 0..3 {
                p[(i, i)] += sp;
            }
            p[(3, 3)] += sv;
            p[(4, 4)] += sv;
            hypothesis.drift = [nalgebra::Vector2::zeros(); 2];
            hypothesis.lost_since_s = None;
            hypothesis.since_reopen = 0;
            reopened = true;
            accepted = (0..rays.len()).collect();
        }
        if let (Some(uav), true) = (stepped, hypothesis.since_reopen >= REOPEN_HOLD) {
            // A bias step: forget what we believed about that bias and the position.
            let sb = tc.reopen_bias_sigma_deg.to_radians().powi(2);
            let sp = tc.initial_position_sigma_m.powi(2);
            p[(5 + uav, 5 + uav)] += sb;
            // Its rate too: before the re-opening the rate took up part of the step.
            let u = [Uav::Left, Uav::Right][uav];
            p[(RATE + uav, RATE + uav)] += bias_rate(&self.config, u).0.powi(2);
            for i in 0..3 {
                p[(i, i)] += sp;
            }
            // That UAV's keyframes taken before the step carry the old bias: let their
            // yaw errors take up the difference instead of pulling the new bias back.
            for (k, id) in hypothesis.slots.iter().enumerate() {
                if id.0.index() == uav {
                    p[(core + SLOT * k + 3, core + SLOT * k + 3)] += sb;
                }
            }
            hypothesis.drift = [nalgebra::Vector2::zeros(); 2];
            hypothesis.since_reopen = 0;
            reopened = true;
            // Against the widened prediction every ray of this geolocation is plausible.
            accepted = (0..rays.len()).collect();
        }

        // Iterated EKF update over every accepted ray at once; the correlated tilts are
        // consider states (`considered_tilts`): their rows of the gain are zero.
        let consider = self.considered_tilts(&hypothesis.slots);
        let n = s.len();
        let s_prior = s.clone();
        // The start's first update leaves the current pair's rays out: each hypothesis
        // starts where they meet (`start`), so they are its prior already; taken again
        // they counted twice, and the first second's altitude claimed more than it knew
        // (exact rays, 80 m up and 40 m apart, 48 runs: z error / v_acc rms 1.27 → 1.15
        // in the first 1.5 s, beyond 3σ 0.5 → 0.2 %; `the_start_counts_the_current_pair_once`).
        // They are not scored either (the hypotheses' weights come from the past
        // images' rays) nor counted as gated out.
        let gated_in = accepted.clone();
        if starting {
            accepted.retain(|&i| i >= 2);
        }
        let mut s_iter = s.clone();
        let mut gain_h = None;
        let mut log_likelihood = 0.0;
        for iteration in 0..3 {
            let ray_rows = accepted.len() * 2;
            let m = ray_rows + rotations_accepted.len() * 3;
            if m == 0 {
                break;
            }
            let mut h = DMatrix::<f64>::zeros(m, n);
            let mut r = DVector::<f64>::zeros(m);
            let mut rc = DMatrix::<f64>::zeros(m, m);
            let mut ok = true;
            // `midpoint`: the first iteration's point is the prediction itself.
            let horizontal = self
                .midpoint_jacobians()
                .then(|| [0, 1].map(|i| 0.5 * (s_prior[i] + s_iter[i])));
            for (row, &i) in accepted.iter().enumerate() {
                let Some((rk, ck, hk)) = self.linearise(&rays[i], &s_iter, horizontal) else {
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
            for (j, &i) in rotations_accepted.iter().enumerate() {
                let m = &rotations[i];
                let (rk, hk) = linearise_rotation(m, &rays, &s_iter);
                let lin = DVector::from_column_slice(rk.as_slice()) + &hk * (&s_prior - &s_iter);
                let row = ray_rows + 3 * j;
                r.rows_mut(row, 3).copy_from(&lin);
                h.view_mut((row, 0), (3, n)).copy_from(&hk);
                rc.view_mut((row, row), (3, 3))
                    .copy_from(&rotation_noise(m));
            }
            let sm = &h * &p * h.transpose() + &rc;
            if iteration == 0 {
                // At the prediction (s_iter = prior): −½ (rᵀ S⁻¹ r + ln det S).
                let Some(chol) = sm.clone().cholesky() else {
                    break;
                };
                let ln_det = 2.0 * chol.l().diagonal().iter().map(|v| v.ln()).sum::<f64>();
                log_likelihood = -0.5 * (r.dot(&chol.solve(&r)) + ln_det);
            }
            let Some(sinv) = sm.try_inverse() else { break };
            let mut k = &p * h.transpose() * sinv;
            for &c in &consider {
                k.row_mut(c).fill(0.0);
            }
            s_iter = &s_prior - &k * r;
            gain_h = Some((k, h, rc));
        }
        if let Some((k, h, rc)) = gain_h {
            let i_kh = DMatrix::<f64>::identity(n, n) - &k * h;
            // With consider states the gain is not the optimal one: the Joseph form
            // keeps P the covariance of the estimate it goes with.
            let pn = if consider.is_empty() {
                &i_kh * &p
            } else {
                &i_kh * &p * i_kh.transpose() + &k * rc * k.transpose()
            };
            p = (&pn + pn.transpose()) * 0.5;
            s = s_iter;
        }
        // What the update made of each image's pose error, before the current pair's
        // go: its rays' own (their UAV's correlated block added) and each keyframe's.
        let error_of = |ray: &Ray| -> [f64; 6] {
            std::array::from_fn(|k| s[ray.slot + k] + ray.gm.map_or(0.0, |g| s[g + k]))
        };
        let mut pose_errors = ImagePoseErrors {
            t_s,
            ..ImagePoseErrors::default()
        };
        for ray in &rays[..current_rays] {
            pose_errors.current[ray.obs.uav.index()] = Some(error_of(ray));
        }
        pose_errors.past = hypothesis
            .slots
            .iter()
            .enumerate()
            .map(|(k, id)| (*id, std::array::from_fn(|j| s[core + SLOT * k + j])))
            .collect();
        // Marginalise the current pair's pose errors.
        let s = s.rows(0, kept).into_owned();
        let p = p.view((0, 0), (kept, kept)).into_owned();
        if !s.iter().all(|v| v.is_finite()) || !p.iter().all(|v| v.is_finite()) {
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
            pose_errors,
        };
        for (i, ld) in log_det.iter().enumerate() {
            if !gated_in.contains(&i) {
                log_likelihood -= 0.5 * (GATE + ld);
            }
        }
        for (i, ld) in rotation_log_det.iter().enumerate() {
            if !rotations_accepted.contains(&i) && ld.is_finite() {
                log_likelihood -= 0.5 * (ROTATION_GATE + ld);
            }
        }
        hypothesis.state = (t_s, s, p);
        Ok((out, log_likelihood, current_taken))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::SyntheticScenario;
    use rand::SeedableRng;
    use shared_types::conventions::Intrinsics;
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
            let past: Vec<PastImage> = o[2..]
                .iter()
                .filter(|_| n > 1)
                .map(|ob| {
                    next_id += 1;
                    // White errors only: the capture time is not used.
                    past_image((ob.uav, next_id), t, *ob)
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

    /// Every update says what it made of its images' pose errors (the other
    /// vehicles' fixes remove them, `others_message.rs`): the current pair's and every
    /// keyframe's, at the update's time; without navigation noise they are all near
    /// zero (yaw within 0.1°), and with it (σ_att 2°) some image's yaw is not.
    #[test]
    fn each_update_says_what_it_made_of_its_images_pose_errors() {
        let quiet = SyntheticScenario {
            noise: NavNoise::NONE,
            ..SyntheticScenario::default()
        };
        for (scenario, noisy) in [(quiet, false), (SyntheticScenario::default(), true)] {
            let run = fly(&scenario, 10.0, 4);
            let (t, last, _, _) = run.last().unwrap();
            let e = &last.pose_errors;
            assert_eq!(e.t_s, *t);
            assert!(e.current.iter().all(Option::is_some), "{e:?}");
            assert!(!e.past.is_empty(), "{e:?}");
            let all = e
                .current
                .iter()
                .flatten()
                .chain(e.past.iter().map(|(_, v)| v));
            let largest_yaw = all.map(|v| v[3].abs()).fold(0.0, f64::max).to_degrees();
            assert!(
                if noisy {
                    largest_yaw > 0.5
                } else {
                    largest_yaw < 0.1
                },
                "{largest_yaw}° ({noisy})"
            );
        }
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
                let past: Vec<PastImage> = o[2..]
                    .iter()
                    .enumerate()
                    .map(|(i, ob)| past_image((ob.uav, 1000 * k + i as u64), 1.25 * k as f64, *ob))
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
        // Not at the mismatched window, and the stated accuracy covers the error (with
        // bias hypotheses the start is where the current rays meet under the leading
        // hypothesis's biases: tens of metres off, and saying so).
        let d = e.estimate.position - tr.target;
        assert!(d.norm() < 100.0, "{d:?}");
        let xy = nalgebra::Vector2::new(d.x, d.y);
        let information = e
            .estimate
            .covariance
            .fixed_view::<2, 2>(0, 0)
            .try_inverse()
            .expect("covariance");
        let nees = xy.dot(&(information * xy));
        assert!(nees < 13.8, "{d:?}: NEES {nees:.1}");
    }

    /// Without window estimates (the paper's window failed: tilted cameras, large
    /// biases), and not on the current pair alone, the filter starts once three sets
    /// with past images of both UAVs have rays that agree, where the current rays
    /// meet under its hypotheses' biases, and states an accuracy that covers its
    /// error; a set whose right camera took a vehicle far away holds the start back.
    #[test]
    fn the_filter_starts_without_window_estimates_when_the_rays_agree() {
        let scenario = SyntheticScenario::default();
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let mut f = TemporalEstimator::new(EstimatorConfig::default()).unwrap();
        let trial = |t: f64, rng: &mut rand::rngs::StdRng| scenario.trial(t, 2, rng).unwrap();
        let lag = scenario.keyframe_interval_s();
        // Not on the current pair alone.
        let tr = trial(4.9, &mut rng);
        let o = &tr.observations;
        let e = f.update(4.9, [&o[0], &o[1]], &[], None);
        assert!(matches!(e, Err(EstimatorError::NotStarted { .. })), "{e:?}");
        // A right detection 150 px away (another vehicle) in the second set.
        let mut started = None;
        for k in 0..6 {
            let t = 5.0 + k as f64 / 15.0;
            let tr = trial(t, &mut rng);
            let mut o = tr.observations.clone();
            if k == 1 {
                o[1].pixel.x += 150.0;
            }
            // One past image of each UAV (the trial's order: L, R now, then L, R earlier).
            let past: Vec<PastImage> = o[2..]
                .iter()
                .map(|ob| past_image((ob.uav, 100 + k as u64), t - lag, *ob))
                .collect();
            match f.update(t, [&o[0], &o[1]], &past, None) {
                Ok(e) => {
                    started = Some((k, e, tr.target));
                    break;
                }
                Err(e) => assert!(matches!(e, EstimatorError::NotStarted { .. }), "{e:?}"),
            }
        }
        let (k, e, target) = started.expect("started without window estimates");
        // Sets 0 and 1 disagree; 1, 2 and 3 too (the jump); 2, 3 and 4 agree.
        assert_eq!(k, 4, "the third agreeing set after the jump starts it");
        let (nees, beyond) = nees_of(&e, target);
        assert!(
            !beyond,
            "NEES {nees:.1}: {:?}",
            e.estimate.position - target
        );
    }

    /// NEES over x, y (their 2×2 covariance) and z (v_acc) of one estimate, and whether
    /// it is beyond 3σ (horizontal beyond 3 h_acc or vertical beyond 3 v_acc).
    fn nees_of(e: &TemporalEstimate, truth: Point3<f64>) -> (f64, bool) {
        let d = e.estimate.position - truth;
        let c = e.estimate.covariance.fixed_view::<2, 2>(0, 0).into_owned();
        let Some(ci) = c.try_inverse() else {
            panic!("singular horizontal covariance {c}")
        };
        let h = nalgebra::Vector2::new(d.x, d.y);
        let v = e.estimate.altitude_std_error_m;
        let h_acc = (c[(0, 0)] + c[(1, 1)]).sqrt();
        let nees = (h.transpose() * ci * h)[(0, 0)] + (d.z / v).powi(2);
        (nees, h.norm() > 3.0 * h_acc || d.z.abs() > 3.0 * v)
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
                let (nees, beyond) = nees_of(&e, truth);
                sum += nees;
                gross += usize::from(beyond);
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
            "cannot start without a window estimate or past images"
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
    pub(crate) fn past_image(id: ImageId, t_s: f64, observation: Observation) -> PastImage {
        PastImage {
            id,
            t_s,
            observation,
            rotation_from: [None; 2],
        }
    }

    /// (t, estimate, truth target, true biases) per estimate.
    type Flight = Vec<(f64, TemporalEstimate, Point3<f64>, [f64; 2])>;

    /// What goes wrong in a [`fly_keyframes`] flight.
    #[derive(Clone, Copy, Default)]
    struct Disturbance {
        /// From this time the left AHRS's yaw reads this many degrees more (frames
        /// taken before keep the old bias).
        left_bias_step: Option<(f64, f64)>,
        /// From this time the target is this far (x, y metres) from where its route
        /// puts it: a replay looping back to its start, or a manoeuvre the constant
        /// velocity model cannot follow.
        target_jump: Option<(f64, [f64; 2])>,
        /// From this time, for this many geolocations, the right camera's detection
        /// is a look-alike this far (x, y metres) from the target, and the set has
        /// no past images (the chain's pairs without a shared keyframe, unchecked).
        right_look_alike: Option<(f64, usize, [f64; 2])>,
        /// The current images' pose samples go to a [`TelemetryNoise`] and the filter
        /// takes the σ's it raises (as the geolocation service does).
        measure_noise: bool,
        /// Each past image carries its true rotation from both current cameras, with
        /// this much white error per axis, degrees (what matching's homographies
        /// measure: `PastImage::rotation_from`).
        rotations_sigma_deg: Option<f64>,
    }

    /// A flight as the chain gives it: keyframes picked by the baseline constraint
    /// (`keyframe_spacing_m` of true travel, a ring of 6, the newest 3 per UAV in each
    /// set) keep the pose noise drawn when they were taken, as long as they are reused;
    /// every pixel is the exact projection of the target's current position. The chain
    /// matches nothing before each ring holds 3, so neither does this.
    /// (`fly` draws new noise for every past image of every trial: no reuse.)
    fn fly_keyframes(
        sc: &SyntheticScenario,
        config: EstimatorConfig,
        seconds: f64,
        seed: u64,
        disturbance: Disturbance,
    ) -> (Flight, usize) {
        let (run, filter) = fly_keyframes_with(sc, config, seconds, seed, disturbance);
        (run, filter.hypotheses())
    }

    /// [`fly_keyframes`] giving the filter as it ends.
    fn fly_keyframes_with(
        sc: &SyntheticScenario,
        config: EstimatorConfig,
        seconds: f64,
        seed: u64,
        disturbance: Disturbance,
    ) -> (Flight, TemporalEstimator) {
        use rand_distr::{Distribution, Normal};
        use shared_types::conventions::{camera_to_world, Attitude};
        struct Keyframe {
            id: u64,
            t_s: f64,
            true_pose: (Point3<f64>, Attitude),
            measured: (Point3<f64>, Attitude),
        }
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        // The rotations' errors from a generator of their own: the same seed flies the
        // same navigation errors with them or without.
        let mut rotation_rng = rand::rngs::StdRng::seed_from_u64(seed ^ 0x5eed);
        // The scenario's navigation errors as the simulator draws them (white, or
        // Gauss–Markov with its jitter), one error state per UAV.
        let mut nav = [shared_types::nav_noise::NavErrorState::default(); 2];
        let unit = Normal::new(0.0, 1.0).unwrap();
        let project = |(p, a): (Point3<f64>, Attitude), target: Point3<f64>| {
            sc.intrinsics
                .project(camera_to_world(sc.camera_attitude(a)).transpose() * (target - p))
                .filter(|px| {
                    (0.0..sc.image_width as f64).contains(&px.x)
                        && (0.0..sc.image_height as f64).contains(&px.y)
                })
        };
        let mut filter = TemporalEstimator::new(config).unwrap();
        let mut telemetry = crate::telemetry_noise::TelemetryNoise::new();
        let mut raise = crate::telemetry_noise::NoiseRaise::new();
        let mut rings: [Vec<Keyframe>; 2] = [Vec::new(), Vec::new()];
        let mut out = Vec::new();
        let mut id = 0u64;
        let mut look_alike_taken = 0;
        // The AHRS's yaw biases, the left's step included.
        let true_bias = |t: f64| {
            let mut b = sc.bias.at(t);
            if let Some((_, deg)) = disturbance.left_bias_step.filter(|d| t >= d.0) {
                b[0] += deg.to_radians();
            }
            b
        };
        let mut t = 2.0;
        while t < seconds {
            let jump = match disturbance.target_jump {
                Some((at, [dx, dy])) if t >= at => nalgebra::Vector3::new(dx, dy, 0.0),
                _ => nalgebra::Vector3::zeros(),
            };
            let target = sc.target_at(t) + jump;
            let look_alike = disturbance
                .right_look_alike
                .filter(|(at, frames, _)| t >= *at && look_alike_taken < *frames)
                .map(|(_, _, [dx, dy])| target + nalgebra::Vector3::new(dx, dy, 0.0));
            let mut current = Vec::new();
            let mut current_true = [None; 2];
            for uav in [Uav::Left, Uav::Right] {
                id += 1;
                let (p, a) = sc.uav_at(uav, t);
                current_true[uav.index()] = Some(a);
                let bias = true_bias(t)[uav.index()];
                let e = nav[uav.index()].next(&sc.noise, t, || unit.sample(&mut rng));
                let measured = (
                    p + nalgebra::Vector3::new(e[0], e[1], e[2]),
                    sc.camera_attitude(Attitude::new(
                        a.yaw + bias + e[3].to_radians(),
                        a.pitch + e[4].to_radians(),
                        a.roll + e[5].to_radians(),
                    )),
                );
                if disturbance.measure_noise {
                    let a = measured.1;
                    let sample = shared_types::messages::PoseSample {
                        x_m: measured.0.x,
                        y_m: measured.0.y,
                        z_m: measured.0.z,
                        yaw_deg: a.yaw.to_degrees(),
                        pitch_deg: a.pitch.to_degrees(),
                        roll_deg: a.roll.to_degrees(),
                        mount: shared_types::messages::MountSample::from_mount(sc.mount()),
                    };
                    telemetry.add(uav, t, &sample);
                }
                let seen = match (uav, look_alike) {
                    (Uav::Right, Some(other)) => other,
                    _ => target,
                };
                if let Some(pixel) = project((p, a), seen) {
                    current.push(Observation {
                        uav,
                        position: measured.0,
                        attitude: measured.1,
                        mount: sc.mount(),
                        pixel,
                        intrinsics: sc.intrinsics,
                    });
                }
                let ring = &mut rings[uav.index()];
                if ring
                    .last()
                    .is_none_or(|k| (k.true_pose.0 - p).norm() >= sc.keyframe_spacing_m)
                {
                    ring.push(Keyframe {
                        id,
                        t_s: t,
                        true_pose: (p, a),
                        measured,
                    });
                    if ring.len() > 6 {
                        ring.remove(0);
                    }
                }
            }
            if disturbance.measure_noise {
                let [l, r] = [Uav::Left, Uav::Right]
                    .map(|u| raise.raised(u, telemetry.measured(u).as_ref(), config.noise(u)));
                filter.set_noise(l, r).unwrap();
            }
            let mut past = Vec::new();
            for (uav, ring) in [Uav::Left, Uav::Right].into_iter().zip(&rings) {
                // The chain admits after matching: not the current frame itself.
                for k in ring.iter().rev().filter(|k| k.id < id - 1).take(3) {
                    if let Some(pixel) = project(k.true_pose, target) {
                        let (position, attitude) = k.measured;
                        let o = Observation {
                            uav,
                            position,
                            attitude,
                            mount: sc.mount(),
                            pixel,
                            intrinsics: sc.intrinsics,
                        };
                        let mut image = past_image((uav, k.id), k.t_s, o);
                        if let Some(sigma) = disturbance.rotations_sigma_deg {
                            let ck = camera_to_world(sc.camera_attitude(k.true_pose.1));
                            for (side, a) in current_true.iter().enumerate() {
                                let Some(a) = a else { continue };
                                let cc = camera_to_world(sc.camera_attitude(*a));
                                let noise = nalgebra::Vector3::from_fn(|_, _| {
                                    sigma.to_radians() * unit.sample(&mut rotation_rng)
                                });
                                let r =
                                    nalgebra::Rotation3::from_matrix_unchecked(ck.transpose() * cc)
                                        * nalgebra::Rotation3::from_scaled_axis(noise);
                                image.rotation_from[side] = Some(r.scaled_axis());
                            }
                        }
                        past.push(image);
                    }
                }
            }
            if current.len() == 2 && look_alike.is_some() {
                look_alike_taken += 1;
                if let Ok(e) = filter.update(t, [&current[0], &current[1]], &[], None) {
                    out.push((t, e, target, true_bias(t)));
                }
            } else if current.len() == 2 && past.len() == 6 {
                let mut all = current.clone();
                all.extend(past.iter().map(|image| image.observation));
                let window = crate::geolocate(&all, &config).ok();
                if let Ok(e) = filter.update(t, [&current[0], &current[1]], &past, window.as_ref())
                {
                    out.push((t, e, target, true_bias(t)));
                }
            }
            t += 1.0 / 15.0;
        }
        (out, filter)
    }

    /// A bias step is one AHRS's: a +15° step of the left yaw re-opens the left bias
    /// alone (the right's σ stays small), and the filter follows the step. (Both
    /// biases are re-opened never: both cameras' rays drifting together are something
    /// other than the target, refused; see `suite_traffic` seed 5 in docs/temporal.md.)
    #[test]
    fn a_left_bias_step_reopens_the_left_bias_alone() {
        let sc = SyntheticScenario::default();
        let step = Disturbance {
            left_bias_step: Some((12.0, 15.0)),
            ..Default::default()
        };
        for seed in 0..4 {
            let end_errors = |d| {
                let (run, _) = fly_keyframes(&sc, EstimatorConfig::default(), 24.0, 700 + seed, d);
                let (_, e, _, b) = run.last().cloned().expect("estimates");
                [0, 1].map(|i| (e.estimate.yaw_bias[i] - b[i]).to_degrees())
            };
            let calm = end_errors(Disturbance::default());
            let (run, _) = fly_keyframes(&sc, EstimatorConfig::default(), 24.0, 700 + seed, step);
            let reopened: Vec<_> = run.iter().filter(|r| r.1.reopened).collect();
            let stepped = end_errors(step);
            eprintln!(
                "seed {seed}: re-opened at {:?} s; bias errors at 24 s {stepped:.1?}° (no step: {calm:.1?}°)",
                reopened.iter().map(|r| r.0).collect::<Vec<_>>()
            );
            // Followed within 3 s: re-opened then, or (the bias rate taking part of
            // the step) the left bias back within 3° of the truth by 15 s.
            let left_error_at_15 = run
                .iter()
                .filter(|r| (14.0..15.0).contains(&r.0))
                .map(|r| (r.1.estimate.yaw_bias[0] - r.3[0]).to_degrees().abs())
                .fold(f64::INFINITY, f64::min);
            eprintln!("seed {seed}: left bias error at 14–15 s {left_error_at_15:.1}°");
            assert!(
                reopened.iter().any(|r| (12.0..15.0).contains(&r.0)) || left_error_at_15 < 3.0,
                "seed {seed}: not re-opened within 3 s, the left bias {left_error_at_15:.1}° off at 15 s"
            );
            for (t, e, _, _) in &reopened {
                let c = &e.estimate.covariance;
                assert!(
                    c[(2, 2)].sqrt().to_degrees() > 5.0 && c[(3, 3)].sqrt().to_degrees() < 2.0,
                    "seed {seed} at {t:.2} s: bias σ {:.1}° / {:.1}°",
                    c[(2, 2)].sqrt().to_degrees(),
                    c[(3, 3)].sqrt().to_degrees()
                );
            }
            // The step followed: 12 s later both biases as good as without it (±1.5°).
            assert!(
                (0..2).all(|i| stepped[i].abs() < calm[i].abs() + 1.5),
                "seed {seed}: {stepped:.1?}° against {calm:.1?}°"
            );
        }
    }

    /// Eq. (34)'s biases drift at 0.2°/s. A bias that only random-walks trails such a
    /// drift: its error sat on the far side of the drift's sign in 15 of 16 UAV-runs
    /// of the chain, |error| 1.1° against a stated 0.75° (docs/temporal.md "The biases'
    /// drift"). With a rate state per bias the lag after 10 s is half the frozen
    /// rate's and the error as large as stated (z² near 1); frozen at zero, the lag
    /// and an overconfident bias show on the same flights (8 seeds, synthetic rays with
    /// keyframes reused as the chain does).
    #[test]
    fn the_biases_follow_eq34s_drift() {
        let sc = SyntheticScenario::default();
        let rate = match sc.bias {
            BiasModel::Eq34 { rate_deg_s, .. } => rate_deg_s,
            _ => unreachable!("the default scenario's biases are eq. (34)'s"),
        };
        assert!(rate > 0.0);
        // (mean error along the drift in °, mean z² of the bias errors) after 10 s.
        let lag = |config: EstimatorConfig| {
            let (mut along, mut z2, mut n) = (0.0, 0.0, 0usize);
            for seed in 0..8 {
                let (run, _) = fly_keyframes(&sc, config, 20.0, 900 + seed, Disturbance::default());
                for (_, e, _, b) in run.iter().filter(|r| r.0 >= 10.0) {
                    for (i, truth) in b.iter().enumerate() {
                        let err = e.estimate.yaw_bias[i] - truth;
                        let var = e.estimate.covariance[(2 + i, 2 + i)];
                        along += err.to_degrees();
                        z2 += err * err / var;
                        n += 1;
                    }
                }
            }
            (along / n as f64, z2 / n as f64)
        };
        let with_rate = lag(EstimatorConfig::default());
        let mut frozen = EstimatorConfig::default();
        frozen.temporal.initial_bias_rate_sigma_deg_per_s = 1e-9;
        frozen.temporal.bias_rate_walk_deg_per_s_per_sqrt_s = 1e-9;
        let without = lag(frozen);
        eprintln!(
            "bias error along the drift, z²: with the rate {:.2}°, {:.2}; frozen {:.2}°, {:.2}",
            with_rate.0, with_rate.1, without.0, without.1
        );
        // Measured: −0.52°, z² 0.78 with the rate (σ 0.2°/s; −0.35° at 0.3°/s);
        // −1.03°, z² 2.17 frozen.
        assert!(
            without.0 < -0.6 && with_rate.0.abs() < without.0.abs() - 0.3,
            "lag with the rate {with_rate:.2?}, frozen {without:.2?}"
        );
        assert!(
            (0.5..1.5).contains(&with_rate.1) && without.1 > 1.5,
            "z² with the rate {with_rate:.2?}, frozen {without:.2?}"
        );
    }

    /// The rates are held at zero for a UAV whose attitude error is correlated (its
    /// Gauss–Markov yaw state carries the slow wander; `bias_rate`), and free for one
    /// whose attitude error is white, each UAV on its own.
    #[test]
    fn a_correlated_attitude_error_holds_that_uavs_bias_rate() {
        let mut config = EstimatorConfig::default();
        let white = bias_rate(&config, Uav::Left);
        assert_eq!(
            white,
            (0.2f64.to_radians(), 0.01f64.to_radians()),
            "the defaults"
        );
        config.noise_right.attitude_tau_s = 10.0;
        assert_eq!(bias_rate(&config, Uav::Left), white);
        assert_eq!(bias_rate(&config, Uav::Right), (0.0, 0.0));
        // Held: after a flight the right rate and its variance are still zero, the
        // left rate has moved.
        let sc = SyntheticScenario::default();
        let (run, filter) = fly_keyframes_with(&sc, config, 12.0, 1, Disturbance::default());
        assert!(!run.is_empty());
        let snap = filter.snapshot();
        let core = snap.core.expect("started");
        let n = core.state.len();
        let var = |i: usize| core.covariance[i * n + i];
        assert_eq!((core.state[RATE + 1], var(RATE + 1)), (0.0, 0.0));
        assert!(core.state[RATE] != 0.0 && var(RATE) > 0.0);
    }

    /// A look-alike 12 m from the target taken by the right camera for two
    /// geolocations (sets without past images, as the chain's unchecked pairs are) is
    /// not a bias step: the right bias is not re-opened, the filter does not turn it
    /// toward the look-alike, and a second later the estimate is where it would have
    /// been without the look-alike (`suite_traffic` seed 3: a re-opening on the
    /// look-alike's first frame turned the right bias 40°).
    #[test]
    fn a_look_alike_for_two_frames_does_not_reopen_a_bias() {
        let sc = SyntheticScenario::default();
        let taken = Disturbance {
            right_look_alike: Some((12.0, 2, [6.0, 10.0])),
            ..Default::default()
        };
        for seed in 0..4 {
            let fly = |d| fly_keyframes(&sc, EstimatorConfig::default(), 14.0, 900 + seed, d).0;
            let (calm, run) = (fly(Disturbance::default()), fly(taken));
            let reopened: Vec<f64> = run
                .iter()
                .filter(|r| r.1.reopened && r.0 >= 12.0)
                .map(|r| r.0)
                .collect();
            assert!(
                reopened.is_empty(),
                "seed {seed}: re-opened at {reopened:?} s"
            );
            let at = |run: &Flight, t: f64| {
                run.iter()
                    .find(|r| r.0 >= t)
                    .map(|r| {
                        let e = &r.1.estimate;
                        let h = (e.position - r.2).xy().norm();
                        let b = [0, 1].map(|i| (e.yaw_bias[i] - r.3[i]).to_degrees().abs());
                        (h, b)
                    })
                    .unwrap_or_else(|| panic!("seed {seed}: no estimate after {t} s"))
            };
            let (h, b) = at(&run, 13.0);
            let (h0, b0) = at(&calm, 13.0);
            eprintln!(
                "seed {seed}: at 13 s {h:.2} m, biases {b:.1?}° (without it {h0:.2} m, {b0:.1?}°)"
            );
            assert!(h < h0 + 0.5, "seed {seed}: {h:.2} m against {h0:.2} m");
            assert!(
                (0..2).all(|i| b[i] < b0[i] + 1.0),
                "seed {seed}: {b:.1?}° against {b0:.1?}°"
            );
        }
    }

    /// A target that is suddenly 20 m behind its predicted track (both cameras' rays
    /// drift together) is not explained by turning the biases: the filter coasts for
    /// `LOST_AFTER_S`, then re-acquires the position with the biases kept, and is on
    /// the target again (error within 3 m and 3 h_acc) a second later.
    #[test]
    fn a_target_that_jumps_is_reacquired_with_the_biases_kept() {
        let sc = SyntheticScenario::default();
        let jump = Disturbance {
            target_jump: Some((12.0, [-20.0, 0.0])),
            ..Default::default()
        };
        for seed in 0..3 {
            let (calm, _) = fly_keyframes(
                &sc,
                EstimatorConfig::default(),
                20.0,
                800 + seed,
                Disturbance::default(),
            );
            let (run, _) = fly_keyframes(&sc, EstimatorConfig::default(), 20.0, 800 + seed, jump);
            let bias_err = |r: &(f64, TemporalEstimate, Point3<f64>, [f64; 2])| {
                [0, 1].map(|i| (r.1.estimate.yaw_bias[i] - r.3[i]).to_degrees())
            };
            let reacquired: Vec<f64> = run
                .iter()
                .filter(|r| r.1.reopened && r.0 >= 12.0)
                .map(|r| r.0)
                .collect();
            eprintln!("seed {seed}: re-opened at {reacquired:?} s");
            let at = *reacquired
                .first()
                .unwrap_or_else(|| panic!("seed {seed}: not re-acquired"));
            assert!(
                (12.0 + LOST_AFTER_S..12.0 + LOST_AFTER_S + 1.0).contains(&at),
                "seed {seed}: re-acquired at {at:.2} s"
            );
            // Once the running means have left their region (a few frames), no ray is
            // taken until the re-acquisition.
            for r in run.iter().filter(|r| (12.2..at).contains(&r.0)) {
                assert_eq!(
                    r.1.quality,
                    Quality::Coasting,
                    "seed {seed} at {:.2} s",
                    r.0
                );
                assert_eq!(
                    r.1.rays_used, 0,
                    "seed {seed} at {:.2} s: took rays while lost",
                    r.0
                );
            }
            for r in run.iter().filter(|r| r.0 >= at + 1.0) {
                let err = ((r.1.estimate.position - r.2).xy()).norm();
                let c = &r.1.estimate.covariance;
                let h_acc = (c[(0, 0)] + c[(1, 1)]).sqrt();
                assert!(
                    err < 3.0 && err < 3.0 * h_acc,
                    "seed {seed} at {:.2} s: {err:.2} m off, h_acc {h_acc:.2} m",
                    r.0
                );
            }
            // The biases were not turned to explain the jump.
            let (end, end_calm) = (
                bias_err(run.last().unwrap()),
                bias_err(calm.last().unwrap()),
            );
            eprintln!("seed {seed}: bias errors at 20 s {end:.1?}° (no jump: {end_calm:.1?}°)");
            assert!(
                (0..2).all(|i| end[i].abs() < end_calm[i].abs() + 1.0),
                "seed {seed}: {end:.1?}° against {end_calm:.1?}°"
            );
            let worst_during = run
                .iter()
                .filter(|r| r.0 >= 12.0)
                .map(|r| bias_err(r).map(f64::abs).into_iter().fold(0.0, f64::max))
                .fold(0.0, f64::max);
            assert!(
                worst_during < 5.0,
                "seed {seed}: bias error up to {worst_during:.1}°"
            );
        }
    }

    /// (mean NEES over x, y and z; share of estimates beyond 3σ) of `runs` flights.
    fn calibration_with_keyframes(
        sc: &SyntheticScenario,
        config: EstimatorConfig,
        runs: u64,
    ) -> (f64, f64) {
        let (mut sum, mut n, mut gross) = (0.0, 0usize, 0usize);
        let mut undecided = Vec::new();
        for seed in 0..runs {
            let (run, open) = fly_keyframes(sc, config, 20.0, 500 + seed, Disturbance::default());
            if open > 1 {
                undecided.push((seed, open));
            }
            for (_, e, truth, _) in run {
                let (nees, beyond) = nees_of(&e, truth);
                sum += nees;
                gross += usize::from(beyond);
                n += 1;
            }
        }
        assert!(n as u64 > 150 * runs, "{n} estimates");
        // The start's 49 hypotheses are down to at most two by 20 s, three for a camera
        // looking ahead. Tempered weights (`likelihood_temper` 0.3) part more slowly
        // than Bayes' rule, which decided every run here by 20 s: two are still open
        // in 2 of the 24 runs 100 m up and 14 of the 24 250 m up; 45° ahead two in 2
        // of the 12 and three in 1 (seed 6). A camera 45° ahead reads its yaw worse
        // than its body's 2° (the body's pitch and roll errors turn into it: ~2.8°,
        // `Observation::pose_without_error`), so its rays tell the biases apart more
        // slowly (with those errors taken as 2° on the equivalent angles, at most two
        // were open). Their spread is in the stated accuracy, so the NEES counts it.
        eprintln!("(seed, hypotheses) still open at 20 s: {undecided:?}");
        let most_open = if sc.camera_tilt_deg == 0.0 { 2 } else { 3 };
        assert!(
            undecided.iter().all(|(_, open)| *open <= most_open),
            "(seed, hypotheses) still open at 20 s: {undecided:?}"
        );
        (sum / n as f64, gross as f64 / n as f64)
    }

    /// A mean NEES inside its χ² `region` and at most 1 % of estimates beyond 3σ.
    fn assert_calibrated(label: &str, nees: f64, gross: f64, region: (f64, f64)) {
        eprintln!(
            "{label}: mean NEES {nees:.2} (region {:.2}–{:.2}), beyond 3σ {:.1} %",
            region.0,
            region.1,
            100.0 * gross
        );
        assert!(
            (region.0..=region.1).contains(&nees),
            "{label}: mean NEES {nees:.2} outside {region:?}"
        );
        assert!(gross <= 0.01, "{label}: {:.1} % beyond 3σ", 100.0 * gross);
    }

    /// Issue #23: a recording does not say how noisy its GPS and AHRS are, and the
    /// filter is told the paper's Table 2 σ's (3 m, 2°). On sensors twice as noisy
    /// (6 m, 4°; 12 runs of 20 s) it claimed twice the accuracy it had: NEES 13.2,
    /// 27 % beyond 3σ. With the σ's raised to what the pose samples show
    /// (`telemetry_noise`): NEES 3.6, 1.1 % beyond 3σ, as calibrated as a filter told
    /// the sensors' true σ's (3.3, 1.6 %).
    #[test]
    fn noisier_sensors_than_configured_are_measured_from_the_telemetry() {
        let noisy = SyntheticScenario {
            noise: shared_types::nav_noise::NavNoise::isotropic(6.0, 4.0),
            ..Default::default()
        };
        let runs = 12u64;
        let calibration = |config: EstimatorConfig, measure_noise: bool| {
            let (mut sum, mut n, mut gross) = (0.0, 0usize, 0usize);
            for seed in 0..runs {
                let d = Disturbance {
                    measure_noise,
                    ..Default::default()
                };
                let (run, _) = fly_keyframes(&noisy, config, 20.0, 900 + seed, d);
                for (_, e, truth, _) in run {
                    let (nees, beyond) = nees_of(&e, truth);
                    sum += nees;
                    gross += usize::from(beyond);
                    n += 1;
                }
            }
            (sum / n as f64, gross as f64 / n as f64)
        };
        let default = EstimatorConfig::default();
        let (told, told_gross) = calibration(default, false);
        let (measured, measured_gross) = calibration(default, true);
        let truth = EstimatorConfig {
            noise_left: crate::NoiseModel::isotropic(6.0, 4.0, 1.0),
            noise_right: crate::NoiseModel::isotropic(6.0, 4.0, 1.0),
            ..default
        };
        let (true_nees, true_gross) = calibration(truth, false);
        eprintln!(
            "told 3 m / 2° on 6 m / 4° sensors: NEES {told:.2}, beyond 3σ {:.1} %; \
             σ's from the telemetry: NEES {measured:.2}, beyond 3σ {:.1} %; \
             told 6 m / 4°: NEES {true_nees:.2}, beyond 3σ {:.1} %",
            100.0 * told_gross,
            100.0 * measured_gross,
            100.0 * true_gross
        );
        assert!(told > 4.5 && told_gross > 0.1, "told: NEES {told:.2}");
        // χ²(3 × 12 runs) / 12 at 2.5 % and 97.5 %: 1.78 and 4.54. Beyond 3σ: as
        // often as with the true σ's told (1.6 % here: these sensors' 4° at 100 m).
        assert!((1.78..=4.54).contains(&measured), "NEES {measured:.2}");
        assert!(
            measured_gross <= true_gross.max(0.01) + 0.005,
            "{measured_gross}"
        );
    }

    /// Issue #23: the start is honest from its first estimate. Each start hypothesis
    /// begins where the current pair's rays meet; its first update applied those rays
    /// again, and the first 1.5 s claimed more than they knew (48 runs 80 m up, 40 m
    /// apart, where one pair's altitude is worth ±12 m: z error / v_acc rms 1.27,
    /// 0.5 % beyond 3σ; counted once, 1.15 and 0.2 %, with a 15 m position σ). Since
    /// the start's position prior is the meeting point's own covariance (`start_prior`,
    /// calibrated alone: z rms 0.99) the first 1.5 s measure 1.23 and 0.5 %, and
    /// counting the pair twice 1.37 and 2.2 %: the past images' first update still
    /// claims ~20 % more altitude than it has (not found).
    #[test]
    fn the_start_counts_the_current_pair_once() {
        let sc = SyntheticScenario {
            keyframe_spacing_m: 8.0,
            altitude_agl_m: 80.0,
            uav_separation_m: 40.0,
            ..Default::default()
        };
        let (mut z2, mut beyond, mut n) = (0.0, 0usize, 0usize);
        for seed in 0..48u64 {
            let (run, _) = fly_keyframes(
                &sc,
                EstimatorConfig::default(),
                6.0,
                700 + seed,
                Disturbance::default(),
            );
            let t0 = run[0].0;
            for (_, e, truth, _) in run.into_iter().take_while(|r| r.0 - t0 < 1.5) {
                let (_, gross) = nees_of(&e, truth);
                z2 += ((e.estimate.position.z - truth.z) / e.estimate.altitude_std_error_m).powi(2);
                beyond += usize::from(gross);
                n += 1;
            }
        }
        let rms = (z2 / n as f64).sqrt();
        let share = beyond as f64 / n as f64;
        eprintln!(
            "first 1.5 s: z error / v_acc rms {rms:.2}, beyond 3σ {:.1} %",
            100.0 * share
        );
        assert!(n > 48 * 15, "{n} estimates");
        assert!(rms < 1.3, "z error / v_acc rms {rms:.2}");
        assert!(share < 0.01, "{:.1} % beyond 3σ", 100.0 * share);
    }

    /// Issue #23: the Monte Carlo's `suite_high_hd` (250 m up, 120 m apart, 1280×720)
    /// was 13 % beyond 3σ, and its seed 1 17 m low all run. Exact rays with keyframes
    /// reused as the chain reuses them show the same without any image: one filter
    /// started at one point slides along the valley of near-equal fits and claims a few
    /// metres 30–140 m off (24 runs: NEES 133, 17 % beyond 3σ; 100 m up: 6.7, 4.5 %).
    /// With the start's bias hypotheses (`bias_hypotheses` = 7, `hypotheses.rs`; 3 as
    /// well) both are calibrated. χ²(72) at 2.5 % and 97.5 %: 51.0 and 96.6, over 24 runs.
    #[test]
    fn nees_is_within_its_chi2_region_with_keyframes_reused_100_and_250_m_up() {
        let default = SyntheticScenario {
            keyframe_spacing_m: 8.0,
            ..Default::default()
        };
        let high = SyntheticScenario {
            altitude_agl_m: 250.0,
            uav_separation_m: 120.0,
            speed_mps: 11.0,
            turn_rate_deg_s: 0.0,
            image_width: 1280,
            image_height: 720,
            intrinsics: Intrinsics::new(1108.5, 1108.5, 639.5, 359.5),
            ..default
        };
        let runs = 24;
        let region = (51.0 / runs as f64, 96.6 / runs as f64);
        let hypotheses = EstimatorConfig::default();
        assert_eq!(hypotheses.temporal.bias_hypotheses, 7);
        for (label, sc) in [("100 m", default), ("250 m", high)] {
            let (nees, gross) = calibration_with_keyframes(&sc, hypotheses, runs);
            assert_calibrated(label, nees, gross, region);
        }
        // One filter (`bias_hypotheses = 1`) on the 250 m flight: the failure above.
        let mut one = EstimatorConfig::default();
        one.temporal.bias_hypotheses = 1;
        let (nees, gross) = calibration_with_keyframes(&high, one, runs);
        eprintln!(
            "250 m, one filter: mean NEES {nees:.2}, beyond 3σ {:.1} %",
            100.0 * gross
        );
        assert!(
            nees > 2.0 * region.1 && gross > 0.05,
            "{nees:.2}, {gross:.3}"
        );
    }

    /// The synthetic flight under the simulator's consumer GPS errors (Table 2's σ's,
    /// keyframes every 8 m) and the filter told so.
    fn consumer_gps_flight() -> (SyntheticScenario, EstimatorConfig) {
        use shared_types::nav_noise::{NavErrorModel, NavNoise};
        let sc = SyntheticScenario {
            keyframe_spacing_m: 8.0,
            noise: NavNoise {
                model: NavErrorModel::consumer_gps(),
                ..NavNoise::isotropic(3.0, 2.0)
            },
            ..Default::default()
        };
        let mut config = EstimatorConfig::default();
        told_consumer_gps(&mut config);
        (sc, config)
    }

    /// Issue #23 item 7: under correlated navigation errors (the simulator's consumer
    /// GPS: τ 120 s + 0.3 m, AHRS τ 10 s + 0.2°, σ's of Table 2), told so, the filter
    /// is as honest as under white ones, from the first estimate. Estimating the
    /// correlated tilts and cloning keyframes as if taken now gave NEES 7.8 and 12.9 %
    /// beyond 3σ over the first 24 of these runs (`considered_tilts`, the slots' lag).
    #[test]
    fn nees_is_within_its_chi2_region_under_correlated_navigation_errors() {
        let (sc, config) = consumer_gps_flight();
        // 48 runs: over 24 the share beyond 3σ moved by 0.4 points with the temper
        // (one seed late in its run near 3σ at every temper); over these 48 it is 0.25 %
        // at 1 and 0.61 % at 0.3. χ²(144) at 2.5 % and 97.5 %: 112.7 and 179.1.
        let runs = 48;
        let region = (112.7 / runs as f64, 179.1 / runs as f64);
        let (nees, gross) = calibration_with_keyframes(&sc, config, runs);
        assert_calibrated("Gauss–Markov", nees, gross, region);
    }

    /// The drift monitor's variance: white innovations keep α/(2 − α) (factor 1); an
    /// innovation that is all a pose error held from one geolocation to the next
    /// (ρ = 1) spreads the running mean (1 + β)/(1 − β) = 19 times wider; a share
    /// that is new each time (ρ = 0) adds nothing.
    #[test]
    fn the_running_means_variance_takes_the_correlated_share_in() {
        let beta = 1.0 - DRIFT_ALPHA;
        assert_eq!(persistence_factor(&[]), 1.0);
        assert!((persistence_factor(&[(1.0, 1.0)]) - (1.0 + beta) / (1.0 - beta)).abs() < 1e-6);
        assert!((persistence_factor(&[(0.5, 0.0)]) - 1.0).abs() < 1e-12);
        let half = persistence_factor(&[(0.25, 0.99), (0.25, 0.99)]);
        let c = beta * 0.99;
        assert!(
            (half - (0.5 + 0.5 * (1.0 + c) / (1.0 - c))).abs() < 1e-9,
            "{half}"
        );
        // Shares over 1 (a linearisation's rounding) are scaled to 1.
        assert!((persistence_factor(&[(0.8, 1.0), (0.8, 1.0)]) - 19.0).abs() < 1e-6);
    }

    /// The synthetic flights under the default Gauss–Markov errors (as the calibration
    /// test above), told so, on the target all along: the drift monitor neither
    /// re-opens a bias nor makes the filter coast. With the running mean judged
    /// against its variance for independent innovations (α/(2 − α)) these 8 flights
    /// re-opened a bias at 28 estimates (none coasted here; in the chain both UAVs'
    /// means left together and 12–34 % of a correlated run's estimates coasted): the
    /// correlated tilts are the same error from one geolocation to the next and the
    /// mean cannot average them away (docs/temporal.md "The drift monitor under
    /// correlated errors").
    #[test]
    fn correlated_errors_raise_no_false_alarm() {
        let (sc, config) = consumer_gps_flight();
        let (mut coasting, mut reopened, mut n) = (0, 0, 0);
        for seed in 0..8 {
            let (run, _) = fly_keyframes(&sc, config, 20.0, 500 + seed, Disturbance::default());
            for (_, e, _, _) in &run {
                n += 1;
                coasting += usize::from(e.quality == Quality::Coasting);
                reopened += usize::from(e.reopened);
            }
        }
        eprintln!("{n} estimates: {coasting} coasting, {reopened} re-opened");
        assert!(n > 8 * 150, "{n} estimates");
        assert_eq!((coasting, reopened), (0, 0), "coasting, re-opened");
    }

    /// A 15° step of the left yaw under Gauss–Markov errors: near nadir it is within
    /// the correlated tilts' spread for the monitor, so the update alone follows it.
    /// 12 s later the left bias is within 8° of the truth on every flight (measured
    /// 2.6–5.9°; 1.2–6.4° when false alarms re-opened it, before the running mean's
    /// variance took the correlated share in).
    #[test]
    fn a_bias_step_is_followed_under_correlated_errors() {
        let (sc, config) = consumer_gps_flight();
        let step = Disturbance {
            left_bias_step: Some((12.0, 15.0)),
            ..Default::default()
        };
        for seed in 0..4 {
            let (run, _) = fly_keyframes(&sc, config, 24.0, 700 + seed, step);
            let (_, e, _, b) = run.last().cloned().expect("estimates");
            let left = (e.estimate.yaw_bias[0] - b[0]).to_degrees();
            let (_, before, _, b0) = run
                .iter()
                .rev()
                .find(|r| r.0 < 12.0)
                .cloned()
                .expect("estimates before the step");
            let left_before = (before.estimate.yaw_bias[0] - b0[0]).to_degrees();
            eprintln!("seed {seed}: left bias error {left_before:+.1}° before the step, {left:+.1}° 12 s after it");
            assert!(
                left.abs() < 8.0,
                "seed {seed}: left bias {left:+.1}° off 12 s after the step"
            );
        }
    }

    /// Two cameras looking 45° ahead of nadir, trailing the vehicle by 100 m (the
    /// `gimbal` scene's geometry), meet along their lines of sight where opposite biases
    /// put them, tens to hundreds of metres from the target. Exact rays with keyframes
    /// reused, the AHRS's errors on the body (12 runs): with each start hypothesis at an
    /// independent 15 m position σ the filter claimed 10–20 m while 100–400 m off (NEES
    /// 111, 66 % beyond 3σ); with the meeting point's own prior (`start_prior`) 10.7 and
    /// 14 %; with the grid split where that point curves 5.0 and 0.3 %; with the bias
    /// walk in the keyframes' yaws 3.8 and 0 %. χ²(36) at 2.5 % and 97.5 % over 12 runs:
    /// 1.78–4.54.
    #[test]
    fn an_oblique_start_is_honest() {
        let sc = SyntheticScenario {
            keyframe_spacing_m: 8.0,
            camera_tilt_deg: 45.0,
            trail_m: 100.0,
            ..Default::default()
        };
        let runs = 12;
        let region = (21.34 / runs as f64, 54.44 / runs as f64);
        let (nees, gross) = calibration_with_keyframes(&sc, EstimatorConfig::default(), runs);
        assert_calibrated("45° ahead", nees, gross, region);
    }

    /// The images' measure of each past camera's rotation from the current ones
    /// (`PastImage::rotation_from`, matching's homographies: ~0.1° where the AHRS reads
    /// each attitude to 2°) ties the images' attitude errors together: on exact rays
    /// with keyframes reused, nadir 100 m up and 45° ahead, the horizontal error after
    /// 10 s falls and the stated accuracy stays true (NEES in its χ² region, at most
    /// 1 % beyond 3σ) when the filter is told the rotations' σ; told the defaults
    /// (0.5 / 0.3° and 4 / 0.8° across, for the chain's homographies reused ~30
    /// times) it is cautious, never over-confident. Turned off (`rotation_sigma_deg`
    /// 0), the rotations are ignored. With the AHRS's error taken off the Euler angles
    /// of a 45° camera's equivalent attitude (before `Observation::pose_without_error`
    /// took it off the body's) the defaults gave NEES 2.15 there: the two errors
    /// cancelled; with it the defaults give 1.76, the σ told 2.12.
    #[test]
    fn relative_rotations_from_the_images_tie_the_attitude_errors_together() {
        let nadir = SyntheticScenario {
            keyframe_spacing_m: 8.0,
            ..Default::default()
        };
        let oblique = SyntheticScenario {
            camera_tilt_deg: 45.0,
            trail_m: 100.0,
            ..nadir
        };
        let runs = 12u64;
        let region = (21.34 / runs as f64, 54.44 / runs as f64);
        let with = Disturbance {
            rotations_sigma_deg: Some(0.1),
            ..Default::default()
        };
        let mut off = EstimatorConfig::default();
        off.temporal.rotation_sigma_deg = [0.0; 2];
        off.temporal.cross_rotation_sigma_deg = [0.0; 2];
        let mut told = EstimatorConfig::default();
        told.temporal.rotation_sigma_deg = [0.1; 2];
        told.temporal.cross_rotation_sigma_deg = [0.1; 2];
        for (label, sc) in [("nadir", nadir), ("45° ahead", oblique)] {
            let mut figures = Vec::new();
            // Turned off, the rotations must change nothing: two seeds show it (each
            // run is the same to the last bit), the other configurations fly all.
            for (config, disturbance, seeds) in [
                (EstimatorConfig::default(), Disturbance::default(), runs),
                (told, with, runs),
                (off, with, 2),
                (EstimatorConfig::default(), with, runs),
            ] {
                let (mut h, mut nh, mut nees, mut gross, mut n) =
                    (0.0, 0usize, 0.0, 0usize, 0usize);
                let mut first_two = Vec::new();
                for seed in 0..seeds {
                    let (run, _) = fly_keyframes(&sc, config, 20.0, 900 + seed, disturbance);
                    for (t, e, truth, _) in run {
                        let (v, beyond) = nees_of(&e, truth);
                        nees += v;
                        gross += usize::from(beyond);
                        n += 1;
                        if seed < 2 {
                            first_two.push(e.estimate.position);
                        }
                        if t >= 10.0 {
                            h += (e.estimate.position.x - truth.x)
                                .hypot(e.estimate.position.y - truth.y);
                            nh += 1;
                        }
                    }
                }
                figures.push((
                    h / nh as f64,
                    nees / n as f64,
                    gross as f64 / n as f64,
                    first_two,
                ));
            }
            eprintln!(
                "{label}: (horizontal MAE after 10 s, NEES, beyond 3σ) without rotations, with (σ told), with (the defaults): {:?}",
                [0, 1, 3].map(|i| (figures[i].0, figures[i].1, figures[i].2))
            );
            let [(without, _, _, ref without_two), (with_mae, nees, gross, _), (_, _, _, ref off_two), (_, nees_defaults, gross_defaults, _)] =
                figures[..]
            else {
                unreachable!()
            };
            assert_calibrated(label, nees, gross, region);
            assert!(
                nees_defaults <= region.1 && gross_defaults <= 0.01,
                "{label}: told the default σ's, NEES {nees_defaults:.2}, {:.1} % beyond 3σ",
                100.0 * gross_defaults
            );
            assert!(
                with_mae < 0.8 * without,
                "{label}: {with_mae:.3} m against {without:.3} m"
            );
            assert!(
                !off_two.is_empty() && off_two == without_two,
                "{label}: off is not the same as without rotations"
            );
        }
    }

    /// The other UAV's rotations are inflated under a correlated attitude error of
    /// either UAV, and only those: the same UAV's, and every one under white errors,
    /// keep the configured σ's (`CORRELATED_CROSS_ROTATION_INFLATION`).
    #[test]
    fn the_other_uavs_rotations_are_inflated_under_correlated_attitude_errors() {
        let white = EstimatorConfig::default();
        let tc = white.temporal;
        let (l, r) = (Uav::Left, Uav::Right);
        assert_eq!(rotation_sigma_deg(&white, l, l), tc.rotation_sigma_deg);
        assert_eq!(
            rotation_sigma_deg(&white, l, r),
            tc.cross_rotation_sigma_deg
        );
        let inflated = tc.cross_rotation_sigma_deg.map(|s| 3.0 * s);
        let mut one = white;
        one.noise_right.attitude_tau_s = 10.0;
        for (current, past) in [(l, r), (r, l)] {
            assert_eq!(rotation_sigma_deg(&one, current, past), inflated);
        }
        assert_eq!(rotation_sigma_deg(&one, r, r), tc.rotation_sigma_deg);
        assert_eq!(rotation_sigma_deg(&one, l, l), tc.rotation_sigma_deg);
        // A correlated position error alone is not an attitude error.
        let mut position = white;
        position.noise_left.position_tau_s = 120.0;
        assert_eq!(
            rotation_sigma_deg(&position, l, r),
            tc.cross_rotation_sigma_deg
        );
    }

    /// A tempered likelihood (0.3) weighs the start's hypotheses more slowly than
    /// Bayes' rule (1): on the same oblique flight (45° ahead, where the start's valley
    /// is long) more of them stay open, and their spread stays in the stated accuracy.
    /// A temper outside (0, 1] is refused.
    #[test]
    fn a_tempered_likelihood_keeps_the_hypotheses_open_longer() {
        let sc = SyntheticScenario {
            camera_tilt_deg: 45.0,
            trail_m: 100.0,
            ..Default::default()
        };
        let with_temper = |temper| {
            let mut c = EstimatorConfig::default();
            c.temporal.likelihood_temper = temper;
            c
        };
        let mut filters =
            [with_temper(1.0), with_temper(0.3)].map(|c| TemporalEstimator::new(c).unwrap());
        let mut open = [0usize; 2];
        let mut h_acc = [0.0f64; 2];
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let mut next_id = 0u64;
        let mut t = 5.0;
        while t < 9.0 {
            if let Ok(trial) = sc.trial(t, 4, &mut rng) {
                let o = &trial.observations;
                let past: Vec<PastImage> = o[2..]
                    .iter()
                    .map(|ob| {
                        next_id += 1;
                        past_image((ob.uav, next_id), t, *ob)
                    })
                    .collect();
                let window = crate::geolocate(o, &EstimatorConfig::default()).ok();
                for (k, f) in filters.iter_mut().enumerate() {
                    if let Ok(e) = f.update(t, [&o[0], &o[1]], &past, window.as_ref()) {
                        open[k] += f.hypotheses();
                        let c = e.estimate.covariance;
                        h_acc[k] += (c[(0, 0)] + c[(1, 1)]).sqrt();
                    }
                }
            }
            t += 0.1;
        }
        assert!(open[0] > 0, "the filter never started");
        assert!(open[1] > open[0], "hypotheses open over the run: {open:?}");
        assert!(h_acc[1] > h_acc[0], "summed h_acc: {h_acc:?}");
        for (temper, ok) in [
            (0.0, false),
            (-0.1, false),
            (0.3, true),
            (1.0, true),
            (1.5, false),
            (f64::NAN, false),
            (f64::INFINITY, false),
        ] {
            let mut c = EstimatorConfig::default();
            c.temporal.likelihood_temper = temper;
            let r = TemporalEstimator::new(c);
            assert_eq!(r.is_ok(), ok, "temper {temper}");
            if let Err(e) = r {
                assert!(e.to_string().contains("likelihood_temper"), "{e}");
            }
        }
    }

    /// A cap on the start's hypotheses outside 1–400 is refused with the key's name.
    #[test]
    fn the_start_hypotheses_cap_is_checked() {
        for (cap, ok) in [(0, false), (1, true), (49, true), (400, true), (401, false)] {
            let mut config = EstimatorConfig::default();
            config.temporal.max_start_hypotheses = cap;
            match TemporalEstimator::new(config) {
                Ok(_) => assert!(ok, "cap {cap} taken"),
                Err(e) => {
                    assert!(!ok, "cap {cap} refused: {e}");
                    assert!(e.to_string().contains("max_start_hypotheses"), "{e}");
                }
            }
        }
    }

    /// The estimator told both UAVs' errors are the simulator's consumer GPS and AHRS
    /// (`NavErrorModel::consumer_gps`).
    fn told_consumer_gps(config: &mut EstimatorConfig) {
        use shared_types::nav_noise::NavErrorModel;
        let NavErrorModel::GaussMarkov {
            position_tau_s,
            position_jitter_m,
            attitude_tau_s,
            attitude_jitter_deg,
        } = NavErrorModel::consumer_gps()
        else {
            unreachable!("consumer_gps is a Gauss–Markov model")
        };
        for n in [&mut config.noise_left, &mut config.noise_right] {
            n.position_tau_s = position_tau_s;
            n.position_jitter_m = position_jitter_m;
            n.attitude_tau_s = attitude_tau_s;
            n.attitude_jitter_deg = attitude_jitter_deg;
        }
    }

    /// Under correlated camera tilts (GPS and attitude Gauss–Markov errors, 250 m up,
    /// 120 m apart, exact rays), Jacobians taken halfway between the prediction and
    /// the iterate (`jacobian_at = "midpoint"`) leave a smaller altitude offset and a
    /// truer v_acc than at the iterate (docs/temporal.md, "Still open" 2; the same 24
    /// seeds for both).
    #[test]
    fn midpoint_jacobians_shrink_the_correlated_altitude_offset() {
        use shared_types::nav_noise::NavErrorModel;
        let mut sc = SyntheticScenario {
            keyframe_spacing_m: 8.0,
            altitude_agl_m: 250.0,
            uav_separation_m: 120.0,
            sigma_pixel_px: 0.5,
            image_width: 1280,
            image_height: 720,
            intrinsics: Intrinsics::new(1108.5, 1108.5, 639.5, 359.5),
            ..Default::default()
        };
        sc.noise = NavNoise::isotropic(3.0, 2.0);
        sc.noise.model = NavErrorModel::consumer_gps();
        let figures = |at: JacobianAt| {
            let mut config = EstimatorConfig::default();
            config.temporal.jacobian_at = at;
            told_consumer_gps(&mut config);
            for n in [&mut config.noise_left, &mut config.noise_right] {
                n.sigma_pixel_px = 0.7;
            }
            let (mut sum, mut n, mut inside) = (0.0, 0usize, 0usize);
            for seed in 0..24 {
                let (run, _) =
                    fly_keyframes(&sc, config, 20.0, 5000 + seed, Disturbance::default());
                for (t, e, truth, _) in run.iter().filter(|r| r.0 >= 10.0) {
                    let dz = e.estimate.position.z - truth.z;
                    assert!(dz.is_finite(), "{at:?} seed {seed} t {t}");
                    sum += dz;
                    n += 1;
                    inside += usize::from(dz.abs() <= e.estimate.altitude_std_error_m);
                }
            }
            assert!(n > 0, "{at:?}: no estimate after 10 s");
            (sum / n as f64, inside as f64 / n as f64)
        };
        let (offset_iterate, inside_iterate) = figures(JacobianAt::Iterate);
        let (offset_midpoint, inside_midpoint) = figures(JacobianAt::Midpoint);
        eprintln!(
            "mean vertical error after 10 s: iterate {offset_iterate:+.1} m ({:.0} % inside v_acc), \
             midpoint {offset_midpoint:+.1} m ({:.0} %)",
            100.0 * inside_iterate,
            100.0 * inside_midpoint
        );
        assert!(
            offset_midpoint.abs() < 0.5 * offset_iterate.abs(),
            "midpoint {offset_midpoint:+.1} m vs iterate {offset_iterate:+.1} m"
        );
        assert!(inside_midpoint > inside_iterate);
    }

    /// `jacobian_at = "auto"` (the default) is `iterate` under a white error model and
    /// `midpoint` under a correlated one, estimate for estimate; and the two differ, so
    /// the comparison can fail.
    #[test]
    fn auto_jacobians_follow_the_error_model() {
        use shared_types::nav_noise::NavErrorModel;
        let mut sc = SyntheticScenario {
            keyframe_spacing_m: 8.0,
            sigma_pixel_px: 0.5,
            ..Default::default()
        };
        sc.noise = NavNoise::isotropic(3.0, 2.0);
        sc.noise.model = NavErrorModel::consumer_gps();
        let track = |at: JacobianAt, correlated: bool| {
            let mut config = EstimatorConfig::default();
            config.temporal.jacobian_at = at;
            if correlated {
                told_consumer_gps(&mut config);
            }
            let (run, _) = fly_keyframes(&sc, config, 12.0, 7, Disturbance::default());
            let positions: Vec<[f64; 3]> =
                run.iter().map(|r| r.1.estimate.position.into()).collect();
            assert!(!positions.is_empty(), "{at:?}: no estimate");
            positions
        };
        for correlated in [false, true] {
            let auto = track(JacobianAt::Auto, correlated);
            let iterate = track(JacobianAt::Iterate, correlated);
            let midpoint = track(JacobianAt::Midpoint, correlated);
            assert_ne!(iterate, midpoint, "correlated {correlated}");
            let expected = if correlated { midpoint } else { iterate };
            assert_eq!(auto, expected, "correlated {correlated}");
        }
    }
}
