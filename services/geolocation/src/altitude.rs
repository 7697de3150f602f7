//! Section 2.2: the target's altitude z_P from every left/right image pair, by the
//! midpoint of the common perpendicular of the two rays (eq. 16–18), per-image means
//! (eq. 20) and least squares over all images (eq. 21–23).
//!
//! The paper writes eq. (16) in the left camera frame (`T_RL`, `R_RL`). The midpoint is
//! invariant to the frame it is computed in, so it is computed here in the world frame:
//! `[d_L, −d_R, d_L × d_R] (a, b, c)ᵀ = O_R − O_L` with world rays `d = C_w^c K⁻¹(u,v,1)ᵀ`.
//! Eq. (17)/(18) then read `h_ij = z_vL − z_P'` and `h_ji = z_vR − z_P'`, the relative
//! altitude (eq. 2, positive down) of the midpoint P' below each camera.

use crate::ground_model::PreparedRay;
use crate::{EstimatorError, Observation};
use nalgebra::{Matrix3, Point3, Vector3};
use shared_types::conventions::Uav;

/// The closest points of two rays, eq. (16).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayPairMidpoint {
    /// a₀, b₀: distances along the left and right rays (in ray lengths).
    pub a: f64,
    pub b: f64,
    /// P': midpoint of the common perpendicular.
    pub midpoint: Point3<f64>,
    /// Length of the common perpendicular (how far the rays miss each other), metres.
    pub gap_m: f64,
}

/// Why a ray pair was left out of eq. (20).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PairRejection {
    NearParallel,
    BehindCamera,
}

/// Eq. (16): solve `[d_L, −d_R, d_L × d_R] (a, b, c)ᵀ = O_R − O_L` for the endpoints of
/// the common perpendicular J of the rays `O_L + a d_L` and `O_R + b d_R`.
pub fn ray_pair_midpoint(
    origin_left: Point3<f64>,
    dir_left: Vector3<f64>,
    origin_right: Point3<f64>,
    dir_right: Vector3<f64>,
    min_angle_rad: f64,
) -> Result<RayPairMidpoint, PairRejection> {
    let cross = dir_left.cross(&dir_right);
    let sin_angle = cross.norm() / (dir_left.norm() * dir_right.norm());
    if sin_angle.is_nan() || sin_angle <= min_angle_rad.sin().max(1e-9) {
        return Err(PairRejection::NearParallel);
    }
    let m = Matrix3::from_columns(&[dir_left, -dir_right, cross]);
    let abc = m
        .lu()
        .solve(&(origin_right - origin_left))
        .ok_or(PairRejection::NearParallel)?;
    let (a, b) = (abc.x, abc.y);
    if !(a > 0.0 && b > 0.0) {
        return Err(PairRejection::BehindCamera);
    }
    let end_left = origin_left + a * dir_left;
    let end_right = origin_right + b * dir_right;
    Ok(RayPairMidpoint {
        a,
        b,
        midpoint: Point3::from((end_left.coords + end_right.coords) / 2.0),
        gap_m: (end_right - end_left).norm(),
    })
}

/// Result of Section 2.2.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AltitudeEstimate {
    /// z_P of eq. (23), world ENU metres.
    pub z_target: f64,
    /// Sample standard error of z_P from the residuals of eq. (22) (0 with fewer than
    /// two contributing images). A spread, not a calibrated σ.
    pub std_error_m: f64,
    /// Images that had at least one usable pair (the rows of eq. 22).
    pub images_used: usize,
    pub pairs_used: usize,
    pub pairs_near_parallel: usize,
    pub pairs_behind_camera: usize,
}

