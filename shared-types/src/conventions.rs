//! Frame conventions, defined once for every dualgeo crate.
//!
//! These follow `docs/recording-format.md` (the recording format, version 1) exactly;
//! `docs/conventions.md` has the sketch. In short:
//!
//! * **World `w`**: local ENU, metres. x east, y north, z up.
//! * **Navigation `n`**: local NED (x north, y east, z down), only as the reference of
//!   the attitude angles.
//! * **Body `b`**: FRD (x forward, y right, z down).
//! * **Attitude**: aerospace Z-Y-X Euler angles (yaw ψ, pitch θ, roll φ) of the body
//!   relative to NED: `C_n^b = Rz(ψ) · Ry(θ) · Rx(φ)` maps body vectors to NED.
//!   yaw 0 = nose north, +90° = nose east; pitch positive nose up; roll positive right
//!   wing down.
//! * **Camera `c`** (OpenCV): x right in the image, y down in the image, z along the
//!   optical axis. Pixels: (0, 0) is the centre of the top-left pixel.
//! * **Nadir mount**: optical axis = body down, image x = body right, image y = body
//!   backward, so the top of the image points to the nose.
//!
//! The paper writes `C_w^c` for the rotation "from the camera coordinate system c to the
//! world coordinate system w" (eq. 1); [`camera_to_world`] builds exactly that, and it is
//! the only place in dualgeo that does.

use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Which of the two UAVs an image or a pose belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Uav {
    Left,
    Right,
}

impl Uav {
    /// Index used for per-UAV arrays: left = 0, right = 1.
    pub fn index(self) -> usize {
        match self {
            Uav::Left => 0,
            Uav::Right => 1,
        }
    }

    /// The name used in recordings (`left`, `right`).
    pub fn name(self) -> &'static str {
        match self {
            Uav::Left => "left",
            Uav::Right => "right",
        }
    }
}

/// Aerospace Z-Y-X attitude of the body (FRD) relative to NED, in **radians**.
///
/// Recordings and messages carry degrees; convert with [`Attitude::from_degrees`] at the
/// boundary. Everything inside dualgeo computes in radians.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Attitude {
    /// ψ, rotation about NED down; 0 = nose north, +π/2 = nose east.
    pub yaw: f64,
    /// θ, positive nose up.
    pub pitch: f64,
    /// φ, positive right wing down.
    pub roll: f64,
}

impl Attitude {
    pub fn new(yaw: f64, pitch: f64, roll: f64) -> Self {
        Self { yaw, pitch, roll }
    }

    pub fn from_degrees(yaw_deg: f64, pitch_deg: f64, roll_deg: f64) -> Self {
        Self::new(
            yaw_deg.to_radians(),
            pitch_deg.to_radians(),
            roll_deg.to_radians(),
        )
    }

    /// The same attitude with a yaw bias (radians) removed: measured = true + bias
    /// (eq. 10 and the recording format), so the corrected yaw is `yaw − bias`.
    pub fn corrected_for_yaw_bias(self, bias: f64) -> Self {
        Self {
            yaw: self.yaw - bias,
            ..self
        }
    }

    pub fn is_finite(&self) -> bool {
        self.yaw.is_finite() && self.pitch.is_finite() && self.roll.is_finite()
    }
}

/// Rotation from NED to ENU (its own inverse): swaps x and y and flips z.
pub fn ned_to_enu() -> Matrix3<f64> {
    Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0)
}

/// `C_n^b`: body (FRD) vectors to NED, `Rz(ψ) Ry(θ) Rx(φ)`.
pub fn body_to_ned(att: Attitude) -> Matrix3<f64> {
    Rotation3::from_euler_angles(att.roll, att.pitch, att.yaw).into_inner()
}

/// Nadir mount: camera (OpenCV) vectors to body (FRD). Columns are the camera axes in
/// the body frame: image x = body right, image y = body backward, optical axis = body down.
pub fn nadir_camera_to_body() -> Matrix3<f64> {
    Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
}

