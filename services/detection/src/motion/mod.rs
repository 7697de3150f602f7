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
//!    track, of the colour `acquire_bgr` when the operator names one ([`track`]).
//!    Several vehicles move in a street: the centre is right for a camera that
//!    points at the target (a tracking gimbal); two nadir UAVs flying either side of
//!    it see it off-centre, beside any car that follows it, so designate it there;
//! 4. its outline and top come from the difference with the frame `long_gap_frames`
//!    back, in a window around it ([`movers::Differencer::outline`]).
//!
//! A vehicle that looks like the ground it is on drops out of the differences for a
//! few frames: its patch from the last frame it moved in holds it ([`hold`], at most
//! `hold_frames` frames). A vehicle that stops or hides disappears from the
//! differences: the track then coasts (in the image and carried by the ground, at its
//! velocities for at most 8 frames); after `coast_frames` frames its search radius
//! grows, up to 3×, and after four times that it is dropped and the next mover near
//! where it should be is taken for it. When the ground's motion is lost (the camera jumped beyond KLT and the
//! phase correlation), the history starts again and the track is looked for within
//! `acquire_radius_px`.

mod config;
pub mod ground_motion;
mod hold;
pub mod movers;
#[cfg(test)]
mod test_scene;
mod track;

pub use config::MotionConfig;

use crate::prediction_gate::Gate;
use crate::{DetectError, Detection};
use ground_motion::{scale_matrix, GroundMotion, History};
use hold::Hold;
use movers::{Differencer, Mover};
use nalgebra::{Matrix3, Vector3};
use opencv::core as cv;
use opencv::prelude::*;
use track::{Pick, Track};

/// What the motion detector did since the last [`MotionDetector::take_counts`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MotionCounts {
    /// Movers found, summed over frames.
    pub movers: u64,
    /// Frames whose ground motion could not be measured (the history restarts).
    pub no_ground: u64,
    /// Tracks started (no gate, no track: the mover nearest the designation or the
    /// image centre).
    pub acquired: u64,
    /// Tracks dropped after 4 × `coast_frames` frames without the target.
    pub track_lost: u64,
    /// Frames whose target was its patch, held without a mover (`hold.rs`).
    pub held: u64,
}

#[derive(Default)]
struct Camera {
    ground: GroundMotion,
    history: Option<History>,
    small: cv::Mat,
    grey: cv::Mat,
    previous: Option<(cv::Mat, cv::Mat)>,
    track: Option<Track>,
    /// The target's patch from the last frame it moved in.
    hold: Hold,
    /// Where to acquire when there is no track (the designation), once.
    designated: Option<[f64; 2]>,
    frames: u64,
}

impl Camera {
    /// Takes in the newest `frame`: its small and grey images, the ground's motion
    /// since the previous frame, the history registered onto it, and the track's
    /// last place carried by that motion. True when the ground's motion could not be
    /// measured (the history starts again and the track goes blind).
    fn register(
        &mut self,
        frame: &cv::Mat,
        c: &MotionConfig,
        camera: usize,
    ) -> opencv::Result<bool> {
        let small_size = cv::Size::new(
            (frame.cols() / c.scale as i32).max(1),
            (frame.rows() / c.scale as i32).max(1),
        );
        if c.scale == 1 {
            frame.copy_to(&mut self.small)?;
        } else {
            opencv::imgproc::resize(
                frame,
                &mut self.small,
                small_size,
                0.0,
                0.0,
                opencv::imgproc::INTER_AREA,
            )?;
        }
        opencv::imgproc::cvt_color_def(
            &self.small,
            &mut self.grey,
            opencv::imgproc::COLOR_BGR2GRAY,
        )?;
        let to_full = scale_matrix(c.scale as f64);
        let to_small = to_full.try_inverse().unwrap_or_else(Matrix3::identity);
        self.frames += 1;
        let seed = (camera as u64) << 40 | self.frames;
        let history = self.history.get_or_insert_with(|| {
            History::new(2 * c.short_gap_frames.max(c.long_gap_frames) as usize)
        });
        let step = self.ground.step(&self.grey, seed)?;
        // The ground's motion since the previous frame, full-resolution pixels.
        let had_previous = self.previous.is_some();
        let (moved, lost) = match (step, &mut self.previous) {
            // The previous frame's buffers go into the history; recycled ones come
            // back, and the newest frame is copied into them below (one copy a frame).
            (Some(h_small), Some((small, full))) => {
                let h = to_full * h_small * to_small;
                history.push(small, full, h);
                (Some(h), false)
            }
            _ => {
                history.clear();
                if let Some(t) = &mut self.track {
                    t.blind = true;
                }
                (None, had_previous)
            }
        };
        match &mut self.previous {
            Some((small, full)) => {
                self.small.copy_to(small)?;
                frame.copy_to(full)?;
            }
            None => self.previous = Some((self.small.try_clone()?, frame.try_clone()?)),
        }
        // The track's last place, carried by the ground's motion (kept when the ground
        // was not measured this frame).
        if let (Some(t), Some(h)) = (&mut self.track, moved) {
            let p = h * Vector3::new(t.carried[0], t.carried[1], 1.0);
            if p.z.abs() > 1e-9 {
                t.carried = [p.x / p.z, p.y / p.z];
            }
        }
        Ok(lost)
    }

