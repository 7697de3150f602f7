//! Eq. (24)–(28): the corresponding point of the target's *current* position in a past
//! image, as the intersection of two epipolar lines.
//!
//! With F_Ln the fundamental matrix between the current left image and past image n
//! (x_nᵀ F_Ln x_L = 0), the line of eq. (27) is `l₁ = F_Ln (u_L, v_L, 1)ᵀ`. It is the
//! same line as `[T_Ln × p'_L] K_n⁻¹ x = 0`: F = K_n⁻ᵀ [T]× R K_L⁻¹ already holds the
//! rotation and translation the paper recovers by decomposing F. So the line is taken
//! from F directly, which skips a decomposition and its four-fold ambiguity. Likewise
//! `l₂ = F_Rn (u_R, v_R, 1)ᵀ` (eq. 28), and p_n = l₁ × l₂.

use crate::config::{FundamentalMethod, MatchingConfig};
use crate::features::Features;
use crate::ground_plane::{
    dominant_homography, fundamental_from_essential, level_plane_motion, to_matrix, PlaneModel,
};
use crate::hamming::{knn2, knn2_within, Nearest2};
use crate::robust_fit::usac_params;
use nalgebra::{Matrix3, Vector3};
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::conventions::Intrinsics;
use shared_types::lens::Distortion;

/// Why a past image gave no corresponding point (counted per reason).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MatchReject {
    TooFewMatches {
        matches: usize,
    },
    FundamentalFailed,
    TooFewInliers {
        inliers: usize,
    },
    NearParallelLines {
        angle_deg: f64,
    },
    OutsideImage {
        u: f64,
        v: f64,
    },
    /// A current side has nothing tracked to this past image yet (warm-up, a lost
    /// track, a newly selected keyframe) and its refresh has not landed: the pair is
    /// answered without it rather than wait (`chain/refresh.rs`).
    AwaitingRefresh,
    /// The last refresh fitted this past image, but not on the level ground plane
    /// (the 5-point fallback): there are no ground points for tracking to follow
    /// until the next refresh.
    NoGroundSeeds,
}

impl MatchReject {
    pub fn kind(&self) -> &'static str {
        match self {
            MatchReject::TooFewMatches { .. } => "too_few_matches",
            MatchReject::FundamentalFailed => "fundamental_failed",
            MatchReject::TooFewInliers { .. } => "too_few_inliers",
            MatchReject::NearParallelLines { .. } => "near_parallel_lines",
            MatchReject::OutsideImage { .. } => "outside_image",
            MatchReject::AwaitingRefresh => "awaiting_refresh",
            MatchReject::NoGroundSeeds => "no_ground_seeds",
        }
    }
}

/// F between a current image and a past one: `x_pastᵀ F x_current = 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairGeometry {
    pub f: Matrix3<f64>,
    pub matches: usize,
    /// Matches supporting the fitted model (the plane's, for `ground_plane`).
    pub inliers: usize,
    /// For `ground_plane`: whether the level plane or the 5-point fallback gave F.
    pub model: Option<PlaneModel>,
    /// For `ground_plane`: the dominant plane's homography (current → past pixels),
    /// the prior for guided matching with the next current frame.
    pub homography: Option<Matrix3<f64>>,
    /// For a level plane's F: the rotation of its decomposition, `X_past = R
    /// X_current` in camera axes (the images' own measure of it; the estimator's
    /// relative-rotation measurement).
    pub rotation: Option<Matrix3<f64>>,
}

/// Ratio-tested Hamming matches from `current` to `past`, as point pairs. `scratch`
/// holds the neighbour lists between calls.
pub fn match_points(
    current: &Features,
    past: &Features,
    ratio: f32,
    scratch: &mut Vec<Option<Nearest2>>,
) -> (cv::Vector<cv::Point2f>, cv::Vector<cv::Point2f>) {
    knn2(&current.descriptors, &past.descriptors, scratch);
    ratio_tested(current, past, ratio, scratch)
}

