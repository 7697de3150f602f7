//! The navigation state's white noise, measured from the pose samples themselves
//! (issue #23: a stated 1σ that stays true when a recording's sensors are noisier than
//! the configured noise model says).
//!
//! The paper's Q1–Q3 (eq. 8–10) are the σ's of the measured positions and attitudes.
//! `[estimator.noise_*]` states them (the paper's Table 2 values by default), but a
//! recording does not say how noisy its GPS and AHRS are. White noise shows in the
//! samples: a vehicle's true position and attitude are smooth over a frame period, so
//! each sample's distance from the chord through its two neighbours,
//! `r = y₁ − (h₂ y₀ + h₁ y₂) / (h₁ + h₂)` (h the time steps), is the noise alone
//! (its variance is σ² (1 + (h₁² + h₂²) / (h₁ + h₂)²), 1.5 σ² for even steps) plus
//! half the acceleration times h₁ h₂ (at 30 Hz and 3 m/s², 2 mm; at 100°/s² of
//! yaw, 0.06°).
//!
//! **What is done with it: the configured σ is raised, never lowered.** A slowly
//! wandering error (a consumer GPS's Gauss–Markov wander) does not show in the chord
//! at all, only its jitter does; a GPS sampled at 5 Hz and interpolated to the frames
//! shows almost nothing. So a measured σ below the configured one says nothing about
//! the configured one, while one above it says the filter would be over-confident
//! with the configured σ. A channel is raised once its σ̂ over the last [`WINDOW`]
//! chords (n of them) is beyond the configured σ by [`BOUND_SE`] standard errors
//! (σ̂ / (1 + 5 / √n) above it: σ̂'s relative standard error is 1/√n here, measured
//! with the chords' overlap; 5 of them, since the test is repeated with every sample
//! and σ̂ is skewed upwards over few chords). From then on, until the stream starts
//! over, that channel's σ is σ̂ itself (the best estimate once the configured value
//! is refuted; kept raised so that it does not flip back and forth at the threshold),
//! never below the configured σ. On sensors as noisy as configured nothing is raised
//! (the configuration is used as it is, bit for bit); on sensors twice as noisy the
//! σ's are raised within 2–3 s at 30 Hz. Where the configured error model is
//! correlated (`position_tau_s` or `attitude_tau_s` > 0) the white part is its jitter,
//! and the Gauss–Markov error's own frame-to-frame change is taken out first
//! ([`TelemetryNoise::raised`]).
//!
//! σ̂ is robust: the root mean square of the chords within 3.5 σ of the median
//! absolute chord's σ (1.4826 × the MAD), corrected for the cut, so that a step in
//! the attitude (a simulator's unfiltered pitch step, an AHRS re-initialisation)
//! or a GPS jump moves it little. A gap longer than [`MAX_STEP_S`] starts the
//! chord over.

use crate::config::NoiseModel;
use shared_types::conventions::Uav;
use shared_types::messages::{PoseNoise, PoseSample};
use std::collections::VecDeque;

/// Chords kept per channel (30 s at 30 Hz).
pub const WINDOW: usize = 900;
/// Chords before any σ is raised: below that the bound is too loose to matter.
pub const MIN_CHORDS: usize = 20;
/// Longest time step a chord spans, seconds: over longer steps the vehicle's own
/// acceleration is no longer negligible (½ · 3 m/s² · 0.25² s² ≈ 0.1 m).
pub const MAX_STEP_S: f64 = 0.25;
/// Standard errors by which σ̂ must exceed the configured σ before it is taken.
pub const BOUND_SE: f64 = 5.0;
/// The chords kept for the mean square: within this many MAD-σ's.
const CUT: f64 = 3.5;
/// E[r² | |r| ≤ 3.5σ] / σ² for a normal r: the cut's correction.
const CUT_VARIANCE: f64 = 0.993_89;

/// The six channels of a pose sample: x, y, z (m), yaw, pitch, roll (degrees).
const CHANNELS: usize = 6;

