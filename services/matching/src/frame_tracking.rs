//! Frame-to-frame tracking of one UAV's camera between ORB frames (issue #15).
//!
//! ORB on a full frame and Hamming matching against every selected past image cost
//! most of a pair's CPU (docs/pipeline.md). Between frames 33 ms apart the camera
//! barely moves, so the ground points that matched a past image can be *followed*
//! instead of found again: pyramidal Lucas–Kanade (KLT) moves a few hundred of them
//! from frame to frame in about a millisecond.
//!
//! A *refresh* (`chain/refresh.rs`, on a thread of its own) runs ORB on one frame and
//! matches it with the past images; each past image's robust ground-plane fit marks
//! which matches lie on the ground. Up to `track_points_per_image` of those inliers
//! per past image are handed to this tracker when the refresh lands
//! ([`FrameTracker::hand_over`]), each with an id; the chain keeps, per past image,
//! the ids with their past-image points (an *anchor*). The tracker has moved on since
//! the refresh's frame, so it follows the handed-over points through the frames it
//! keeps ([`MAX_LANDING_FRAMES`] and a few more) to its newest one.
//! On the next frames KLT follows the ids, and the chain joins them with the anchor:
//! tracked correspondences, current ↔ past, fitted by the same robust ground-plane
//! estimator as ORB matches (`epipolar::estimate_fundamental`). So every frame still
//! gets a fresh fit of F; only the search for correspondences changes. (A first
//! version chained inter-frame homographies onto the last fit instead; on the
//! `table1` route it raised the median transfer error from 0.31 to 0.40 px, because
//! between close frames roof points are inliers of the inter-frame homography and
//! tilt it off the ground plane.)
//!
//! Choices, where the issue is silent:
//! - **Only ground inliers are tracked**: points on roofs and facades would need a
//!   plane of their own.
//! - **Each step is checked**: the tracked points of consecutive frames must agree
//!   on one homography within `track_ransac_px`; a point KLT loses, leaves the frame
//!   or breaks that agreement is dropped. Fewer than `track_min_inliers` left (or a
//!   gap of more than [`MAX_GAP_S`], or a frame of another size) loses the track: a
//!   new *epoch* begins, anchors never cross epochs, and the chain asks for a
//!   refresh.
//! - **This file runs no ORB while tracking**: the chain decides when a frame is
//!   refreshed (`VisionChain::wants_refresh`) and hands the grey pixels to the
//!   refresh thread. With tracking off (`track_between_orb = false`) every frame
//!   runs ORB here, on the per-pair path, as before issue #15.

use crate::config::MatchingConfig;
use crate::features::{Features, OrbExtractor};
use crate::frame::{extract_undistorted, ChainCounts, ChainError, FrameInput};
use crate::robust_fit::{seed_cv_rng, usac_params};
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::conventions::{Intrinsics, Uav};
use shared_types::lens::Distortion;
use std::collections::VecDeque;
use std::sync::Arc;

/// KLT's search window and pyramid depth: 9 × 9 px on 4 levels follows a motion of
/// up to ~35 px between the frames tracked (several skipped frames at 30 FPS), and
/// the points are ORB corners, well textured. Measured on the `table1` route (every
/// pair, ~340 points a frame): 21 × 21 took 3.7 ms a frame, 13 × 13 2.3 ms, 9 × 9
/// 1.1 ms, with the same Table 1 errors.
const KLT_WINDOW: i32 = 9;
const KLT_LEVELS: i32 = 3;
/// Frames further apart than this are not tracked: the track is lost. Measured
/// on the scene suite's Table 2 (measured poses): with every 2nd frame of 30 FPS
/// (67 ms apart) tracking kept the default estimator's MAE within ±5 % of ORB on
/// every frame (docs/pipeline.md); with every 3rd (100 ms), `suite_photo_urban`'s MAE
/// x / y went from 1.50 / 1.97 m to 2.06 / 2.78 m. So tracking follows consecutive
/// frames and a skipped one of 30 FPS, not sparser streams.
pub const MAX_GAP_S: f64 = 0.08;