/// `C_G^c` (recording format v2): camera (OpenCV) vectors to the gimbal frame G. The
/// camera looks along G's +x; image right is G's +y, image down G's +z.
pub fn camera_to_gimbal() -> Matrix3<f64> {
    Matrix3::new(0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
}

/// A camera's orientation on its UAV (recording format v2): the gimbal frame G
/// relative to the body FRD frame, as aerospace Z-Y-X angles in **radians** (MAVLink's
/// GIMBAL_DEVICE_ATTITUDE_STATUS in vehicle frame). A nadir camera is G = (0, −π/2, 0).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Mount(pub Attitude);

impl Mount {
    /// Straight down, image top toward the nose: version 1's only mount.
    pub const NADIR: Mount = Mount(Attitude {
        yaw: 0.0,
        pitch: -std::f64::consts::FRAC_PI_2,
        roll: 0.0,
    });

    pub fn from_degrees(yaw_deg: f64, pitch_deg: f64, roll_deg: f64) -> Self {
        Self(Attitude::from_degrees(yaw_deg, pitch_deg, roll_deg))
    }

    /// `C_b^c = C_b^G · C_G^c`: camera vectors to body (FRD).
    pub fn camera_to_body(self) -> Matrix3<f64> {
        body_to_ned(self.0) * camera_to_gimbal()
    }

    /// The attitude a body with a *nadir* camera would need for its camera to point as
    /// this mount's camera does on a body at `body`: the one attitude with
    /// `camera_to_world(equivalent) = C_enu^ned · C_n^b(body) · C_b^c(mount)`.
    ///
    /// Every estimator, matcher and gate of dualgeo is written for a nadir camera's
    /// `camera_to_world(attitude)`; a tilted or gimballed camera enters them as this
    /// equivalent attitude, converted once where the pose is read. The yaw bias carries
    /// over exactly: it is a rotation about the world vertical applied on the left
    /// (`Rz(ψ + b) = Rz(b) · Rz(ψ)`), so the equivalent yaw has the body's bias. The
    /// AHRS's pitch and roll errors, about the body's axes, spread over all three
    /// equivalent angles (for a camera tilted off nadir, some of them into the yaw).
    /// Singular only for an optical axis along the horizon (equivalent pitch ±90°), a
    /// view that cannot geolocate a ground target.
    pub fn equivalent_nadir_attitude(self, body: Attitude) -> Attitude {
        let nadir_inverse = nadir_camera_to_body().transpose();
        let r = body_to_ned(body) * self.camera_to_body() * nadir_inverse;
        let (roll, pitch, yaw) = Rotation3::from_matrix_unchecked(r).euler_angles();
        Attitude { yaw, pitch, roll }
    }

    /// The inverse of [`Mount::equivalent_nadir_attitude`]: the body's attitude from
    /// its camera's equivalent nadir attitude, `C_n^b(body) = C_n^b(equivalent) ·
    /// C_b^c(nadir) · C_b^c(mount)ᵀ`. The estimator takes the AHRS's errors off the
    /// body's angles through it: that is where the AHRS errs. Singular only for a body
    /// pitched ±90°.
    pub fn body_attitude(self, equivalent: Attitude) -> Attitude {
        let r =
            body_to_ned(equivalent) * nadir_camera_to_body() * self.camera_to_body().transpose();
        let (roll, pitch, yaw) = Rotation3::from_matrix_unchecked(r).euler_angles();
        Attitude { yaw, pitch, roll }
    }

    /// Whether this is the nadir mount exactly (the body's attitude is its camera's).
    pub fn is_nadir(self) -> bool {
        self == Mount::NADIR
    }
}

/// `C_w^c` of eq. (1): rotation taking camera-frame vectors to the world (ENU) frame for
/// a nadir camera on a body with attitude `att`.
///
/// `C_w^c = C_enu^ned · C_n^b(ψ, θ, φ) · C_b^c(nadir)`, computed as
/// `yaw_to_world(ψ) · LevelledCamera::new(θ, φ).rotation` (the same product, split so
/// that estimators can update the yaw without recomputing the rest).
pub fn camera_to_world(att: Attitude) -> Matrix3<f64> {
    yaw_to_world(att.yaw) * LevelledCamera::new(att.pitch, att.roll).rotation
}

/// `C_enu^ned · Rz(ψ)`: the yaw part of [`camera_to_world`].
pub fn yaw_to_world(yaw: f64) -> Matrix3<f64> {
    ned_to_enu() * Rotation3::from_axis_angle(&Vector3::z_axis(), yaw).into_inner()
}

/// `∂/∂ψ [C_enu^ned · Rz(ψ)] = C_enu^ned · Rz(ψ) · [e_z]×`.
pub fn yaw_to_world_derivative(yaw: f64) -> Matrix3<f64> {
    yaw_to_world(yaw) * Vector3::z().cross_matrix()
}

/// The pitch/roll part of [`camera_to_world`], `Ry(θ) Rx(φ) C_b^c(nadir)`, and its
/// partial derivatives. Each elementary rotation has `dR_a/dα = R_a(α) · [e_a]×`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelledCamera {
    pub rotation: Matrix3<f64>,
    /// `Ry(θ) [e_y]× Rx(φ) C_b^c`.
    pub d_pitch: Matrix3<f64>,
    /// `Ry(θ) Rx(φ) [e_x]× C_b^c`.
    pub d_roll: Matrix3<f64>,
}

