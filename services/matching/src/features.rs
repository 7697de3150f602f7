//! ORB features of one frame, computed once and shared (a keyframe keeps its features,
//! not its pixels).

use opencv::core as cv;
use opencv::prelude::*;

use crate::config::{MatchingConfig, OrbScore};
use crate::grid::PointGrid;
use crate::hamming::{pack, Descriptor};
use crate::rectify::Rectification;
use shared_types::conventions::Intrinsics;
use shared_types::lens::Distortion;

/// Keypoints of a rectified view stay this far (pixels, the ORB patch's size) inside
/// the frame's footprint.
const RECTIFIED_EDGE_PX: i32 = 31;

/// Cell size of [`Features::grid`], pixels.
const GRID_CELL_PX: f32 = 32.0;

/// Keypoint positions and their ORB descriptors (same order), packed for
/// [`crate::hamming::knn2`], and bucketed for guided matching.
#[derive(Debug, Clone, Default)]
pub struct Features {
    pub points: Vec<cv::Point2f>,
    pub descriptors: Vec<Descriptor>,
    pub grid: PointGrid,
}

impl Features {
    pub fn new(
        points: Vec<cv::Point2f>,
        descriptors: Vec<Descriptor>,
        width: u32,
        height: u32,
    ) -> Self {
        let xy: Vec<[f32; 2]> = points.iter().map(|p| [p.x, p.y]).collect();
        Self {
            grid: PointGrid::new(&xy, width, height, GRID_CELL_PX),
            points,
            descriptors,
        }
    }
}

impl Features {
    /// Moves every keypoint to its undistorted position (the ideal pinhole pixel of the
    /// same K), so epipolar geometry holds on them; keypoints the lens model cannot
    /// invert are dropped with their descriptors. Returns how many were dropped.
    pub fn undistort(
        &mut self,
        k: &Intrinsics,
        lens: &Distortion,
        width: u32,
        height: u32,
    ) -> usize {
        if lens.is_none() {
            return 0;
        }
        let before = self.points.len();
        let mut points = Vec::with_capacity(before);
        let mut descriptors = Vec::with_capacity(before);
        for (p, d) in self.points.iter().zip(&self.descriptors) {
            if let Some([u, v]) = lens.undistort_pixel(k, p.x as f64, p.y as f64) {
                points.push(cv::Point2f::new(u as f32, v as f32));
                descriptors.push(*d);
            }
        }
        *self = Features::new(points, descriptors, width, height);
        before - self.points.len()
    }
}

pub struct OrbExtractor {
    orb: cv::Ptr<opencv::features2d::ORB>,
    gray: cv::Mat,
    /// A rectified view's pixels and keypoint mask, and the frame's footprint
    /// (`extract_rectified`), kept between frames.
    warped: cv::Mat,
    mask: cv::Mat,
    footprint: cv::Mat,
    /// `rectify_above_tilt_deg`.
    pub rectify_above_tilt_deg: f64,
    subpixel: bool,
    budget: usize,
    scale_with_area: bool,
    candidate_factor: usize,
    spread_cells: usize,
    fast_thresholds: Vec<i32>,
}

/// What one extraction did beyond the plain ORB call (matching's counters).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ExtractReport {
    /// FAST candidates before spreading.
    pub candidates: usize,
    /// Times the FAST threshold was lowered because the frame had too few corners.
    pub threshold_lowered: usize,
}

