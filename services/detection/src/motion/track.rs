//! A camera's track of the target among the movers: its two predictions, its
//! velocities (α–β filters) and its colour, and which mover it takes ([`pick`]).

use super::config::MotionConfig;
use super::movers::Mover;
use crate::prediction_gate::Gate;

/// One camera's track: where the target was last found, that place carried since by
/// the ground's motion, and how it moves per frame in the image and against the ground.
/// Two predictions, because either model can fail: a ground homography fitted to roofs
/// carries a point wrongly, and a camera that slews moves everything in the image.
#[derive(Debug, Clone, Copy)]
pub(super) struct Track {
    pub(super) centre: [f64; 2],
    pub(super) carried: [f64; 2],
    pub(super) image_velocity: [f64; 2],
    pub(super) ground_velocity: [f64; 2],
    pub(super) missed: u32,
    /// Frames held by its patch since the last mover (`hold.rs`): its place against
    /// the ground is still the last mover's, carried, plus its own motion since.
    pub(super) held: u32,
    /// Its mean colour, smoothed, and when the track started: a mover matches when
    /// it is near either (wrong picks cannot drag the colour away from the target's).
    pub(super) bgr: [f64; 3],
    pub(super) first_bgr: [f64; 3],
    /// The camera's ground was lost since it was last found (the camera jumped): the
    /// predictions no longer hold, so it is looked for as at an acquisition.
    pub(super) blind: bool,
}

impl Track {
    pub(super) fn new(m: &Mover) -> Self {
        Self {
            centre: m.centre,
            carried: m.centre,
            image_velocity: [0.0; 2],
            ground_velocity: [0.0; 2],
            missed: 0,
            held: 0,
            bgr: m.bgr,
            first_bgr: m.bgr,
            blind: false,
        }
    }

    /// How far `m`'s colour is from the track's (now or at its start, the nearer): the
    /// largest channel difference.
    pub(super) fn colour_distance(&self, m: &Mover) -> f64 {
        let far = |bgr: &[f64; 3]| {
            (0..3)
                .map(|i| (bgr[i] - m.bgr[i]).abs())
                .fold(0.0, f64::max)
        };
        far(&self.bgr).min(far(&self.first_bgr))
    }

    /// Where it should be in this frame: in the image, and against the ground. Over a
    /// gap the velocities carry it at most [`EXTRAPOLATE_FRAMES`] frames: a velocity is
    /// a guess, and a long extrapolation of a wrong one runs away.
    pub(super) fn predictions(&self) -> [[f64; 2]; 2] {
        let n = (self.missed + 1).min(EXTRAPOLATE_FRAMES) as f64;
        let g = n + self.held as f64;
        [
            [
                self.centre[0] + n * self.image_velocity[0],
                self.centre[1] + n * self.image_velocity[1],
            ],
            [
                self.carried[0] + g * self.ground_velocity[0],
                self.carried[1] + g * self.ground_velocity[1],
            ],
        ]
    }

    /// Found again as `m`. An α–β filter: each velocity moves by [`VELOCITY_GAIN`] of
    /// the prediction's miss, clamped to [`MAX_VELOCITY_STEP_PX`], and only when the
    /// previous frame found it as a mover too (a pick after a gap, or after frames
    /// held by its patch, may be wrong, and would teach a wrong velocity that the next
    /// gap extrapolates).
    pub(super) fn found(&mut self, m: &Mover) {
        let at = m.centre;
        if self.missed == 0 && self.held == 0 {
            let [image, ground] = self.predictions();
            let step =
                |miss: f64| VELOCITY_GAIN * miss.clamp(-MAX_VELOCITY_STEP_PX, MAX_VELOCITY_STEP_PX);
            for i in 0..2 {
                self.image_velocity[i] += step(at[i] - image[i]);
                self.ground_velocity[i] += step(at[i] - ground[i]);
            }
        }
        for i in 0..3 {
            self.bgr[i] = 0.8 * self.bgr[i] + 0.2 * m.bgr[i];
        }
        self.centre = at;
        self.carried = at;
        self.missed = 0;
        self.held = 0;
        self.blind = false;
    }

    /// Held at `at` by its patch (no mover: `hold.rs`): its place in the image is the
    /// patch's; against the ground it is still the last mover's place carried plus
    /// its ground velocity (a patch that slid with the ground leaves that); the
    /// velocities and colour stay as the last mover taught them.
    pub(super) fn held(&mut self, at: [f64; 2]) {
        self.centre = at;
        self.missed = 0;
        self.held += 1;
    }
}

/// A coasting track's velocities carry it at most this many frames.
const EXTRAPOLATE_FRAMES: u32 = 8;
/// The α–β filter's velocity gain, and the largest miss it learns from, pixels.
const VELOCITY_GAIN: f64 = 0.3;
const MAX_VELOCITY_STEP_PX: f64 = 4.0;

/// Why a mover was taken, or none.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Pick {
    None,
    /// Inside the gate, or near the track.
    Followed(Mover),
    /// A new track: nearest the designation or the image centre, of the named colour.
    Acquired(Mover),
}

/// Which of `movers` is the target: inside the geolocation filter's `gate` when there
/// is one; else near `track` (within `track_radius_px` of either prediction, growing
/// to 3× after `coast_frames` missed frames, `acquire_radius_px` after the camera went
/// blind) and of its colour; with neither, nearest `designated` (within
/// `acquire_radius_px`) or the image `centre`, of the colour `acquire_bgr` names.
pub(super) fn pick(
    c: &MotionConfig,
    movers: &[Mover],
    gate: Option<Gate>,
    track: Option<&Track>,
    designated: Option<[f64; 2]>,
    centre: [f64; 2],
) -> Pick {
    let distance = |m: &Mover, p: [f64; 2]| (m.centre[0] - p[0]).hypot(m.centre[1] - p[1]);
    let nearest = |p: [f64; 2], keep: &dyn Fn(&Mover) -> bool| {
        movers
            .iter()
            .filter(|m| keep(m))
            .min_by(|a, b| distance(a, p).total_cmp(&distance(b, p)))
            .copied()
    };
    match (gate, track) {
        (Some(g), _) => {
            nearest(g.centre, &|m| g.contains(m.centre)).map_or(Pick::None, Pick::Followed)
        }
        (None, Some(t)) => {
            // The radius holds for `coast_frames`, then grows to 3× (a car beside the
            // target must not take over after a few frames' gap).
            let coast = c.coast_frames.max(1);
            let radius = if t.blind {
                c.acquire_radius_px
            } else {
                c.track_radius_px
                    * (1.0 + t.missed.saturating_sub(coast) as f64 / coast as f64).min(3.0)
            };
            let [a, b] = t.predictions();
            let to_track = |m: &Mover| distance(m, a).min(distance(m, b));
            movers
                .iter()
                .filter(|m| to_track(m) <= radius && t.colour_distance(m) <= c.colour_tolerance)
                .min_by(|x, y| to_track(x).total_cmp(&to_track(y)))
                .copied()
                .map_or(Pick::None, Pick::Followed)
        }
        (None, None) => {
            let named = |m: &Mover| {
                c.acquire_bgr.is_none_or(|bgr| {
                    (0..3).all(|i| (bgr[i] - m.bgr[i]).abs() <= 2.0 * c.colour_tolerance)
                })
            };
            let m = match designated {
                Some(at) => nearest(at, &|m| named(m) && distance(m, at) <= c.acquire_radius_px),
                None => nearest(centre, &named),
            };
            m.map_or(Pick::None, Pick::Acquired)
        }
    }
}
