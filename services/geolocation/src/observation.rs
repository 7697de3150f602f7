//! The estimator's input: one image's measured navigation state and target pixel.

use crate::EstimatorError;
use nalgebra::{Point3, Vector2, Vector3};
use shared_types::conventions::{Attitude, Intrinsics, Mount, Uav};
use shared_types::messages::{MountSample, ObservationEntry, PoseSample};

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

/// What the temporal filter knows of the pose errors of the images of its last
/// update: the leading hypothesis's posterior mean of each image's error `e` (x, y,
/// z, yaw, pitch, roll; measured = true + e, as [`Observation::pose_without_error`]
/// takes it), the current pair's before they are marginalised and each keyframe's
/// slot (a UAV's correlated block added where it has one). Beyond the paper: the other
/// vehicles are located through the same images (`others_message.rs`), and a
/// keyframe's error, reused by many pairs, is what their fixes could not average.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ImagePoseErrors {
    /// The time of the update, seconds (the set's `t_s`).
    pub t_s: f64,
    /// The current (left, right) images', where the update had them.
    pub current: [Option<[f64; 6]>; 2],
    /// Each keyframe's that had a slot.
    pub past: Vec<(ImageId, [f64; 6])>,
}

impl ImagePoseErrors {
    /// The error of the current image of `uav`.
    pub fn of_current(&self, uav: Uav) -> Option<[f64; 6]> {
        self.current[uav.index()]
    }

    /// The error of past image `id`.
    pub fn of_past(&self, id: ImageId) -> Option<[f64; 6]> {
        self.past.iter().find(|(i, _)| *i == id).map(|(_, e)| *e)
    }
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
    /// Measured attitude (AHRS), radians. Its yaw carries the unknown bias δψ. For a
    /// tilted or gimballed camera, its equivalent nadir attitude
    /// (`Mount::equivalent_nadir_attitude`).
    pub attitude: Attitude,
    /// The camera's mount on the body, through which `attitude` was turned (the nadir
    /// mount: `attitude` is the body's own).
    pub mount: Mount,
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
    ///
    /// The attitude error is the AHRS's, on the **body's** Euler angles (where the
    /// σ_att of Table 2 applies). For a nadir camera that is the image's own attitude.
    /// A mounted camera's equivalent attitude is turned back to its body's, the error
    /// removed there and the mount applied again: 45° off nadir, 2° body errors move
    /// the equivalent yaw and roll by 2.8° each, correlated 0.71, which an error on
    /// the equivalent angles (σ 2°, independent) under-states (docs/temporal.md
    /// "Mounted cameras' attitude errors").
    pub fn pose_without_error(&self, yaw_bias: [f64; 2], e: &[f64]) -> (Point3<f64>, Attitude) {
        let bias = yaw_bias[self.uav.index()];
        let without = |a: Attitude| Attitude {
            yaw: a.yaw - bias - e[3],
            pitch: a.pitch - e[4],
            roll: a.roll - e[5],
        };
        let att = if self.mount.is_nadir() {
            without(self.attitude)
        } else {
            self.mount
                .equivalent_nadir_attitude(without(self.mount.body_attitude(self.attitude)))
        };
        let position = Point3::new(
            self.position.x - e[0],
            self.position.y - e[1],
            self.position.z - e[2],
        );
        (position, att)
    }

