//! A geometric stand-in for the paper's Gazebo scenario (Section 3.1), without images:
//! a vehicle driving a gently curving road, two nadir UAVs 100 m above the ground and
//! 70 m apart across the direction of travel, past images picked by the baseline
//! constraint T_re, and the navigation noise of the paper's experiments (Gaussian
//! position and attitude noise, yaw biases by eq. 34).
//!
//! The target pixels are exact projections of the target's *current* position into each
//! image's true pose (perfect detection and matching, plus optional pixel noise). This is
//! evaluation data: the generator knows the truth, the estimator only gets the
//! [`Trial::observations`].

use crate::Observation;
use nalgebra::{Point3, Vector2, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use shared_types::conventions::{camera_to_world, Attitude, Intrinsics, Mount, Uav};
pub use shared_types::nav_noise::{BiasModel, NavNoise};

/// The scenario's geometry and noise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SyntheticScenario {
    /// Ground altitude, metres (non-zero on purpose: the estimator must find it).
    pub ground_z_m: f64,
    /// Height of the target point (top face of the vehicle) above the ground, metres.
    pub target_height_m: f64,
    /// UAV height above the ground, metres (paper: 100).
    pub altitude_agl_m: f64,
    /// Distance between the UAVs across the direction of travel, metres (paper: 70).
    pub uav_separation_m: f64,
    /// Target speed, m/s.
    pub speed_mps: f64,
    /// Target heading at t = 0 (from north, clockwise), degrees.
    pub initial_heading_deg: f64,
    /// Target turn rate, degrees per second.
    pub turn_rate_deg_s: f64,
    /// T_re: the baseline constraint between consecutive images of one UAV, metres.
    /// The biases are observable only through the UAVs' displacement between images, so
    /// the default is as long as keeps the target in view: with 4 images per UAV the
    /// oldest is 30 m back and the target ~166 px from its centre (100 m AGL, 60° HFOV).
    /// `cargo run --release -p dualgeo-bench --bin baseline_sweep` shows the trade.
    pub keyframe_spacing_m: f64,
    /// Amplitude of the UAVs' true roll and pitch oscillation, degrees.
    pub sway_deg: f64,
    pub image_width: u32,
    pub image_height: u32,
    pub intrinsics: Intrinsics,
    pub noise: NavNoise,
    /// σ per pixel coordinate of the target point (detection/matching noise), pixels.
    pub sigma_pixel_px: f64,
    pub bias: BiasModel,
    /// How far the camera looks forward of straight down, degrees (0: the paper's nadir
    /// camera). A tilted camera's image enters the estimator as its equivalent nadir
    /// attitude (`Mount::equivalent_nadir_attitude`), the AHRS's errors applied to the
    /// body as the simulator does, so some of its pitch and roll errors turn into the
    /// equivalent yaw.
    #[serde(default)]
    pub camera_tilt_deg: f64,
    /// How far behind the target the UAVs fly, metres (0: abreast, the paper's
    /// geometry). A tilted camera sees the target at its centre line from
    /// `altitude_agl_m · tan(camera_tilt_deg)` behind.
    #[serde(default)]
    pub trail_m: f64,
}

impl Default for SyntheticScenario {
    /// The paper's Table 2 protocol: σ_att 2°, σ_pos 3 m, δψ0 = 20° with eq. (34).
    fn default() -> Self {
        Self {
            ground_z_m: 12.0,
            target_height_m: 1.5,
            altitude_agl_m: 100.0,
            uav_separation_m: 70.0,
            speed_mps: 8.0,
            initial_heading_deg: 30.0,
            turn_rate_deg_s: 2.0,
            keyframe_spacing_m: 10.0,
            sway_deg: 2.0,
            image_width: 640,
            image_height: 480,
            intrinsics: Intrinsics::new(554.26, 554.26, 319.5, 239.5),
            noise: NavNoise::isotropic(3.0, 2.0),
            sigma_pixel_px: 0.0,
            bias: BiasModel::Eq34 {
                delta0_deg: 20.0,
                rate_deg_s: 0.2,
            },
            camera_tilt_deg: 0.0,
            trail_m: 0.0,
        }
    }
}

/// One geolocation's worth of synthetic data.
#[derive(Debug, Clone, PartialEq)]
pub struct Trial {
    pub t_s: f64,
    /// Current left, current right, then the left past images newest first, then the right.
    pub observations: Vec<Observation>,
    /// Truth (evaluation only): the target point at `t_s`.
    pub target: Point3<f64>,
    /// Truth (evaluation only): (δψ_L, δψ_R) at `t_s`, radians.
    pub yaw_bias: [f64; 2],
    /// UAV–target distances of the two current images: the one-shot baseline's
    /// rangefinder reading.
    pub ranges_m: [f64; 2],
}

/// A trial could not be generated (the scenario does not keep the target in view).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("target out of view of the {uav:?} image at t = {t_s:.2} s (pixel {u:.1}, {v:.1})")]
pub struct OutOfView {
    pub uav: Uav,
    pub t_s: f64,
    pub u: f64,
    pub v: f64,
}

impl SyntheticScenario {
    fn heading(&self, t_s: f64) -> f64 {
        (self.initial_heading_deg + self.turn_rate_deg_s * t_s).to_radians()
    }