/// Section 2.2 over all left/right image pairs: eq. (16)–(23).
///
/// `yaw_bias[uav]` (radians) is removed from each measured yaw before the rays are built
/// (eq. 19; measured = true + bias per eq. 10, so the correction is `ψ − δψ`; the paper's
/// `ψ + δψ` in eq. 19 is read as the same correction under the opposite sign convention).
/// Works for any numbers of left and right images (N_L × N_R pairs); the paper's case is
/// N_L = N_R = N.
pub fn estimate_altitude(
    observations: &[Observation],
    rays: &[PreparedRay],
    yaw_bias: [f64; 2],
    min_ray_angle_rad: f64,
) -> Result<AltitudeEstimate, EstimatorError> {
    struct Image {
        dir: Vector3<f64>,
        h_sum: f64,
        h_count: usize,
    }
    let mut images: Vec<Image> = observations
        .iter()
        .zip(rays)
        .map(|(o, ray)| Image {
            dir: ray.direction(o.corrected_yaw(yaw_bias)),
            h_sum: 0.0,
            h_count: 0,
        })
        .collect();
    let (mut pairs_used, mut near_parallel, mut behind) = (0, 0, 0);

    for (i, left) in observations.iter().enumerate() {
        if left.uav != Uav::Left {
            continue;
        }
        for (j, right) in observations.iter().enumerate() {
            if right.uav != Uav::Right {
                continue;
            }
            match ray_pair_midpoint(
                left.position,
                images[i].dir,
                right.position,
                images[j].dir,
                min_ray_angle_rad,
            ) {
                Ok(pair) => {
                    // Eq. (17): h_ij, relative altitude below the left camera.
                    images[i].h_sum += left.position.z - pair.midpoint.z;
                    images[i].h_count += 1;
                    // Eq. (18): h_ji, relative altitude below the right camera.
                    images[j].h_sum += right.position.z - pair.midpoint.z;
                    images[j].h_count += 1;
                    pairs_used += 1;
                }
                Err(PairRejection::NearParallel) => near_parallel += 1,
                Err(PairRejection::BehindCamera) => behind += 1,
            }
        }
    }
    if pairs_used == 0 {
        return Err(EstimatorError::NoValidRayPair {
            near_parallel,
            behind_camera: behind,
        });
    }

    // Eq. (20): h̄_k = mean of image k's relative altitudes. Eq. (22)'s right-hand side
    // is z_v,k − h̄_k; eq. (23) with J = ones is its mean.
    let mut rhs_sum = 0.0;
    let mut rhs_sq = 0.0;
    let mut images_used = 0usize;
    for (o, image) in observations.iter().zip(&images) {
        if image.h_count == 0 {
            continue;
        }
        let h_bar = image.h_sum / image.h_count as f64;
        let row = o.position.z - h_bar;
        rhs_sum += row;
        rhs_sq += row * row;
        images_used += 1;
    }
    let n = images_used as f64;
    // Eq. (23): z_P = (JᵀJ)⁻¹ Jᵀ r = mean(r) for J = 1_{2N×1}.
    let z_target = rhs_sum / n;
    let std_error_m = if images_used > 1 {
        let var = ((rhs_sq - n * z_target * z_target) / (n - 1.0)).max(0.0);
        (var / n).sqrt()
    } else {
        0.0
    };
    if !z_target.is_finite() || !std_error_m.is_finite() {
        return Err(EstimatorError::NonFiniteResult {
            what: "target altitude",
        });
    }
    Ok(AltitudeEstimate {
        z_target,
        std_error_m,
        images_used,
        pairs_used,
        pairs_near_parallel: near_parallel,
        pairs_behind_camera: behind,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn crossing_rays_meet_at_their_intersection() {
        let p = Point3::new(3.0, 4.0, 12.0);
        let ol = Point3::new(-35.0, 0.0, 110.0);
        let or = Point3::new(35.0, 2.0, 109.0);
        let m = ray_pair_midpoint(ol, (p - ol) * 0.01, or, (p - or) * 0.02, 0.01).unwrap();
        assert!((m.midpoint - p).norm() < 1e-9);
        assert!(m.gap_m < 1e-9);
        assert!((m.a - 100.0).abs() < 1e-6 && (m.b - 50.0).abs() < 1e-6);
    }

    #[test]
    fn parallel_and_behind_are_rejected() {
        let d = Vector3::new(0.1, 0.0, -1.0);
        let o = Point3::origin();
        assert_eq!(
            ray_pair_midpoint(o, d, Point3::new(5.0, 0.0, 0.0), d, 0.01),
            Err(PairRejection::NearParallel)
        );
        // Rays diverging upward meet only behind the cameras.
        let r = ray_pair_midpoint(
            Point3::new(-10.0, 0.0, 0.0),
            Vector3::new(-1.0, 0.0, -1.0),
            Point3::new(10.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, -1.0),
            0.01,
        );
        assert_eq!(r, Err(PairRejection::BehindCamera));
    }

    proptest! {
        /// The midpoint is equidistant from both rays and the segment is perpendicular
        /// to both (the definition of J in Section 2.2).
        #[test]
        fn midpoint_is_on_the_common_perpendicular(
            ox in -50.0f64..50.0, oy in -50.0f64..50.0,
            dx in -0.5f64..0.5, dy in -0.5f64..0.5, ex in -0.5f64..0.5, ey in -0.5f64..0.5,
        ) {
            let ol = Point3::new(-35.0, 0.0, 100.0);
            let or = Point3::new(35.0 + ox, oy, 98.0);
            let dl = Vector3::new(dx + 0.35, dy, -1.0);
            let dr = Vector3::new(ex - 0.35, ey, -1.0);
            if let Ok(m) = ray_pair_midpoint(ol, dl, or, dr, 0.02) {
                let el = ol + m.a * dl;
                let er = or + m.b * dr;
                let seg = er - el;
                prop_assert!(seg.dot(&dl).abs() < 1e-6 * (1.0 + seg.norm()));
                prop_assert!(seg.dot(&dr).abs() < 1e-6 * (1.0 + seg.norm()));
                prop_assert!(((m.midpoint - el).norm() - (m.midpoint - er).norm()).abs() < 1e-9);
            }
        }
    }
}
