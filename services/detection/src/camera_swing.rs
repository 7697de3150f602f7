//! A camera's measured swing between the frame where the target was last seen and the
//! one being detected.
//!
//! A UAV's camera can turn 10–16° between two frames (a route corner's acceleration
//! pitches the body; a gust): every pixel moves 100–160 px at once. The image track's
//! hint stays where the target was, and a car of the target's colour that the swing
//! brought near it is taken for the target (`multi_town` seed 3 of the multi-target
//! report: the right camera pitched 16° at 4.43 s, the target moved 157 px while a red
//! look-alike landed 47 px from the hint; every pair after that was two vehicles, and
//! the filter started from three of them with the right bias 24° off).
//!
//! The AHRS measures the swing. A pixel seen along direction `d` in the camera at
//! rotation `R_p` (camera → world) is seen along `R_cᵀ R_p d` in the camera at `R_c`:
//! the rotation-only transfer (the infinite homography `K R_cᵀ R_p K⁻¹`); the UAV's
//! own translation between the frames is left out (a metre at 100 m is 5 px).
//!
//! **When it is used (a choice).** Each measured attitude carries its noise (white per
//! sample, `[detection.gate] sigma_attitude_deg` per axis), so the transfer moves a
//! pixel by the noise of two samples even when the camera did not turn: about
//! f · σ · √2 per image axis (27 px at 640 × 480, 60° and 2°), far more than a car
//! moves between frames. So the hint moves only when the swing is larger than that
//! noise can make it: beyond [`SWING_SIGMAS`] of it (137 px at 640 × 480: a turn of
//! ~14° or more). Smaller swings leave the hint as it was, as before.
//!
//! Pure geometry over plain data.

use nalgebra::{Matrix3, Vector2};
use shared_types::conventions::{camera_to_world, Intrinsics};
use shared_types::lens::Distortion;
use shared_types::messages::PoseSample;

/// How many σ of the two samples' attitude noise a swing must move the hint by to be
/// followed. The noise's move is Rayleigh-distributed, beyond k σ with probability
/// exp(−k²/2): at the prediction gate's 3.7 that is one frame in a thousand, and on
/// `multi_town` seed 1 one such frame (the noise alone moved the hint 92 px) put the
/// left camera on a look-alike for the rest of the run (546 pairs refused as two
/// vehicles). At 5, one in 270 000; the 16° swing of seed 3 (5.7 σ) is still followed.
pub const SWING_SIGMAS: f64 = 5.0;

/// One frame's camera as its measured pose and lens describe it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraView {
    /// Camera → world (ENU), from the measured attitude.
    pub rotation: Matrix3<f64>,
    pub intrinsics: Intrinsics,
    pub distortion: Distortion,
}

impl CameraView {
    /// The view of a frame whose (equivalent nadir) measured pose is `pose`; `None`
    /// when a value is not finite.
    pub fn new(pose: &PoseSample, intrinsics: Intrinsics, distortion: Distortion) -> Option<Self> {
        let rotation = camera_to_world(pose.attitude());
        (rotation.iter().all(|v| v.is_finite()) && intrinsics.is_valid()).then_some(Self {
            rotation,
            intrinsics,
            distortion,
        })
    }

    /// `pixel` (recorded, distorted) of this view, seen from `to` by rotation alone;
    /// `None` when it falls behind `to`'s camera or the lens cannot undistort it.
    pub fn transfer(&self, to: &CameraView, pixel: [f64; 2]) -> Option<[f64; 2]> {
        let k = &self.intrinsics;
        let [u, v] = self.distortion.undistort_pixel(k, pixel[0], pixel[1])?;
        let ray = k.pixel_to_ray(Vector2::new(u, v));
        let seen = to.rotation.transpose() * (self.rotation * ray);
        let p = to.intrinsics.project(seen)?;
        let out = to.distortion.distort_pixel(&to.intrinsics, p.x, p.y);
        out.iter().all(|v| v.is_finite()).then_some(out)
    }
}

/// Where `pixel` of view `from` is in view `to` when the camera turned between them by
/// more than `sigmas` of the attitude noise can move it (module docs); `None` when it
/// did not (or the transfer fails).
pub fn swung(
    from: &CameraView,
    to: &CameraView,
    pixel: [f64; 2],
    sigma_attitude_rad: f64,
    sigmas: f64,
) -> Option<[f64; 2]> {
    let moved = from.transfer(to, pixel)?;
    let k = &from.intrinsics;
    // Two samples' noise about the three axes: pitch and roll move a pixel by about
    // f·σ, the yaw (about the optical axis) by r·σ at r px from the centre.
    let r = (pixel[0] - k.cx).hypot(pixel[1] - k.cy);
    let noise_px = std::f64::consts::SQRT_2 * sigma_attitude_rad * (k.fx * k.fy + r * r).sqrt();
    let shift = (moved[0] - pixel[0]).hypot(moved[1] - pixel[1]);
    (shift > sigmas * noise_px).then_some(moved)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use shared_types::conventions::Intrinsics;

    fn view(yaw: f64, pitch: f64, roll: f64) -> CameraView {
        let pose = PoseSample {
            yaw_deg: yaw,
            pitch_deg: pitch,
            roll_deg: roll,
            ..PoseSample::default()
        };
        CameraView::new(
            &pose,
            Intrinsics::from_hfov(640, 480, 60.0),
            Distortion::default(),
        )
        .expect("view")
    }

    /// A 16° pitch moves the hint by ~155 px, beyond 5 × the noise (137 px): the
    /// hint follows it. An 8° one (seed 1's noise of two samples) leaves it.
    #[test]
    fn a_large_swing_moves_the_hint_and_a_small_one_does_not() {
        let (a, b) = (view(30.0, 0.0, 0.0), view(30.0, -16.0, 0.0));
        let p = [319.5, 239.5];
        let moved = swung(&a, &b, p, 2f64.to_radians(), SWING_SIGMAS).expect("swung");
        let shift = (moved[0] - p[0]).hypot(moved[1] - p[1]);
        assert!((150.0..162.0).contains(&shift), "{moved:?}");
        let small = view(30.0, 6.0, -5.4);
        assert_eq!(swung(&a, &small, p, 2f64.to_radians(), SWING_SIGMAS), None);
    }

    proptest! {
        /// The transfer there and back returns the pixel; one to the same view is the
        /// identity.
        #[test]
        fn the_transfer_is_invertible(
            y in -180.0..180.0f64, p in -15.0..15.0f64, r in -15.0..15.0f64,
            dp in -12.0..12.0f64, dr in -12.0..12.0f64,
            u in 100.0..540.0f64, v in 80.0..400.0f64,
        ) {
            let (a, b) = (view(y, p, r), view(y, p + dp, r + dr));
            let same = a.transfer(&a, [u, v]).expect("same");
            prop_assert!((same[0] - u).abs() < 1e-6 && (same[1] - v).abs() < 1e-6);
            if let Some(there) = a.transfer(&b, [u, v]) {
                let back = b.transfer(&a, there).expect("back");
                prop_assert!((back[0] - u).abs() < 1e-6 && (back[1] - v).abs() < 1e-6);
            }
        }
    }
}