/// The latest a refresh may land, in frames after its own: the tracker keeps this
/// many frames' pyramids (and two more) to follow handed-over points through.
pub const MAX_LANDING_FRAMES: u32 = 8;
const HISTORY: usize = MAX_LANDING_FRAMES as usize + 3;

/// The ground points a frame tracked: ids given at seeding, with their undistorted
/// positions in this frame, in increasing id order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TrackedPoints {
    pub ids: Vec<u32>,
    pub points: Vec<cv::Point2f>,
}

/// Where a frame stands in its UAV's tracking.
#[derive(Debug, Clone, PartialEq)]
pub struct Motion {
    /// Ids are meaningful only within their epoch (a hand-over or a lost track starts
    /// a new one).
    pub epoch: u64,
    /// Frames tracked since the epoch began.
    pub step: u64,
    pub tracked: Arc<TrackedPoints>,
}

/// One current frame as matching holds it until its pair is matched: ORB features
/// (tracking off), what it tracked, and its grey pixels (for a refresh).
pub struct Observed {
    pub seq: u64,
    pub features: Option<Arc<Features>>,
    pub motion: Option<Motion>,
    /// The UAV's previous frame is more than [`MAX_GAP_S`] back: nothing can be
    /// followed into this one (a sparse stream, a long drop), so its refresh lands on
    /// it and its pair waits for it.
    pub after_gap: bool,
    grey: Option<Arc<cv::Mat>>,
}

impl Observed {
    /// A frame with ORB features and no tracking.
    pub fn with_features(seq: u64, features: Arc<Features>) -> Self {
        Self {
            seq,
            features: Some(features),
            motion: None,
            after_gap: false,
            grey: None,
        }
    }

    /// The grey pixels of a tracked frame (what a refresh runs ORB on).
    pub fn grey(&self) -> Option<&Arc<cv::Mat>> {
        self.grey.as_ref()
    }
}

/// What one observation did (matching's counters and trace).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrackReport {
    /// ORB ran on this frame (tracking off).
    pub orb: bool,
    /// KLT followed the previous frame's points.
    pub tracked: bool,
    /// There were points to follow and tracking failed.
    pub lost: bool,
}

/// The camera of a kept frame (what undistorting its points needs).
#[derive(Debug, Clone, Copy)]
struct Camera {
    intrinsics: Intrinsics,
    distortion: Distortion,
    width: u32,
    height: u32,
}

/// A frame the tracker keeps: the newest, and the few before it that a landing
/// refresh may have been taken on.
struct Kept {
    seq: u64,
    t_s: f64,
    camera: Camera,
    /// Its KLT pyramid (level 0 is its grey pixels).
    pyramid: cv::Vector<cv::Mat>,
}

/// Points being followed: in the recorded (distorted) pixels of the newest kept
/// frame, with their ids.
#[derive(Default)]
struct Followed {
    points: cv::Vector<cv::Point2f>,
    ids: Vec<u32>,
}

/// One UAV's tracker, with the ORB extractor its frames use when tracking is off.
pub struct FrameTracker {
    orb: OrbExtractor,
    enabled: bool,
    min_inliers: usize,
    ransac_px: f64,
    config: MatchingConfig,
    /// The newest frames, oldest first (at most [`HISTORY`]).
    kept: VecDeque<Kept>,
    /// What the newest kept frame tracked.
    followed: Followed,
    epoch: u64,
    step: u64,
    /// Grey images, reused once nobody holds them (the previous frame, pending pairs,
    /// refreshes): a steady stream allocates nothing, so the service's memory stays
    /// flat.
    greys: Vec<Arc<cv::Mat>>,
    /// Pyramid buffers of frames no longer kept, refilled by the next frames.
    spare_pyramids: Vec<cv::Vector<cv::Mat>>,
}

/// At most this many pooled grey images (a frame held longer gets its own).
const GREY_POOL: usize = 16;

