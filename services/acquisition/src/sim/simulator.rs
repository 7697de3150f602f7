//! The live source: steps the scenario one frame period at a time and renders each
//! UAV's view into a caller's buffer.

use super::city::City;
use super::gimbal::GimbalTrack;
use super::lens::LensMap;
use super::motion::{Motion, Route, TrueState};
use super::render::{CameraView, Renderer, Surface, TrafficBox, VehicleBox, VEHICLE_TOP_BGR};
use super::scenario::SimConfig;
use super::SimError;
use nalgebra::Point3;
use opencv::prelude::*;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::Distribution;
use shared_types::conventions::{camera_to_world, wrap_angle, Attitude, Intrinsics, Mount, Uav};
use shared_types::lens::Distortion;
use shared_types::messages::{MountSample, PoseSample};
use shared_types::nav_noise::NavErrorState;
use std::sync::Arc;

/// One UAV's image at one instant: what was true and what the sensors said.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimFrame {
    pub uav: Uav,
    pub seq: u64,
    pub t_s: f64,
    /// The true camera (used to render).
    pub view: CameraView,
    /// The camera's true pose: its position and, for a tilted camera, the equivalent
    /// nadir attitude (`Mount::equivalent_nadir_attitude`); what every consumer of a
    /// frame's pose uses. The body's own for a nadir camera.
    pub true_pose: PoseSample,
    /// GPS + AHRS: truth plus Gaussian noise, the yaw plus its bias (the camera's, as
    /// `true_pose`).
    pub measured: PoseSample,
    /// The body's true and measured poses, as a recording stores them (telemetry.csv
    /// and truth.csv carry the body's attitude and the mount separately).
    pub body_true: PoseSample,
    pub body_measured: PoseSample,
    /// The target point (centre of the vehicle's top face), ENU.
    pub target: [f64; 3],
    /// Its exact projection, when inside the image.
    pub target_px: Option<[f64; 2]>,
    /// A tracking gimbal's angles at this frame (`[camera] gimbal`): true, and as its
    /// encoders report them, degrees (yaw, pitch, roll).
    pub gimbal: Option<GimbalAngles>,
}

/// One moving vehicle as one image shows it (truth_targets.csv; evaluation only).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleTruth {
    /// 0: the target; 1 + index in the scenario's traffic list: a traffic car.
    pub id: u32,
    /// The centre of its top face, ENU metres.
    pub point: [f64; 3],
    /// Its projection into the image; `None` outside it or hidden.
    pub px: Option<[f64; 2]>,
}

/// A gimbal's angles in one frame, degrees (yaw, pitch, roll of G relative to the body).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GimbalAngles {
    pub true_deg: [f64; 3],
    pub measured_deg: [f64; 3],
}

/// Both UAVs' frames at one instant, and the vehicle they see.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimStep {
    pub frames: [SimFrame; 2],
    pub vehicle: VehicleBox,
    /// Truth for scoring: the top centres of the traffic cars coloured like the target
    /// (look-alikes), ENU; the first four.
    pub look_alikes: [Option<[f64; 3]>; 4],
}

pub struct Simulator {
    config: SimConfig,
    city: Arc<City>,
    motion: Motion,
    rng: StdRng,
    /// Each UAV's navigation errors (white or correlated over time).
    nav_errors: [NavErrorState; 2],
    /// Each UAV's tracking gimbal, when the camera has one.
    gimbals: [GimbalTrack; 2],
    intrinsics: Intrinsics,
    seq: u64,
    renderers: [Renderer; 2],
    /// A distorted camera's resampling map, with each UAV's pinhole canvas.
    lens: Option<(Arc<LensMap>, [Vec<u8>; 2])>,
    /// The traffic at the last [`Simulator::step`] (rendered with it), and the target's
    /// arc length at the first step (traffic moves relative to it).
    traffic: Vec<TrafficBox>,
    start_s_m: Option<f64>,
}

impl Simulator {
    /// Builds the town (or loads the orthophoto) and places everything at t = 0.
    pub fn new(config: SimConfig) -> Result<Self, SimError> {
        config.validate()?;
        let mut city = City::generate(config.city).with_occluders(&config.occluders);
        if let Some(path) = &config.ground_image {
            let (w, h, bgr) = read_photo(path)?;
            city = city.with_ground_image(w, h, bgr);
        }
        if let Some(path) = &config.roof_image {
            let (w, h, bgr) = read_photo(path)?;
            city = city.with_roof_image(w, h, bgr);
        }
        Self::with_city(config, Arc::new(city))
    }

