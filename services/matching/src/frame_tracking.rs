//! Frame-to-frame tracking of one UAV's camera between ORB frames (issue #15).
//!
//! ORB on a full frame and Hamming matching against every selected past image cost
//! most of a pair's CPU (docs/pipeline.md). Between frames 33 ms apart the camera
//! barely moves, so the ground points that matched a past image can be *followed*
//! instead of found again: pyramidal Lucas–Kanade (KLT) moves a few hundred of them
//! from frame to frame in about a millisecond.
//!
//! On a frame that ran ORB, each past image's robust ground-plane fit marks which
//! matches lie on the ground. Up to `track_points_per_image` of those inliers per past
//! image are handed to this tracker ([`FrameTracker::seed`]), each with an id; the
//! chain keeps, per past image, the ids with their past-image points (an *anchor*).
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
//!   gap of more than 0.5 s, or a frame of another size) loses the track: the frame
//!   runs ORB and a new *epoch* begins, and anchors never cross epochs.
//! - **Refresh**: ORB and Hamming matching run at least every `track_refresh_frames`
//!   frames of a UAV (the two UAVs half a period apart), on every frame its keyframe
//!   ring may admit,
//!   and when a selected past image has neither an anchor nor a failure recorded
//!   since the last refresh (the chain decides, `VisionChain::wants_features`).
//!   A past image whose fit failed on the last ORB frame is not retried before the
//!   next refresh.

use crate::config::MatchingConfig;
use crate::features::{Features, OrbExtractor};
use crate::frame::{extract_undistorted, ChainCounts, ChainError, FrameInput, FrameMeta};
use crate::robust_fit::{seed_cv_rng, usac_params};
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::conventions::{Intrinsics, Uav};
use shared_types::lens::Distortion;
use std::sync::Arc;

/// KLT's search window and pyramid depth: 9 × 9 px on 4 levels follows a motion of
/// up to ~35 px between the frames tracked (several skipped frames at 30 FPS), and
/// the points are ORB corners, well textured. Measured on the `table1` route (every
/// pair, ~340 points a frame): 21 × 21 took 3.7 ms a frame, 13 × 13 2.3 ms, 9 × 9
/// 1.1 ms, with the same Table 1 errors.
const KLT_WINDOW: i32 = 9;
const KLT_LEVELS: i32 = 3;
/// Frames further apart than this are not tracked: the next one runs ORB. Measured
/// on the scene suite's Table 2 (measured poses): with every 2nd frame of 30 FPS
/// (67 ms apart) tracking kept the default estimator's MAE within ±5 % of ORB on
/// every frame (docs/pipeline.md); with every 3rd (100 ms), `suite_photo_urban`'s MAE
/// x / y went from 1.50 / 1.97 m to 2.06 / 2.78 m. So tracking follows consecutive
/// frames and a skipped one of 30 FPS, not sparser streams.
const MAX_GAP_S: f64 = 0.08;

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
    /// Ids are meaningful only within their epoch (a seeding or a lost track starts
    /// a new one).
    pub epoch: u64,
    /// Frames tracked since the epoch was seeded.
    pub step: u64,
    pub tracked: Arc<TrackedPoints>,
}

/// One current frame as matching holds it until its pair is matched: ORB features if
/// they were computed, what it tracked, and its grey pixels when there are no features
/// (so that ORB can still run if the pair needs it).
pub struct Observed {
    pub seq: u64,
    pub features: Option<Arc<Features>>,
    pub motion: Option<Motion>,
    grey: Option<Arc<cv::Mat>>,
}

impl Observed {
    /// A frame with ORB features and no tracking.
    pub fn with_features(seq: u64, features: Arc<Features>) -> Self {
        Self {
            seq,
            features: Some(features),
            motion: None,
            grey: None,
        }
    }
}

/// What one observation did (matching's counters and trace).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrackReport {
    /// ORB ran on this frame.
    pub orb: bool,
    /// KLT followed the previous frame's points.
    pub tracked: bool,
    /// There were points to follow and tracking failed.
    pub lost: bool,
}