    /// The track after this frame: found again, started, or one more frame missed; a
    /// track missed for 4 × `coast_frames` is dropped (true), and the next mover near
    /// where it should be is taken for it.
    fn update_track(&mut self, outlined: Option<&Mover>, c: &MotionConfig) -> bool {
        match (outlined, &mut self.track) {
            (Some(m), Some(t)) => t.found(m),
            (Some(m), None) => self.track = Some(Track::new(m)),
            (None, Some(t)) if t.missed < 4 * c.coast_frames => t.missed += 1,
            (None, Some(t)) => {
                self.designated = Some(t.predictions()[0]);
                self.track = None;
                return true;
            }
            (None, None) => {}
        }
        false
    }
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

    /// Forgets `camera`'s ground motion, history and track: its stream jumped (a new
    /// segment), so the old frames are not the ground under it now. The operator's
    /// designation (`acquire_px`) stands again.
    pub fn start_over(&mut self, camera: usize) {
        let Some(cam) = self.cameras.get_mut(camera) else {
            return;
        };
        *cam = Camera::default();
        cam.designated = self.config.acquire_px.map(|at| at[camera]);
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
        // The movers are this frame's only: a frame that finds none (no history, the
        // ground lost) must not leave the other camera's in place.
        self.movers.clear();
        let c = self.config;
        let cam = self
            .cameras
            .get_mut(camera)
            .ok_or_else(|| DetectError::Config(format!("camera {camera} is not 0 or 1")))?;
        if cam.register(frame, &c, camera)? {
            self.counts.no_ground += 1;
        }
        let s = c.scale as f64;
        let to_full = scale_matrix(s);
        let to_small = to_full.try_inverse().unwrap_or_else(Matrix3::identity);
        let Some(history) = &cam.history else {
            return Ok(None);
        };
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
        let picked = match track::pick(
            &c,
            &self.movers,
            gate,
            cam.track.as_ref(),
            cam.designated,
            centre,
        ) {
            Pick::None => None,
            Pick::Followed(m) => Some(m),
            Pick::Acquired(m) => {
                self.counts.acquired += 1;
                cam.designated = None;
                Some(m)
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
        // No mover for the target: its patch, where the track is against the ground
        // (`hold.rs`).
        let held = match (&outlined, &cam.track) {
            (None, Some(t)) if !t.blind && c.hold_frames > 0 => {
                cam.hold
                    .find(frame, t.predictions()[1], gate.as_ref(), &c)?
            }
            _ => None,
        };
        match (&outlined, held) {
            (Some(m), _) if c.hold_frames > 0 => {
                // Where the track expected it, if it was found in the last frame too.
                let expected = cam
                    .track
                    .filter(|t| t.missed == 0 && !t.blind)
                    .map(|t| t.predictions());
                cam.hold.learn(frame, m, expected)?;
            }
            (None, Some(m)) => {
                if let Some(t) = &mut cam.track {
                    t.held(m.centre);
                }
                self.counts.held += 1;
                return Ok(Some(Detection {
                    bbox: m.bbox,
                    centre: m.centre,
                    confidence: 1.0,
                }));
            }
            _ => {}
        }
        if cam.update_track(outlined.as_ref(), &c) {
            self.counts.track_lost += 1;
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
            cam.hold.forget();
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
        let mut out = test_scene::shifted(&test_scene::ground(640, 480, 7), 2.0 * k as f64, 0.0);
        for (y, bgr) in [(150, [36.0, 28.0, 214.0]), (250, [230.0, 230.0, 230.0])] {
            test_scene::draw_box(&mut out, cv::Rect::new(100 + 6 * k, y, 24, 10), bgr);
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