/// The measured white noise of one UAV's pose samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredNoise {
    /// σ̂ of x, y, z (m) and yaw, pitch, roll (degrees).
    pub sigma: [f64; CHANNELS],
    /// Chords it is measured over.
    pub chords: usize,
    /// The chords' mean time step, seconds.
    pub mean_step_s: f64,
}

impl MeasuredNoise {
    /// σ̂ / (1 + 5 / √n) per channel: a channel is raised once this is above its
    /// configured σ.
    pub fn lower_bound(&self) -> [f64; CHANNELS] {
        let k = 1.0 + BOUND_SE / (self.chords as f64).sqrt();
        self.sigma.map(|s| s / k)
    }

    /// As the set message carries it.
    pub fn to_msg(&self) -> PoseNoise {
        PoseNoise {
            sigma: self.sigma,
            mean_step_s: self.mean_step_s,
            chords: self.chords.min(u32::MAX as usize) as u32,
            _reserved: 0,
        }
    }

    /// From the set message: `None` when not measured yet ([`MIN_CHORDS`]) or not
    /// finite (a message is input: nothing in it is trusted to be well formed).
    pub fn from_msg(msg: &PoseNoise) -> Option<Self> {
        let finite = msg.sigma.iter().all(|s| s.is_finite() && *s >= 0.0)
            && msg.mean_step_s.is_finite()
            && msg.mean_step_s > 0.0;
        (finite && msg.chords as usize >= MIN_CHORDS).then_some(Self {
            sigma: msg.sigma,
            chords: msg.chords as usize,
            mean_step_s: msg.mean_step_s,
        })
    }
}

#[derive(Debug, Clone, Default)]
struct Series {
    /// The last (up to) two samples: (t, channels).
    last: VecDeque<(f64, [f64; CHANNELS])>,
    /// Normalised chords per channel (each ~ N(0, σ²) for white noise).
    chords: [VecDeque<f64>; CHANNELS],
    /// Each chord's mean time step, seconds.
    steps: VecDeque<f64>,
    /// The measurement over the chords so far (from [`MIN_CHORDS`] on).
    latest: Option<MeasuredNoise>,
}

/// Per UAV, the chords of its pose samples (see the module's documentation).
#[derive(Debug, Clone, Default)]
pub struct TelemetryNoise {
    series: [Series; 2],
    /// The absolute chords of one channel, sorted in part for their median: kept, so
    /// that a frame's measurement allocates nothing.
    scratch: Vec<f64>,
}

/// Per UAV and channel, whether its σ̂ has refuted the configured σ: raised from then
/// on (the module's documentation).
#[derive(Debug, Clone, Default)]
pub struct NoiseRaise {
    latched: [[bool; CHANNELS]; 2],
}

/// `a − b` for angles in degrees, in (−180, 180].
fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    if d > 180.0 {
        d - 360.0
    } else {
        d
    }
}

