//! A frame as matching takes it (pixels, measured pose, detection, camera), ORB on it,
//! and the error and adaptation counts every stage shares: the layer under both the
//! chain ([`crate::chain`]) and frame-to-frame tracking ([`crate::frame_tracking`]),
//! which build on it and not on each other's internals.

use crate::features::{Features, OrbExtractor};
use opencv::core as cv;
use shared_types::conventions::Intrinsics;
use shared_types::lens::Distortion;
use shared_types::messages::{Candidate, DetectionMsg, PoseSample, MAX_CANDIDATES};

/// One current frame as the chain needs it.
#[derive(Debug, Clone, Copy)]
pub struct FrameInput<'a> {
    pub seq: u64,
    pub t_s: f64,
    /// Measured pose (GPS + AHRS).
    pub pose: PoseSample,
    /// BGR or grey pixels.
    pub image: &'a cv::Mat,
    /// The detector's target pixel, if it found the target.
    pub detection: Option<[f64; 2]>,
    pub intrinsics: Intrinsics,
    /// The lens distortion of `image` and `detection` (zeros = pinhole).
    pub distortion: Distortion,
    pub width: u32,
    pub height: u32,
}

impl<'a> FrameInput<'a> {
    /// The same frame with other pixels (its grey copy).
    pub fn with_image<'b>(&self, image: &'b cv::Mat) -> FrameInput<'b> {
        FrameInput::from_meta(&self.meta(), image)
    }

    /// A frame from its description and pixels.
    pub fn from_meta(m: &FrameMeta, image: &'a cv::Mat) -> Self {
        FrameInput {
            seq: m.seq,
            t_s: m.t_s,
            pose: m.pose,
            image,
            detection: m.detection,
            intrinsics: m.intrinsics,
            distortion: m.distortion,
            width: m.width,
            height: m.height,
        }
    }

    /// Everything but the pixels.
    pub fn meta(&self) -> FrameMeta {
        FrameMeta {
            seq: self.seq,
            t_s: self.t_s,
            pose: self.pose,
            detection: self.detection,
            intrinsics: self.intrinsics,
            distortion: self.distortion,
            width: self.width,
            height: self.height,
            others: Others::default(),
        }
    }
}

/// The other objects detection found in a frame beside the target (several targets),
/// in the recorded (distorted) pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Others {
    count: usize,
    items: [Candidate; MAX_CANDIDATES],
}

impl Others {
    /// A detection message's candidates.
    pub fn of(d: &DetectionMsg) -> Self {
        let items = d.candidates();
        let mut out = Self {
            count: items.len(),
            ..Self::default()
        };
        out.items[..items.len()].copy_from_slice(items);
        out
    }

    pub fn as_slice(&self) -> &[Candidate] {
        &self.items[..self.count]
    }
}

/// A current frame without its pixels: what matching needs once ORB has run.
/// `detection` is in the recorded (distorted) pixels; matching undistorts it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameMeta {
    pub seq: u64,
    pub t_s: f64,
    pub pose: PoseSample,
    pub detection: Option<[f64; 2]>,
    pub intrinsics: Intrinsics,
    pub distortion: Distortion,
    pub width: u32,
    pub height: u32,
    /// The other objects detection found (none from a [`FrameInput`]).
    pub others: Others,
}

#[derive(Debug, thiserror::Error)]
pub enum ChainError {
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("OpenCV: {0}")]
    OpenCv(String),
    /// Frame-to-frame tracking lost hold of a frame's pixels (a bug, never input).
    #[error("frame tracking: {0}")]
    Tracking(&'static str),
}

impl From<opencv::Error> for ChainError {
    fn from(e: opencv::Error) -> Self {
        ChainError::OpenCv(e.message)
    }
}

/// What the chain had to adapt since the last [`crate::VisionChain::take_counts`]: the
/// fallbacks and retries that keep it working on scenes unlike the one it was tuned on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ChainCounts {
    /// Current-side matchings run again with `retry_ratio_test`.
    pub retried_looser_ratio: u64,
    /// Of those, the ones that then gave a usable F.
    pub retry_rescued: u64,
    /// Frames whose FAST threshold was lowered for want of corners.
    pub fast_threshold_lowered: u64,
    /// Keypoints dropped because the lens model could not undistort them.
    pub keypoints_outside_lens: u64,
    /// Frames whose ORB features were found on their straight-down view (a tilted or
    /// gimballed camera, `rectify.rs`).
    pub rectified_frames: u64,
    /// Current frames whose detection could not be undistorted.
    pub detections_outside_lens: u64,
    /// Past-image sides whose homography was carried by tracking (no ORB, no fit).
    pub chained_sides: u64,
    /// Refreshes landed (`chain/refresh.rs`).
    pub refreshes: u64,
    /// Of those with ground points, the ones the tracker could not take (the frame no
    /// longer kept, too few followed): the old epoch went on.
    pub refresh_not_followed: u64,
    /// Refreshes OpenCV refused (the frame is lost to the refresh, the chain goes on).
    pub refresh_failed: u64,
    /// Matched sets whose two detections were two vehicles (`chain::target_pair`):
    /// mended from a candidate, or dropped; and sets not checked (no homography
    /// between the current images on this pair).
    pub target_pair_repaired: u64,
    pub target_pair_mismatch: u64,
    pub target_pair_unchecked: u64,
    /// Past images whose transfer failed with a mended pair's pixels.
    pub target_pair_past_dropped: u64,
}

impl std::ops::AddAssign for ChainCounts {
    fn add_assign(&mut self, c: Self) {
        self.retried_looser_ratio += c.retried_looser_ratio;
        self.retry_rescued += c.retry_rescued;
        self.fast_threshold_lowered += c.fast_threshold_lowered;
        self.keypoints_outside_lens += c.keypoints_outside_lens;
        self.rectified_frames += c.rectified_frames;
        self.detections_outside_lens += c.detections_outside_lens;
        self.chained_sides += c.chained_sides;
        self.refreshes += c.refreshes;
        self.refresh_not_followed += c.refresh_not_followed;
        self.refresh_failed += c.refresh_failed;
        self.target_pair_repaired += c.target_pair_repaired;
        self.target_pair_mismatch += c.target_pair_mismatch;
        self.target_pair_unchecked += c.target_pair_unchecked;
        self.target_pair_past_dropped += c.target_pair_past_dropped;
    }
}

/// ORB on one frame, its keypoints then moved to their undistorted positions, with
/// what that took (lowered FAST thresholds, keypoints the lens model dropped).
pub fn extract_undistorted(
    orb: &mut OrbExtractor,
    frame: &FrameInput,
) -> Result<(Features, ChainCounts), ChainError> {
    // A tilted or gimballed camera's frame: ORB on its straight-down view.
    let view = crate::rectify::rectification(
        &frame.intrinsics,
        frame.pose.attitude(),
        frame.width,
        frame.height,
        orb.rectify_above_tilt_deg,
    );
    let (mut features, report) = match &view {
        Some(view) => orb.extract_rectified(frame.image, view)?,
        None => orb.extract_reported(frame.image)?,
    };
    let dropped = features.undistort(
        &frame.intrinsics,
        &frame.distortion,
        frame.width,
        frame.height,
    );
    let counts = ChainCounts {
        fast_threshold_lowered: (report.threshold_lowered > 0) as u64,
        keypoints_outside_lens: dropped as u64,
        rectified_frames: view.is_some() as u64,
        ..ChainCounts::default()
    };
    Ok((features, counts))
}
