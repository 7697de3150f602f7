//! The motion detector (`[detection] kind = "motion"`): a vehicle of any colour,
//! found because it moves against the ground, from a moving camera, with no model.
//!
//! Per camera and frame:
//! 1. the frame is scaled down by `scale` and the ground's motion since the previous
//!    frame is measured (KLT + RANSAC homography, [`ground_motion`]); the camera's last
//!    `long_gap_frames` frames are kept registered onto the newest;
//! 2. the newest frame is differenced with the frames `short_gap_frames` and twice that
//!    back, warped onto it, and the blobs that differ from both are the movers
//!    ([`movers`]); parked cars and buildings do not move against the ground;
//! 3. the target is the mover nearest where it should be: inside the geolocation
//!    filter's gate when there is one, else within `track_radius_px` of this camera's
//!    track (its last position carried by the ground's motion plus its own motion);
//!    with neither, the mover nearest `acquire_px` (the operator's designation in the
//!    first frames, per camera) or, without one, nearest the image centre starts a
//!    track, of the colour `acquire_bgr` when the operator names one. Several vehicles move in a street: the centre is right for a camera that
//!    points at the target (a tracking gimbal); two nadir UAVs flying either side of
//!    it see it off-centre, beside any car that follows it, so designate it there;
//! 4. its outline and top come from the difference with the frame `long_gap_frames`
//!    back, in a window around it ([`movers::Differencer::outline`]).
//!
//! A vehicle that stops or hides disappears from the differences: the track then
//! coasts (carried by the ground, at its own last velocity); after `coast_frames`
//! frames its search radius doubles, and after four times that it is dropped and the
//! next mover is acquired as at the start.

pub mod ground_motion;
pub mod movers;

use crate::prediction_gate::Gate;
use crate::{DetectError, Detection};
use ground_motion::{scale_matrix, GroundMotion, History};
use movers::{Differencer, Mover};
use nalgebra::{Matrix3, Vector3};
use opencv::core as cv;
use opencv::prelude::*;
use serde::{Deserialize, Serialize};

/// `[detection.motion]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotionConfig {
    /// The frame is scaled down by this factor for the ground's motion and the movers
    /// (the outline is found at full resolution).
    pub scale: u32,
    /// The double difference's gap, frames (0.33 s at 30 FPS: a car at 6 m/s moves
    /// 2 m).
    pub short_gap_frames: u32,
    /// The outline's gap, frames (1 s at 30 FPS: the car has left its old place).
    pub long_gap_frames: u32,
    /// A pixel has changed when one colour channel lies this far outside the old
    /// frame's 3 × 3 range.
    pub threshold: f64,
    /// Blobs thinner than this (full-resolution pixels) are not movers (a building's
    /// parallax leaves thin strips).
    pub min_side_px: u32,
    /// Smallest mover, full-resolution pixels.
    pub min_area_px: u32,
    /// How far from the track's prediction the target may be, pixels.
    pub track_radius_px: f64,
    /// Frames the track coasts without the target before its radius doubles (and
    /// four times that before it is dropped).
    pub coast_frames: u32,
    /// Where the target is when the detector first looks (frame `2 ×
    /// short_gap_frames` of each camera: it needs that many frames behind it), per
    /// camera (left, right), full-resolution pixels: the operator's designation. The
    /// mover nearest it within `acquire_radius_px` starts the track. None: the mover
    /// nearest the image centre, at any distance. It serves once; a track dropped later
    /// is looked for where it was (or at [`MotionDetector::designate`]'s pixel).
    pub acquire_px: Option<[[f64; 2]; 2]>,
    pub acquire_radius_px: f64,
    /// The target's colour (BGR, 0–255) as the operator names it ("the silver car"):
    /// a track starts only on a mover whose mean colour is within 2 ×
    /// `colour_tolerance` of it in every channel (a mover's mean mixes its roof with
    /// its darker sides). None: any colour.
    pub acquire_bgr: Option<[f64; 3]>,
    /// A mover is the track's only if its mean colour is within this of the track's
    /// in every channel (a white car beside a silver one is not it).
    pub colour_tolerance: f64,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            scale: 2,
            short_gap_frames: 10,
            long_gap_frames: 30,
            threshold: 30.0,
            min_side_px: 4,
            min_area_px: 32,
            track_radius_px: 30.0,
            coast_frames: 15,
            acquire_px: None,
            acquire_radius_px: 60.0,
            acquire_bgr: None,
            colour_tolerance: 25.0,
        }
    }
}