struct Previous {
    seq: u64,
    t_s: f64,
    /// Its KLT pyramid (level 0 is its grey pixels).
    pyramid: cv::Vector<cv::Mat>,
    /// Tracked points in the recorded (distorted) pixels, and their ids.
    points: cv::Vector<cv::Point2f>,
    ids: Vec<u32>,
}

/// One UAV's tracker, with the ORB extractor its frames use.
pub struct FrameTracker {
    orb: OrbExtractor,
    enabled: bool,
    refresh_frames: u64,
    min_inliers: usize,
    ransac_px: f64,
    config: MatchingConfig,
    previous: Option<Previous>,
    epoch: u64,
    step: u64,
    /// The sequence number of the last frame that ran ORB.
    last_orb_seq: Option<u64>,
    /// Shifts this UAV's refreshes against the other's (see `refresh_due`).
    phase: u64,
    /// Grey images, reused once nobody holds them (the previous frame, pending pairs):
    /// a steady stream allocates nothing, so the service's memory stays flat.
    greys: Vec<Arc<cv::Mat>>,
    /// The pyramid buffers the previous frame gave up, refilled by the next.
    spare_pyramid: cv::Vector<cv::Mat>,
}

/// At most this many pooled grey images (a frame held longer gets its own).
const GREY_POOL: usize = 12;

impl FrameTracker {
    /// The tracker of `uav`'s camera.
    pub fn new(config: &MatchingConfig, uav: Uav) -> Result<Self, ChainError> {
        let refresh_frames = config.track_refresh_frames.max(1) as u64;
        Ok(Self {
            phase: uav.index() as u64 * refresh_frames / 2,
            greys: Vec::new(),
            spare_pyramid: cv::Vector::new(),
            orb: OrbExtractor::new(config)?,
            enabled: config.track_between_orb,
            refresh_frames,
            min_inliers: config.track_min_inliers,
            ransac_px: config.track_ransac_px,
            config: config.clone(),
            previous: None,
            epoch: 0,
            step: 0,
            last_orb_seq: None,
        })
    }

    /// The epoch and step frame `seq` will have if it is tracked without ORB; `None`
    /// when it will run ORB anyway.
    pub fn next_step(&self, seq: u64) -> Option<(u64, u64)> {
        let p = self.previous.as_ref()?;
        let ok = self.enabled && !self.refresh_due(seq) && p.ids.len() >= self.min_inliers;
        ok.then_some((self.epoch, self.step + 1))
    }

    /// A refresh is due when `seq` (shifted by this UAV's phase) crosses a multiple of
    /// `track_refresh_frames` since the last ORB frame: at most that many frames
    /// apart. The right UAV's phase is half a period: the two UAVs refresh on
    /// different pairs, so a refresh pair runs one ORB (on one core) beside one
    /// tracked frame rather than two ORBs that take both cores from decoding and
    /// detection. Measured (pipeline bench, same hour): see docs/pipeline.md.
    fn refresh_due(&self, seq: u64) -> bool {
        let k = self.refresh_frames;
        self.last_orb_seq
            .is_none_or(|last| (seq + self.phase) / k != (last + self.phase) / k)
    }

    /// ORB on a frame, its keypoints undistorted (no tracking).
    pub fn extract(&mut self, frame: &FrameInput) -> Result<(Features, ChainCounts), ChainError> {
        extract_undistorted(&mut self.orb, frame)
    }

    /// ORB on an observed frame that has none yet, from its grey pixels.
    pub fn ensure_features(
        &mut self,
        observed: &mut Observed,
        frame: &FrameMeta,
    ) -> Result<ChainCounts, ChainError> {
        if observed.features.is_some() {
            return Ok(ChainCounts::default());
        }
        let Some(grey) = observed.grey.as_ref() else {
            return Err(ChainError::Tracking(
                "a frame without features kept no pixels",
            ));
        };
        let (features, mut counts) =
            extract_undistorted(&mut self.orb, &FrameInput::from_meta(frame, grey))?;
        counts.late_orb += 1;
        observed.features = Some(Arc::new(features));
        observed.grey = None;
        Ok(counts)
    }