impl LevelledCamera {
    pub fn new(pitch: f64, roll: f64) -> Self {
        let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), pitch).into_inner();
        let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), roll).into_inner();
        let mount = nadir_camera_to_body();
        Self {
            rotation: ry * rx * mount,
            d_pitch: ry * Vector3::y().cross_matrix() * rx * mount,
            d_roll: ry * rx * Vector3::x().cross_matrix() * mount,
        }
    }
}

/// Partial derivatives of [`camera_to_world`] with respect to (yaw, pitch, roll).
pub fn camera_to_world_partials(att: Attitude) -> [Matrix3<f64>; 3] {
    let level = LevelledCamera::new(att.pitch, att.roll);
    let yaw = yaw_to_world(att.yaw);
    [
        yaw_to_world_derivative(att.yaw) * level.rotation,
        yaw * level.d_pitch,
        yaw * level.d_roll,
    ]
}

/// Pinhole intrinsics of eq. (26), in pixels, OpenCV convention. Pixels are undistorted
/// before they reach the estimator: matching moves the keypoints and the detection
/// through [`crate::lens::Distortion`] (the recording's `distortion`); images are not
/// remapped.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Intrinsics {
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Self { fx, fy, cx, cy }
    }

    /// A camera whose horizontal field of view is `hfov_deg` with square pixels and the
    /// principal point in the middle of a `width` × `height` image.
    pub fn from_hfov(width: u32, height: u32, hfov_deg: f64) -> Self {
        let f = (width as f64 / 2.0) / (hfov_deg.to_radians() / 2.0).tan();
        Self::new(
            f,
            f,
            (width as f64 - 1.0) / 2.0,
            (height as f64 - 1.0) / 2.0,
        )
    }

    /// `K⁻¹ [u, v, 1]ᵀ`: the camera-frame direction of a pixel (eq. 24's inner term),
    /// scaled so its z component is 1. The paper's `(x_p, y_p, f)` with `f_x = f_y = f`
    /// is this vector times `f`; every use in dualgeo is scale-invariant.
    pub fn pixel_to_ray(&self, pixel: Vector2<f64>) -> Vector3<f64> {
        Vector3::new(
            (pixel.x - self.cx) / self.fx,
            (pixel.y - self.cy) / self.fy,
            1.0,
        )
    }

    /// Projects a camera-frame point to pixels; `None` when it is not in front of the camera.
    pub fn project(&self, p_cam: Vector3<f64>) -> Option<Vector2<f64>> {
        if p_cam.z <= 0.0 || !p_cam.iter().all(|v| v.is_finite()) {
            return None;
        }
        Some(Vector2::new(
            self.fx * p_cam.x / p_cam.z + self.cx,
            self.fy * p_cam.y / p_cam.z + self.cy,
        ))
    }

    /// The 3×3 matrix K of eq. (26).
    pub fn matrix(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    pub fn is_valid(&self) -> bool {
        self.fx.is_finite()
            && self.fy.is_finite()
            && self.cx.is_finite()
            && self.cy.is_finite()
            && self.fx > 0.0
            && self.fy > 0.0
    }
}

