//! Typed estimator errors. Every rejection has a reason; none is ever a NaN.

use thiserror::Error;

/// Why the estimator refused an input or could not produce an estimate.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EstimatorError {
    #[error("need at least one image of each UAV and {needed} images in all; got {left} left and {right} right")]
    TooFewImages {
        needed: usize,
        left: usize,
        right: usize,
    },
    #[error("image {index}: {what} is not finite")]
    NonFinite { index: usize, what: &'static str },
    #[error("image {index}: camera intrinsics are invalid (focal lengths must be finite and > 0)")]
    BadIntrinsics { index: usize },
    #[error("image {index}: the target ray does not point below the horizon (down component {down:.3e})")]
    RayNotDownward { index: usize, down: f64 },
    #[error("image {index}: target altitude {z_target:.2} m is not below the UAV at {z_uav:.2} m")]
    TargetAboveUav {
        index: usize,
        z_target: f64,
        z_uav: f64,
    },
    #[error("no usable left/right ray pair: {near_parallel} near-parallel, {behind_camera} meet behind a camera")]
    NoValidRayPair {
        near_parallel: usize,
        behind_camera: usize,
    },
    #[error(
        "weighted least squares is singular or ill-conditioned (reciprocal condition {rcond:.2e})"
    )]
    SingularNormalMatrix { rcond: f64 },
    #[error("the estimate is not finite ({what})")]
    NonFiniteResult { what: &'static str },
    #[error("consistency filter (N = 2): the two past images disagree by {disagreement_deg:.2}° >= TH; geolocation terminated")]
    InconsistentPastImages { disagreement_deg: f64 },
    #[error(
        "only {estimated} past image(s) for the consistency filter to compare; {required} needed"
    )]
    TooFewPastImagesToCompare { estimated: usize, required: usize },
    #[error("the temporal filter has not started: {reason}")]
    NotStarted { reason: &'static str },
    #[error("invalid estimator configuration: {0}")]
    Config(String),
}

impl EstimatorError {
    /// A short stable name for counters and logs (`rejected{reason="near_parallel"}`).
    pub fn kind(&self) -> &'static str {
        match self {
            EstimatorError::TooFewImages { .. } => "too_few_images",
            EstimatorError::NonFinite { .. } => "non_finite_input",
            EstimatorError::BadIntrinsics { .. } => "bad_intrinsics",
            EstimatorError::RayNotDownward { .. } => "ray_not_downward",
            EstimatorError::TargetAboveUav { .. } => "target_above_uav",
            EstimatorError::NoValidRayPair { .. } => "no_valid_ray_pair",
            EstimatorError::SingularNormalMatrix { .. } => "singular_normal_matrix",
            EstimatorError::NonFiniteResult { .. } => "non_finite_result",
            EstimatorError::InconsistentPastImages { .. } => "inconsistent_past_images",
            EstimatorError::TooFewPastImagesToCompare { .. } => "too_few_past_images_to_compare",
            EstimatorError::NotStarted { .. } => "not_started",
            EstimatorError::Config(_) => "config",
        }
    }
}