    /// The target point (top face centre) at `t_s`, world ENU.
    pub fn target_at(&self, t_s: f64) -> Point3<f64> {
        let h0 = self.initial_heading_deg.to_radians();
        let w = self.turn_rate_deg_s.to_radians();
        let v = self.speed_mps;
        // Velocity (east, north) = v (sin h, cos h), h = h0 + w t.
        let (x, y) = if w.abs() < 1e-9 {
            (v * t_s * h0.sin(), v * t_s * h0.cos())
        } else {
            let h = h0 + w * t_s;
            (
                (v / w) * (h0.cos() - h.cos()),
                (v / w) * (h.sin() - h0.sin()),
            )
        };
        Point3::new(x, y, self.ground_z_m + self.target_height_m)
    }

    /// True position and attitude of a UAV at `t_s`: abreast of the target, half the
    /// separation to its side, nose along the track, swaying gently.
    pub fn uav_at(&self, uav: Uav, t_s: f64) -> (Point3<f64>, Attitude) {
        let h = self.heading(t_s);
        let right = Vector3::new(h.cos(), -h.sin(), 0.0);
        let side = match uav {
            Uav::Left => -0.5,
            Uav::Right => 0.5,
        };
        let phase = match uav {
            Uav::Left => 0.0,
            Uav::Right => 1.3,
        };
        let ground = self.target_at(t_s);
        let back = self.trail_m * Vector3::new(h.sin(), h.cos(), 0.0);
        let position = Point3::new(
            ground.x + side * self.uav_separation_m * right.x - back.x,
            ground.y + side * self.uav_separation_m * right.y - back.y,
            self.ground_z_m + self.altitude_agl_m + (0.37 * t_s + phase).sin(),
        );
        let sway = self.sway_deg.to_radians();
        let attitude = Attitude::new(
            h,
            sway * (0.9 * t_s + phase).sin(),
            sway * (1.1 * t_s + 2.0 * phase).cos(),
        );
        (position, attitude)
    }

    /// The attitude the estimator is given for a body at `body`: the body's own for a
    /// nadir camera, else its camera's equivalent nadir attitude (the form every
    /// recording of a tilted camera is read into).
    pub fn camera_attitude(&self, body: Attitude) -> Attitude {
        if self.camera_tilt_deg == 0.0 {
            body
        } else {
            self.mount().equivalent_nadir_attitude(body)
        }
    }

    /// The camera's mount: nadir, or fixed `camera_tilt_deg` forward of it.
    pub fn mount(&self) -> Mount {
        if self.camera_tilt_deg == 0.0 {
            Mount::NADIR
        } else {
            Mount::from_degrees(0.0, self.camera_tilt_deg - 90.0, 0.0)
        }
    }

    /// Time between two images of one UAV that satisfy the baseline constraint.
    pub fn keyframe_interval_s(&self) -> f64 {
        self.keyframe_spacing_m / self.speed_mps
    }

    /// Data for one geolocation at `t_s` with `n_per_uav` images per UAV (the current
    /// one and N − 1 past ones).
    pub fn trial<R: Rng>(
        &self,
        t_s: f64,
        n_per_uav: usize,
        rng: &mut R,
    ) -> Result<Trial, OutOfView> {
        let target = self.target_at(t_s);
        let pos_noise = self.noise.sigma_position_m.map(normal);
        let att_noise = self
            .noise
            .sigma_attitude_deg
            .map(|s| normal(s.to_radians()));
        let px_noise = normal(self.sigma_pixel_px);
        let mut observations = Vec::with_capacity(2 * n_per_uav);
        let mut ranges_m = [0.0; 2];
        // Current pair first, then each UAV's past images newest first.
        let mut order = vec![(Uav::Left, 0), (Uav::Right, 0)];
        for uav in [Uav::Left, Uav::Right] {
            order.extend((1..n_per_uav).map(|k| (uav, k)));
        }
        for (uav, k) in order {
            let t_k = t_s - k as f64 * self.keyframe_interval_s();
            let (position, attitude) = self.uav_at(uav, t_k);
            let cam =
                camera_to_world(self.camera_attitude(attitude)).transpose() * (target - position);
            let pixel = self
                .intrinsics
                .project(cam)
                .filter(|p| self.in_image(*p))
                .ok_or(OutOfView {
                    uav,
                    t_s: t_k,
                    u: self.intrinsics.fx * cam.x / cam.z + self.intrinsics.cx,
                    v: self.intrinsics.fy * cam.y / cam.z + self.intrinsics.cy,
                })?;
            if k == 0 {
                ranges_m[uav.index()] = (target - position).norm();
            }
            let bias = self.bias.at(t_k)[uav.index()];
            let mut sample = |d: &Option<Normal<f64>>| d.map_or(0.0, |d| d.sample(rng));
            observations.push(Observation {
                uav,
                position: position
                    + Vector3::new(
                        sample(&pos_noise[0]),
                        sample(&pos_noise[1]),
                        sample(&pos_noise[2]),
                    ),
                attitude: self.camera_attitude(Attitude::new(
                    attitude.yaw + bias + sample(&att_noise[0]),
                    attitude.pitch + sample(&att_noise[1]),
                    attitude.roll + sample(&att_noise[2]),
                )),
                mount: self.mount(),
                pixel: pixel + Vector2::new(sample(&px_noise), sample(&px_noise)),
                intrinsics: self.intrinsics,
            });
        }
        Ok(Trial {
            t_s,
            observations,
            target,
            yaw_bias: self.bias.at(t_s),
            ranges_m,
        })
    }

    fn in_image(&self, p: Vector2<f64>) -> bool {
        p.x >= 0.0
            && p.y >= 0.0
            && p.x <= self.image_width as f64 - 1.0
            && p.y <= self.image_height as f64 - 1.0
    }
}

fn normal(sigma: f64) -> Option<Normal<f64>> {
    (sigma > 0.0)
        .then(|| Normal::new(0.0, sigma).ok())
        .flatten()
}