impl FrameTracker {
    /// The tracker of `uav`'s camera.
    pub fn new(config: &MatchingConfig, _uav: Uav) -> Result<Self, ChainError> {
        Ok(Self {
            greys: Vec::new(),
            spare_pyramids: Vec::new(),
            orb: OrbExtractor::new(config)?,
            // Only the ground plane's fit gives ground points to follow: with another
            // F method every frame runs ORB, as with tracking off.
            enabled: config.track_between_orb
                && config.fundamental == crate::config::FundamentalMethod::GroundPlane,
            min_inliers: config.track_min_inliers,
            ransac_px: config.track_ransac_px,
            config: config.clone(),
            kept: VecDeque::with_capacity(HISTORY + 1),
            followed: Followed::default(),
            epoch: 0,
            step: 0,
        })
    }

    /// The stream jumped (a new segment): the frames kept and the points followed are
    /// dropped and the counters start again, as for a new stream; the buffers stay
    /// for the next frames (rebuilding them every pass grew the service).
    pub fn start_over(&mut self) {
        while let Some(old) = self.kept.pop_front() {
            if self.spare_pyramids.len() < 2 {
                self.spare_pyramids.push(old.pyramid);
            }
        }
        self.followed.points.clear();
        self.followed.ids.clear();
        self.epoch = 0;
        self.step = 0;
    }

    /// Whether frames are tracked (else every frame runs ORB here).
    pub fn enabled(&self) -> bool {
        self.enabled
    }

    /// ORB on a frame, its keypoints undistorted (no tracking).
    pub fn extract(&mut self, frame: &FrameInput) -> Result<(Features, ChainCounts), ChainError> {
        extract_undistorted(&mut self.orb, frame)
    }

    /// Follows the previous frame's points into `frame` (ORB instead when tracking is
    /// off). A tracked frame keeps its grey pixels for a refresh.
    pub fn observe(
        &mut self,
        frame: &FrameInput,
    ) -> Result<(Observed, ChainCounts, TrackReport), ChainError> {
        let mut report = TrackReport::default();
        if !self.enabled {
            let (features, counts) = self.extract(frame)?;
            report.orb = true;
            let observed = Observed::with_features(frame.seq, Arc::new(features));
            return Ok((observed, counts, report));
        }
        let grey = self.grey_of(frame.image)?;
        let mut pyramid = self.spare_pyramids.pop().unwrap_or_default();
        opencv::video::build_optical_flow_pyramid(
            &*grey,
            &mut pyramid,
            cv::Size::new(KLT_WINDOW, KLT_WINDOW),
            KLT_LEVELS,
            false,
            cv::BORDER_REFLECT_101,
            cv::BORDER_CONSTANT,
            // Copy level 0: the grey image goes back to the pool while the pyramid
            // lives on as a kept frame's.
            false,
        )?;
        let camera = Camera {
            intrinsics: frame.intrinsics,
            distortion: frame.distortion,
            width: frame.width,
            height: frame.height,
        };
        let had_points = self.followed.ids.len() >= self.min_inliers;
        let after_gap = self
            .kept
            .back()
            .is_some_and(|p| frame.seq <= p.seq || frame.t_s - p.t_s > MAX_GAP_S);
        let next = match self.kept.back() {
            Some(p) if had_points && frame.seq > p.seq && frame.t_s - p.t_s <= MAX_GAP_S => {
                self.follow(p, &self.followed, &pyramid, &camera, frame.seq)?
            }
            _ => None,
        };
        report.lost = had_points && next.is_none();
        let motion = match next {
            Some((followed, tracked)) => {
                report.tracked = true;
                self.step += 1;
                self.followed = followed;
                Some(Motion {
                    epoch: self.epoch,
                    step: self.step,
                    tracked: Arc::new(tracked),
                })
            }
            None => {
                // Nothing to follow from here on until a refresh lands.
                self.epoch += 1;
                self.step = 0;
                self.followed = Followed::default();
                None
            }
        };
        self.kept.push_back(Kept {
            seq: frame.seq,
            t_s: frame.t_s,
            camera,
            pyramid,
        });
        while self.kept.len() > HISTORY {
            if let Some(old) = self.kept.pop_front() {
                if self.spare_pyramids.len() < 2 {
                    self.spare_pyramids.push(old.pyramid);
                }
            }
        }
        let observed = Observed {
            seq: frame.seq,
            grey: Some(grey),
            features: None,
            motion,
            after_gap,
        };
        Ok((observed, ChainCounts::default(), report))
    }

