//! ORB features of one frame, computed once and shared (a keyframe keeps its features,
//! not its pixels).

use opencv::core as cv;
use opencv::prelude::*;

use crate::hamming::{pack, Descriptor};

/// Keypoint positions and their ORB descriptors (same order), packed for
/// [`crate::hamming::knn2`].
#[derive(Debug, Clone, Default)]
pub struct Features {
    pub points: Vec<cv::Point2f>,
    pub descriptors: Vec<Descriptor>,
}

pub struct OrbExtractor {
    orb: cv::Ptr<opencv::features2d::ORB>,
    gray: cv::Mat,
    subpixel: bool,
}

impl OrbExtractor {
    /// `levels` pyramid levels (scale 1.2); `subpixel` refines each keypoint with
    /// `cornerSubPix` (ORB keypoints sit on a level's integer grid: ±1.2^level/2 px).
    pub fn new(features: i32, levels: i32, subpixel: bool) -> opencv::Result<Self> {
        Ok(Self {
            orb: opencv::features2d::ORB::create(
                features,
                1.2,
                levels,
                31,
                0,
                2,
                opencv::features2d::ORB_ScoreType::HARRIS_SCORE,
                31,
                20,
            )?,
            gray: cv::Mat::default(),
            subpixel,
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
        Ok(Features {
            points: points.to_vec(),
            descriptors: packed,
        })
    }
}
