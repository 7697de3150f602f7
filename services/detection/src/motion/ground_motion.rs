//! How the ground moved between a camera's frames: KLT corners followed from the
//! previous (down-scaled) frame and a RANSAC homography over them, and the camera's
//! recent frames with each one's homography onto the newest.
//!
//! The homography is the ground's because the ground is the dominant plane of a
//! downward-looking camera's view: roofs and movers are RANSAC's outliers, and the
//! corners kept for the next frame are the inliers only (a vehicle's corners drop out).
//! Coordinates are full-resolution pixels (OpenCV's convention, (0, 0) the top-left
//! pixel's centre); the corners are followed at `1 / scale` of that.

use nalgebra::Matrix3;
use opencv::core as cv;
use opencv::prelude::*;
use std::collections::VecDeque;

/// Fewer corners than this left after RANSAC: detect a fresh set on the next frame.
const MIN_CORNERS: usize = 60;
/// Corners detected when refreshing, at least `CORNER_SPACING_PX` apart (small image).
const MAX_CORNERS: i32 = 200;
const CORNER_SPACING_PX: f64 = 8.0;
/// Fewer RANSAC inliers than this: no homography (the frame pair is not registered).
const MIN_INLIERS: i32 = 20;
/// KLT's pyramid levels above the image: a 15-pixel window follows up to ~100 small
/// pixels of motion at 4 (a UAV's pitch that steps 12° between frames moves a
/// 320-pixel-wide image ~60 pixels).
const PYRAMID_LEVELS: i32 = 4;
/// RANSAC's inlier threshold, small-image pixels.
const RANSAC_PX: f64 = 1.0;

/// The full-resolution ↔ small-image map for a scale `s`: full = s · small + (s − 1) / 2.
pub fn scale_matrix(s: f64) -> Matrix3<f64> {
    let o = (s - 1.0) / 2.0;
    Matrix3::new(s, 0.0, o, 0.0, s, o, 0.0, 0.0, 1.0)
}

/// Follows the ground from frame to frame in one camera.
#[derive(Default)]
pub struct GroundMotion {
    previous: Option<cv::Mat>,
    corners: cv::Vector<cv::Point2f>,
    next: cv::Vector<cv::Point2f>,
    status: cv::Vector<u8>,
    error: cv::Vector<f32>,
}

impl GroundMotion {
    /// The homography taking the previous frame's small-image pixels to `grey`'s (the
    /// newest small grey frame), then keeps `grey` as the previous frame. `None` on the
    /// first frame, after a size change, or when too few corners agree. `seed` seeds
    /// OpenCV's RANSAC so that a replay repeats.
    pub fn step(&mut self, grey: &cv::Mat, seed: u64) -> opencv::Result<Option<Matrix3<f64>>> {
        let previous = self.previous.take();
        let result = match &previous {
            Some(previous) if previous.size()? == grey.size()? => {
                if self.corners.len() < MIN_CORNERS {
                    opencv::imgproc::good_features_to_track(
                        previous,
                        &mut self.corners,
                        MAX_CORNERS,
                        0.01,
                        CORNER_SPACING_PX,
                        &cv::no_array(),
                        3,
                        false,
                        0.04,
                    )?;
                }
                let corners = self.corners.clone();
                match self.follow(previous, grey, seed, None)? {
                    Some(h) => Some(h),
                    // A jump beyond KLT's reach (a UAV's attitude stepping between
                    // frames): the whole image's shift by phase correlation starts the
                    // corners off, once.
                    None => {
                        let shift = self.global_shift(previous, grey)?;
                        self.corners = corners;
                        self.follow(previous, grey, seed, Some(shift))?
                    }
                }
            }
            _ => {
                self.corners.clear();
                None
            }
        };
        self.previous = Some(match previous {
            Some(mut previous) => {
                grey.copy_to(&mut previous)?;
                previous
            }
            None => grey.try_clone()?,
        });
        Ok(result)
    }

    /// The whole frame's translation from `previous` to `grey`, small-image pixels.
    fn global_shift(&mut self, previous: &cv::Mat, grey: &cv::Mat) -> opencv::Result<[f32; 2]> {
        let (mut a, mut b) = (cv::Mat::default(), cv::Mat::default());
        previous.convert_to(&mut a, cv::CV_32F, 1.0, 0.0)?;
        grey.convert_to(&mut b, cv::CV_32F, 1.0, 0.0)?;
        let mut window = cv::Mat::default();
        opencv::imgproc::create_hanning_window(&mut window, grey.size()?, cv::CV_32F)?;
        let p = opencv::imgproc::phase_correlate(&a, &b, &window, None)?;
        Ok([p.x as f32, p.y as f32])
    }