impl OrbExtractor {
    /// ORB as `config` says: `orb_features` keypoints ranked by `orb_score` on
    /// `orb_levels` pyramid levels (scale 1.2), refined with `cornerSubPix` when
    /// `subpixel_keypoints` (ORB keypoints sit on a level's integer grid:
    /// ±1.2^level/2 px).
    ///
    /// With `orb_spread_cells > 0` the features are spread over the image: ORB detects
    /// `orb_candidate_factor` × the budget, the image is cut into about
    /// `orb_spread_cells` cells, and each cell keeps its best keypoints up to an equal
    /// share of the budget; the share cells could not use goes to the best of the rest.
    /// Without it, a frame whose roofs and facades are busier than its ground gives
    /// nearly all its features to the buildings, and the ground plane (the geometry
    /// matching relies on) starves. A frame with fewer candidates than the budget is
    /// detected again at lower FAST thresholds (`orb_fast_thresholds`): the open,
    /// low-texture scenes.
    pub fn new(config: &MatchingConfig) -> opencv::Result<Self> {
        let score = match config.orb_score {
            OrbScore::Fast => opencv::features2d::ORB_ScoreType::FAST_SCORE,
            OrbScore::Harris => opencv::features2d::ORB_ScoreType::HARRIS_SCORE,
        };
        let spread = config.orb_spread_cells > 0;
        let factor = if spread {
            config.orb_candidate_factor.max(1)
        } else {
            1
        };
        let thresholds = if config.orb_fast_thresholds.is_empty() {
            vec![20]
        } else {
            config.orb_fast_thresholds.clone()
        };
        Ok(Self {
            orb: opencv::features2d::ORB::create(
                config.orb_features.saturating_mul(factor),
                1.2,
                config.orb_levels,
                31,
                0,
                2,
                score,
                31,
                thresholds[0],
            )?,
            gray: cv::Mat::default(),
            warped: cv::Mat::default(),
            mask: cv::Mat::default(),
            footprint: cv::Mat::default(),
            rectify_above_tilt_deg: config.rectify_above_tilt_deg,
            subpixel: config.subpixel_keypoints,
            budget: config.orb_features.max(0) as usize,
            scale_with_area: config.orb_scale_with_area,
            candidate_factor: factor.max(1) as usize,
            spread_cells: config.orb_spread_cells,
            fast_thresholds: thresholds,
        })
    }

    /// The feature budget of a `width` × `height` frame: `orb_features` up to 640 × 480,
    /// then in proportion to the pixel count (at most 2×) when `orb_scale_with_area`.
    pub fn budget_for(&self, width: i32, height: i32) -> usize {
        if !self.scale_with_area {
            return self.budget;
        }
        let ratio = (width.max(0) as f64 * height.max(0) as f64) / (640.0 * 480.0);
        (self.budget as f64 * ratio.clamp(1.0, 2.0)).round() as usize
    }

    /// ORB on a BGR or grey frame.
    pub fn extract(&mut self, frame: &cv::Mat) -> opencv::Result<Features> {
        self.extract_reported(frame).map(|(f, _)| f)
    }

    /// [`OrbExtractor::extract`], and what it had to do.
    pub fn extract_reported(
        &mut self,
        frame: &cv::Mat,
    ) -> opencv::Result<(Features, ExtractReport)> {
        let grey = self.grey_of(frame)?;
        let gray = grey.as_ref().unwrap_or(frame);
        let (width, height) = (gray.cols(), gray.rows());
        let budget = self.budget_for(width, height);
        let detected = self.detect(gray, &cv::no_array(), budget);
        if let Some(g) = grey {
            self.gray = g;
        }
        let (points, packed, report) = detected?;
        let features = Features::new(
            points.to_vec(),
            packed,
            width.max(0) as u32,
            height.max(0) as u32,
        );
        Ok((features, report))
    }

    /// ORB on `view`, the frame warped to look straight down (`crate::rectify`): the
    /// keypoints are found and described on the view, inside the frame's footprint, and
    /// returned at their positions in the frame. The budget is the frame's.
    pub fn extract_rectified(
        &mut self,
        frame: &cv::Mat,
        view: &Rectification,
    ) -> opencv::Result<(Features, ExtractReport)> {
        let grey = self.grey_of(frame)?;
        let gray = grey.as_ref().unwrap_or(frame);
        let (width, height) = (gray.cols(), gray.rows());
        let budget = self.budget_for(width, height);
        let h = view.homography;
        let h_cv = cv::Mat::from_slice_2d(&[
            [h[(0, 0)], h[(0, 1)], h[(0, 2)]],
            [h[(1, 0)], h[(1, 1)], h[(1, 2)]],
            [h[(2, 0)], h[(2, 1)], h[(2, 2)]],
        ])?;
        let size = cv::Size::new(view.size[0], view.size[1]);
        let mut warped = std::mem::take(&mut self.warped);
        let mut mask = std::mem::take(&mut self.mask);
        let mut footprint = std::mem::take(&mut self.footprint);
        opencv::imgproc::warp_perspective(
            gray,
            &mut warped,
            &h_cv,
            size,
            opencv::imgproc::INTER_LINEAR,
            cv::BORDER_REPLICATE,
            cv::Scalar::default(),
        )?;
        // Keypoints only where the frame is, a patch's half-width inside its edge (the
        // replicated border has no texture of its own, but its seam does).
        if let Some(g) = grey {
            self.gray = g;
        }
        if (footprint.cols(), footprint.rows()) != (width, height) {
            footprint = cv::Mat::new_rows_cols_with_default(
                height,
                width,
                cv::CV_8UC1,
                cv::Scalar::all(255.0),
            )?;
        }
        opencv::imgproc::warp_perspective(
            &footprint,
            &mut mask,
            &h_cv,
            size,
            opencv::imgproc::INTER_NEAREST,
            cv::BORDER_CONSTANT,
            cv::Scalar::all(0.0),
        )?;
        let kernel = opencv::imgproc::get_structuring_element_def(
            opencv::imgproc::MORPH_RECT,
            cv::Size::new(RECTIFIED_EDGE_PX, RECTIFIED_EDGE_PX),
        )?;
        let mut eroded = cv::Mat::default();
        opencv::imgproc::erode_def(&mask, &mut eroded, &kernel)?;
        let detected = self.detect(&warped, &eroded, budget);
        (self.warped, self.mask, self.footprint) = (warped, eroded, footprint);
        let (points, packed, report) = detected?;
        let back = h.try_inverse().ok_or_else(|| {
            opencv::Error::new(cv::StsBadArg, "rectifying homography is singular")
        })?;
        let mut kept_points = Vec::with_capacity(points.len());
        let mut kept = Vec::with_capacity(points.len());
        for (p, d) in points.iter().zip(packed) {
            let q = back * nalgebra::Vector3::new(p.x as f64, p.y as f64, 1.0);
            let (u, v) = (q.x / q.z, q.y / q.z);
            let inside = q.z > 0.0
                && (0.0..=(width - 1) as f64).contains(&u)
                && (0.0..=(height - 1) as f64).contains(&v);
            if inside {
                kept_points.push(cv::Point2f::new(u as f32, v as f32));
                kept.push(d);
            }
        }
        let features = Features::new(kept_points, kept, width.max(0) as u32, height.max(0) as u32);
        Ok((features, report))
    }