/// Guided matching: each current keypoint is compared only with the past keypoints
/// within `radius_px` of where `homography` (current → past pixels, from an earlier
/// frame's dominant plane) puts it. About 30× fewer comparisons than [`match_points`],
/// and fewer outliers for the robust fit.
pub fn match_points_guided(
    current: &Features,
    past: &Features,
    homography: &Matrix3<f64>,
    radius_px: f32,
    ratio: f32,
    scratch: &mut Vec<Option<Nearest2>>,
) -> (cv::Vector<cv::Point2f>, cv::Vector<cv::Point2f>) {
    let predicted: Vec<Option<[f32; 2]>> = current
        .points
        .iter()
        .map(|p| {
            let q = homography * Vector3::new(p.x as f64, p.y as f64, 1.0);
            (q.z > 0.0).then(|| [(q.x / q.z) as f32, (q.y / q.z) as f32])
        })
        .collect();
    knn2_within(
        &current.descriptors,
        &predicted,
        &past.descriptors,
        &past.grid,
        radius_px,
        scratch,
    );
    ratio_tested(current, past, ratio, scratch)
}

/// Lowe's ratio test on neighbour lists: the kept pairs as points.
fn ratio_tested(
    current: &Features,
    past: &Features,
    ratio: f32,
    neighbours: &[Option<Nearest2>],
) -> (cv::Vector<cv::Point2f>, cv::Vector<cv::Point2f>) {
    let (mut a, mut b) = (cv::Vector::new(), cv::Vector::new());
    for (i, n) in neighbours.iter().enumerate() {
        let Some(n) = n else { continue };
        if (n.best as f32) < ratio * n.second as f32 {
            a.push(current.points[i]);
            b.push(past.points[n.best_index]);
        }
    }
    (a, b)
}

/// Estimates F from matched points by the configured robust method. `up` is the
/// vertical in the current camera's frame (from the measured roll and pitch), which
/// the `ground_plane` method needs to pick the level plane's decomposition.
pub fn estimate_fundamental(
    current: &cv::Vector<cv::Point2f>,
    past: &cv::Vector<cv::Point2f>,
    intrinsics: (&Intrinsics, &Intrinsics),
    up: &Vector3<f64>,
    config: &MatchingConfig,
) -> Result<PairGeometry, MatchReject> {
    estimate_fundamental_masked(
        current,
        past,
        intrinsics,
        up,
        config,
        &mut cv::Mat::default(),
    )
}

/// [`estimate_fundamental`], with `mask` marking the inliers of the model used (the
/// ground plane's, for a `ground_plane` F from the level plane).
pub fn estimate_fundamental_masked(
    current: &cv::Vector<cv::Point2f>,
    past: &cv::Vector<cv::Point2f>,
    intrinsics: (&Intrinsics, &Intrinsics),
    up: &Vector3<f64>,
    config: &MatchingConfig,
    mask: &mut cv::Mat,
) -> Result<PairGeometry, MatchReject> {
    let matches = current.len();
    if matches < config.min_inliers.max(8) {
        return Err(MatchReject::TooFewMatches { matches });
    }
    let fail = |_| MatchReject::FundamentalFailed;
    let (f, model, homography, rotation) = match config.fundamental {
        FundamentalMethod::Ransac8Point => {
            let f = opencv::calib3d::find_fundamental_mat(
                current,
                past,
                opencv::calib3d::FM_RANSAC,
                config.ransac_threshold_px,
                config.ransac_confidence,
                config.ransac_max_iterations,
                mask,
            )
            .map_err(fail)?;
            (single_solution(&f)?, None, None, None)
        }
        FundamentalMethod::Magsac => {
            let params = usac_params(config, config.ransac_threshold_px).map_err(fail)?;
            let f = opencv::calib3d::find_fundamental_mat_2(current, past, mask, params)
                .map_err(fail)?;
            (single_solution(&f)?, None, None, None)
        }
        FundamentalMethod::Essential => (
            essential_as_fundamental(current, past, intrinsics, config, mask)?,
            None,
            None,
            None,
        ),
        FundamentalMethod::GroundPlane => {
            let (f, model, h, rotation) =
                ground_plane_fundamental(current, past, intrinsics, up, config, mask)?;
            (
                f,
                Some(model),
                (model == PlaneModel::GroundPlane).then_some(h),
                rotation,
            )
        }
    };
    let inliers = cv::count_non_zero(mask).map_err(fail)? as usize;
    if inliers < config.min_inliers {
        return Err(MatchReject::TooFewInliers { inliers });
    }
    if !f.iter().all(|v| v.is_finite()) || f.norm() == 0.0 {
        return Err(MatchReject::FundamentalFailed);
    }
    Ok(PairGeometry {
        f,
        matches,
        inliers,
        model,
        homography,
        rotation,
    })
}

/// OpenCV may return several stacked solutions (7-point) or none: exactly one 3×3 or
/// a failure.
fn single_solution(f: &cv::Mat) -> Result<Matrix3<f64>, MatchReject> {
    if f.rows() != 3 || f.cols() != 3 {
        return Err(MatchReject::FundamentalFailed);
    }
    to_matrix(f).map_err(|_| MatchReject::FundamentalFailed)
}

