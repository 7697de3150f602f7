//! The simulator's tracking gimbal (`[camera] gimbal`, recording format v2 `mount =
//! "gimbal"`): each frame the camera turns toward the vehicle through a first-order lag.
//!
//! The gimbal frame G is the contract's: aerospace Z-Y-X angles relative to the body FRD
//! frame, the camera looking along G's +x (`shared_types::conventions::Mount`). A
//! direction `d` in the body frame is on the optical axis when G's yaw is
//! `atan2(d_y, d_x)` and its pitch `−asin(d_z)` (roll 0): nadir is pitch −90°.

use super::scenario::TrackingGimbal;
use nalgebra::{Point3, Vector3};
use shared_types::conventions::{body_to_ned, ned_to_enu, wrap_angle, Attitude, Mount};

/// Yaw and pitch (radians, roll 0) of a gimbal on a body at `body` whose optical axis
/// points from `from` to `to` (ENU); none when they coincide.
pub fn aim(body: Attitude, from: Point3<f64>, to: Point3<f64>) -> Option<[f64; 2]> {
    let d_enu: Vector3<f64> = to - from;
    let n = d_enu.norm();
    if !(n.is_finite() && n > 1e-9) {
        return None;
    }
    // ENU → NED (the same permutation both ways), then NED → body.
    let d = body_to_ned(body).transpose() * (ned_to_enu() * (d_enu / n));
    Some([d.y.atan2(d.x), -d.z.clamp(-1.0, 1.0).asin()])
}

/// One UAV's gimbal between frames: its true yaw and pitch.
#[derive(Debug, Clone, Copy, Default)]
pub struct GimbalTrack {
    angles: Option<[f64; 2]>,
}

impl GimbalTrack {
    /// The gimbal's true mount after one frame period `dt` of turning toward `target`:
    /// the first frame is on target; later ones close `1 − exp(−dt/τ)` of the gap. A
    /// view straight down (yaw undefined) keeps the last yaw.
    pub fn step(
        &mut self,
        spec: &TrackingGimbal,
        body: Attitude,
        camera: Point3<f64>,
        target: Point3<f64>,
        dt: f64,
    ) -> Mount {
        let current = self.angles;
        let goal = aim(body, camera, target)
            .or(current)
            .unwrap_or([0.0, -std::f64::consts::FRAC_PI_2]);
        let next = match current {
            None => goal,
            Some([yaw, pitch]) => {
                let k = if spec.tau_s > 0.0 {
                    1.0 - (-dt / spec.tau_s).exp()
                } else {
                    1.0
                };
                // Near nadir the yaw that aims is ill-defined and swings: hold it.
                let yaw_goal = if goal[1].cos() < 0.05 { yaw } else { goal[0] };
                [
                    wrap_angle(yaw + k * wrap_angle(yaw_goal - yaw)),
                    pitch + k * (goal[1] - pitch),
                ]
            }
        };
        self.angles = Some(next);
        Mount(Attitude {
            yaw: next[0],
            pitch: next[1],
            roll: 0.0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shared_types::conventions::camera_to_world;

    /// The camera of the aimed mount looks at the target: its optical axis, through the
    /// same conversion every consumer uses (equivalent nadir attitude), is the
    /// direction to it.
    #[test]
    fn an_aimed_gimbal_puts_the_target_on_the_optical_axis() {
        let body = Attitude::from_degrees(35.0, 4.0, -3.0);
        let from = Point3::new(10.0, -20.0, 100.0);
        for to in [
            Point3::new(60.0, 40.0, 0.0),
            Point3::new(-50.0, 0.0, 5.0),
            Point3::new(12.0, -15.0, 0.0),
        ] {
            let [yaw, pitch] = aim(body, from, to).unwrap();
            let mount = Mount(Attitude {
                yaw,
                pitch,
                roll: 0.0,
            });
            let axis = camera_to_world(mount.equivalent_nadir_attitude(body)) * Vector3::z();
            let want = (to - from).normalize();
            assert!((axis - want).norm() < 1e-9, "{axis} vs {want}");
        }
        assert!(aim(body, from, from).is_none());
    }

    #[test]
    fn the_gimbal_lags_a_moving_target_and_settles_on_a_still_one() {
        let spec = TrackingGimbal {
            tau_s: 0.3,
            encoder_noise_deg: 0.0,
        };
        let body = Attitude::from_degrees(0.0, 0.0, 0.0);
        let camera = Point3::new(0.0, 0.0, 100.0);
        let mut g = GimbalTrack::default();
        let first = g.step(
            &spec,
            body,
            camera,
            Point3::new(0.0, 100.0, 0.0),
            1.0 / 30.0,
        );
        assert!(
            (first.0.pitch.to_degrees() + 45.0).abs() < 1e-9,
            "{first:?}"
        );
        // The target jumps 20 m ahead: after one frame the gimbal has moved a tenth of
        // the way (dt/τ = 1/9), after 3 s it is there.
        let ahead = Point3::new(0.0, 120.0, 0.0);
        let goal = aim(body, camera, ahead).unwrap()[1];
        let one = g.step(&spec, body, camera, ahead, 1.0 / 30.0).0.pitch;
        let k = 1.0 - (-1.0f64 / 9.0).exp();
        assert!((one - (first.0.pitch + k * (goal - first.0.pitch))).abs() < 1e-12);
        for _ in 0..90 {
            g.step(&spec, body, camera, ahead, 1.0 / 30.0);
        }
        let settled = g.step(&spec, body, camera, ahead, 1.0 / 30.0).0.pitch;
        assert!((settled - goal).abs() < 1e-4);
    }
}
