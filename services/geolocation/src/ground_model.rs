//! Eq. (1): the target's horizontal position from one image at a given target altitude,
//! `F(τ1, τ2, τ3)` of eq. (7), and its partial derivatives used by eq. (12)–(15).
//!
//! ```text
//! [x_P]   [x_v]    (z_P − z_v)      [1 0 0]
//! [y_P] = [y_v] + ───────────── ·  [0 1 0] · C_w^c · (x_p, y_p, f)ᵀ         (1)
//!                 (0,0,1) C_w^c (x_p, y_p, f)ᵀ
//! ```
//!
//! `(x_p, y_p, f)` is replaced by `K⁻¹ (u, v, 1)ᵀ` (eq. 24's form), which is the same ray
//! for f_x = f_y = f and also handles f_x ≠ f_y; eq. (1) is invariant to the ray's scale.

use crate::{EstimatorError, Observation};
use nalgebra::{Matrix2x6, SMatrix, Vector2, Vector3};
use shared_types::conventions::{
    camera_to_world, yaw_to_world, yaw_to_world_derivative, Attitude, LevelledCamera,
};

/// ∂F/∂τ for one image: τ1 of eq. (5) (own UAV), and τ3's own yaw entry.
pub type Matrix2x7 = SMatrix<f64, 2, 7>;

/// F of one image and its Jacobians at the linearisation point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundFix {
    /// F(γ): (x_P, y_P) from this image, eq. (1).
    pub xy: Vector2<f64>,
    /// ∂F/∂τ1 (or ∂F/∂τ2 for the right UAV): columns x_v, y_v, z_v, x_p, y_p, θ, φ.
    pub d_nav: Matrix2x7,
    /// ∂F/∂ψ of this image's own UAV: the image's column of ∂F/∂τ3 (eq. 12–13).
    pub d_yaw: Vector2<f64>,
    /// ∂F/∂z_P (not in the paper's regression; used by error propagation).
    pub d_z_target: Vector2<f64>,
}

/// One image's target ray with everything that does not depend on the yaw computed once:
/// `C_w^c K⁻¹(u,v,1)ᵀ = yaw_to_world(ψ) · level`, and likewise for the derivatives with
/// respect to pitch, roll and the pixel. The iteration only changes the yaw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreparedRay {
    /// `Ry Rx C_b^c K⁻¹(u,v,1)ᵀ`, and its derivatives by θ, φ, u, v.
    level: Vector3<f64>,
    level_d_pitch: Vector3<f64>,
    level_d_roll: Vector3<f64>,
    level_d_u: Vector3<f64>,
    level_d_v: Vector3<f64>,
}

impl PreparedRay {
    pub fn new(obs: &Observation) -> Self {
        let cam = LevelledCamera::new(obs.attitude.pitch, obs.attitude.roll);
        let ray = obs.intrinsics.pixel_to_ray(obs.pixel);
        Self {
            level: cam.rotation * ray,
            level_d_pitch: cam.d_pitch * ray,
            level_d_roll: cam.d_roll * ray,
            level_d_u: cam.rotation * Vector3::new(1.0 / obs.intrinsics.fx, 0.0, 0.0),
            level_d_v: cam.rotation * Vector3::new(0.0, 1.0 / obs.intrinsics.fy, 0.0),
        }
    }

    /// World direction of the ray for yaw `yaw` (radians).
    pub fn direction(&self, yaw: f64) -> Vector3<f64> {
        yaw_to_world(yaw) * self.level
    }
}

/// The world-frame direction of the target ray of `obs` under `attitude`.
pub fn world_ray(obs: &Observation, attitude: Attitude) -> Vector3<f64> {
    camera_to_world(attitude) * obs.intrinsics.pixel_to_ray(obs.pixel)
}

/// Eq. (1) for image `index`: the target's (x_P, y_P) at altitude `z_target`, using
/// `attitude` (the measured attitude, with the yaw corrected by the current bias
/// estimate) and the measured position.
pub fn ground_xy(
    index: usize,
    obs: &Observation,
    attitude: Attitude,
    z_target: f64,
) -> Result<Vector2<f64>, EstimatorError> {
    let d = world_ray(obs, attitude);
    let scale = ray_scale(index, obs, d, z_target)?;
    Ok(obs.position.xy().coords + scale * d.xy())
}