/// The `ground_plane` method (see [`crate::ground_plane`]): the level plane's
/// homography, decomposed; the 5-point E when the dominant plane is not level. `mask`
/// marks the inliers of whichever model was used. The level plane's rotation comes
/// with it (none from the fallback).
#[allow(clippy::type_complexity)]
fn ground_plane_fundamental(
    current: &cv::Vector<cv::Point2f>,
    past: &cv::Vector<cv::Point2f>,
    (k_current, k_past): (&Intrinsics, &Intrinsics),
    up: &Vector3<f64>,
    config: &MatchingConfig,
    mask: &mut cv::Mat,
) -> Result<(Matrix3<f64>, PlaneModel, Matrix3<f64>, Option<Matrix3<f64>>), MatchReject> {
    let fail = |_| MatchReject::FundamentalFailed;
    let (kc, kp) = (k_current.matrix(), k_past.matrix());
    let h = dominant_homography(current, past, config, mask)
        .map_err(fail)?
        .ok_or(MatchReject::FundamentalFailed)?;
    let kp_inv = kp.try_inverse().ok_or(MatchReject::FundamentalFailed)?;
    let motion = level_plane_motion(&(kp_inv * h * kc), up).map_err(fail)?;
    match motion {
        Some(m) if m.tilt_deg <= config.max_ground_tilt_deg => Ok((
            fundamental_from_essential(&m.essential(), &kc, &kp)
                .ok_or(MatchReject::FundamentalFailed)?,
            PlaneModel::GroundPlane,
            h,
            Some(m.rotation),
        )),
        _ => Ok((
            essential_as_fundamental(current, past, (k_current, k_past), config, mask)?,
            PlaneModel::EssentialFallback,
            h,
            None,
        )),
    }
}

/// E by the 5-point solver in USAC on normalised coordinates, returned as
/// F = K_pastᵀ⁻¹ E K_current⁻¹.
fn essential_as_fundamental(
    current: &cv::Vector<cv::Point2f>,
    past: &cv::Vector<cv::Point2f>,
    (k_current, k_past): (&Intrinsics, &Intrinsics),
    config: &MatchingConfig,
    mask: &mut cv::Mat,
) -> Result<Matrix3<f64>, MatchReject> {
    let fail = |_| MatchReject::FundamentalFailed;
    let normalise = |pts: &cv::Vector<cv::Point2f>, k: &Intrinsics| -> cv::Vector<cv::Point2d> {
        pts.iter()
            .map(|p| cv::Point2d::new((p.x as f64 - k.cx) / k.fx, (p.y as f64 - k.cy) / k.fy))
            .collect()
    };
    let (a, b) = (normalise(current, k_current), normalise(past, k_past));
    let identity = cv::Mat::eye(3, 3, cv::CV_64F)
        .map_err(fail)?
        .to_mat()
        .map_err(fail)?;
    // Threshold in normalised units: the pixel threshold over the mean focal length.
    let threshold = config.ransac_threshold_px / (0.5 * (k_past.fx + k_past.fy));
    let params = usac_params(config, threshold).map_err(fail)?;
    let no_distortion = cv::Mat::default();
    let e = opencv::calib3d::find_essential_mat_4(
        &a,
        &b,
        &identity,
        &identity,
        &no_distortion,
        &no_distortion,
        mask,
        params,
    )
    .map_err(fail)?;
    let e = single_solution(&e)?;
    fundamental_from_essential(&e, &k_current.matrix(), &k_past.matrix())
        .ok_or(MatchReject::FundamentalFailed)
}

/// The frame a transferred point must fall in. Points are undistorted (ideal pinhole
/// pixels), so with a lens the test is on the point *distorted back*: under barrel
/// distortion the ideal image reaches beyond the sensor's rectangle, and a point there
/// is still seen.
pub struct ImageBounds<'a> {
    pub intrinsics: &'a Intrinsics,
    pub distortion: &'a Distortion,
    pub width: u32,
    pub height: u32,
}

impl ImageBounds<'_> {
    /// Whether the undistorted pixel (u, v) is seen at least `border` px inside the frame.
    pub fn contains(&self, u: f64, v: f64, border: f64) -> bool {
        if !(u.is_finite() && v.is_finite()) {
            return false;
        }
        let [ud, vd] = if self.distortion.is_none() {
            [u, v]
        } else {
            self.distortion.distort_pixel(self.intrinsics, u, v)
        };
        ud >= border
            && vd >= border
            && ud <= self.width as f64 - 1.0 - border
            && vd <= self.height as f64 - 1.0 - border
    }
}