impl TelemetryNoise {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one pose sample of `uav` taken at `t_s`. A sample not after the last one
    /// (the same image seen again) or not finite is ignored.
    ///
    /// A mounted camera's attitude is measured as its body's (`Mount::body_attitude`):
    /// the AHRS errs on the body's angles, which the filter's σ_att is of
    /// (`Observation::pose_without_error`), and a gimbal's own turns are no noise.
    pub fn add(&mut self, uav: Uav, t_s: f64, pose: &PoseSample) {
        let mount = pose.mount.mount();
        let [yaw, pitch, roll] = if mount.is_nadir() {
            [pose.yaw_deg, pose.pitch_deg, pose.roll_deg]
        } else {
            let body = mount.body_attitude(pose.attitude());
            [body.yaw, body.pitch, body.roll].map(f64::to_degrees)
        };
        let y = [pose.x_m, pose.y_m, pose.z_m, yaw, pitch, roll];
        if !t_s.is_finite() || y.iter().any(|v| !v.is_finite()) {
            return;
        }
        let s = &mut self.series[uav.index()];
        if let Some((t_last, _)) = s.last.back() {
            if t_s <= *t_last {
                return;
            }
            if t_s - t_last > MAX_STEP_S {
                s.last.clear();
            }
        }
        s.last.push_back((t_s, y));
        if s.last.len() > 3 {
            s.last.pop_front();
        }
        if s.last.len() < 3 {
            return;
        }
        let (t0, y0) = s.last[0];
        let (t1, y1) = s.last[1];
        let (t2, y2) = s.last[2];
        let (h1, h2) = (t1 - t0, t2 - t1);
        let scale = (1.0 + (h1 * h1 + h2 * h2) / ((h1 + h2) * (h1 + h2))).sqrt();
        s.steps.push_back(0.5 * (h1 + h2));
        if s.steps.len() > WINDOW {
            s.steps.pop_front();
        }
        for c in 0..CHANNELS {
            // Angles about the middle sample, so that a wrap through ±180° is no step.
            let (a, b) = if c >= 3 {
                (angle_diff(y0[c], y1[c]), angle_diff(y2[c], y1[c]))
            } else {
                (y0[c] - y1[c], y2[c] - y1[c])
            };
            let r = -(h2 * a + h1 * b) / (h1 + h2);
            let q = &mut s.chords[c];
            q.push_back(r / scale);
            if q.len() > WINDOW {
                q.pop_front();
            }
        }
        let n = s.chords[0].len();
        s.latest = (n >= MIN_CHORDS).then(|| MeasuredNoise {
            sigma: std::array::from_fn(|c| robust_sigma(&s.chords[c], &mut self.scratch)),
            chords: n,
            mean_step_s: s.steps.iter().sum::<f64>() / s.steps.len() as f64,
        });
    }

    /// The measured noise of `uav`, once it has [`MIN_CHORDS`] chords.
    pub fn measured(&self, uav: Uav) -> Option<MeasuredNoise> {
        self.series[uav.index()].latest
    }

    /// Both UAVs' measured noise as the set message carries it (`chords` 0 where not
    /// measured yet).
    pub fn to_msg(&self) -> [PoseNoise; 2] {
        [Uav::Left, Uav::Right].map(|u| self.measured(u).map(|m| m.to_msg()).unwrap_or_default())
    }
}

impl NoiseRaise {
    pub fn new() -> Self {
        Self::default()
    }