    /// A BGR frame in grey, in the extractor's buffer taken out of it (the caller puts
    /// it back); none for a frame already grey.
    fn grey_of(&mut self, frame: &cv::Mat) -> opencv::Result<Option<cv::Mat>> {
        if frame.channels() != 3 {
            return Ok(None);
        }
        let mut grey = std::mem::take(&mut self.gray);
        opencv::imgproc::cvt_color_def(frame, &mut grey, opencv::imgproc::COLOR_BGR2GRAY)?;
        Ok(Some(grey))
    }

    /// FAST (thresholds lowered while the image has fewer candidates than the budget),
    /// spread, described and packed; sub-pixel positions when configured.
    fn detect(
        &mut self,
        gray: &cv::Mat,
        mask: &impl cv::ToInputArray,
        budget: usize,
    ) -> opencv::Result<(cv::Vector<cv::Point2f>, Vec<Descriptor>, ExtractReport)> {
        let mut report = ExtractReport::default();
        self.orb.set_max_features(
            budget
                .saturating_mul(self.candidate_factor)
                .min(i32::MAX as usize) as i32,
        )?;
        let mut keypoints = cv::Vector::<cv::KeyPoint>::new();
        for (i, &threshold) in self.fast_thresholds.iter().enumerate() {
            self.orb.set_fast_threshold(threshold)?;
            self.orb.detect(gray, &mut keypoints, mask)?;
            let last = i + 1 == self.fast_thresholds.len();
            if keypoints.len() >= budget || last {
                break;
            }
            report.threshold_lowered += 1;
        }
        report.candidates = keypoints.len();
        if self.spread_cells > 0 && keypoints.len() > budget {
            keypoints = spread(
                &keypoints,
                budget,
                self.spread_cells,
                gray.cols(),
                gray.rows(),
            );
        }
        let mut descriptors = cv::Mat::default();
        self.orb.compute(gray, &mut keypoints, &mut descriptors)?;
        let mut points: cv::Vector<cv::Point2f> = keypoints.iter().map(|k| k.pt()).collect();
        if self.subpixel && !points.is_empty() {
            let criteria =
                cv::TermCriteria::new(cv::TermCriteria_COUNT + cv::TermCriteria_EPS, 20, 0.01)?;
            opencv::imgproc::corner_sub_pix(
                gray,
                &mut points,
                cv::Size::new(2, 2),
                cv::Size::new(-1, -1),
                criteria,
            )?;
        }
        let mut packed = Vec::with_capacity(points.len());
        for r in 0..descriptors.rows() {
            let row = descriptors.at_row::<u8>(r)?;
            packed.push(pack(row).ok_or_else(|| {
                opencv::Error::new(cv::StsBadSize, "ORB descriptor is not 32 bytes")
            })?);
        }
        Ok((points, packed, report))
    }
}