    /// Follows the previous frame's points into `frame`, and runs ORB when
    /// `want_features` or when tracking cannot go on (see the module's doc).
    pub fn observe(
        &mut self,
        frame: &FrameInput,
        want_features: bool,
    ) -> Result<(Observed, ChainCounts, TrackReport), ChainError> {
        let mut report = TrackReport::default();
        if !self.enabled {
            let (features, counts) = self.extract(frame)?;
            report.orb = true;
            let observed = Observed::with_features(frame.seq, Arc::new(features));
            return Ok((observed, counts, report));
        }
        let grey = self.grey_of(frame.image)?;
        let mut pyramid = std::mem::take(&mut self.spare_pyramid);
        opencv::video::build_optical_flow_pyramid(
            &*grey,
            &mut pyramid,
            cv::Size::new(KLT_WINDOW, KLT_WINDOW),
            KLT_LEVELS,
            false,
            cv::BORDER_REFLECT_101,
            cv::BORDER_CONSTANT,
            // Copy level 0: the grey image goes back to the pool while the pyramid
            // lives on as the previous frame's.
            false,
        )?;
        let had_points = self
            .previous
            .as_ref()
            .is_some_and(|p| p.ids.len() >= self.min_inliers);
        let followed = match self.previous.as_ref() {
            Some(p) if had_points && frame.seq > p.seq && frame.t_s - p.t_s <= MAX_GAP_S => {
                self.follow(p, &pyramid, frame)?
            }
            _ => None,
        };
        report.lost = had_points && followed.is_none();
        let (points, ids, motion) = match followed {
            Some((points, ids, tracked)) => {
                report = TrackReport {
                    tracked: true,
                    ..TrackReport::default()
                };
                self.step += 1;
                let motion = Motion {
                    epoch: self.epoch,
                    step: self.step,
                    tracked: Arc::new(tracked),
                };
                (points, ids, Some(motion))
            }
            None => {
                // Nothing to follow from here on until the chain seeds this frame.
                self.epoch += 1;
                self.step = 0;
                (cv::Vector::new(), Vec::new(), None)
            }
        };
        // A frame nobody asked features of and that cannot be followed keeps its pixels
        // instead: ORB runs late if its pair turns out to need it.
        let run_orb = want_features || (motion.is_some() && self.refresh_due(frame.seq));
        let mut counts = ChainCounts::default();
        let mut features = None;
        if run_orb {
            let (f, c) = extract_undistorted(&mut self.orb, &frame.with_image(&grey))?;
            counts = c;
            features = Some(Arc::new(f));
            self.last_orb_seq = Some(frame.seq);
            report.orb = true;
        }
        let observed = Observed {
            seq: frame.seq,
            grey: features.is_none().then(|| Arc::clone(&grey)),
            features,
            motion,
        };
        let before = self.previous.replace(Previous {
            seq: frame.seq,
            t_s: frame.t_s,
            pyramid,
            points,
            ids,
        });
        if let Some(before) = before {
            self.spare_pyramid = before.pyramid;
        }
        Ok((observed, counts, report))
    }

    /// Starts a new epoch from frame `seq` (the last one observed) with these ground
    /// points (undistorted pixels): point i gets id i. `None` when the tracker has
    /// moved past that frame (its next frame was observed first): nothing is seeded.
    pub fn seed(
        &mut self,
        seq: u64,
        points: &[cv::Point2f],
        k: &Intrinsics,
        lens: &Distortion,
    ) -> Option<u64> {
        let previous = self.previous.as_mut().filter(|p| p.seq == seq)?;
        previous.points = points
            .iter()
            .map(|p| {
                let [u, v] = lens.distort_pixel(k, p.x as f64, p.y as f64);
                cv::Point2f::new(u as f32, v as f32)
            })
            .collect();
        previous.ids = (0..points.len() as u32).collect();
        self.epoch += 1;
        self.step = 0;
        Some(self.epoch)
    }