    /// A refresh taken on frame `seq` lands: its ground points (undistorted pixels;
    /// point i gets id i) are followed from that frame through every frame kept since
    /// to the newest, and a new epoch begins there with the ones that held. Returns
    /// the epoch and what the newest frame tracked, or `None` when that frame is no
    /// longer kept or too few points held (the old epoch goes on).
    pub fn hand_over(
        &mut self,
        seq: u64,
        points: &[cv::Point2f],
        k: &Intrinsics,
        lens: &Distortion,
    ) -> Result<Option<(u64, TrackedPoints)>, ChainError> {
        let Some(from) = self.kept.iter().position(|f| f.seq == seq) else {
            return Ok(None);
        };
        let mut followed = Followed {
            points: points
                .iter()
                .map(|p| {
                    let [u, v] = lens.distort_pixel(k, p.x as f64, p.y as f64);
                    cv::Point2f::new(u as f32, v as f32)
                })
                .collect(),
            ids: (0..points.len() as u32).collect(),
        };
        let mut tracked = TrackedPoints {
            ids: followed.ids.clone(),
            points: points.to_vec(),
        };
        for i in from + 1..self.kept.len() {
            let (a, b) = (&self.kept[i - 1], &self.kept[i]);
            if b.t_s - a.t_s > MAX_GAP_S {
                return Ok(None);
            }
            match self.follow(a, &followed, &b.pyramid, &b.camera, b.seq)? {
                Some((f, t)) => (followed, tracked) = (f, t),
                None => return Ok(None),
            }
        }
        if followed.ids.len() < self.min_inliers {
            return Ok(None);
        }
        self.followed = followed;
        self.epoch += 1;
        self.step = 0;
        Ok(Some((self.epoch, tracked)))
    }

    /// KLT from a kept frame's points into the next pyramid, then the check that the
    /// followed points agree on one homography. The kept points (distorted, for the
    /// next step) with their ids, and the same undistorted for matching.
    fn follow(
        &self,
        previous: &Kept,
        from: &Followed,
        pyramid: &cv::Vector<cv::Mat>,
        camera: &Camera,
        seq: u64,
    ) -> Result<Option<(Followed, TrackedPoints)>, ChainError> {
        let size = |p: &cv::Vector<cv::Mat>| p.get(0).and_then(|m| m.size());
        if previous.pyramid.len() != pyramid.len() || size(&previous.pyramid)? != size(pyramid)? {
            return Ok(None);
        }
        let mut next = cv::Vector::<cv::Point2f>::new();
        let mut status = cv::Vector::<u8>::new();
        let mut error = cv::Vector::<f32>::new();
        let criteria =
            cv::TermCriteria::new(cv::TermCriteria_COUNT + cv::TermCriteria_EPS, 30, 0.01)?;
        opencv::video::calc_optical_flow_pyr_lk(
            &previous.pyramid,
            pyramid,
            &from.points,
            &mut next,
            &mut status,
            &mut error,
            cv::Size::new(KLT_WINDOW, KLT_WINDOW),
            KLT_LEVELS,
            criteria,
            0,
            1e-4,
        )?;
        let (k, lens) = (&camera.intrinsics, &camera.distortion);
        let undistort = |p: cv::Point2f| {
            lens.undistort_pixel(k, p.x as f64, p.y as f64)
                .map(|[u, v]| cv::Point2f::new(u as f32, v as f32))
        };
        let (w, h) = (camera.width as f32, camera.height as f32);
        let mut kept = Vec::with_capacity(next.len());
        let (mut to, mut back) = (
            cv::Vector::<cv::Point2f>::new(),
            cv::Vector::<cv::Point2f>::new(),
        );
        for i in 0..next.len().min(from.ids.len()) {
            let (a, b) = (next.get(i)?, from.points.get(i)?);
            if status.get(i)? == 0 || !(a.x >= 0.0 && a.y >= 0.0 && a.x < w && a.y < h) {
                continue;
            }
            let (Some(ua), Some(ub)) = (undistort(a), undistort(b)) else {
                continue;
            };
            to.push(ua);
            back.push(ub);
            kept.push((a, ua, from.ids[i]));
        }
        if kept.len() < self.min_inliers.max(4) {
            return Ok(None);
        }
        let mut params = usac_params(&self.config, self.ransac_px)?;
        params.max_iterations = self.config.homography_max_iterations;
        let mut mask = cv::Mat::default();
        seed_cv_rng(&[0xf011_0000, seq, kept.len() as u64])?;
        let homography = opencv::calib3d::find_homography_1(&to, &back, &mut mask, params)?;
        if homography.rows() != 3 || mask.rows() != kept.len() as i32 {
            return Ok(None);
        }
        let mut followed = Followed::default();
        let mut tracked = TrackedPoints::default();
        for (i, (a, ua, id)) in kept.into_iter().enumerate() {
            if *mask.at::<u8>(i as i32)? != 0 {
                followed.points.push(a);
                followed.ids.push(id);
                tracked.ids.push(id);
                tracked.points.push(ua);
            }
        }
        if followed.ids.len() < self.min_inliers {
            return Ok(None);
        }
        Ok(Some((followed, tracked)))
    }
}