    /// Follows the corners from `previous` into `grey` (starting them at `shift` when
    /// given) and fits the homography; the inliers are kept for the next frame.
    fn follow(
        &mut self,
        previous: &cv::Mat,
        grey: &cv::Mat,
        seed: u64,
        shift: Option<[f32; 2]>,
    ) -> opencv::Result<Option<Matrix3<f64>>> {
        if self.corners.len() < 4 {
            return Ok(None);
        }
        let mut flags = 0;
        if let Some([dx, dy]) = shift {
            self.next.clear();
            for p in &self.corners {
                self.next.push(cv::Point2f::new(p.x + dx, p.y + dy));
            }
            flags = opencv::video::OPTFLOW_USE_INITIAL_FLOW;
        }
        let criteria =
            cv::TermCriteria::new(cv::TermCriteria_COUNT + cv::TermCriteria_EPS, 20, 0.03)?;
        opencv::video::calc_optical_flow_pyr_lk(
            previous,
            grey,
            &self.corners,
            &mut self.next,
            &mut self.status,
            &mut self.error,
            cv::Size::new(15, 15),
            PYRAMID_LEVELS,
            criteria,
            flags,
            1e-4,
        )?;
        let (mut from, mut to) = (cv::Vector::<cv::Point2f>::new(), cv::Vector::new());
        for i in 0..self.next.len() {
            if self.status.get(i)? != 0 {
                from.push(self.corners.get(i)?);
                to.push(self.next.get(i)?);
            }
        }
        self.corners.clear();
        if from.len() < MIN_INLIERS as usize {
            return Ok(None);
        }
        opencv::core::set_rng_seed((seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 33) as i32)?;
        let mut mask = cv::Mat::default();
        let h = opencv::calib3d::find_homography(
            &from,
            &to,
            &mut mask,
            opencv::calib3d::RANSAC,
            RANSAC_PX,
        )?;
        if h.rows() != 3 || h.cols() != 3 || mask.rows() != from.len() as i32 {
            return Ok(None);
        }
        let mut inliers = 0;
        for i in 0..from.len() {
            if *mask.at::<u8>(i as i32)? != 0 {
                self.corners.push(to.get(i)?);
                inliers += 1;
            }
        }
        if inliers < MIN_INLIERS {
            self.corners.clear();
            return Ok(None);
        }
        let mut m = Matrix3::zeros();
        for r in 0..3 {
            for c in 0..3 {
                m[(r, c)] = *h.at_2d::<f64>(r as i32, c as i32)?;
            }
        }
        Ok(m.iter().all(|v| v.is_finite()).then_some(m))
    }
}

/// One past frame: its small and full-resolution BGR images, and the homography taking
/// its full-resolution pixels to the newest frame's.
pub struct Past {
    pub small: cv::Mat,
    pub full: cv::Mat,
    pub to_now: Matrix3<f64>,
}

/// A camera's last `capacity` frames, registered onto the newest.
pub struct History {
    frames: VecDeque<Past>,
    capacity: usize,
}

impl History {
    pub fn new(capacity: usize) -> Self {
        Self {
            frames: VecDeque::with_capacity(capacity + 1),
            capacity: capacity.max(1),
        }
    }

    /// The newest frame has arrived: `small` and `full` are the frame before it and `h`
    /// takes its full-resolution pixels to the newest's. Every older frame's map is
    /// extended by `h`. The images are swapped in, not copied: the caller gets back the
    /// oldest entry's buffers beyond the capacity (or empty ones) to fill next.
    pub fn push(&mut self, small: &mut cv::Mat, full: &mut cv::Mat, h: Matrix3<f64>) {
        for past in &mut self.frames {
            past.to_now = h * past.to_now;
        }
        let recycled = if self.frames.len() >= self.capacity {
            self.frames.pop_front()
        } else {
            None
        };
        let mut entry = recycled.unwrap_or_else(|| Past {
            small: cv::Mat::default(),
            full: cv::Mat::default(),
            to_now: Matrix3::identity(),
        });
        std::mem::swap(small, &mut entry.small);
        std::mem::swap(full, &mut entry.full);
        entry.to_now = h;
        self.frames.push_back(entry);
    }

    /// Forgets every frame (the ground was lost: the chain of homographies is broken).
    pub fn clear(&mut self) {
        self.frames.clear();
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The frame `k` frames before the newest (1: the previous one).
    pub fn back(&self, k: usize) -> Option<&Past> {
        self.frames
            .len()
            .checked_sub(k)
            .and_then(|i| self.frames.get(i))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scale_map_keeps_pixel_centres() {
        let s = scale_matrix(2.0);
        // Small pixel 0 covers full pixels 0 and 1: its centre is at 0.5.
        let p = s * nalgebra::Vector3::new(0.0, 0.0, 1.0);
        assert_eq!((p.x, p.y), (0.5, 0.5));
        assert_eq!(scale_matrix(1.0), Matrix3::identity());
    }

    #[test]
    fn the_ground_motion_of_a_shifted_texture_is_the_shift() {
        // A random texture shifted by (3, −2) pixels.
        let grey = |m: &cv::Mat| {
            let mut g = cv::Mat::default();
            opencv::imgproc::cvt_color_def(m, &mut g, opencv::imgproc::COLOR_BGR2GRAY).unwrap();
            g
        };
        let ground = super::super::test_scene::ground(320, 240, 12345);
        let (blurred, moved) = (
            grey(&ground),
            grey(&super::super::test_scene::shifted(&ground, 3.0, -2.0)),
        );
        let mut g = GroundMotion::default();
        assert!(g.step(&blurred, 1).unwrap().is_none());
        let h = g.step(&moved, 2).unwrap().expect("registered");
        let p = h * nalgebra::Vector3::new(160.0, 120.0, 1.0);
        assert!(
            (p.x / p.z - 163.0).abs() < 0.05 && (p.y / p.z - 118.0).abs() < 0.05,
            "{h}"
        );
    }

    #[test]
    fn the_history_chains_every_frame_onto_the_newest() {
        let mut h = History::new(3);
        let t = |dx: f64| Matrix3::new(1.0, 0.0, dx, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        for dx in [1.0, 2.0, 4.0, 8.0] {
            h.push(&mut cv::Mat::default(), &mut cv::Mat::default(), t(dx));
        }
        assert_eq!(h.len(), 3);
        assert_eq!(h.back(1).unwrap().to_now, t(8.0));
        assert_eq!(h.back(3).unwrap().to_now, t(14.0));
        assert!(h.back(4).is_none());
    }
}