    /// `configured` with the white σ of each channel the samples have shown to be
    /// noisier raised to σ̂ (module documentation); `configured` itself when none is.
    ///
    /// Where the configured error is correlated (Gauss–Markov, stationary σ_gm, time
    /// constant τ) its own frame-to-frame change shows in the chords too: with
    /// ρ = e^(−h/τ) a chord over even steps h has the variance
    /// σ_gm² (1.5 − 2ρ + 0.5ρ²) + 1.5 σ_jitter², so that part (normalised) is taken
    /// out of σ̂² before it is compared with the jitter, and the jitter is raised to the
    /// largest remainder over the raised channels (the model has one jitter for the
    /// position and one for the attitude).
    pub fn raised(
        &mut self,
        uav: Uav,
        measured: Option<&MeasuredNoise>,
        configured: &NoiseModel,
    ) -> NoiseModel {
        let Some(m) = measured else {
            return *configured;
        };
        let h = m.mean_step_s;
        let n = configured;
        // The part of a chord's variance (normalised) a Gauss–Markov error explains.
        let gm = |sigma: f64, tau: f64| {
            if tau > 0.0 {
                let rho = (-h / tau).exp();
                sigma * sigma * (1.5 - 2.0 * rho + 0.5 * rho * rho) / 1.5
            } else {
                0.0
            }
        };
        let att = [n.sigma_yaw_deg, n.sigma_pitch_deg, n.sigma_roll_deg];
        // Per channel: (the configured white σ, the Gauss–Markov part of σ̂²).
        let model: [(f64, f64); CHANNELS] = std::array::from_fn(|c| {
            if c < 3 {
                let s = n.sigma_position_m[c];
                if n.position_tau_s > 0.0 {
                    (n.position_jitter_m, gm(s, n.position_tau_s))
                } else {
                    (s, 0.0)
                }
            } else if n.attitude_tau_s > 0.0 {
                (n.attitude_jitter_deg, gm(att[c - 3], n.attitude_tau_s))
            } else {
                (att[c - 3], 0.0)
            }
        });
        let latched = &mut self.latched[uav.index()];
        let bound = m.lower_bound();
        let mut white = [None; CHANNELS];
        for c in 0..CHANNELS {
            let (configured_white, gm_var) = model[c];
            let lb = bound[c];
            if lb * lb - gm_var > configured_white * configured_white {
                latched[c] = true;
            }
            if latched[c] {
                let measured = (m.sigma[c] * m.sigma[c] - gm_var).max(0.0).sqrt();
                white[c] = Some(measured.max(configured_white));
            }
        }
        let mut out = *n;
        let largest = |w: &[Option<f64>]| w.iter().flatten().copied().reduce(f64::max);
        if n.position_tau_s > 0.0 {
            if let Some(j) = largest(&white[..3]) {
                out.position_jitter_m = j;
            }
        } else {
            for (s, w) in out.sigma_position_m.iter_mut().zip(&white[..3]) {
                *s = w.unwrap_or(*s);
            }
        }
        if n.attitude_tau_s > 0.0 {
            if let Some(j) = largest(&white[3..]) {
                out.attitude_jitter_deg = j;
            }
        } else {
            out.sigma_yaw_deg = white[3].unwrap_or(out.sigma_yaw_deg);
            out.sigma_pitch_deg = white[4].unwrap_or(out.sigma_pitch_deg);
            out.sigma_roll_deg = white[5].unwrap_or(out.sigma_roll_deg);
        }
        out
    }
}