/// Keeps `budget` of `keypoints` spread over a grid of about `cells` cells of a
/// `width` × `height` image: each cell its best (by response) up to an equal share, then
/// the best of the rest until the budget is spent. Deterministic: ties keep ORB's order.
pub fn spread(
    keypoints: &cv::Vector<cv::KeyPoint>,
    budget: usize,
    cells: usize,
    width: i32,
    height: i32,
) -> cv::Vector<cv::KeyPoint> {
    let (w, h) = (width.max(1) as f64, height.max(1) as f64);
    let cols = ((cells as f64 * w / h).sqrt().round() as usize).max(1);
    let rows = (cells / cols).max(1);
    let cell_of = |k: &cv::KeyPoint| {
        let p = k.pt();
        let c = ((p.x as f64 / w * cols as f64) as usize).min(cols - 1);
        let r = ((p.y as f64 / h * rows as f64) as usize).min(rows - 1);
        r * cols + c
    };
    let mut order: Vec<usize> = (0..keypoints.len()).collect();
    let response: Vec<f32> = keypoints.iter().map(|k| k.response()).collect();
    order.sort_by(|&a, &b| response[b].total_cmp(&response[a]));
    let share = budget.div_ceil(cols * rows);
    let mut used = vec![0usize; cols * rows];
    let mut keep = vec![false; keypoints.len()];
    let mut kept = 0;
    for &i in &order {
        if kept == budget {
            break;
        }
        let Ok(k) = keypoints.get(i) else { continue };
        let c = cell_of(&k);
        if used[c] < share {
            used[c] += 1;
            keep[i] = true;
            kept += 1;
        }
    }
    for &i in &order {
        if kept == budget {
            break;
        }
        if !keep[i] {
            keep[i] = true;
            kept += 1;
        }
    }
    keypoints
        .iter()
        .zip(keep)
        .filter_map(|(k, kept)| kept.then_some(k))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keypoint(x: f32, y: f32, response: f32) -> cv::KeyPoint {
        cv::KeyPoint::new_coords(x, y, 31.0, -1.0, response, 0, -1).unwrap()
    }

    #[test]
    fn spreading_gives_the_quiet_half_its_share() {
        // 400 strong corners in the left half (a busy roof), 100 weak ones in the right
        // half (the ground).
        let mut all = cv::Vector::<cv::KeyPoint>::new();
        for i in 0..400 {
            all.push(keypoint(
                (i % 20) as f32 * 15.0,
                (i / 20) as f32 * 23.0,
                100.0 + i as f32,
            ));
        }
        for i in 0..100 {
            all.push(keypoint(
                330.0 + (i % 10) as f32 * 30.0,
                (i / 10) as f32 * 47.0,
                10.0,
            ));
        }
        let kept = spread(&all, 200, 48, 640, 480);
        assert_eq!(kept.len(), 200);
        let right = kept.iter().filter(|k| k.pt().x >= 320.0).count();
        // By response alone the right half would get none.
        assert!(right >= 80, "right half kept {right}");
    }

    #[test]
    fn spreading_fills_the_budget_from_the_best_when_cells_run_dry() {
        let mut all = cv::Vector::<cv::KeyPoint>::new();
        for i in 0..300 {
            all.push(keypoint(
                5.0 + (i % 10) as f32,
                5.0 + (i / 10) as f32,
                i as f32,
            ));
        }
        let kept = spread(&all, 100, 48, 640, 480);
        assert_eq!(kept.len(), 100);
        let weakest = kept
            .iter()
            .map(|k| k.response())
            .fold(f32::INFINITY, f32::min);
        assert!(weakest >= 200.0, "kept a weak one: {weakest}");
    }

    #[test]
    fn the_budget_follows_the_pixel_count_above_vga() {
        let config = MatchingConfig::default();
        let orb = OrbExtractor::new(&config).unwrap();
        let base = config.orb_features as usize;
        assert_eq!(orb.budget_for(640, 480), base);
        assert_eq!(
            orb.budget_for(320, 240),
            base,
            "smaller frames keep the base budget"
        );
        assert_eq!(
            orb.budget_for(800, 600),
            (base as f64 * 1.5625).round() as usize
        );
        assert_eq!(orb.budget_for(1280, 720), 2 * base, "capped at 2x");
        let fixed = OrbExtractor::new(&MatchingConfig {
            orb_scale_with_area: false,
            ..config
        })
        .unwrap();
        assert_eq!(fixed.budget_for(1280, 720), base);
    }
}