/// `(z_P − z_v) / ((0,0,1) d)`: how far along `d` the ray meets altitude `z_target`.
fn ray_scale(
    index: usize,
    obs: &Observation,
    d: Vector3<f64>,
    z_target: f64,
) -> Result<f64, EstimatorError> {
    // A ray within ~0.06° of the horizon cannot meet the ground at any sane range.
    const MIN_DOWN: f64 = 1e-3;
    let down = -d.z / d.norm();
    if down.is_nan() || down <= MIN_DOWN {
        return Err(EstimatorError::RayNotDownward { index, down });
    }
    if z_target.is_nan() || z_target >= obs.position.z {
        return Err(EstimatorError::TargetAboveUav {
            index,
            z_target,
            z_uav: obs.position.z,
        });
    }
    Ok((z_target - obs.position.z) / d.z)
}

/// Eq. (1) with its analytic Jacobians with respect to the navigation state τ (eq. 5–6),
/// the yaw (τ3) and the target altitude, for `obs` with its yaw replaced by `yaw`.
///
/// With `d = C_w^c(ψ,θ,φ) K⁻¹(u,v,1)ᵀ`, `h = z_P − z_v` and `F = p_v,xy + h d_xy / d_z`:
/// `∂F/∂x_v = e_x`, `∂F/∂y_v = e_y`, `∂F/∂z_v = −d_xy/d_z`, `∂F/∂z_P = d_xy/d_z` and, for
/// any α that moves the ray, `∂F/∂α = h (d'_xy d_z − d_xy d'_z) / d_z²` with `d' = ∂d/∂α`.
pub fn prepared_ground_fix(
    index: usize,
    obs: &Observation,
    ray: &PreparedRay,
    yaw: f64,
    z_target: f64,
) -> Result<GroundFix, EstimatorError> {
    let world = yaw_to_world(yaw);
    let d = world * ray.level;
    let scale = ray_scale(index, obs, d, z_target)?;
    let h = z_target - obs.position.z;
    let d_xy = d.xy();
    let along = |dd: Vector3<f64>| h * (dd.xy() * d.z - d_xy * dd.z) / (d.z * d.z);

    let d_yaw = along(yaw_to_world_derivative(yaw) * ray.level);
    let d_z_target = d_xy / d.z;
    let mut d_nav = Matrix2x7::zeros();
    d_nav
        .fixed_view_mut::<2, 6>(0, 0)
        .copy_from(&Matrix2x6::from_columns(&[
            Vector2::x(),
            Vector2::y(),
            -d_z_target,
            along(world * ray.level_d_u),
            along(world * ray.level_d_v),
            along(world * ray.level_d_pitch),
        ]));
    d_nav.set_column(6, &along(world * ray.level_d_roll));

    Ok(GroundFix {
        xy: obs.position.xy().coords + scale * d_xy,
        d_nav,
        d_yaw,
        d_z_target,
    })
}

