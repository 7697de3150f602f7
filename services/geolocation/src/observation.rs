//! The estimator's input: one image's measured navigation state and target pixel.

use crate::EstimatorError;
use nalgebra::{Point3, Vector2};
use shared_types::conventions::{Attitude, Intrinsics, Uav};

/// One image `g_k`: the measured state γ of its UAV when it was taken and the pixel of
/// the target's *current* position P in it (from detection for the current images,
/// from corresponding-point matching for past ones).
///
/// The camera centre is taken to be the UAV position (the paper's model, eq. 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    pub uav: Uav,
    /// Measured position (GPS), world ENU, metres: (x_v, y_v, z_v).
    pub position: Point3<f64>,
    /// Measured attitude (AHRS), radians. Its yaw carries the unknown bias δψ.
    pub attitude: Attitude,
    /// Target pixel (u, v), OpenCV convention, undistorted.
    pub pixel: Vector2<f64>,
    pub intrinsics: Intrinsics,
}

impl Observation {
    /// Eq. (19)'s yaw: the measured yaw with this image's UAV's bias estimate removed
    /// (`yaw_bias` indexed by `Uav::index`, radians; measured = true + bias, eq. 10).
    pub fn corrected_yaw(&self, yaw_bias: [f64; 2]) -> f64 {
        self.attitude
            .corrected_for_yaw_bias(yaw_bias[self.uav.index()])
            .yaw
    }

    /// Checks that every number is finite and the intrinsics are usable.
    pub fn validate(&self, index: usize) -> Result<(), EstimatorError> {
        let finite = |ok: bool, what| {
            if ok {
                Ok(())
            } else {
                Err(EstimatorError::NonFinite { index, what })
            }
        };
        finite(self.position.iter().all(|v| v.is_finite()), "position")?;
        finite(self.attitude.is_finite(), "attitude")?;
        finite(self.pixel.iter().all(|v| v.is_finite()), "pixel")?;
        if !self.intrinsics.is_valid() {
            return Err(EstimatorError::BadIntrinsics { index });
        }
        Ok(())
    }
}

/// Validates a whole observation set: finite, both UAVs present, at least `needed` images.
pub fn validate_set(observations: &[Observation], needed: usize) -> Result<(), EstimatorError> {
    let left = observations.iter().filter(|o| o.uav == Uav::Left).count();
    let right = observations.len() - left;
    if left == 0 || right == 0 || observations.len() < needed {
        return Err(EstimatorError::TooFewImages {
            needed,
            left,
            right,
        });
    }
    observations
        .iter()
        .enumerate()
        .try_for_each(|(i, o)| o.validate(i))
}