    /// KLT from the previous frame, then the check that the followed points agree on
    /// one homography. The kept points (distorted, for the next step), their ids, and
    /// the same undistorted for matching.
    #[allow(clippy::type_complexity)]
    fn follow(
        &self,
        previous: &Previous,
        pyramid: &cv::Vector<cv::Mat>,
        frame: &FrameInput,
    ) -> Result<Option<(cv::Vector<cv::Point2f>, Vec<u32>, TrackedPoints)>, ChainError> {
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
            &previous.points,
            &mut next,
            &mut status,
            &mut error,
            cv::Size::new(KLT_WINDOW, KLT_WINDOW),
            KLT_LEVELS,
            criteria,
            0,
            1e-4,
        )?;
        let (k, lens) = (&frame.intrinsics, &frame.distortion);
        let undistort = |p: cv::Point2f| {
            lens.undistort_pixel(k, p.x as f64, p.y as f64)
                .map(|[u, v]| cv::Point2f::new(u as f32, v as f32))
        };
        let (w, h) = (frame.width as f32, frame.height as f32);
        let mut kept = Vec::with_capacity(next.len());
        let (mut from, mut to) = (
            cv::Vector::<cv::Point2f>::new(),
            cv::Vector::<cv::Point2f>::new(),
        );
        for i in 0..next.len().min(previous.ids.len()) {
            let (a, b) = (next.get(i)?, previous.points.get(i)?);
            if status.get(i)? == 0 || !(a.x >= 0.0 && a.y >= 0.0 && a.x < w && a.y < h) {
                continue;
            }
            let (Some(ua), Some(ub)) = (undistort(a), undistort(b)) else {
                continue;
            };
            from.push(ua);
            to.push(ub);
            kept.push((a, ua, previous.ids[i]));
        }
        if kept.len() < self.min_inliers.max(4) {
            return Ok(None);
        }
        let mut params = usac_params(&self.config, self.ransac_px)?;
        params.max_iterations = self.config.homography_max_iterations;
        let mut mask = cv::Mat::default();
        seed_cv_rng(&[0xf011_0000, frame.seq, kept.len() as u64])?;
        let homography = opencv::calib3d::find_homography_1(&from, &to, &mut mask, params)?;
        if homography.rows() != 3 || mask.rows() != kept.len() as i32 {
            return Ok(None);
        }
        let mut points = cv::Vector::new();
        let (mut ids, mut tracked) = (Vec::new(), TrackedPoints::default());
        for (i, (a, ua, id)) in kept.into_iter().enumerate() {
            if *mask.at::<u8>(i as i32)? != 0 {
                points.push(a);
                ids.push(id);
                tracked.ids.push(id);
                tracked.points.push(ua);
            }
        }
        if ids.len() < self.min_inliers {
            return Ok(None);
        }
        Ok(Some((points, ids, tracked)))
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

    /// Seeds the tracker with (a stride through) the ORB points of an observed frame.
    fn seed_from(tracker: &mut FrameTracker, f: &FrameInput, o: &Observed) -> Vec<cv::Point2f> {
        let points: Vec<cv::Point2f> = o
            .features
            .as_ref()
            .expect("an ORB frame")
            .points
            .iter()
            .step_by(5)
            .copied()
            .collect();
        tracker
            .seed(f.seq, &points, &f.intrinsics, &f.distortion)
            .expect("seeded");
        points
    }

