//! The live source: steps the scenario one frame period at a time and renders each
//! UAV's view into a caller's buffer.

use super::city::City;
use super::motion::{Motion, Route, TrueState};
use super::render::{CameraView, Renderer, VehicleBox};
use super::scenario::SimConfig;
use super::SimError;
use nalgebra::Point3;
use opencv::prelude::*;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use shared_types::conventions::{camera_to_world, wrap_angle, Attitude, Intrinsics, Uav};
use shared_types::messages::PoseSample;
use std::sync::Arc;

/// One UAV's image at one instant: what was true and what the sensors said.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimFrame {
    pub uav: Uav,
    pub seq: u64,
    pub t_s: f64,
    /// The true camera (used to render).
    pub view: CameraView,
    pub true_pose: PoseSample,
    /// GPS + AHRS: truth plus Gaussian noise, the yaw plus its bias.
    pub measured: PoseSample,
    /// The target point (centre of the vehicle's top face), ENU.
    pub target: [f64; 3],
    /// Its exact projection, when inside the image.
    pub target_px: Option<[f64; 2]>,
}

/// Both UAVs' frames at one instant, and the vehicle they see.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimStep {
    pub frames: [SimFrame; 2],
    pub vehicle: VehicleBox,
}

pub struct Simulator {
    config: SimConfig,
    city: Arc<City>,
    motion: Motion,
    rng: StdRng,
    noise: [Option<Normal<f64>>; 6],
    intrinsics: Intrinsics,
    seq: u64,
    renderers: [Renderer; 2],
}

impl Simulator {
    /// Builds the town (or loads the orthophoto) and places everything at t = 0.
    pub fn new(config: SimConfig) -> Result<Self, SimError> {
        config.validate()?;
        let mut city = City::generate(config.city);
        if let Some(path) = &config.ground_image {
            let img = opencv::imgcodecs::imread(path.as_os_str(), opencv::imgcodecs::IMREAD_COLOR)
                .map_err(|e| SimError::GroundImage {
                    path: path.clone(),
                    reason: e.message,
                })?;
            if img.empty() {
                return Err(SimError::GroundImage {
                    path: path.clone(),
                    reason: "cannot be read as an image".into(),
                });
            }
            let bytes = img.data_bytes().map_err(|e| SimError::GroundImage {
                path: path.clone(),
                reason: e.message,
            })?;
            city = city.with_ground_image(img.cols() as usize, img.rows() as usize, bytes.to_vec());
        }
        Self::with_city(config, Arc::new(city))
    }

    /// As [`Simulator::new`] with an already built town (shared between simulators).
    pub fn with_city(config: SimConfig, city: Arc<City>) -> Result<Self, SimError> {
        config.validate()?;
        let route = Route::new(&config.driving).map_err(SimError::Config)?;
        let dt = 1.0 / config.frame_rate_hz;
        let motion = Motion::new(
            route,
            config.flight,
            config.city.ground_z_m,
            config.driving.start_m,
            dt,
        );
        let c = config.camera;
        let normal = |s: f64| (s > 0.0).then(|| Normal::new(0.0, s).ok()).flatten();
        let [px, py, pz] = config.noise.sigma_position_m;
        let [ay, ap, ar] = config.noise.sigma_attitude_deg;
        Ok(Self {
            intrinsics: Intrinsics::from_hfov(c.width, c.height, c.hfov_deg),
            rng: StdRng::seed_from_u64(config.seed),
            noise: [
                normal(px),
                normal(py),
                normal(pz),
                normal(ay),
                normal(ap),
                normal(ar),
            ],
            city,
            motion,
            seq: 0,
            renderers: [Renderer::new(), Renderer::new()],
            config,
        })
    }

    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    pub fn city(&self) -> &Arc<City> {
        &self.city
    }

    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// Frames per UAV this run will produce.
    pub fn frame_count(&self) -> u64 {
        self.config.frame_count()
    }

