//! # detection
//!
//! Finding the target in a frame: the [`Detector`] trait, the classical colour-blob
//! detector ([`ColourBlobDetector`], the default) and the YOLO detector over OpenCV DNN
//! ([`yolo`]), run in a stream by [`learned`] with a template tracker between its
//! answers, and the motion detector ([`motion`]: whatever moves against the ground).
//! `[detection] kind` chooses ([`config`]). Detectors see pixels only, never truth.

pub mod camera_swing;
pub mod candidates;
mod colour_blob;
pub mod config;
pub mod constellation;
pub mod frame_view;
mod hue_mask;
pub mod learned;
pub mod motion;
pub mod other_colours;
mod partial_view;
pub mod prediction_gate;
pub mod template_track;
mod tracked;
pub mod yolo;

pub use colour_blob::{ColourBlobConfig, ColourBlobDetector, MAX_LANDMARKS};
pub use partial_view::{PartialViewConfig, PartialViewGuard, TrackHint};
pub use tracked::{TrackCounts, TrackedDetector};

use opencv::core as cv;

/// The target in one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// Bounding box: left, top, width, height in pixels.
    pub bbox: [f64; 4],
    /// The target point's pixel (OpenCV convention: (0, 0) is the top-left pixel's centre).
    pub centre: [f64; 2],
    /// In [0, 1].
    pub confidence: f32,
}

#[derive(Debug, thiserror::Error)]
pub enum DetectError {
    #[error("frame must be 8-bit BGR (3 channels), got {channels} channels of depth {depth}")]
    BadFrame { channels: i32, depth: i32 },
    #[error("bad frame layout: {0}")]
    BadFrameLayout(String),
    #[error("invalid detector configuration: {0}")]
    Config(String),
    #[error("model {path}: {reason}")]
    Model { path: String, reason: String },
    #[error("OpenCV: {0}")]
    OpenCv(String),
}

impl From<opencv::Error> for DetectError {
    fn from(e: opencv::Error) -> Self {
        DetectError::OpenCv(e.message)
    }
}

/// Finds the target in a BGR frame; `Ok(None)` when it is not there.
pub trait Detector: Send {
    fn detect(&mut self, frame: &cv::Mat) -> Result<Option<Detection>, DetectError>;
}

pub(crate) fn check_bgr(frame: &cv::Mat) -> Result<(), DetectError> {
    use opencv::prelude::*;
    if frame.channels() != 3 || frame.depth() != cv::CV_8U {
        return Err(DetectError::BadFrame {
            channels: frame.channels(),
            depth: frame.depth(),
        });
    }
    Ok(())
}