impl FrameTracker {
    /// The frame's grey pixels, in a pooled image nobody else holds when there is one.
    fn grey_of(&mut self, image: &cv::Mat) -> Result<Arc<cv::Mat>, ChainError> {
        let free = self.greys.iter().position(|g| Arc::strong_count(g) == 1);
        let mut grey = match free {
            Some(i) => self.greys.swap_remove(i),
            None => Arc::new(cv::Mat::default()),
        };
        let Some(target) = Arc::get_mut(&mut grey) else {
            return Err(ChainError::Tracking("a pooled grey image is shared"));
        };
        if image.channels() == 3 {
            opencv::imgproc::cvt_color_def(image, target, opencv::imgproc::COLOR_BGR2GRAY)?;
        } else {
            image.copy_to(target)?;
        }
        if self.greys.len() < GREY_POOL {
            self.greys.push(Arc::clone(&grey));
        }
        Ok(grey)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;
    use shared_types::messages::PoseSample;

    const W: i32 = 640;
    const H: i32 = 480;

    /// A textured grey frame: seeded noise, blurred to corners KLT and ORB can hold.
    fn texture() -> cv::Mat {
        let mut noise =
            cv::Mat::new_rows_cols_with_default(H, W, cv::CV_8UC1, cv::Scalar::all(0.0))
                .expect("mat");
        cv::set_rng_seed(7).expect("seed");
        cv::randu(&mut noise, &cv::Scalar::all(0.0), &cv::Scalar::all(255.0)).expect("randu");
        let mut blurred = cv::Mat::default();
        opencv::imgproc::gaussian_blur_def(&noise, &mut blurred, cv::Size::new(5, 5), 1.5)
            .expect("blur");
        blurred
    }

    /// `image` seen through `h` (a point p of `image` lands at h·p).
    fn warp(image: &cv::Mat, h: &Matrix3<f64>) -> cv::Mat {
        let m = cv::Mat::from_slice_2d(&[
            [h[(0, 0)], h[(0, 1)], h[(0, 2)]],
            [h[(1, 0)], h[(1, 1)], h[(1, 2)]],
            [h[(2, 0)], h[(2, 1)], h[(2, 2)]],
        ])
        .expect("mat");
        let mut out = cv::Mat::default();
        opencv::imgproc::warp_perspective(
            image,
            &mut out,
            &m,
            cv::Size::new(W, H),
            opencv::imgproc::INTER_LINEAR,
            cv::BORDER_REFLECT,
            cv::Scalar::default(),
        )
        .expect("warp");
        out
    }

    fn frame(seq: u64, t_s: f64, image: &cv::Mat) -> FrameInput<'_> {
        FrameInput {
            seq,
            t_s,
            pose: PoseSample::default(),
            image,
            detection: None,
            intrinsics: Intrinsics::new(500.0, 500.0, 320.0, 240.0),
            distortion: Distortion::default(),
            width: W as u32,
            height: H as u32,
        }
    }