    /// This image with the pose error `e` removed from its measured pose (its yaw
    /// bias left in): what its pose would be had the navigation erred by nothing but
    /// the bias. Non-finite errors leave it as it is.
    pub fn with_pose_error_removed(&self, e: &[f64; 6]) -> Observation {
        if !e.iter().all(|v| v.is_finite()) {
            return *self;
        }
        let (position, attitude) = self.pose_without_error([0.0; 2], e);
        Observation {
            position,
            attitude,
            ..*self
        }
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
        finite(self.mount.0.is_finite(), "mount")?;
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
                mount: MountSample::from_mount(self.mount),
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
            mount: entry.pose.mount.mount(),
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
    use proptest::prelude::*;
    use shared_types::conventions::camera_to_world;

    fn image(attitude: Attitude, mount: Mount) -> Observation {
        Observation {
            uav: Uav::Right,
            position: Point3::new(1.0, -2.0, 100.0),
            attitude,
            mount,
            pixel: Vector2::new(320.0, 240.0),
            intrinsics: Intrinsics::new(500.0, 500.0, 320.0, 240.0),
        }
    }

    /// A nadir camera's attitude is its body's: the bias and the error come off its
    /// Euler angles, exactly as eq. (10) writes the bias.
    #[test]
    fn a_nadir_images_error_comes_off_its_euler_angles() {
        let o = image(Attitude::new(0.5, 0.03, -0.02), Mount::NADIR);
        let e = [1.0, 2.0, 3.0, 0.01, -0.02, 0.03];
        let (p, a) = o.pose_without_error([0.0, 0.2], &e);
        assert_eq!(p, Point3::new(0.0, -4.0, 97.0));
        assert_eq!(
            (a.yaw, a.pitch, a.roll),
            (0.5 - 0.2 - 0.01, 0.03 + 0.02, -0.02 - 0.03)
        );
    }

    /// The 2° of roll an AHRS reads on a body whose camera looks 45° forward: taking
    /// the error off the body's angles gives the camera's true rotation back; taking
    /// it off the equivalent attitude's angles leaves most of it.
    #[test]
    fn the_equivalent_angles_miss_a_mounted_cameras_body_error() {
        let mount = Mount::from_degrees(0.0, -45.0, 0.0);
        let truth = Attitude::from_degrees(30.0, 1.0, -1.0);
        let err = 2f64.to_radians();
        let measured = mount.equivalent_nadir_attitude(Attitude {
            roll: truth.roll + err,
            ..truth
        });
        let e = [0.0, 0.0, 0.0, 0.0, 0.0, err];
        let want = camera_to_world(mount.equivalent_nadir_attitude(truth));
        let left = |o: Observation| {
            let (_, a) = o.pose_without_error([0.0; 2], &e);
            nalgebra::Rotation3::from_matrix_unchecked(camera_to_world(a).transpose() * want)
                .angle()
        };
        let body = left(image(measured, mount));
        let equivalent = left(image(measured, Mount::NADIR));
        assert!(body < 1e-9, "{body}");
        assert!(equivalent > 0.5 * err, "{} of {err}", equivalent);
    }

    proptest! {
        /// Any mount, any body near level, any heading: the AHRS's error and the
        /// bias taken off the body's angles give the camera's true rotation.
        #[test]
        fn a_mounted_cameras_body_error_comes_off_exactly(
            yaw in -180.0f64..180.0, pitch in -15.0f64..15.0, roll in -15.0f64..15.0,
            gy in -180.0f64..180.0, gp in -85.0f64..-20.0, gr in -10.0f64..10.0,
            ey in -3.0f64..3.0, ep in -3.0f64..3.0, er in -3.0f64..3.0,
            bias in -40.0f64..40.0,
        ) {
            let mount = Mount::from_degrees(gy, gp, gr);
            let truth = Attitude::from_degrees(yaw, pitch, roll);
            let measured = mount.equivalent_nadir_attitude(Attitude::from_degrees(
                yaw + bias + ey,
                pitch + ep,
                roll + er,
            ));
            let e = [0.0, 0.0, 0.0, ey.to_radians(), ep.to_radians(), er.to_radians()];
            let (_, a) = image(measured, mount).pose_without_error([0.0, bias.to_radians()], &e);
            let want = camera_to_world(mount.equivalent_nadir_attitude(truth));
            prop_assert!((camera_to_world(a) - want).norm() < 1e-9);
        }
    }

    #[test]
    fn entry_round_trip_and_bad_uav() {
        let o = Observation {
            uav: Uav::Right,
            position: Point3::new(1.0, -2.0, 100.0),
            attitude: Attitude::from_degrees(30.0, 2.0, -1.0),
            mount: Mount::from_degrees(10.0, -45.0, 1.0),
            pixel: Vector2::new(320.5, 200.25),
            intrinsics: Intrinsics::new(500.0, 501.0, 320.0, 240.0),
        };
        let back = Observation::from_entry(&o.to_entry(), 0).unwrap();
        assert_eq!(back.uav, o.uav);
        assert!((back.position - o.position).norm() < 1e-12);
        assert!((back.attitude.yaw - o.attitude.yaw).abs() < 1e-12);
        assert!((back.mount.0.pitch - o.mount.0.pitch).abs() < 1e-12);
        let nadir = Observation {
            mount: Mount::NADIR,
            ..o
        };
        assert_eq!(
            Observation::from_entry(&nadir.to_entry(), 0).unwrap().mount,
            Mount::NADIR
        );
        assert_eq!(back.pixel, o.pixel);
        let mut bad = o.to_entry();
        bad.uav = 7;
        assert!(Observation::from_entry(&bad, 3).is_err());
        let mut nan = o.to_entry();
        nan.pixel[0] = f64::NAN;
        assert!(Observation::from_entry(&nan, 3).is_err());
    }
}
