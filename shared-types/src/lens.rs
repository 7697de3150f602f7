//! Lens distortion in OpenCV's model (`k1, k2, p1, p2, k3`: radial and tangential), the
//! `distortion` of `recording.toml`. Pure arithmetic, so the simulator can render it and
//! matching can remove it with one definition.
//!
//! A distorted pixel is `K · distort(K⁻¹ · undistorted pixel)`. Everything after
//! detection and ORB (epipolar geometry, the estimator) works on *undistorted* pixels of
//! the same K: the ideal pinhole image the camera would have taken.

use crate::conventions::Intrinsics;
use serde::{Deserialize, Serialize};

/// OpenCV's five distortion coefficients.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Distortion(pub [f64; 5]);

/// Fixed-point iterations of [`Distortion::undistort_normalised`]. OpenCV's
/// `undistortPoints` uses 5 by default; 20 reach 1e-6 px at the corners of a strongly
/// distorted (k1 = −0.3) wide image.
const UNDISTORT_ITERATIONS: usize = 20;

impl Distortion {
    pub const NONE: Self = Self([0.0; 5]);

    pub fn is_none(&self) -> bool {
        self.0.iter().all(|c| *c == 0.0)
    }

    pub fn is_finite(&self) -> bool {
        self.0.iter().all(|c| c.is_finite())
    }

    /// Ideal normalised coordinates (x/z, y/z) → distorted normalised coordinates.
    pub fn distort_normalised(&self, x: f64, y: f64) -> [f64; 2] {
        let [k1, k2, p1, p2, k3] = self.0;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        [
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        ]
    }

    /// Distorted normalised coordinates → ideal ones, by the fixed-point iteration
    /// OpenCV's `undistortPoints` uses. `None` when it does not converge (a point far
    /// outside the lens's valid field, or non-finite input).
    pub fn undistort_normalised(&self, xd: f64, yd: f64) -> Option<[f64; 2]> {
        if !(xd.is_finite() && yd.is_finite()) {
            return None;
        }
        let [k1, k2, p1, p2, k3] = self.0;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..UNDISTORT_ITERATIONS {
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
            if radial.abs() < 1e-6 {
                return None;
            }
            let dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
            let dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
            x = (xd - dx) / radial;
            y = (yd - dy) / radial;
        }
        let back = self.distort_normalised(x, y);
        let residual = (back[0] - xd).hypot(back[1] - yd);
        (residual < 1e-6 && x.is_finite() && y.is_finite()).then_some([x, y])
    }

    /// Ideal (pinhole) pixel → the pixel the distorted camera records.
    pub fn distort_pixel(&self, k: &Intrinsics, u: f64, v: f64) -> [f64; 2] {
        if self.is_none() {
            return [u, v];
        }
        let [x, y] = self.distort_normalised((u - k.cx) / k.fx, (v - k.cy) / k.fy);
        [k.fx * x + k.cx, k.fy * y + k.cy]
    }

    /// Recorded (distorted) pixel → the ideal pinhole pixel of the same K.
    pub fn undistort_pixel(&self, k: &Intrinsics, u: f64, v: f64) -> Option<[f64; 2]> {
        if self.is_none() {
            return Some([u, v]);
        }
        let [x, y] = self.undistort_normalised((u - k.cx) / k.fx, (v - k.cy) / k.fy)?;
        Some([k.fx * x + k.cx, k.fy * y + k.cy])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A strong barrel lens, like a wide action camera's.
    const BARREL: Distortion = Distortion([-0.28, 0.09, 0.0012, -0.0008, -0.012]);

    #[test]
    fn none_is_the_identity() {
        let k = Intrinsics::new(554.0, 554.0, 319.5, 239.5);
        assert_eq!(
            Distortion::NONE.distort_pixel(&k, 3.25, 470.0),
            [3.25, 470.0]
        );
        assert_eq!(
            Distortion::NONE.undistort_pixel(&k, 3.25, 470.0),
            Some([3.25, 470.0])
        );
    }

    #[test]
    fn barrel_pulls_the_corners_in() {
        let k = Intrinsics::new(554.0, 554.0, 319.5, 239.5);
        let [u, v] = BARREL.distort_pixel(&k, 0.0, 0.0);
        assert!(u > 10.0 && v > 5.0, "{u} {v}");
        let centre = BARREL.distort_pixel(&k, 319.5, 239.5);
        assert!((centre[0] - 319.5).abs() < 1e-12 && (centre[1] - 239.5).abs() < 1e-12);
    }

    #[test]
    fn non_finite_input_is_refused() {
        assert_eq!(BARREL.undistort_normalised(f64::NAN, 0.0), None);
    }

    proptest! {
        #[test]
        fn undistort_inverts_distort_over_a_1280x720_image(
            u in 0.0f64..1279.0, v in 0.0f64..719.0,
        ) {
            let k = Intrinsics::new(1108.0, 1108.0, 639.5, 359.5);
            let ideal = BARREL.undistort_pixel(&k, u, v).expect("inside the lens field");
            let back = BARREL.distort_pixel(&k, ideal[0], ideal[1]);
            prop_assert!((back[0] - u).abs() < 1e-4 && (back[1] - v).abs() < 1e-4);
        }
    }
}