/// σ of chords that are N(0, σ²) but for a few outliers: the RMS of those within
/// 3.5 MAD-σ's, corrected for the cut.
fn robust_sigma(chords: &VecDeque<f64>, scratch: &mut Vec<f64>) -> f64 {
    scratch.clear();
    scratch.extend(chords.iter().map(|r| r.abs()));
    let mid = scratch.len() / 2;
    let (_, median, _) = scratch.select_nth_unstable_by(mid, f64::total_cmp);
    let mad_sigma = 1.4826 * *median;
    if mad_sigma <= 0.0 {
        return 0.0;
    }
    let cut = CUT * mad_sigma;
    let (sum, count) = chords
        .iter()
        .filter(|r| r.abs() <= cut)
        .fold((0.0, 0usize), |(s, k), r| (s + r * r, k + 1));
    if count == 0 {
        return mad_sigma;
    }
    (sum / count as f64 / CUT_VARIANCE).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A UAV's true pose at `t`: flying a curve at 10 m/s with a slow wobble.
    fn truth(t: f64) -> [f64; CHANNELS] {
        [
            10.0 * t + 2.0 * (0.3 * t).sin(),
            5.0 * (0.2 * t).cos(),
            100.0 + 0.5 * (0.5 * t).sin(),
            170.0 + 8.0 * t, // turning through ±180°
            0.3 * (2.0 * t).sin(),
            0.3 * (1.7 * t).cos(),
        ]
    }

    fn pose(y: [f64; CHANNELS]) -> PoseSample {
        PoseSample {
            x_m: y[0],
            y_m: y[1],
            z_m: y[2],
            yaw_deg: y[3],
            pitch_deg: y[4],
            roll_deg: y[5],
            mount: Default::default(),
        }
    }

    /// `configured` raised by one look at `noise`'s measurement.
    fn raise_once(noise: &TelemetryNoise, uav: Uav, configured: &NoiseModel) -> NoiseModel {
        NoiseRaise::new().raised(uav, noise.measured(uav).as_ref(), configured)
    }

    /// `seconds` of samples at `hz` with white noise σ_pos, σ_att.
    fn fly(seed: u64, hz: f64, seconds: f64, sigma_pos: f64, sigma_att: f64) -> TelemetryNoise {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let mut noise = TelemetryNoise::new();
        let frames = (seconds * hz) as usize;
        for k in 0..frames {
            let t = k as f64 / hz;
            noise.add(
                Uav::Left,
                t,
                &pose(measured(t, &mut rng, sigma_pos, sigma_att)),
            );
        }
        noise
    }

    /// The true pose at `t` with white noise σ_pos (m) and σ_att (°) added.
    fn measured(
        t: f64,
        rng: &mut rand::rngs::StdRng,
        sigma_pos: f64,
        sigma_att: f64,
    ) -> [f64; CHANNELS] {
        let p = Normal::new(0.0, sigma_pos).unwrap();
        let a = Normal::new(0.0, sigma_att).unwrap();
        let mut y = truth(t);
        for (c, v) in y.iter_mut().enumerate() {
            *v += if c < 3 { p.sample(rng) } else { a.sample(rng) };
        }
        y
    }

    #[test]
    fn white_noise_is_measured_at_its_sigma() {
        let m = fly(1, 30.0, 31.0, 3.0, 2.0).measured(Uav::Left).unwrap();
        assert_eq!(m.chords, WINDOW);
        assert!((m.mean_step_s - 1.0 / 30.0).abs() < 1e-9);
        // Through the set message and back.
        assert_eq!(MeasuredNoise::from_msg(&m.to_msg()), Some(m));
        let mut bad = m.to_msg();
        bad.sigma[2] = f64::NAN;
        assert_eq!(MeasuredNoise::from_msg(&bad), None);
        assert_eq!(MeasuredNoise::from_msg(&PoseNoise::default()), None);
        for c in 0..3 {
            assert!((m.sigma[c] / 3.0 - 1.0).abs() < 0.1, "{m:?}");
        }
        for c in 3..6 {
            assert!((m.sigma[c] / 2.0 - 1.0).abs() < 0.1, "{m:?}");
        }
        // Every second pair (the Monte Carlo's rate) measures the same.
        let m = fly(2, 15.0, 30.0, 3.0, 2.0).measured(Uav::Left).unwrap();
        assert!((m.sigma[0] / 3.0 - 1.0).abs() < 0.12, "{m:?}");
        assert!((m.sigma[3] / 2.0 - 1.0).abs() < 0.12, "{m:?}");
    }

    /// A camera 45° forward of nadir: the pose samples carry its equivalent attitude,
    /// whose yaw and roll the body's 2° errors move by ~2.8°. Measured on the body's
    /// angles (through the sample's mount) the AHRS's 2° comes back; read off the
    /// equivalent angles it would not.
    #[test]
    fn a_mounted_cameras_attitude_noise_is_measured_on_its_body() {
        let mount = shared_types::conventions::Mount::from_degrees(0.0, -45.0, 0.0);
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let (mut body, mut equivalent) = (TelemetryNoise::new(), TelemetryNoise::new());
        for k in 0..900 {
            let t = k as f64 / 30.0;
            let sample = pose(measured(t, &mut rng, 3.0, 2.0)).on_mount(mount);
            body.add(Uav::Left, t, &sample);
            let stripped = PoseSample {
                mount: Default::default(),
                ..sample
            };
            equivalent.add(Uav::Left, t, &stripped);
        }
        let (b, e) = (
            body.measured(Uav::Left).unwrap(),
            equivalent.measured(Uav::Left).unwrap(),
        );
        for c in 3..6 {
            assert!((b.sigma[c] / 2.0 - 1.0).abs() < 0.12, "{b:?}");
        }
        assert!(e.sigma[3] > 2.4 && e.sigma[5] > 2.4, "{e:?}");
    }

    /// On sensors as noisy as configured, nothing is raised on any seed at any time:
    /// the configured filter runs bit for bit.
    #[test]
    fn the_configured_noise_is_kept_when_the_samples_agree_with_it() {
        let configured = NoiseModel::default();
        for seed in 0..40 {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let mut noise = TelemetryNoise::new();
            let mut raise = NoiseRaise::new();
            for k in 0..600 {
                let t = k as f64 / 30.0;
                noise.add(Uav::Left, t, &pose(measured(t, &mut rng, 3.0, 2.0)));
                assert_eq!(
                    raise.raised(Uav::Left, noise.measured(Uav::Left).as_ref(), &configured),
                    configured,
                    "seed {seed}, t {t:.2}: {:?}",
                    noise.measured(Uav::Left)
                );
            }
        }
    }

    #[test]
    fn noisier_sensors_raise_the_sigmas() {
        let configured = NoiseModel::default();
        // Twice the configured noise: raised to σ̂ within 3 s, then within 3 standard
        // errors of the truth (±1/√n: 88 chords, then 898).
        for (seconds, tolerance) in [(3.0, 0.33), (30.0, 0.11)] {
            let noise = fly(3, 30.0, seconds, 6.0, 4.0);
            let n = raise_once(&noise, Uav::Left, &configured);
            for s in n.sigma_position_m {
                assert!((s / 6.0 - 1.0).abs() < tolerance, "{seconds} s: {n:?}");
            }
            for s in [n.sigma_yaw_deg, n.sigma_pitch_deg, n.sigma_roll_deg] {
                assert!((s / 4.0 - 1.0).abs() < tolerance, "{seconds} s: {n:?}");
            }
        }
        let noise = fly(3, 30.0, 5.0, 6.0, 4.0);
        let n = raise_once(&noise, Uav::Left, &configured);
        assert_eq!(n.sigma_pixel_px, configured.sigma_pixel_px);
        // Lower than configured: the configured σ's stay.
        let quiet = fly(4, 30.0, 30.0, 0.5, 0.3);
        assert_eq!(raise_once(&quiet, Uav::Left, &configured), configured);
        // The other UAV has no samples: its model is the configured one.
        assert_eq!(raise_once(&noise, Uav::Right, &configured), configured);
    }

    /// `seconds` at 30 Hz of a Gauss–Markov error (σ_gm, τ) plus white jitter on
    /// every channel (the position's values in m, the attitude's in degrees).
    fn fly_correlated(
        seed: u64,
        seconds: f64,
        pos: (f64, f64, f64),
        att: (f64, f64, f64),
    ) -> TelemetryNoise {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let unit = Normal::new(0.0, 1.0).unwrap();
        let h = 1.0 / 30.0;
        let mut gm = [0.0; CHANNELS];
        for (c, g) in gm.iter_mut().enumerate() {
            let (sigma, _, _) = if c < 3 { pos } else { att };
            *g = sigma * unit.sample(&mut rng);
        }
        let mut noise = TelemetryNoise::new();
        for k in 0..(seconds * 30.0) as usize {
            let t = k as f64 * h;
            let mut y = truth(t);
            for (c, v) in y.iter_mut().enumerate() {
                let (sigma, tau, jitter) = if c < 3 { pos } else { att };
                let rho = (-h / tau).exp();
                gm[c] = rho * gm[c] + sigma * (1.0 - rho * rho).sqrt() * unit.sample(&mut rng);
                *v += gm[c] + jitter * unit.sample(&mut rng);
            }
            noise.add(Uav::Left, t, &pose(y));
        }
        noise
    }

    #[test]
    fn a_correlated_models_jitter_is_what_is_raised() {
        let configured = NoiseModel {
            position_tau_s: 120.0,
            position_jitter_m: 0.3,
            attitude_tau_s: 10.0,
            attitude_jitter_deg: 0.2,
            ..Default::default()
        };
        // As configured (the simulator's `gauss_markov` model): nothing raised, though
        // the AHRS's 10 s wander adds a third to its chords' σ at 30 Hz.
        for seed in 0..10 {
            let noise = fly_correlated(seed, 20.0, (3.0, 120.0, 0.3), (2.0, 10.0, 0.2));
            assert_eq!(
                raise_once(&noise, Uav::Left, &configured),
                configured,
                "seed {seed}"
            );
        }
        // A jitter of 1 m and 0.8°: raised to it (the largest of three channels').
        let noise = fly_correlated(5, 20.0, (3.0, 120.0, 1.0), (2.0, 10.0, 0.8));
        let n = raise_once(&noise, Uav::Left, &configured);
        assert!((0.9..=1.15).contains(&n.position_jitter_m), "{n:?}");
        assert!((0.72..=0.95).contains(&n.attitude_jitter_deg), "{n:?}");
        // The stationary σ's are the configuration's.
        assert_eq!(n.sigma_position_m, configured.sigma_position_m);
        assert_eq!(n.sigma_yaw_deg, configured.sigma_yaw_deg);
    }

    /// A step in the attitude (an AHRS re-initialisation, a simulator's unfiltered
    /// pitch step) and a GPS jump move σ̂ little.
    #[test]
    fn steps_and_jumps_are_outliers() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(6);
        let mut noise = TelemetryNoise::new();
        for k in 0..600 {
            let t = k as f64 / 30.0;
            let mut y = measured(t, &mut rng, 3.0, 2.0);
            if k >= 300 {
                y[4] += 12.0;
                y[0] += 20.0;
            }
            noise.add(Uav::Left, t, &pose(y));
        }
        let m = noise.measured(Uav::Left).unwrap();
        assert!((m.sigma[0] / 3.0 - 1.0).abs() < 0.12, "{m:?}");
        assert!((m.sigma[4] / 2.0 - 1.0).abs() < 0.12, "{m:?}");
        assert_eq!(
            raise_once(&noise, Uav::Left, &NoiseModel::default()),
            NoiseModel::default()
        );
    }

    /// A GPS sampled at 5 Hz and interpolated to the frames (a flight log) shows
    /// almost no chord: nothing is raised, and nothing is lowered.
    #[test]
    fn interpolated_samples_raise_nothing() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let p = Normal::new(0.0, 3.0).unwrap();
        let fixes: Vec<f64> = (0..101)
            .map(|k| truth(k as f64 / 5.0)[0] + p.sample(&mut rng))
            .collect();
        let mut noise = TelemetryNoise::new();
        for k in 0..600 {
            let t = k as f64 / 30.0;
            let i = ((t * 5.0).floor() as usize).min(99);
            let f = t * 5.0 - i as f64;
            let mut y = truth(t);
            y[0] = fixes[i] * (1.0 - f) + fixes[i + 1] * f;
            noise.add(Uav::Left, t, &pose(y));
        }
        assert_eq!(
            raise_once(&noise, Uav::Left, &NoiseModel::default()),
            NoiseModel::default()
        );
    }

    #[test]
    fn repeated_non_finite_and_gapped_samples_are_handled() {
        let mut noise = TelemetryNoise::new();
        let y = truth(0.0);
        noise.add(Uav::Left, 0.0, &pose(y));
        noise.add(Uav::Left, 0.0, &pose(y)); // the same image again
        noise.add(Uav::Left, f64::NAN, &pose(y));
        let mut bad = y;
        bad[3] = f64::INFINITY;
        noise.add(Uav::Left, 0.1, &pose(bad));
        assert_eq!(noise.series[0].last.len(), 1);
        // A gap starts the chord over.
        noise.add(Uav::Left, 1.0, &pose(truth(1.0)));
        assert_eq!(noise.series[0].last.len(), 1);
        assert!(noise.measured(Uav::Left).is_none());
        // Angles through ±180° are no step.
        assert!((angle_diff(-179.0, 179.0) - 2.0).abs() < 1e-12);
        assert!((angle_diff(179.0, -179.0) + 2.0).abs() < 1e-12);
    }
}
