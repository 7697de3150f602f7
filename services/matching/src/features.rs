//! ORB features of one frame, computed once and shared (a keyframe keeps its features,
//! not its pixels).

use opencv::core as cv;
use opencv::prelude::*;

use crate::config::{MatchingConfig, OrbScore};
use crate::grid::PointGrid;
use crate::hamming::{pack, Descriptor};

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

pub struct OrbExtractor {
    orb: cv::Ptr<opencv::features2d::ORB>,
    gray: cv::Mat,
    subpixel: bool,
}

impl OrbExtractor {
    /// ORB as `config` says: `orb_features` keypoints ranked by `orb_score` on
    /// `orb_levels` pyramid levels (scale 1.2), refined with `cornerSubPix` when
    /// `subpixel_keypoints` (ORB keypoints sit on a level's integer grid:
    /// ±1.2^level/2 px).
    pub fn new(config: &MatchingConfig) -> opencv::Result<Self> {
        let score = match config.orb_score {
            OrbScore::Fast => opencv::features2d::ORB_ScoreType::FAST_SCORE,
            OrbScore::Harris => opencv::features2d::ORB_ScoreType::HARRIS_SCORE,
        };
        Ok(Self {
            orb: opencv::features2d::ORB::create(
                config.orb_features,
                1.2,
                config.orb_levels,
                31,
                0,
                2,
                score,
                31,
                20,
            )?,
            gray: cv::Mat::default(),
            subpixel: config.subpixel_keypoints,
        })
    }

    /// ORB on a BGR or grey frame.
    pub fn extract(&mut self, frame: &cv::Mat) -> opencv::Result<Features> {
        let gray = if frame.channels() == 3 {
            opencv::imgproc::cvt_color_def(frame, &mut self.gray, opencv::imgproc::COLOR_BGR2GRAY)?;
            &self.gray
        } else {
            frame
        };
        let mut keypoints = cv::Vector::<cv::KeyPoint>::new();
        let mut descriptors = cv::Mat::default();
        self.orb
            .detect_and_compute_def(gray, &cv::no_array(), &mut keypoints, &mut descriptors)?;
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
        Ok(Features::new(
            points.to_vec(),
            packed,
            gray.cols().max(0) as u32,
            gray.rows().max(0) as u32,
        ))
    }
}
