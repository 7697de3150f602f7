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
//!    track. Several vehicles move in a street: the centre is right for a camera that
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
    /// is acquired again nearest the centre (or [`MotionDetector::designate`]).
    pub acquire_px: Option<[[f64; 2]; 2]>,
    pub acquire_radius_px: f64,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            scale: 2,
            short_gap_frames: 10,
            long_gap_frames: 30,
            threshold: 30.0,
            min_side_px: 6,
            min_area_px: 48,
            track_radius_px: 30.0,
            coast_frames: 15,
            acquire_px: None,
            acquire_radius_px: 60.0,
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
        {
            return Err(
                "threshold must be in (0, 255], track_radius_px and acquire_radius_px > 0".into(),
            );
        }
        if self
            .acquire_px
            .is_some_and(|a| a.iter().flatten().any(|v| !v.is_finite()))
        {
            return Err("acquire_px must be finite".into());
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

/// One camera's track: where the target was in the newest frame it was found, and
/// how it moves against the ground (pixels per frame).
#[derive(Debug, Clone, Copy)]
struct Track {
    centre: [f64; 2],
    velocity: [f64; 2],
    missed: u32,
}

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
        // The track's prediction: carried by the ground, plus its own motion.
        let predicted = match (cam.track, moved) {
            (Some(t), Some(h)) => {
                let p = h * Vector3::new(t.centre[0], t.centre[1], 1.0);
                Some([p.x / p.z + t.velocity[0], p.y / p.z + t.velocity[1]])
            }
            _ => None,
        };
        let k = c.short_gap_frames as usize;
        let (Some(near), Some(far)) = (history.back(k), history.back(2 * k)) else {
            cam.track = None;
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
        let picked = match (gate, predicted) {
            (Some(g), _) => nearest(g.centre, &|m| g.contains(m.centre)),
            (None, Some(p)) => {
                let missed = cam.track.map_or(0, |t| t.missed);
                let radius = if missed > c.coast_frames {
                    2.0 * c.track_radius_px
                } else {
                    c.track_radius_px
                };
                nearest(p, &|m| distance(m, p) <= radius)
            }
            (None, None) => {
                let m = match cam.designated {
                    Some(at) => nearest(at, &|m| distance(m, at) <= c.acquire_radius_px),
                    None => nearest(centre, &|_| true),
                };
                if m.is_some() {
                    self.counts.acquired += 1;
                    cam.designated = None;
                }
                m
            }
        };
        let outlined = match (picked, history.back(c.long_gap_frames as usize)) {
            (Some(m), Some(old)) => self
                .differencer
                .outline(
                    frame,
                    (&old.full, &old.to_now),
                    &m,
                    c.threshold,
                    c.min_area_px as i32 / 2,
                )?
                .or(Some(m)),
            (m, _) => m,
        };
        match (outlined, cam.track) {
            (Some(m), previous) => {
                let velocity = match (previous, predicted) {
                    // Its own motion: where it is against where the ground took it.
                    (Some(t), Some(p)) => {
                        let carried = [p[0] - t.velocity[0], p[1] - t.velocity[1]];
                        let v = [m.centre[0] - carried[0], m.centre[1] - carried[1]];
                        [0.5 * (t.velocity[0] + v[0]), 0.5 * (t.velocity[1] + v[1])]
                    }
                    _ => [0.0, 0.0],
                };
                cam.track = Some(Track {
                    centre: m.centre,
                    velocity,
                    missed: 0,
                });
            }
            (None, Some(t)) => {
                cam.track = match predicted {
                    Some(p) if t.missed < 4 * c.coast_frames => Some(Track {
                        centre: p,
                        missed: t.missed + 1,
                        ..t
                    }),
                    _ => {
                        self.counts.track_lost += 1;
                        None
                    }
                };
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

    /// The counts since the last call, and starts again from zero.
    pub fn take_counts(&mut self) -> MotionCounts {
        std::mem::take(&mut self.counts)
    }
}