    fn apply(h: &Matrix3<f64>, p: [f64; 2]) -> [f64; 2] {
        let q = h * nalgebra::Vector3::new(p[0], p[1], 1.0);
        [q.x / q.z, q.y / q.z]
    }

    /// Hands the tracker (a stride through) the ORB points of frame `f`, as a refresh
    /// taken on it would.
    fn refresh_on(tracker: &mut FrameTracker, f: &FrameInput) -> (Vec<cv::Point2f>, u64) {
        let (features, _) = tracker.extract(f).expect("ORB");
        let points: Vec<cv::Point2f> = features.points.iter().step_by(5).copied().collect();
        let (epoch, _) = tracker
            .hand_over(f.seq, &points, &f.intrinsics, &f.distortion)
            .expect("no OpenCV error")
            .expect("handed over");
        (points, epoch)
    }

    /// A small turn and drift, as between frames 33 ms apart (and a bit more).
    fn small_step() -> Matrix3<f64> {
        let (a, t) = (0.6_f64.to_radians(), [3.2, -1.7]);
        Matrix3::new(
            a.cos(),
            -a.sin(),
            t[0],
            a.sin(),
            a.cos(),
            t[1],
            0.0,
            0.0,
            1.0,
        )
    }

    /// Median distance of the tracked points from where `h` moved their seeds.
    fn median_error(tracked: &TrackedPoints, seeds: &[cv::Point2f], h: &Matrix3<f64>) -> f64 {
        let mut errors: Vec<f64> = tracked
            .ids
            .iter()
            .zip(&tracked.points)
            .map(|(id, p)| {
                let s = seeds[*id as usize];
                let want = apply(h, [s.x as f64, s.y as f64]);
                ((p.x as f64 - want[0]).powi(2) + (p.y as f64 - want[1]).powi(2)).sqrt()
            })
            .collect();
        errors.sort_by(f64::total_cmp);
        errors[errors.len() / 2]
    }

    #[test]
    fn followed_points_land_where_the_image_moved_them() {
        let first = texture();
        let step = small_step();
        let second = warp(&first, &step);
        let third = warp(&second, &step);
        let config = MatchingConfig::default();
        let mut tracker = FrameTracker::new(&config, Uav::Left).expect("tracker");
        let f1 = frame(1, 0.0, &first);
        let (o1, _, r1) = tracker.observe(&f1).expect("first");
        assert!(!r1.orb && !r1.tracked && o1.features.is_none() && o1.grey().is_some());
        let (seeds, epoch) = refresh_on(&mut tracker, &f1);
        let (_, _, r2) = tracker.observe(&frame(2, 0.033, &second)).expect("second");
        let (o3, _, r3) = tracker.observe(&frame(3, 0.066, &third)).expect("third");
        assert!(
            r2.tracked && !r2.orb && r3.tracked && !r3.orb,
            "{r2:?} {r3:?}"
        );
        assert!(o3.features.is_none(), "a tracked frame runs no ORB");
        let motion = o3.motion.expect("motion");
        assert_eq!((motion.epoch, motion.step), (epoch, 2));
        let tracked = &motion.tracked;
        assert!(
            tracked.ids.len() * 10 > seeds.len() * 8,
            "{} of {} points followed",
            tracked.ids.len(),
            seeds.len()
        );
        assert!(tracked.ids.windows(2).all(|w| w[0] < w[1]), "ids in order");
        let median = median_error(tracked, &seeds, &(step * step));
        assert!(median < 0.1, "median {median} px after two steps");
    }