    #[test]
    fn followed_points_land_where_the_image_moved_them() {
        let first = texture();
        // A small turn and drift, as between frames 33 ms apart (and a bit more).
        let (a, t) = (0.6_f64.to_radians(), [3.2, -1.7]);
        let step = Matrix3::new(
            a.cos(),
            -a.sin(),
            t[0],
            a.sin(),
            a.cos(),
            t[1],
            0.0,
            0.0,
            1.0,
        );
        let second = warp(&first, &step);
        let third = warp(&second, &step);
        let config = MatchingConfig::default();
        let mut tracker = FrameTracker::new(&config, Uav::Left).expect("tracker");
        let f1 = frame(1, 0.0, &first);
        let (o1, _, r1) = tracker.observe(&f1, true).expect("first");
        assert!(r1.orb && !r1.tracked, "{r1:?}");
        let seeds = seed_from(&mut tracker, &f1, &o1);
        let (_, _, r2) = tracker
            .observe(&frame(2, 0.033, &second), false)
            .expect("second");
        let (o3, _, r3) = tracker
            .observe(&frame(3, 0.066, &third), false)
            .expect("third");
        assert!(
            r2.tracked && !r2.orb && r3.tracked && !r3.orb,
            "{r2:?} {r3:?}"
        );
        assert!(o3.features.is_none(), "a tracked frame runs no ORB");
        let motion = o3.motion.expect("motion");
        assert_eq!(motion.step, 2);
        let tracked = &motion.tracked;
        assert!(
            tracked.ids.len() * 10 > seeds.len() * 8,
            "{} of {} points followed",
            tracked.ids.len(),
            seeds.len()
        );
        assert!(tracked.ids.windows(2).all(|w| w[0] < w[1]), "ids in order");
        let mut errors: Vec<f64> = tracked
            .ids
            .iter()
            .zip(&tracked.points)
            .map(|(id, p)| {
                let s = seeds[*id as usize];
                let want = apply(&(step * step), [s.x as f64, s.y as f64]);
                ((p.x as f64 - want[0]).powi(2) + (p.y as f64 - want[1]).powi(2)).sqrt()
            })
            .collect();
        errors.sort_by(f64::total_cmp);
        let median = errors[errors.len() / 2];
        assert!(median < 0.1, "median {median} px after two steps");
    }

    #[test]
    fn a_refresh_is_due_every_few_frames_and_a_gap_loses_the_track() {
        let image = texture();
        let config = MatchingConfig {
            track_refresh_frames: 3,
            ..MatchingConfig::default()
        };
        let mut tracker = FrameTracker::new(&config, Uav::Left).expect("tracker");
        let mut orb = Vec::new();
        for i in 0..7 {
            let f = frame(i, i as f64 / 30.0, &image);
            let (o, _, r) = tracker.observe(&f, i == 0).expect("observe");
            if r.orb {
                seed_from(&mut tracker, &f, &o);
            }
            orb.push(r.orb);
        }
        assert_eq!(orb, [true, false, false, true, false, false, true]);
        // A second later: not followed across the gap, and (not asked for) no ORB:
        // the frame keeps its pixels for a late ORB.
        let (o, _, r) = tracker
            .observe(&frame(40, 1.5, &image), false)
            .expect("late");
        assert!(
            r.lost && !r.orb && !r.tracked && o.motion.is_none(),
            "{r:?}"
        );
        assert!(o.features.is_none() && o.grey.is_some());
        // Not seeded (say, no detection in that pair): nothing to follow.
        let (_, _, r) = tracker
            .observe(&frame(41, 1.533, &image), false)
            .expect("next");
        assert!(!r.orb && !r.tracked && !r.lost, "{r:?}");
        // Seeding a frame the tracker has moved past does nothing.
        let f = frame(40, 1.5, &image);
        assert!(tracker
            .seed(
                40,
                &[cv::Point2f::new(1.0, 1.0)],
                &f.intrinsics,
                &f.distortion
            )
            .is_none());
    }

    #[test]
    fn a_tracked_frame_can_still_get_its_features_late() {
        let image = texture();
        let config = MatchingConfig::default();
        let mut tracker = FrameTracker::new(&config, Uav::Left).expect("tracker");
        let f1 = frame(1, 0.0, &image);
        let (o1, _, _) = tracker.observe(&f1, true).expect("first");
        seed_from(&mut tracker, &f1, &o1);
        let f2 = frame(2, 0.033, &image);
        let (mut o, _, r) = tracker.observe(&f2, false).expect("second");
        assert!(!r.orb && o.features.is_none());
        let counts = tracker
            .ensure_features(&mut o, &f2.meta())
            .expect("late ORB");
        assert_eq!(counts.late_orb, 1);
        let n = o.features.as_ref().map_or(0, |f| f.points.len());
        assert!(n > 500, "{n} features");
        // A frame that already has them is left alone.
        let again = tracker.ensure_features(&mut o, &f2.meta()).expect("no-op");
        assert_eq!(again.late_orb, 0);
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
                .observe(&frame(i, i as f64 / 30.0, &image), false)
                .expect("observe");
            assert!(r.orb && o.features.is_some() && o.motion.is_none());
        }
        assert!(tracker.next_step(3).is_none());
    }
}
