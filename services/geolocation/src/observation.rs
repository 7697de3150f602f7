//! The estimator's input: one image's measured navigation state and target pixel.

use crate::EstimatorError;
use nalgebra::{Point3, Vector2, Vector3};
use shared_types::conventions::{Attitude, Intrinsics, Uav};
use shared_types::messages::{ObservationEntry, PoseSample};

/// Identifies an image across geolocations: (UAV, frame sequence number).
pub type ImageId = (Uav, u64);

/// A past image of an observation set, as the temporal filter takes it: its identity
/// (a keyframe reused by many sets is recognised by it), when it was taken and what it
/// shows. The capture time tells the filter how far its UAV's correlated pose error
/// has moved on since (`temporal.rs`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PastImage {
    pub id: ImageId,
    /// Capture time, seconds, on the clock of the set's `t_s`.
    pub t_s: f64,
    pub observation: Observation,
    /// Its camera's rotation from the current left (`[0]`) and right (`[1]`) camera as
    /// the images measure it (`X_past = R X_current`, camera axes, a rotation vector in
    /// radians): the temporal filter's relative-rotation measurement. None where
    /// matching measured none.
    pub rotation_from: [Option<Vector3<f64>>; 2],
}

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

    /// The pose with the bias `yaw_bias[uav]` and a pose error `e` (x, y, z, yaw, pitch,
    /// roll; measured = true + e) removed: the filter's residuals and the start's
    /// meeting point both see an image through it.
    pub fn pose_without_error(&self, yaw_bias: [f64; 2], e: &[f64]) -> (Point3<f64>, Attitude) {
        let mut att = self
            .attitude
            .corrected_for_yaw_bias(yaw_bias[self.uav.index()]);
        att.yaw -= e[3];
        att.pitch -= e[4];
        att.roll -= e[5];
        let position = Point3::new(
            self.position.x - e[0],
            self.position.y - e[1],
            self.position.z - e[2],
        );
        (position, att)
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

impl Observation {
    /// The shared-memory form ([`ObservationEntry`]): pose in degrees, as recorded.
    pub fn to_entry(&self) -> ObservationEntry {
        let a = &self.attitude;
        ObservationEntry {
            uav: self.uav.index() as u8,
            pose: PoseSample {
                x_m: self.position.x,
                y_m: self.position.y,
                z_m: self.position.z,
                yaw_deg: a.yaw.to_degrees(),
                pitch_deg: a.pitch.to_degrees(),
                roll_deg: a.roll.to_degrees(),
            },
            pixel: [self.pixel.x, self.pixel.y],
            intrinsics: [
                self.intrinsics.fx,
                self.intrinsics.fy,
                self.intrinsics.cx,
                self.intrinsics.cy,
            ],
            ..Default::default()
        }
    }

    /// Back from the shared-memory form; `index` names the entry in errors.
    pub fn from_entry(entry: &ObservationEntry, index: usize) -> Result<Self, EstimatorError> {
        let uav = match entry.uav {
            0 => Uav::Left,
            1 => Uav::Right,
            _ => {
                return Err(EstimatorError::NonFinite {
                    index,
                    what: "uav code",
                })
            }
        };
        let [fx, fy, cx, cy] = entry.intrinsics;
        let o = Observation {
            uav,
            position: entry.pose.position(),
            attitude: entry.pose.attitude(),
            pixel: Vector2::new(entry.pixel[0], entry.pixel[1]),
            intrinsics: Intrinsics::new(fx, fy, cx, cy),
        };
        o.validate(index)?;
        Ok(o)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entry_round_trip_and_bad_uav() {
        let o = Observation {
            uav: Uav::Right,
            position: Point3::new(1.0, -2.0, 100.0),
            attitude: Attitude::from_degrees(30.0, 2.0, -1.0),
            pixel: Vector2::new(320.5, 200.25),
            intrinsics: Intrinsics::new(500.0, 501.0, 320.0, 240.0),
        };
        let back = Observation::from_entry(&o.to_entry(), 0).unwrap();
        assert_eq!(back.uav, o.uav);
        assert!((back.position - o.position).norm() < 1e-12);
        assert!((back.attitude.yaw - o.attitude.yaw).abs() < 1e-12);
        assert_eq!(back.pixel, o.pixel);
        let mut bad = o.to_entry();
        bad.uav = 7;
        assert!(Observation::from_entry(&bad, 3).is_err());
        let mut nan = o.to_entry();
        nan.pixel[0] = f64::NAN;
        assert!(Observation::from_entry(&nan, 3).is_err());
    }
}