    /// The next instant, or `None` after the configured duration.
    pub fn step(&mut self) -> Option<SimStep> {
        if self.seq >= self.frame_count() {
            return None;
        }
        let state = self.motion.next_state();
        let v = self.config.vehicle;
        let vehicle = VehicleBox {
            x: state.vehicle_xy[0],
            y: state.vehicle_xy[1],
            heading: state.vehicle_heading,
            length_m: v.length_m,
            width_m: v.width_m,
            height_m: v.height_m,
        };
        let target = vehicle.top_centre(self.config.city.ground_z_m);
        let frames = [Uav::Left, Uav::Right].map(|uav| self.frame(&state, uav, target));
        self.seq += 1;
        Some(SimStep { frames, vehicle })
    }

    fn frame(&mut self, state: &TrueState, uav: Uav, target: Point3<f64>) -> SimFrame {
        let i = uav.index();
        let [x, y, z] = state.uav_position[i];
        let [yaw, pitch, roll] = state.uav_attitude[i];
        let attitude = Attitude::new(yaw, pitch, roll);
        let view = CameraView {
            position: Point3::new(x, y, z),
            rotation: camera_to_world(attitude),
            intrinsics: self.intrinsics,
            width: self.config.camera.width,
            height: self.config.camera.height,
        };
        let mut draw = |k: usize| self.noise[k].map_or(0.0, |n| n.sample(&mut self.rng));
        let noise = [draw(0), draw(1), draw(2), draw(3), draw(4), draw(5)];
        let bias = self.config.bias.at(state.t_s)[i];
        let true_pose = pose(x, y, z, yaw, pitch, roll);
        let measured = pose(
            x + noise[0],
            y + noise[1],
            z + noise[2],
            yaw + bias + noise[3].to_radians(),
            pitch + noise[4].to_radians(),
            roll + noise[5].to_radians(),
        );
        let (w, h) = (view.width as f64, view.height as f64);
        let target_px = view
            .project(&target)
            .filter(|p| p[0] >= 0.0 && p[1] >= 0.0 && p[0] <= w - 1.0 && p[1] <= h - 1.0);
        SimFrame {
            uav,
            seq: self.seq,
            t_s: state.t_s,
            view,
            true_pose,
            measured,
            target: [target.x, target.y, target.z],
            target_px,
        }
    }

    /// Renders one UAV's view of `step` as BGR8 into `out` (rows of `stride` bytes).
    pub fn render(&mut self, step: &SimStep, uav: Uav, out: &mut [u8], stride: usize) {
        let frame = &step.frames[uav.index()];
        self.renderers[uav.index()].render(
            &self.city,
            Some(&step.vehicle),
            &frame.view,
            out,
            stride,
        );
    }

    /// Renders both views of `step`, one thread each.
    pub fn render_pair(
        &mut self,
        step: &SimStep,
        left: &mut [u8],
        right: &mut [u8],
        stride: usize,
    ) {
        let city = &self.city;
        let [rl, rr] = &mut self.renderers;
        std::thread::scope(|s| {
            s.spawn(|| {
                rl.render(
                    city,
                    Some(&step.vehicle),
                    &step.frames[0].view,
                    left,
                    stride,
                )
            });
            rr.render(
                city,
                Some(&step.vehicle),
                &step.frames[1].view,
                right,
                stride,
            );
        });
    }

    /// The renderer that drew `uav`'s last image (its per-pixel surface labels).
    pub fn renderer(&self, uav: Uav) -> &Renderer {
        &self.renderers[uav.index()]
    }
}

/// A pose in the recording's units: metres and degrees, yaw wrapped to (−180, 180].
fn pose(x: f64, y: f64, z: f64, yaw: f64, pitch: f64, roll: f64) -> PoseSample {
    PoseSample {
        x_m: x,
        y_m: y,
        z_m: z,
        yaw_deg: wrap_angle(yaw).to_degrees(),
        pitch_deg: pitch.to_degrees(),
        roll_deg: roll.to_degrees(),
    }
}