/// Wraps an angle in radians to (-π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut w = a.rem_euclid(two_pi);
    if w > std::f64::consts::PI {
        w -= two_pi;
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx_eq::assert_close;
    use proptest::prelude::*;
    use std::f64::consts::FRAC_PI_2;

    mod approx_eq {
        macro_rules! assert_close {
            ($a:expr, $b:expr, $tol:expr) => {{
                let (a, b) = ($a, $b);
                assert!((a - b).norm() < $tol, "{a} != {b}");
            }};
        }
        pub(crate) use assert_close;
    }

    #[test]
    fn the_nadir_mount_is_version_ones_camera() {
        assert_close!(Mount::NADIR.camera_to_body(), nadir_camera_to_body(), 1e-15);
        let body = Attitude::from_degrees(37.0, 4.0, -3.0);
        let eq = Mount::NADIR.equivalent_nadir_attitude(body);
        assert_close!(camera_to_world(eq), camera_to_world(body), 1e-12);
        assert!((eq.yaw - body.yaw).abs() < 1e-12 && (eq.pitch - body.pitch).abs() < 1e-12);
    }

    #[test]
    fn the_body_comes_back_from_the_equivalent_attitude() {
        let body = Attitude::from_degrees(-140.0, 6.0, -4.0);
        for mount in [
            Mount::NADIR,
            Mount::from_degrees(0.0, -45.0, 0.0),
            Mount::from_degrees(35.0, -30.0, 2.0),
        ] {
            let back = mount.body_attitude(mount.equivalent_nadir_attitude(body));
            assert_close!(body_to_ned(back), body_to_ned(body), 1e-12);
            assert!((wrap_angle(back.yaw - body.yaw)).abs() < 1e-12);
        }
        assert!(Mount::NADIR.is_nadir() && !Mount::from_degrees(0.0, -45.0, 0.0).is_nadir());
    }

    #[test]
    fn a_camera_pitched_forward_looks_ahead_of_the_uav() {
        // Level, nose north, camera 30° forward of straight down.
        let mount = Mount::from_degrees(0.0, -60.0, 0.0);
        let eq = mount.equivalent_nadir_attitude(Attitude::default());
        let axis = camera_to_world(eq) * Vector3::z();
        assert_close!(axis, Vector3::new(0.0, 0.5, -(3f64.sqrt() / 2.0)), 1e-12);
        // Image right stays east.
        assert_close!(camera_to_world(eq) * Vector3::x(), Vector3::x(), 1e-12);
    }

    proptest! {
        #[test]
        fn the_equivalent_attitude_gives_the_mounted_cameras_rotation(
            yaw in -180.0f64..180.0, pitch in -20.0f64..20.0, roll in -20.0f64..20.0,
            gy in -180.0f64..180.0, gp in -85.0f64..-20.0, gr in -10.0f64..10.0,
        ) {
            let body = Attitude::from_degrees(yaw, pitch, roll);
            let mount = Mount::from_degrees(gy, gp, gr);
            let eq = mount.equivalent_nadir_attitude(body);
            let textbook = ned_to_enu() * body_to_ned(body) * mount.camera_to_body();
            prop_assert!((camera_to_world(eq) - textbook).norm() < 1e-9);
            prop_assert!((body_to_ned(mount.body_attitude(eq)) - body_to_ned(body)).norm() < 1e-9);
        }

        #[test]
        fn a_yaw_bias_carries_over_to_the_equivalent_yaw(
            yaw in -180.0f64..180.0, pitch in -20.0f64..20.0, roll in -20.0f64..20.0,
            gy in -180.0f64..180.0, gp in -85.0f64..-20.0, gr in -10.0f64..10.0,
            bias in -30.0f64..30.0,
        ) {
            let body = Attitude::from_degrees(yaw, pitch, roll);
            let biased = Attitude::from_degrees(yaw + bias, pitch, roll);
            let mount = Mount::from_degrees(gy, gp, gr);
            let (a, b) = (
                mount.equivalent_nadir_attitude(body),
                mount.equivalent_nadir_attitude(biased),
            );
            prop_assert!((wrap_angle(b.yaw - a.yaw) - bias.to_radians()).abs() < 1e-9);
            prop_assert!((b.pitch - a.pitch).abs() < 1e-9 && (b.roll - a.roll).abs() < 1e-9);
        }
    }

    #[test]
    fn split_product_is_the_textbook_product() {
        let att = Attitude::from_degrees(-123.0, 7.0, -4.0);
        let textbook = ned_to_enu() * body_to_ned(att) * nadir_camera_to_body();
        assert!((camera_to_world(att) - textbook).norm() < 1e-12);
    }

    #[test]
    fn level_nose_north_looks_down_with_image_top_north() {
        let c = camera_to_world(Attitude::default());
        assert_close!(c * Vector3::z(), -Vector3::z(), 1e-12); // optical axis down
        assert_close!(c * -Vector3::y(), Vector3::y(), 1e-12); // image top = north
        assert_close!(c * Vector3::x(), Vector3::x(), 1e-12); // image right = east
    }

    #[test]
    fn yaw_east_turns_image_top_east() {
        let c = camera_to_world(Attitude::new(FRAC_PI_2, 0.0, 0.0));
        assert_close!(c * -Vector3::y(), Vector3::x(), 1e-12); // image top = nose = east
        assert_close!(c * Vector3::x(), -Vector3::y(), 1e-12); // image right = south
    }

    #[test]
    fn pitch_up_tilts_optical_axis_forward() {
        // Nose up by 10°: the belly, and the nadir camera, turn towards the nose (north).
        let c = camera_to_world(Attitude::from_degrees(0.0, 10.0, 0.0));
        let axis = c * Vector3::z();
        assert!(axis.y > 0.0 && axis.z < 0.0, "{axis}");
        assert!((axis.y - 10f64.to_radians().sin()).abs() < 1e-12);
    }

    #[test]
    fn roll_right_wing_down_tilts_optical_axis_left() {
        let c = camera_to_world(Attitude::from_degrees(0.0, 0.0, 10.0));
        let axis = c * Vector3::z();
        assert!(axis.x < 0.0 && axis.z < 0.0, "{axis}");
    }

    #[test]
    fn pixel_ray_round_trip() {
        let k = Intrinsics::new(554.26, 560.0, 319.5, 239.5);
        let px = Vector2::new(100.25, 400.75);
        let back = k.project(k.pixel_to_ray(px) * 7.0).unwrap();
        assert_close!(back, px, 1e-9);
        assert_eq!(k.project(Vector3::new(0.0, 0.0, -1.0)), None);
    }

    #[test]
    fn wrap_angle_range() {
        assert!((wrap_angle(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
        assert!((wrap_angle(-std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
        assert!((wrap_angle(0.5) - 0.5).abs() < 1e-15);
    }

    proptest! {
        #[test]
        fn camera_to_world_is_a_proper_rotation(
            yaw in -4.0f64..4.0, pitch in -1.4f64..1.4, roll in -3.0f64..3.0
        ) {
            let c = camera_to_world(Attitude::new(yaw, pitch, roll));
            prop_assert!((c * c.transpose() - Matrix3::identity()).norm() < 1e-12);
            prop_assert!((c.determinant() - 1.0).abs() < 1e-12);
        }

        #[test]
        fn partials_match_central_differences(
            yaw in -4.0f64..4.0, pitch in -1.4f64..1.4, roll in -3.0f64..3.0
        ) {
            let att = Attitude::new(yaw, pitch, roll);
            let d = camera_to_world_partials(att);
            let h = 1e-6;
            let num = |f: &dyn Fn(f64) -> Attitude| {
                (camera_to_world(f(h)) - camera_to_world(f(-h))) / (2.0 * h)
            };
            let fd = [
                num(&|e| Attitude::new(yaw + e, pitch, roll)),
                num(&|e| Attitude::new(yaw, pitch + e, roll)),
                num(&|e| Attitude::new(yaw, pitch, roll + e)),
            ];
            for k in 0..3 {
                prop_assert!((d[k] - fd[k]).norm() < 1e-7, "partial {k}");
            }
        }

        #[test]
        fn yaw_rotates_about_world_up(yaw in -4.0f64..4.0, pitch in -0.5f64..0.5, roll in -0.5f64..0.5) {
            // Adding yaw in NED (about down) rotates world vectors about ENU up by -yaw.
            let c0 = camera_to_world(Attitude::new(0.0, pitch, roll));
            let c1 = camera_to_world(Attitude::new(yaw, pitch, roll));
            let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), -yaw).into_inner();
            prop_assert!((c1 - rz * c0).norm() < 1e-12);
        }
    }
}