    #[test]
    fn a_refresh_that_lands_frames_later_is_followed_to_the_newest_frame() {
        let step = small_step();
        let mut images = vec![texture()];
        for _ in 0..4 {
            let next = warp(images.last().expect("one"), &step);
            images.push(next);
        }
        let config = MatchingConfig::default();
        let mut tracker = FrameTracker::new(&config, Uav::Left).expect("tracker");
        let frames: Vec<FrameInput> = images
            .iter()
            .enumerate()
            .map(|(i, im)| frame(i as u64 + 1, i as f64 / 30.0, im))
            .collect();
        for f in &frames[..3] {
            let (o, _, r) = tracker.observe(f).expect("observe");
            assert!(o.motion.is_none() && !r.tracked, "nothing to follow yet");
        }
        // Taken on frame 1, landing after frame 3 was observed (two frames late).
        let (features, _) = tracker.extract(&frames[0]).expect("ORB");
        let seeds: Vec<cv::Point2f> = features.points.iter().step_by(5).copied().collect();
        let f = &frames[0];
        let (epoch, tracked) = tracker
            .hand_over(1, &seeds, &f.intrinsics, &f.distortion)
            .expect("no OpenCV error")
            .expect("handed over");
        assert!(tracked.ids.len() * 10 > seeds.len() * 8, "most points held");
        let median = median_error(&tracked, &seeds, &(step * step));
        assert!(median < 0.1, "median {median} px on frame 3");
        // Frame 4 goes on in the new epoch from there.
        let (o4, _, r4) = tracker.observe(&frames[3]).expect("fourth");
        let motion = o4.motion.expect("tracked");
        assert!(r4.tracked && motion.epoch == epoch && motion.step == 1);
        let median = median_error(&motion.tracked, &seeds, &(step * step * step));
        assert!(median < 0.1, "median {median} px on frame 4");
    }

    #[test]
    fn a_gap_loses_the_track_and_a_refresh_of_a_frame_no_longer_kept_does_nothing() {
        let image = texture();
        let config = MatchingConfig::default();
        let mut tracker = FrameTracker::new(&config, Uav::Left).expect("tracker");
        let f0 = frame(0, 0.0, &image);
        tracker.observe(&f0).expect("first");
        refresh_on(&mut tracker, &f0);
        for i in 1..4 {
            let (o, _, r) = tracker
                .observe(&frame(i, i as f64 / 30.0, &image))
                .expect("observe");
            assert!(r.tracked && o.motion.is_some(), "frame {i}: {r:?}");
        }
        // A second later: not followed across the gap.
        let (o, _, r) = tracker.observe(&frame(40, 1.5, &image)).expect("late");
        assert!(r.lost && !r.tracked && o.motion.is_none(), "{r:?}");
        assert!(o.features.is_none() && o.grey().is_some());
        // Nothing handed over since: nothing to follow, nothing lost.
        let (_, _, r) = tracker.observe(&frame(41, 1.533, &image)).expect("next");
        assert!(!r.orb && !r.tracked && !r.lost, "{r:?}");
        // A refresh across the gap (frame 3 then 40) does not land.
        let p = [cv::Point2f::new(100.0, 100.0); 40];
        let f3 = frame(3, 0.1, &image);
        let landed = tracker
            .hand_over(3, &p, &f3.intrinsics, &f3.distortion)
            .expect("no OpenCV error");
        assert!(landed.is_none());
        // Nor one of a frame the tracker no longer keeps.
        for i in 42..42 + HISTORY as u64 {
            tracker
                .observe(&frame(i, i as f64 / 30.0, &image))
                .expect("observe");
        }
        let f40 = frame(40, 1.5, &image);
        let landed = tracker
            .hand_over(40, &p, &f40.intrinsics, &f40.distortion)
            .expect("no OpenCV error");
        assert!(landed.is_none());
    }

    #[test]
    fn tracking_off_runs_orb_on_every_frame() {
        let image = texture();
        let config = MatchingConfig {
            track_between_orb: false,
            ..MatchingConfig::default()
        };
        let mut tracker = FrameTracker::new(&config, Uav::Left).expect("tracker");
        for i in 0..3 {
            let (o, _, r) = tracker
                .observe(&frame(i, i as f64 / 30.0, &image))
                .expect("observe");
            assert!(r.orb && o.features.is_some() && o.motion.is_none());
        }
        assert!(!tracker.enabled());
        // Only the ground plane's fit gives points to follow: another F method runs
        // ORB on every frame too.
        let essential = MatchingConfig {
            fundamental: crate::config::FundamentalMethod::Essential,
            ..MatchingConfig::default()
        };
        let tracker = FrameTracker::new(&essential, Uav::Left).expect("tracker");
        assert!(!tracker.enabled());
    }
}
