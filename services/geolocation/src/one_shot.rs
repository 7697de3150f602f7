//! The one-shot baseline of Section 3.1: one image, the UAV–target distance known
//! (e.g. a laser rangefinder), the measured attitude taken as exact, no bias estimation.
//! The target is the point at that distance along the image's target ray.

use crate::ground_model::world_ray;
use crate::{EstimatorError, Observation};
use nalgebra::Point3;

/// `P = O_v + r · d / |d|` with `d = C_w^c K⁻¹ (u, v, 1)ᵀ` from the measured attitude.
pub fn one_shot(observation: &Observation, range_m: f64) -> Result<Point3<f64>, EstimatorError> {
    observation.validate(0)?;
    if !(range_m.is_finite() && range_m > 0.0) {
        return Err(EstimatorError::NonFinite {
            index: 0,
            what: "range (must be finite and > 0)",
        });
    }
    let d = world_ray(observation, observation.attitude);
    let down = -d.z / d.norm();
    if down.is_nan() || down <= 0.0 {
        return Err(EstimatorError::RayNotDownward { index: 0, down });
    }
    Ok(observation.position + d.normalize() * range_m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;
    use shared_types::conventions::{Attitude, Intrinsics, Uav};

    #[test]
    fn exact_pose_and_range_give_the_target() {
        let k = Intrinsics::from_hfov(640, 480, 60.0);
        let target = Point3::new(5.0, 30.0, 12.0);
        let position = Point3::new(-30.0, 28.0, 112.0);
        let attitude = Attitude::from_degrees(40.0, 3.0, -2.0);
        let cam =
            shared_types::conventions::camera_to_world(attitude).transpose() * (target - position);
        let obs = Observation {
            uav: Uav::Left,
            position,
            attitude,
            mount: shared_types::conventions::Mount::NADIR,
            pixel: k.project(cam).unwrap(),
            intrinsics: k,
        };
        let p = one_shot(&obs, (target - position).norm()).unwrap();
        assert!((p - target).norm() < 1e-9);
        assert!(one_shot(&obs, f64::NAN).is_err());
        let bad = Observation {
            pixel: Vector2::new(f64::INFINITY, 0.0),
            ..obs
        };
        assert!(one_shot(&bad, 10.0).is_err());
    }
}