    /// As [`Simulator::new`] with an already built town (shared between simulators).
    pub fn with_city(config: SimConfig, city: Arc<City>) -> Result<Self, SimError> {
        config.validate()?;
        let route = Route::new(&config.driving).map_err(SimError::Config)?;
        let dt = 1.0 / config.frame_rate_hz;
        let mut motion = Motion::new(
            route,
            config.flight,
            config.city.ground_z_m,
            config.driving.start_m,
            dt,
        );
        if let Some(m) = config.camera.mount() {
            motion = motion.with_camera_boresight(m.camera_to_body() * nalgebra::Vector3::z());
        }
        let c = config.camera;
        let intrinsics = Intrinsics::from_hfov(c.width, c.height, c.hfov_deg);
        let lens = Distortion(c.distortion);
        let lens = if lens.is_none() {
            None
        } else {
            let map = LensMap::new(&intrinsics, &lens, c.width, c.height)?;
            let size = 3 * map.canvas[0] * map.canvas[1];
            Some((Arc::new(map), [vec![0u8; size], vec![0u8; size]]))
        };
        Ok(Self {
            lens,
            traffic: Vec::new(),
            start_s_m: None,
            intrinsics: Intrinsics::from_hfov(c.width, c.height, c.hfov_deg),
            rng: StdRng::seed_from_u64(config.seed),
            nav_errors: [NavErrorState::default(); 2],
            gimbals: [GimbalTrack::default(); 2],
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

    /// The lens distortion rendered into the pixels (zeros = pinhole).
    pub fn distortion(&self) -> Distortion {
        Distortion(self.config.camera.distortion)
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
            top_bgr: v.colour_bgr,
        };
        let target = vehicle.top_centre(self.config.city.ground_z_m);
        let start = *self.start_s_m.get_or_insert(state.vehicle_s_m);
        let travelled = state.vehicle_s_m - start;
        let route = self.motion.route();
        self.traffic = self
            .config
            .traffic
            .iter()
            .map(|car| {
                let s = start + car.lead_m + car.speed_factor * travelled;
                let (p, heading) = route.at(s);
                let right = [heading.cos(), -heading.sin()];
                TrafficBox {
                    body: VehicleBox {
                        x: p.x + right[0] * car.lane_m,
                        y: p.y + right[1] * car.lane_m,
                        heading,
                        top_bgr: None,
                        ..vehicle
                    },
                    top_bgr: car.colour_bgr,
                }
            })
            .collect();
        let ground_z = self.config.city.ground_z_m;
        let mut look_alikes = [None; 4];
        let target_bgr = self.config.vehicle.colour_bgr.unwrap_or(VEHICLE_TOP_BGR);
        let same_colour = self.traffic.iter().filter(|t| t.top_bgr == target_bgr);
        for (slot, t) in look_alikes.iter_mut().zip(same_colour) {
            let p = t.body.top_centre(ground_z);
            *slot = Some([p.x, p.y, p.z]);
        }
        let frames = [Uav::Left, Uav::Right].map(|uav| self.frame(&state, uav, target));
        self.seq += 1;
        Some(SimStep {
            frames,
            vehicle,
            look_alikes,
        })
    }

    fn frame(&mut self, state: &TrueState, uav: Uav, target: Point3<f64>) -> SimFrame {
        let i = uav.index();
        let [x, y, z] = state.uav_position[i];
        let [yaw, pitch, roll] = state.uav_attitude[i];
        let body = Attitude::new(yaw, pitch, roll);
        let dt = 1.0 / self.config.frame_rate_hz;
        let camera = self.config.camera;
        let gimbal_true = camera
            .gimbal
            .map(|g| self.gimbals[i].step(&g, body, Point3::new(x, y, z), target, dt));
        let mount = gimbal_true.or(camera.mount());
        let attitude = mount.map_or(body, |m| m.equivalent_nadir_attitude(body));
        let view = CameraView {
            position: Point3::new(x, y, z),
            rotation: camera_to_world(attitude),
            intrinsics: self.intrinsics,
            width: self.config.camera.width,
            height: self.config.camera.height,
        };
        let rng = &mut self.rng;
        let noise = self.nav_errors[i].next(&self.config.noise, state.t_s, || {
            rand_distr::StandardNormal.sample(rng)
        });
        // The encoders' noise is drawn after the navigation noise, and only with a
        // gimbal: every other scenario draws what it always drew.
        let gimbal = match (camera.gimbal, gimbal_true) {
            (Some(spec), Some(m)) => {
                let true_deg = [m.0.yaw, m.0.pitch, m.0.roll].map(f64::to_degrees);
                let mut noisy = |a: f64| {
                    let n: f64 = rand_distr::StandardNormal.sample(&mut self.rng);
                    a + spec.encoder_noise_deg * n
                };
                let measured_deg = [noisy(true_deg[0]), noisy(true_deg[1]), noisy(true_deg[2])];
                Some(GimbalAngles {
                    true_deg,
                    measured_deg,
                })
            }
            _ => None,
        };
        let measured_mount = match gimbal {
            Some(g) => {
                let [y, p, r] = g.measured_deg;
                Some(Mount::from_degrees(y, p, r))
            }
            None => mount,
        };
        let bias = self.config.bias.at(state.t_s)[i];
        let body_true = pose(x, y, z, body);
        let body_measured = pose(
            x + noise[0],
            y + noise[1],
            z + noise[2],
            Attitude::new(
                yaw + bias + noise[3].to_radians(),
                pitch + noise[4].to_radians(),
                roll + noise[5].to_radians(),
            ),
        );
        let true_pose = mount.map_or(body_true, |m| body_true.on_mount(m));
        let measured = measured_mount.map_or(body_measured, |m| body_measured.on_mount(m));
        let (w, h) = (view.width as f64, view.height as f64);
        let lens = self.distortion();
        let target_px = view
            .project(&target)
            .map(|[u, v]| lens.distort_pixel(&view.intrinsics, u, v))
            .filter(|p| p[0] >= 0.0 && p[1] >= 0.0 && p[0] <= w - 1.0 && p[1] <= h - 1.0);
        SimFrame {
            uav,
            seq: self.seq,
            t_s: state.t_s,
            view,
            true_pose,
            measured,
            body_true,
            body_measured,
            target: [target.x, target.y, target.z],
            target_px,
            gimbal,
        }
    }

    /// Renders one UAV's view of `step` as BGR8 into `out` (rows of `stride` bytes):
    /// the pinhole image, through the lens when the camera has distortion, then the
    /// preset's image effects.
    pub fn render(&mut self, step: &SimStep, uav: Uav, out: &mut [u8], stride: usize) {
        let i = uav.index();
        let canvas = self.lens.as_mut().map(|(map, c)| (map.clone(), &mut c[i]));
        render_view(
            &mut self.renderers[i],
            &self.city,
            step,
            &self.traffic,
            uav,
            canvas,
            out,
            stride,
        );
        self.degrade(step, uav, out, stride);
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
        let (cl, cr) = match self.lens.as_mut() {
            Some((map, [cl, cr])) => (Some((map.clone(), cl)), Some((map.clone(), cr))),
            None => (None, None),
        };
        let traffic = &self.traffic;
        std::thread::scope(|s| {
            s.spawn(|| render_view(rl, city, step, traffic, Uav::Left, cl, left, stride));
            render_view(rr, city, step, traffic, Uav::Right, cr, right, stride);
        });
        self.degrade(step, Uav::Left, left, stride);
        self.degrade(step, Uav::Right, right, stride);
    }

    fn degrade(&self, step: &SimStep, uav: Uav, out: &mut [u8], stride: usize) {
        let c = &self.config;
        let frame = &step.frames[uav.index()];
        let seed = c.seed ^ (frame.seq << 1) ^ uav.index() as u64;
        let (w, h) = (c.camera.width as usize, c.camera.height as usize);
        if let Err(e) = c.image.apply(uav.index(), seed, out, w, h, stride) {
            // Only an OpenCV failure gets here (the effects were validated): the frame
            // stays as rendered rather than the source stopping.
            tracing::warn!(?uav, "image effects not applied: {e}");
        }
    }

    /// Whether the target point is seen in `uav`'s last rendered image: inside it and
    /// not hidden (the pixel at its undistorted projection shows the vehicle's top).
    /// Truth, for scoring only.
    pub fn target_visible(&self, step: &SimStep, uav: Uav) -> bool {
        let frame = &step.frames[uav.index()];
        frame.target_px.is_some()
            && self.top_visible(&frame.view, uav, &Point3::from(frame.target), |r, u, v| {
                r.surface(u, v) == Surface::VehicleTop
            })
    }

    /// Whether the undistorted projection of `point` into `uav`'s last render lands on
    /// a pixel `shows` accepts (the render's own canvas, a distorted camera's margin
    /// included).
    fn top_visible(
        &self,
        view: &CameraView,
        uav: Uav,
        point: &Point3<f64>,
        shows: impl Fn(&Renderer, usize, usize) -> bool,
    ) -> bool {
        let Some([u, v]) = view.project(point) else {
            return false;
        };
        let (u, v, w, h) = match &self.lens {
            Some((map, _)) => (
                u + map.margin[0] as f64,
                v + map.margin[1] as f64,
                map.canvas[0],
                map.canvas[1],
            ),
            None => (u, v, view.width as usize, view.height as usize),
        };
        let (u, v) = (u.round(), v.round());
        if u < 0.0 || v < 0.0 || u as usize >= w || v as usize >= h {
            return false;
        }
        shows(&self.renderers[uav.index()], u as usize, v as usize)
    }

    /// Every moving vehicle at `step` as `uav`'s last rendered image (of `step`) shows it, for
    /// `truth_targets.csv` (evaluation only): id 0 is the target, a traffic car is 1 +
    /// its index in the scenario's traffic list (parked cars, `speed_factor = 0`, are
    /// left out as the format says). The pixel is the top centre's projection, `None`
    /// outside the image or hidden.
    pub fn moving_vehicles(&self, step: &SimStep, uav: Uav) -> Vec<VehicleTruth> {
        let frame = &step.frames[uav.index()];
        let target = VehicleTruth {
            id: 0,
            point: frame.target,
            px: frame.target_px.filter(|_| self.target_visible(step, uav)),
        };
        let ground_z = self.config.city.ground_z_m;
        let (w, h) = (frame.view.width as f64, frame.view.height as f64);
        let lens = self.distortion();
        let traffic = self.config.traffic.iter().zip(&self.traffic).enumerate();
        let cars = traffic
            .filter(|(_, (car, _))| car.speed_factor > 0.0)
            .map(|(i, (_, b))| {
                let top = b.body.top_centre(ground_z);
                let px = frame
                    .view
                    .project(&top)
                    .map(|[u, v]| lens.distort_pixel(&frame.view.intrinsics, u, v))
                    .filter(|p| p[0] >= 0.0 && p[1] >= 0.0 && p[0] <= w - 1.0 && p[1] <= h - 1.0)
                    .filter(|_| {
                        self.top_visible(&frame.view, uav, &top, |r, u, v| {
                            r.traffic_top(u, v) == Some(i)
                        })
                    });
                VehicleTruth {
                    id: i as u32 + 1,
                    point: [top.x, top.y, top.z],
                    px,
                }
            });
        std::iter::once(target).chain(cars).collect()
    }

    /// The renderer that drew `uav`'s last image (its per-pixel surface labels).
    pub fn renderer(&self, uav: Uav) -> &Renderer {
        &self.renderers[uav.index()]
    }
}

/// Renders `uav`'s view of `step`: straight into `out`, or into the pinhole canvas and
/// then through the lens map.
#[allow(clippy::too_many_arguments)]
fn render_view(
    renderer: &mut Renderer,
    city: &City,
    step: &SimStep,
    traffic: &[TrafficBox],
    uav: Uav,
    canvas: Option<(Arc<LensMap>, &mut Vec<u8>)>,
    out: &mut [u8],
    stride: usize,
) {
    let view = &step.frames[uav.index()].view;
    match canvas {
        None => renderer.render_with_traffic(city, Some(&step.vehicle), traffic, view, out, stride),
        Some((map, pixels)) => {
            let canvas_view = CameraView {
                intrinsics: map.canvas_intrinsics(&view.intrinsics),
                width: map.canvas[0] as u32,
                height: map.canvas[1] as u32,
                ..*view
            };
            renderer.render_with_traffic(
                city,
                Some(&step.vehicle),
                traffic,
                &canvas_view,
                pixels,
                3 * map.canvas[0],
            );
            map.resample(pixels, out, stride);
        }
    }
}

/// A photograph (ground or roof texture) as BGR8. Aerial imagery often comes as 11- or
/// 16-bit and panchromatic: such an image is stretched to 8 bits between its 1st and
/// 99th percentiles, and grey becomes BGR.
fn read_photo(path: &std::path::Path) -> Result<(usize, usize, Vec<u8>), SimError> {
    let resolved = resolve_data_path(path);
    let err = |reason: String| SimError::GroundImage {
        path: resolved.clone(),
        reason,
    };
    let flags = opencv::imgcodecs::IMREAD_ANYDEPTH | opencv::imgcodecs::IMREAD_ANYCOLOR;
    let img = opencv::imgcodecs::imread(resolved.as_os_str(), flags).map_err(|e| err(e.message))?;
    if img.empty() {
        return Err(err(format!(
            "cannot be read as an image{}",
            if resolved.exists() {
                ""
            } else {
                " (missing: the built-in photo scenes need `bash scripts/setup.sh`, which fetches data/aerial/)"
            }
        )));
    }
    let bgr = photo_to_bgr8(&img).map_err(|e| err(e.message))?;
    let bytes = bgr.data_bytes().map_err(|e| err(e.message))?;
    Ok((bgr.cols() as usize, bgr.rows() as usize, bytes.to_vec()))
}

/// Any depth, 1/3/4 channels → BGR8 (percentile stretch for deeper than 8 bits).
fn photo_to_bgr8(img: &opencv::core::Mat) -> opencv::Result<opencv::core::Mat> {
    use opencv::core as cv;
    let mut eight = img.clone();
    if img.depth() != cv::CV_8U {
        let mut single = cv::Mat::default();
        img.convert_to(&mut single, cv::CV_32F, 1.0, 0.0)?;
        let mut values: Vec<f32> = single.reshape(1, 0)?.data_typed::<f32>()?.to_vec();
        values.retain(|v| v.is_finite());
        values.sort_by(f32::total_cmp);
        let at = |q: f64| {
            values
                .get(((values.len() as f64 - 1.0) * q) as usize)
                .copied()
        };
        let (lo, hi) = (at(0.01).unwrap_or(0.0), at(0.99).unwrap_or(1.0));
        let scale = 255.0 / f64::from((hi - lo).max(1e-6));
        single.convert_to(&mut eight, cv::CV_8U, scale, -f64::from(lo) * scale)?;
    }
    let code = match eight.channels() {
        1 => Some(opencv::imgproc::COLOR_GRAY2BGR),
        4 => Some(opencv::imgproc::COLOR_BGRA2BGR),
        _ => None,
    };
    match code {
        Some(code) => {
            let mut bgr = cv::Mat::default();
            opencv::imgproc::cvt_color_def(&eight, &mut bgr, code)?;
            Ok(bgr)
        }
        None => Ok(eight),
    }
}

/// A preset's image path: as given when it exists (absolute, or relative to the
/// working directory); else under `$DUALGEO_DATA_DIR`; else under the source tree's
/// `data/` (where `scripts/setup.sh` puts the suite's aerial photographs), for a path
/// starting with `data/`.
pub fn resolve_data_path(path: &std::path::Path) -> std::path::PathBuf {
    if path.is_absolute() || path.exists() {
        return path.to_path_buf();
    }
    let relative = path.strip_prefix("data").unwrap_or(path);
    if let Some(dir) = std::env::var_os("DUALGEO_DATA_DIR") {
        let p = std::path::Path::new(&dir).join(relative);
        if p.exists() {
            return p;
        }
    }
    let tree = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data");
    let p = tree.join(relative);
    if p.exists() {
        p
    } else {
        path.to_path_buf()
    }
}

/// A pose in the recording's units: metres and degrees, yaw wrapped to (−180, 180].
fn pose(x: f64, y: f64, z: f64, a: Attitude) -> PoseSample {
    PoseSample {
        x_m: x,
        y_m: y,
        z_m: z,
        yaw_deg: wrap_angle(a.yaw).to_degrees(),
        pitch_deg: a.pitch.to_degrees(),
        roll_deg: a.roll.to_degrees(),
        mount: MountSample::default(),
    }
}