/// [`prepared_ground_fix`] for a single evaluation at `attitude`.
pub fn ground_fix(
    index: usize,
    obs: &Observation,
    attitude: Attitude,
    z_target: f64,
) -> Result<GroundFix, EstimatorError> {
    let obs = Observation { attitude, ..*obs };
    prepared_ground_fix(index, &obs, &PreparedRay::new(&obs), attitude.yaw, z_target)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use proptest::prelude::*;
    use shared_types::conventions::{Intrinsics, Uav};

    fn obs(pos: [f64; 3], att: [f64; 3], px: [f64; 2]) -> Observation {
        Observation {
            uav: Uav::Left,
            position: Point3::from(pos),
            attitude: Attitude::from_degrees(att[0], att[1], att[2]),
            mount: shared_types::conventions::Mount::NADIR,
            pixel: Vector2::from(px),
            intrinsics: Intrinsics::new(554.26, 550.0, 319.5, 239.5),
        }
    }

    #[test]
    fn principal_point_of_level_camera_is_straight_below() {
        let o = obs([10.0, -4.0, 110.0], [37.0, 0.0, 0.0], [319.5, 239.5]);
        let xy = ground_xy(0, &o, o.attitude, 10.0).unwrap();
        assert!((xy - Vector2::new(10.0, -4.0)).norm() < 1e-9);
    }

    #[test]
    fn image_right_is_east_when_nose_north() {
        // 100 m above ground, pixel 55.426 px right of centre = 0.1 rad-ish → 10 m east.
        let o = obs([0.0, 0.0, 100.0], [0.0, 0.0, 0.0], [319.5 + 55.426, 239.5]);
        let xy = ground_xy(0, &o, o.attitude, 0.0).unwrap();
        assert!((xy - Vector2::new(10.0, 0.0)).norm() < 1e-9, "{xy}");
    }

    #[test]
    fn rejects_upward_ray_and_target_above() {
        let o = obs([0.0, 0.0, 100.0], [0.0, 95.0, 0.0], [319.5, 239.5]);
        assert!(matches!(
            ground_xy(3, &o, o.attitude, 0.0),
            Err(EstimatorError::RayNotDownward { index: 3, .. })
        ));
        let o = obs([0.0, 0.0, 100.0], [0.0, 0.0, 0.0], [319.5, 239.5]);
        assert!(matches!(
            ground_xy(1, &o, o.attitude, 120.0),
            Err(EstimatorError::TargetAboveUav { index: 1, .. })
        ));
    }

    /// F as a function of τ = (x_v, y_v, z_v, u, v, θ, φ, ψ, z_P).
    fn f_of(base: &Observation, tau: &[f64; 9]) -> Vector2<f64> {
        let o = Observation {
            position: Point3::new(tau[0], tau[1], tau[2]),
            pixel: Vector2::new(tau[3], tau[4]),
            attitude: Attitude::new(tau[7], tau[5], tau[6]),
            ..*base
        };
        ground_xy(0, &o, o.attitude, tau[8]).unwrap()
    }

    proptest! {
        /// Analytic Jacobians of eq. (1) against central differences.
        #[test]
        fn jacobians_match_central_differences(
            x in -200.0f64..200.0, y in -200.0f64..200.0, z in 60.0f64..160.0,
            u in 0.0f64..640.0, v in 0.0f64..480.0,
            yaw in -180.0f64..180.0, pitch in -12.0f64..12.0, roll in -12.0f64..12.0,
            zt in -20.0f64..30.0,
        ) {
            let o = obs([x, y, z], [yaw, pitch, roll], [u, v]);
            let fix = ground_fix(0, &o, o.attitude, zt).unwrap();
            let tau = [x, y, z, u, v, o.attitude.pitch, o.attitude.roll, o.attitude.yaw, zt];
            // Step sizes suited to each variable's units (m, px, rad).
            let steps = [1e-4, 1e-4, 1e-4, 1e-3, 1e-3, 1e-7, 1e-7, 1e-7, 1e-4];
            let mut numeric = [Vector2::zeros(); 9];
            for (k, h) in steps.iter().enumerate() {
                let (mut lo, mut hi) = (tau, tau);
                lo[k] -= h;
                hi[k] += h;
                numeric[k] = (f_of(&o, &hi) - f_of(&o, &lo)) / (2.0 * h);
            }
            for (k, num) in numeric.iter().take(7).enumerate() {
                let a = fix.d_nav.column(k).into_owned();
                let scale = 1.0 + a.norm();
                prop_assert!((a - num).norm() / scale < 1e-5, "τ1[{k}]: {a} vs {num}");
            }
            prop_assert!((fix.d_yaw - numeric[7]).norm() / (1.0 + fix.d_yaw.norm()) < 1e-5);
            prop_assert!((fix.d_z_target - numeric[8]).norm() / (1.0 + fix.d_z_target.norm()) < 1e-5);
            prop_assert!((fix.xy - f_of(&o, &tau)).norm() < 1e-9);
        }
    }
}