impl MotionConfig {
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=8).contains(&self.scale) {
            return Err(format!("scale {} outside 1..=8", self.scale));
        }
        if self.short_gap_frames == 0 || self.long_gap_frames < self.short_gap_frames {
            return Err("short_gap_frames must be ≥ 1 and long_gap_frames ≥ it".into());
        }
        if 2 * self.short_gap_frames.max(self.long_gap_frames) > 240 {
            return Err("the gaps keep more than 240 frames".into());
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.threshold)
            || self.threshold > 255.0
            || !positive(self.track_radius_px)
            || !positive(self.acquire_radius_px)
            || !positive(self.colour_tolerance)
        {
            return Err(
                "threshold must be in (0, 255]; track_radius_px, acquire_radius_px and colour_tolerance > 0".into(),
            );
        }
        if self
            .acquire_px
            .is_some_and(|a| a.iter().flatten().any(|v| !v.is_finite()))
        {
            return Err("acquire_px must be finite".into());
        }
        if self
            .acquire_bgr
            .is_some_and(|c| c.iter().any(|v| !(0.0..=255.0).contains(v)))
        {
            return Err("acquire_bgr must be three values in 0..=255".into());
        }
        Ok(())
    }
}

/// What the motion detector did since the last [`MotionDetector::take_counts`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MotionCounts {
    /// Movers found, summed over frames.
    pub movers: u64,
    /// Frames whose ground motion could not be measured (the history restarts).
    pub no_ground: u64,
    /// Tracks started (no gate, no track: the mover nearest the centre).
    pub acquired: u64,
    /// Tracks dropped after 4 × `coast_frames` frames without the target.
    pub track_lost: u64,
}

/// One camera's track: where the target was last found, that place carried since by
/// the ground's motion, and how it moves per frame in the image and against the ground.
/// Two predictions, because either model can fail: a ground homography fitted to roofs
/// carries a point wrongly, and a camera that slews moves everything in the image.
#[derive(Debug, Clone, Copy)]
struct Track {
    centre: [f64; 2],
    carried: [f64; 2],
    image_velocity: [f64; 2],
    ground_velocity: [f64; 2],
    missed: u32,
    /// Its mean colour, smoothed, and when the track started: a mover matches when
    /// it is near either (wrong picks cannot drag the colour away from the target's).
    bgr: [f64; 3],
    first_bgr: [f64; 3],
    /// The camera's ground was lost since it was last found (the camera jumped): the
    /// predictions no longer hold, so it is looked for as at an acquisition.
    blind: bool,
}

impl Track {
    fn new(m: &Mover) -> Self {
        Self {
            centre: m.centre,
            carried: m.centre,
            image_velocity: [0.0; 2],
            ground_velocity: [0.0; 2],
            missed: 0,
            bgr: m.bgr,
            first_bgr: m.bgr,
            blind: false,
        }
    }