/// Eq. (27)–(28): the intersection in the past image of the epipolar lines of the
/// current left and right target pixels.
pub fn transfer_point(
    f_left: &Matrix3<f64>,
    pixel_left: [f64; 2],
    f_right: &Matrix3<f64>,
    pixel_right: [f64; 2],
    bounds: &ImageBounds,
    config: &MatchingConfig,
) -> Result<[f64; 2], MatchReject> {
    let l1 = f_left * Vector3::new(pixel_left[0], pixel_left[1], 1.0);
    let l2 = f_right * Vector3::new(pixel_right[0], pixel_right[1], 1.0);
    let (n1, n2) = (l1.xy(), l2.xy());
    let sin = (n1.x * n2.y - n1.y * n2.x).abs() / (n1.norm() * n2.norm());
    let angle_deg = sin.clamp(0.0, 1.0).asin().to_degrees();
    if angle_deg.is_nan() || angle_deg < config.min_line_angle_deg {
        return Err(MatchReject::NearParallelLines { angle_deg });
    }
    let p = l1.cross(&l2);
    let (u, v) = (p.x / p.z, p.y / p.z);
    if !bounds.contains(u, v, config.border_px) {
        return Err(MatchReject::OutsideImage { u, v });
    }
    Ok([u, v])
}

#[cfg(test)]
mod tests {
    use super::*;

    const K: Intrinsics = Intrinsics {
        fx: 500.0,
        fy: 500.0,
        cx: 320.0,
        cy: 240.0,
    };

    fn pinhole(width: u32, height: u32) -> ImageBounds<'static> {
        ImageBounds {
            intrinsics: &K,
            distortion: &Distortion::NONE,
            width,
            height,
        }
    }

    #[test]
    fn under_barrel_distortion_the_seen_field_reaches_past_the_ideal_rectangle() {
        let barrel = Distortion([-0.25, 0.07, 0.0, 0.0, 0.0]);
        let lens = ImageBounds {
            distortion: &barrel,
            ..pinhole(640, 480)
        };
        // An ideal pixel 20 px left of the frame: the pinhole never sees it, the barrel
        // lens pulls it inside.
        assert!(!pinhole(640, 480).contains(-20.0, 240.0, 0.0));
        assert!(lens.contains(-20.0, 240.0, 0.0));
        // Far outside stays outside, and NaN is never inside.
        assert!(!lens.contains(-400.0, 240.0, 0.0));
        assert!(!lens.contains(f64::NAN, 240.0, 0.0));
    }

    #[test]
    fn lines_through_a_point_intersect_at_it() {
        // Two "fundamental matrices" that map the given pixels to lines through (100, 80):
        // any F whose row space maps x to l; use F = [l]ₓ-style constructions directly.
        let target = Vector3::new(100.0, 80.0, 1.0);
        let l1 = target.cross(&Vector3::new(300.0, 10.0, 1.0));
        let l2 = target.cross(&Vector3::new(20.0, 400.0, 1.0));
        // F with F·(0,0,1) = l: put l in the last column.
        let f1 = Matrix3::from_columns(&[Vector3::zeros(), Vector3::zeros(), l1]);
        let f2 = Matrix3::from_columns(&[Vector3::zeros(), Vector3::zeros(), l2]);
        let p = transfer_point(
            &f1,
            [0.0, 0.0],
            &f2,
            [0.0, 0.0],
            &pinhole(640, 480),
            &MatchingConfig::default(),
        )
        .unwrap();
        assert!((p[0] - 100.0).abs() < 1e-9 && (p[1] - 80.0).abs() < 1e-9);

        let parallel = Matrix3::from_columns(&[Vector3::zeros(), Vector3::zeros(), l1 * 3.0]);
        assert!(matches!(
            transfer_point(
                &f1,
                [0.0, 0.0],
                &parallel,
                [0.0, 0.0],
                &pinhole(640, 480),
                &MatchingConfig::default()
            ),
            Err(MatchReject::NearParallelLines { .. })
        ));
        assert!(matches!(
            transfer_point(
                &f1,
                [0.0, 0.0],
                &f2,
                [0.0, 0.0],
                &pinhole(90, 70),
                &MatchingConfig::default()
            ),
            Err(MatchReject::OutsideImage { .. })
        ));
    }
}