    /// How far `m`'s colour is from the track's (now or at its start, the nearer): the
    /// largest channel difference.
    fn colour_distance(&self, m: &Mover) -> f64 {
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
    fn predictions(&self) -> [[f64; 2]; 2] {
        let n = (self.missed + 1).min(EXTRAPOLATE_FRAMES) as f64;
        [
            [
                self.centre[0] + n * self.image_velocity[0],
                self.centre[1] + n * self.image_velocity[1],
            ],
            [
                self.carried[0] + n * self.ground_velocity[0],
                self.carried[1] + n * self.ground_velocity[1],
            ],
        ]
    }

    /// Found again as `m`. An α–β filter: each velocity moves by [`VELOCITY_GAIN`] of
    /// the prediction's miss, clamped to [`MAX_VELOCITY_STEP_PX`], and only when the
    /// previous frame found it too (a pick after a gap may be wrong, and would teach a
    /// wrong velocity that the next gap extrapolates).
    fn found(&mut self, m: &Mover) {
        let at = m.centre;
        if self.missed == 0 {
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
        self.blind = false;
    }
}

/// A coasting track's velocities carry it at most this many frames.
const EXTRAPOLATE_FRAMES: u32 = 8;
/// The α–β filter's velocity gain, and the largest miss it learns from, pixels.
const VELOCITY_GAIN: f64 = 0.3;
const MAX_VELOCITY_STEP_PX: f64 = 4.0;

#[derive(Default)]
struct Camera {
    ground: GroundMotion,
    history: Option<History>,
    small: cv::Mat,
    grey: cv::Mat,
    previous: Option<(cv::Mat, cv::Mat)>,
    track: Option<Track>,
    /// Where to acquire when there is no track (the designation), once.
    designated: Option<[f64; 2]>,
    frames: u64,
}

pub struct MotionDetector {
    config: MotionConfig,
    cameras: [Camera; 2],
    differencer: Differencer,
    movers: Vec<Mover>,
    counts: MotionCounts,
}

impl MotionDetector {
    pub fn new(config: MotionConfig) -> Result<Self, DetectError> {
        config.validate().map_err(DetectError::Config)?;
        let mut cameras: [Camera; 2] = Default::default();
        if let Some(at) = config.acquire_px {
            for (cam, at) in cameras.iter_mut().zip(at) {
                cam.designated = Some(at);
            }
        }
        Ok(Self {
            config,
            cameras,
            differencer: Differencer::default(),
            movers: Vec::with_capacity(64),
            counts: MotionCounts::default(),
        })
    }

    /// The target in `camera`'s (0 = left, 1 = right) BGR `frame`, if it moves;
    /// `gate`: the geolocation filter's prediction in this frame.
    pub fn detect(
        &mut self,
        camera: usize,
        frame: &cv::Mat,
        gate: Option<Gate>,
    ) -> Result<Option<Detection>, DetectError> {
        crate::check_bgr(frame)?;
        let c = self.config;
        let cam = self
            .cameras
            .get_mut(camera)
            .ok_or_else(|| DetectError::Config(format!("camera {camera} is not 0 or 1")))?;
        let s = c.scale as f64;
        let small_size = cv::Size::new(
            (frame.cols() / c.scale as i32).max(1),
            (frame.rows() / c.scale as i32).max(1),
        );
        if c.scale == 1 {
            frame.copy_to(&mut cam.small)?;
        } else {
            opencv::imgproc::resize(
                frame,
                &mut cam.small,
                small_size,
                0.0,
                0.0,
                opencv::imgproc::INTER_AREA,
            )?;
        }
        opencv::imgproc::cvt_color_def(&cam.small, &mut cam.grey, opencv::imgproc::COLOR_BGR2GRAY)?;
        let to_full = scale_matrix(s);
        let to_small = to_full.try_inverse().unwrap_or_else(Matrix3::identity);
        cam.frames += 1;
        let seed = (camera as u64) << 40 | cam.frames;
        let history = cam.history.get_or_insert_with(|| {
            History::new(2 * c.short_gap_frames.max(c.long_gap_frames) as usize)
        });
        let step = cam.ground.step(&cam.grey, seed)?;
        // The ground's motion since the previous frame, full-resolution pixels.
        let moved = match (step, &cam.previous) {
            (Some(h_small), Some((small, full))) => {
                let h = to_full * h_small * to_small;
                history.push(small, full, h)?;
                Some(h)
            }
            _ => {
                if cam.previous.is_some() {
                    self.counts.no_ground += 1;
                }
                history.clear();
                if let Some(t) = &mut cam.track {
                    t.blind = true;
                }
                None
            }
        };
        match &mut cam.previous {
            Some((small, full)) => {
                cam.small.copy_to(small)?;
                frame.copy_to(full)?;
            }
            None => cam.previous = Some((cam.small.try_clone()?, frame.try_clone()?)),
        }
        // The track's last place, carried by the ground's motion (kept when the ground
        // was not measured this frame).
        if let (Some(t), Some(h)) = (&mut cam.track, moved) {
            let p = h * Vector3::new(t.carried[0], t.carried[1], 1.0);
            if p.z.abs() > 1e-9 {
                t.carried = [p.x / p.z, p.y / p.z];
            }
        }
        let k = c.short_gap_frames as usize;
        let (Some(near), Some(far)) = (history.back(k), history.back(2 * k)) else {
            // Not enough frames behind (the start, or the ground was lost): the track
            // waits, and a lost one is looked for where it was.
            return Ok(None);
        };
        let small_h = |h: &Matrix3<f64>| to_small * h * to_full;
        self.differencer.movers(
            &cam.small,
            (&near.small, &small_h(&near.to_now)),
            (&far.small, &small_h(&far.to_now)),
            c.threshold,
            (
                (c.min_side_px as f64 / s).ceil() as i32,
                (c.min_area_px as f64 / (s * s)).ceil() as i32,
            ),
            &to_full,
            &mut self.movers,
        )?;
        self.counts.movers += self.movers.len() as u64;
        let centre = [
            (frame.cols() as f64 - 1.0) / 2.0,
            (frame.rows() as f64 - 1.0) / 2.0,
        ];
        let distance = |m: &Mover, p: [f64; 2]| (m.centre[0] - p[0]).hypot(m.centre[1] - p[1]);
        let nearest = |p: [f64; 2], keep: &dyn Fn(&Mover) -> bool| {
            self.movers
                .iter()
                .filter(|m| keep(m))
                .min_by(|a, b| distance(a, p).total_cmp(&distance(b, p)))
                .copied()
        };
        let picked = match (gate, cam.track) {
            (Some(g), _) => nearest(g.centre, &|m| g.contains(m.centre)),
            (None, Some(t)) => {
                // The radius holds for `coast_frames`, then grows to 3× (a car beside
                // the target must not take over after a few frames' gap).
                let coast = c.coast_frames.max(1);
                let radius = if t.blind {
                    c.acquire_radius_px
                } else {
                    c.track_radius_px
                        * (1.0 + t.missed.saturating_sub(coast) as f64 / coast as f64).min(3.0)
                };
                let [a, b] = t.predictions();
                let to_track = |m: &Mover| distance(m, a).min(distance(m, b));
                self.movers
                    .iter()
                    .filter(|m| to_track(m) <= radius && t.colour_distance(m) <= c.colour_tolerance)
                    .min_by(|x, y| to_track(x).total_cmp(&to_track(y)))
                    .copied()
            }
            (None, None) => {
                let named = |m: &Mover| {
                    c.acquire_bgr.is_none_or(|bgr| {
                        (0..3).all(|i| (bgr[i] - m.bgr[i]).abs() <= 2.0 * c.colour_tolerance)
                    })
                };
                let m = match cam.designated {
                    Some(at) => {
                        nearest(at, &|m| named(m) && distance(m, at) <= c.acquire_radius_px)
                    }
                    None => nearest(centre, &named),
                };
                if m.is_some() {
                    self.counts.acquired += 1;
                    cam.designated = None;
                }
                m
            }
        };
        // The outline from `long_gap_frames` back, or where that frame did not see the
        // mover (the camera turned), from `2 × short_gap_frames` back; the blob itself
        // when neither outlines it.
        let mut outlined = picked;
        if let Some(m) = picked {
            for gap in [c.long_gap_frames, 2 * c.short_gap_frames] {
                let Some(old) = history.back(gap as usize) else {
                    continue;
                };
                let outline = self.differencer.outline(
                    frame,
                    (&old.full, &old.to_now),
                    &m,
                    c.threshold,
                    c.min_area_px as i32 / 2,
                )?;
                if outline.is_some() {
                    outlined = outline;
                    break;
                }
            }
        }
        match (outlined, &mut cam.track) {
            (Some(m), Some(t)) => t.found(&m),
            (Some(m), None) => cam.track = Some(Track::new(&m)),
            (None, Some(t)) if t.missed < 4 * c.coast_frames => t.missed += 1,
            (None, Some(t)) => {
                // Dropped: the next mover near where it should be is taken for it.
                self.counts.track_lost += 1;
                cam.designated = Some(t.predictions()[0]);
                cam.track = None;
            }
            (None, None) => {}
        }
        Ok(outlined.map(|m| Detection {
            bbox: m.bbox,
            centre: m.centre,
            confidence: 1.0,
        }))
    }

    /// The operator points at the target in `camera`'s newest frame: the track is
    /// dropped and the mover nearest `px` (within `acquire_radius_px`) is acquired.
    pub fn designate(&mut self, camera: usize, px: [f64; 2]) {
        if let Some(cam) = self.cameras.get_mut(camera) {
            cam.track = None;
            cam.designated = Some(px);
        }
    }

    /// The movers of the last frame looked at (for diagnostics: `bench --bin detectors
    /// --trace`).
    pub fn last_movers(&self) -> &[Mover] {
        &self.movers
    }

    /// `camera`'s track: its two predictions for the next frame (image, ground) and
    /// the frames it has missed (for diagnostics).
    pub fn track_state(&self, camera: usize) -> Option<([[f64; 2]; 2], u32)> {
        let t = self.cameras.get(camera)?.track?;
        Some((t.predictions(), t.missed))
    }

    /// The counts since the last call, and starts again from zero.
    pub fn take_counts(&mut self) -> MotionCounts {
        std::mem::take(&mut self.counts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frame `k` of a 640 × 480 synthetic flight: a blurred random texture moving
    /// 2 px a frame to the right (the ground), a red box and a white box driving over
    /// it 4 px a frame faster, the white one nearer the image centre.
    fn frame(k: i32) -> cv::Mat {
        let mut rng = 7u64;
        let mut img = cv::Mat::new_rows_cols_with_default(480, 640, cv::CV_8UC3, 0.into()).unwrap();
        for y in 0..480 {
            for x in 0..640 {
                rng = rng
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let v = 60 + (rng >> 58) as u8 * 2;
                *img.at_2d_mut::<cv::Vec3b>(y, x).unwrap() = cv::Vec3b::from([v, v, v]);
            }
        }
        let mut blurred = cv::Mat::default();
        opencv::imgproc::gaussian_blur_def(&img, &mut blurred, cv::Size::new(5, 5), 1.2).unwrap();
        let m = cv::Mat::from_slice_2d(&[[1.0f64, 0.0, 2.0 * k as f64], [0.0, 1.0, 0.0]]).unwrap();
        let mut out = cv::Mat::default();
        opencv::imgproc::warp_affine(
            &blurred,
            &mut out,
            &m,
            blurred.size().unwrap(),
            opencv::imgproc::INTER_LINEAR,
            cv::BORDER_REFLECT,
            cv::Scalar::default(),
        )
        .unwrap();
        for (y, bgr) in [(150, [36.0, 28.0, 214.0]), (250, [230.0, 230.0, 230.0])] {
            opencv::imgproc::rectangle(
                &mut out,
                cv::Rect::new(100 + 6 * k, y, 24, 10),
                cv::Scalar::new(bgr[0], bgr[1], bgr[2], 0.0),
                -1,
                opencv::imgproc::LINE_8,
                0,
            )
            .unwrap();
        }
        out
    }

    /// The detections of frames 21..30 (the detector first looks at frame 21).
    fn follow(config: MotionConfig) -> Vec<[f64; 2]> {
        let mut d = MotionDetector::new(config).unwrap();
        (0..30)
            .filter_map(|k| d.detect(0, &frame(k), None).unwrap().map(|f| f.centre))
            .collect()
    }

    #[test]
    fn a_track_starts_on_the_named_colour_else_nearest_the_centre() {
        // The boxes' centres are at y 154.5 (red) and 254.5 (white); the image
        // centre's y is 239.5.
        let by_centre = follow(MotionConfig::default());
        assert!(!by_centre.is_empty());
        assert!(
            by_centre.iter().all(|c| (c[1] - 254.5).abs() < 2.0),
            "{by_centre:?}"
        );
        let red = follow(MotionConfig {
            acquire_bgr: Some([36.0, 28.0, 214.0]),
            ..MotionConfig::default()
        });
        assert!(!red.is_empty());
        assert!(red.iter().all(|c| (c[1] - 154.5).abs() < 2.0), "{red:?}");
        // Each detection is the box's whole outline: x = 100 + 6k + 11.5 at frame k.
        let last = red[red.len() - 1];
        assert!(
            (last[0] - (100.0 + 6.0 * 29.0 + 11.5)).abs() < 1.0,
            "{last:?}"
        );
    }
}
