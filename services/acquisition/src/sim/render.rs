//! Exact perspective rendering of the town with occlusion.
//!
//! The scene is 2.5-D: a ground plane, axis-aligned box buildings and the vehicle (an
//! oriented box). Every surface is a planar convex quad, so each is rasterised in image
//! space with edge functions (a straight 3-D edge projects to a straight line, so the
//! inside test is exact). The pixel's depth along its ray comes from the ray-plane
//! intersection and resolves occlusion in a depth buffer. Then one shading pass computes
//! each pixel's world point and samples that surface's texture. Pixel (u, v) is
//! sampled through its centre (OpenCV convention), with one ray per pixel and no
//! anti-aliasing.
//!
//! Every scene point is far below the camera, so a quad with a corner less than 1 m in
//! front of the camera is not drawn rather than clipped.

use super::city::City;
use nalgebra::{Matrix3, Point3, Vector3};
use shared_types::conventions::Intrinsics;

/// A pinhole camera in the world: C_w^c, centre, intrinsics and image size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraView {
    pub position: Point3<f64>,
    /// C_w^c: camera → world.
    pub rotation: Matrix3<f64>,
    pub intrinsics: Intrinsics,
    pub width: u32,
    pub height: u32,
}

impl CameraView {
    /// World point → pixel (None behind the camera).
    pub fn project(&self, p: &Point3<f64>) -> Option<[f64; 2]> {
        let c = self.rotation.transpose() * (p - self.position);
        self.intrinsics.project(c).map(|v| [v.x, v.y])
    }

    /// The fundamental matrix F with `x_otherᵀ F x_self = 0` for pixels of one world
    /// point in this view and `other`: `K_o⁻ᵀ [t]× R K_s⁻¹` with `R = R_oᵀ R_s` and
    /// `t = R_oᵀ (C_s − C_o)`. Ground truth for testing matching.
    pub fn fundamental_to(&self, other: &CameraView) -> Option<Matrix3<f64>> {
        let r = other.rotation.transpose() * self.rotation;
        let t = other.rotation.transpose() * (self.position - other.position);
        let e = t.cross_matrix() * r;
        Some(
            other.intrinsics.matrix().try_inverse()?.transpose()
                * e
                * self.intrinsics.matrix().try_inverse()?,
        )
    }

    /// Per-view ray basis: the (unnormalised) ray of pixel (u, v) is `a + u·b + v·c`.
    fn ray_basis(&self) -> [Vector3<f64>; 3] {
        let k = &self.intrinsics;
        let b = self.rotation.column(0) / k.fx;
        let c = self.rotation.column(1) / k.fy;
        let a = self.rotation.column(2) - b * k.cx - c * k.cy;
        [a, b, c]
    }
}

/// The vehicle: an oriented box standing on the ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleBox {
    /// Centre of the footprint, ENU metres.
    pub x: f64,
    pub y: f64,
    /// Heading from north, clockwise, radians (as the yaw convention).
    pub heading: f64,
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    /// The top's colour (BGR), the sides the same darkened; `None`: the target's red
    /// ([`VEHICLE_TOP_BGR`], [`VEHICLE_SIDE_BGR`]).
    pub top_bgr: Option<[u8; 3]>,
}

impl VehicleBox {
    /// The target point of the recording format: the centre of the top face.
    pub fn top_centre(&self, ground_z: f64) -> Point3<f64> {
        Point3::new(self.x, self.y, ground_z + self.height_m)
    }
}

/// What a pixel shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Surface {
    Ground,
    Roof,
    Wall,
    VehicleTop,
    VehicleSide,
    /// Another vehicle (traffic, a distractor).
    Traffic,
}

/// Another vehicle on the roads: a box like the target's, in its own colour (the
/// target's red makes it a distractor for the detector). Its top is `top_bgr`, its sides
/// the same colour darkened as the target's are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrafficBox {
    pub body: VehicleBox,
    pub top_bgr: [u8; 3],
}

/// The vehicle's colours (BGR): a saturated red nothing else in the town uses.
pub const VEHICLE_TOP_BGR: [u8; 3] = [36, 28, 214];
pub const VEHICLE_SIDE_BGR: [u8; 3] = [24, 18, 140];

#[derive(Debug, Clone, Copy)]
enum Material {
    Roof {
        building: u32,
    },
    Wall {
        building: u32,
        origin: [f64; 2],
        axis: [f64; 2],
        light: f32,
    },
    VehicleTop {
        bgr: [u8; 3],
    },
    VehicleSide {
        bgr: [u8; 3],
        light: f32,
    },
    TrafficTop {
        bgr: [u8; 3],
        /// Which car of the traffic list (truth for scoring several targets).
        car: u32,
    },
    TrafficSide {
        bgr: [u8; 3],
        light: f32,
    },
}

#[derive(Debug, Clone, Copy)]
struct Face {
    corners: [Point3<f64>; 4],
    normal: Vector3<f64>,
    material: Material,
}

/// Reusable buffers of one renderer (one per thread).
#[derive(Default)]
pub struct Renderer {
    depth: Vec<f32>,
    label: Vec<u32>,
    faces: Vec<Face>,
    width: usize,
}

const GROUND_LABEL: u32 = u32::MAX;

/// Sun direction (towards the sun), for flat shading of walls and vehicle sides.
fn light_for(normal: Vector3<f64>) -> f32 {
    let sun = Vector3::new(0.45, -0.35, 0.82).normalize();
    (0.55 + 0.45 * normal.dot(&sun).max(0.0)) as f32
}

impl Renderer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Renders `view` of the town (and the vehicle, if any) into `out` as BGR8 rows of
    /// `stride` bytes.
    pub fn render(
        &mut self,
        city: &City,
        vehicle: Option<&VehicleBox>,
        view: &CameraView,
        out: &mut [u8],
        stride: usize,
    ) {
        self.render_with_traffic(city, vehicle, &[], view, out, stride)
    }

    /// [`Renderer::render`] with other vehicles on the roads.
    pub fn render_with_traffic(
        &mut self,
        city: &City,
        vehicle: Option<&VehicleBox>,
        traffic: &[TrafficBox],
        view: &CameraView,
        out: &mut [u8],
        stride: usize,
    ) {
        let (w, h) = (view.width as usize, view.height as usize);
        assert!(
            stride >= 3 * w && out.len() >= stride * (h - 1) + 3 * w,
            "output buffer too small"
        );
        self.width = w;
        self.depth.clear();
        self.depth.resize(w * h, f32::INFINITY);
        self.label.clear();
        self.label.resize(w * h, GROUND_LABEL);
        self.collect_faces(city, vehicle, view);
        for (car, t) in traffic.iter().enumerate() {
            let top = Material::TrafficTop {
                bgr: t.top_bgr,
                car: car as u32,
            };
            let bgr = t.top_bgr;
            let zg = city.config.ground_z_m;
            self.push_box(&t.body, zg, view.position, top, |light| {
                Material::TrafficSide { bgr, light }
            });
        }
        let basis = view.ray_basis();
        for index in 0..self.faces.len() {
            self.rasterise(index, view, &basis);
        }
        self.shade(city, view, &basis, out, stride);
    }

    /// What each pixel of the last render shows (row-major).
    pub fn surface(&self, u: usize, v: usize) -> Surface {
        match self.label[v * self.width + u] {
            GROUND_LABEL => Surface::Ground,
            i => match self.faces[i as usize].material {
                Material::Roof { .. } => Surface::Roof,
                Material::Wall { .. } => Surface::Wall,
                Material::VehicleTop { .. } => Surface::VehicleTop,
                Material::VehicleSide { .. } => Surface::VehicleSide,
                Material::TrafficTop { .. } | Material::TrafficSide { .. } => Surface::Traffic,
            },
        }
    }

    /// Which traffic car's top the pixel of the last render shows (its index in the
    /// traffic list), if any.
    pub fn traffic_top(&self, u: usize, v: usize) -> Option<usize> {
        match self.label[v * self.width + u] {
            GROUND_LABEL => None,
            i => match self.faces[i as usize].material {
                Material::TrafficTop { car, .. } => Some(car as usize),
                _ => None,
            },
        }
    }

    fn collect_faces(&mut self, city: &City, vehicle: Option<&VehicleBox>, view: &CameraView) {
        self.faces.clear();
        let zg = city.config.ground_z_m;
        let cam = view.position;
        let (lo, hi) = footprint(view, zg, zg + city.tallest_m.max(5.0));
        for (i, b) in city.buildings.iter().enumerate() {
            if b.max[0] < lo[0] || b.min[0] > hi[0] || b.max[1] < lo[1] || b.min[1] > hi[1] {
                continue;
            }
            let top = zg + b.height_m;
            let (x0, y0, x1, y1) = (b.min[0], b.min[1], b.max[0], b.max[1]);
            let p = |x: f64, y: f64, z: f64| Point3::new(x, y, z);
            self.faces.push(Face {
                corners: [
                    p(x0, y0, top),
                    p(x1, y0, top),
                    p(x1, y1, top),
                    p(x0, y1, top),
                ],
                normal: Vector3::z(),
                material: Material::Roof { building: i as u32 },
            });
            // Walls: (start, end, outward normal); only those facing the camera.
            let walls = [
                ([x0, y0], [x1, y0], Vector3::new(0.0, -1.0, 0.0)),
                ([x1, y0], [x1, y1], Vector3::new(1.0, 0.0, 0.0)),
                ([x1, y1], [x0, y1], Vector3::new(0.0, 1.0, 0.0)),
                ([x0, y1], [x0, y0], Vector3::new(-1.0, 0.0, 0.0)),
            ];
            for (a, e, n) in walls {
                if !b.walls || n.dot(&(cam - p(a[0], a[1], zg))) <= 0.0 {
                    continue;
                }
                let len = ((e[0] - a[0]).powi(2) + (e[1] - a[1]).powi(2)).sqrt();
                self.faces.push(Face {
                    corners: [
                        p(a[0], a[1], zg),
                        p(e[0], e[1], zg),
                        p(e[0], e[1], top),
                        p(a[0], a[1], top),
                    ],
                    normal: n,
                    material: Material::Wall {
                        building: i as u32,
                        origin: a,
                        axis: [(e[0] - a[0]) / len, (e[1] - a[1]) / len],
                        light: light_for(n),
                    },
                });
            }
        }
        if let Some(v) = vehicle {
            let (top, side) = match v.top_bgr {
                None => (VEHICLE_TOP_BGR, VEHICLE_SIDE_BGR),
                // Darkened as the red's sides are (140/214), like the traffic's.
                Some(bgr) => (bgr, bgr.map(|c| (f32::from(c) * 0.65).round() as u8)),
            };
            self.push_box(v, zg, cam, Material::VehicleTop { bgr: top }, |light| {
                Material::VehicleSide { bgr: side, light }
            });
        }
    }

    /// The top and the camera-facing sides of a vehicle box.
    fn push_box(
        &mut self,
        v: &VehicleBox,
        ground_z: f64,
        camera: Point3<f64>,
        top_material: Material,
        side_material: impl Fn(f32) -> Material,
    ) {
        // Forward and right unit vectors in ENU for a heading from north.
        let f = Vector3::new(v.heading.sin(), v.heading.cos(), 0.0);
        let r = Vector3::new(v.heading.cos(), -v.heading.sin(), 0.0);
        let (hl, hw) = (v.length_m / 2.0, v.width_m / 2.0);
        let base = Point3::new(v.x, v.y, ground_z);
        let corner =
            |sf: f64, sr: f64, z: f64| base + f * (sf * hl) + r * (sr * hw) + Vector3::z() * z;
        let top = v.height_m;
        self.faces.push(Face {
            corners: [
                corner(1.0, 1.0, top),
                corner(-1.0, 1.0, top),
                corner(-1.0, -1.0, top),
                corner(1.0, -1.0, top),
            ],
            normal: Vector3::z(),
            material: top_material,
        });
        let sides = [
            ((1.0, 1.0), (1.0, -1.0), f),
            ((-1.0, 1.0), (1.0, 1.0), r),
            ((-1.0, -1.0), (-1.0, 1.0), -f),
            ((1.0, -1.0), (-1.0, -1.0), -r),
        ];
        for ((af, ar), (bf, br), n) in sides {
            if n.dot(&(camera - corner(af, ar, 0.0))) <= 0.0 {
                continue;
            }
            self.faces.push(Face {
                corners: [
                    corner(af, ar, 0.0),
                    corner(bf, br, 0.0),
                    corner(bf, br, top),
                    corner(af, ar, top),
                ],
                normal: n,
                material: side_material(light_for(n)),
            });
        }
    }

    fn rasterise(&mut self, index: usize, view: &CameraView, basis: &[Vector3<f64>; 3]) {
        let face = self.faces[index];
        let mut s = [[0.0f64; 2]; 4];
        for (k, c) in face.corners.iter().enumerate() {
            let pc = view.rotation.transpose() * (c - view.position);
            if pc.z < 1.0 {
                return;
            }
            let k_ = &view.intrinsics;
            s[k] = [k_.fx * pc.x / pc.z + k_.cx, k_.fy * pc.y / pc.z + k_.cy];
        }
        let Some((min_u, max_u)) = pixel_span(s.map(|p| p[0]), view.width) else {
            return;
        };
        let Some((min_v, max_v)) = pixel_span(s.map(|p| p[1]), view.height) else {
            return;
        };
        // Twice the signed area gives the winding; edge functions are then ≥ 0 inside.
        let area: f64 = (0..4)
            .map(|i| {
                let (a, b) = (s[i], s[(i + 1) % 4]);
                a[0] * b[1] - b[0] * a[1]
            })
            .sum();
        if area.abs() < 1e-9 {
            return;
        }
        let sign = area.signum();
        // E_i(u, v) = A_i u + B_i v + C_i.
        let mut edges = [[0.0f64; 3]; 4];
        for i in 0..4 {
            let (a, b) = (s[i], s[(i + 1) % 4]);
            edges[i] = [
                sign * (a[1] - b[1]),
                sign * (b[0] - a[0]),
                sign * (a[0] * b[1] - b[0] * a[1]),
            ];
        }
        // Depth along the ray: t = (n·P0 − n·C) / (n·a + u n·b + v n·c).
        let n = face.normal;
        let num = n.dot(&(face.corners[0] - view.position));
        let (na, nb, nc) = (n.dot(&basis[0]), n.dot(&basis[1]), n.dot(&basis[2]));
        let label = index as u32;
        let width = self.width;
        for v in min_v..=max_v {
            let vf = v as f64;
            for u in min_u..=max_u {
                let uf = u as f64;
                if edges.iter().any(|e| e[0] * uf + e[1] * vf + e[2] < 0.0) {
                    continue;
                }
                let t = (num / (na + uf * nb + vf * nc)) as f32;
                let i = v * width + u;
                if t > 0.0 && t < self.depth[i] {
                    self.depth[i] = t;
                    self.label[i] = label;
                }
            }
        }
    }

    fn shade(
        &self,
        city: &City,
        view: &CameraView,
        basis: &[Vector3<f64>; 3],
        out: &mut [u8],
        stride: usize,
    ) {
        let zg = city.config.ground_z_m;
        let cam = view.position.coords;
        let (w, h) = (view.width as usize, view.height as usize);
        for v in 0..h {
            let row_ray = basis[0] + basis[2] * v as f64;
            let row = &mut out[v * stride..v * stride + 3 * w];
            for u in 0..w {
                let d = row_ray + basis[1] * u as f64;
                let i = v * w + u;
                let bgr = match self.label[i] {
                    GROUND_LABEL => {
                        let t = (zg - cam.z) / d.z;
                        city.ground_colour(cam.x + t * d.x, cam.y + t * d.y)
                    }
                    face => {
                        let p = cam + d * self.depth[i] as f64;
                        shade_face(city, &self.faces[face as usize].material, p, zg)
                    }
                };
                // Round to nearest; `as` saturates at 0 and 255.
                row[3 * u] = (bgr[0] + 0.5) as u8;
                row[3 * u + 1] = (bgr[1] + 0.5) as u8;
                row[3 * u + 2] = (bgr[2] + 0.5) as u8;
            }
        }
    }
}

#[inline]
fn shade_face(city: &City, material: &Material, p: Vector3<f64>, zg: f64) -> [f32; 3] {
    match *material {
        Material::Roof { building } => {
            let b = &city.buildings[building as usize];
            let t = city
                .roof
                .sample(p.x + b.texture_offset[0], p.y + b.texture_offset[1]);
            // A darker parapet along the roof's edge.
            let edge = (p.x - b.min[0])
                .min(b.max[0] - p.x)
                .min(p.y - b.min[1])
                .min(b.max[1] - p.y);
            let k = if edge < 0.4 { 0.55 } else { 1.0 };
            [
                t[0] * b.tint[0] * k,
                t[1] * b.tint[1] * k,
                t[2] * b.tint[2] * k,
            ]
        }
        Material::Wall {
            building,
            origin,
            axis,
            light,
        } => {
            let b = &city.buildings[building as usize];
            let s = (p.x - origin[0]) * axis[0] + (p.y - origin[1]) * axis[1];
            let t = city.facade.sample(s + b.texture_offset[0], p.z - zg);
            [
                t[0] * b.tint[0] * light,
                t[1] * b.tint[1] * light,
                t[2] * b.tint[2] * light,
            ]
        }
        Material::VehicleTop { bgr } => bgr.map(f32::from),
        Material::VehicleSide { bgr, light } => bgr.map(|c| c as f32 * light),
        Material::TrafficTop { bgr, .. } => bgr.map(f32::from),
        // Sides darkened like the target's (140/214 of the top), then lit.
        Material::TrafficSide { bgr, light } => bgr.map(|c| c as f32 * 0.65 * light),
    }
}

/// The pixel centres (0..size) whose coordinate lies within the span of `coords`.
fn pixel_span(coords: [f64; 4], size: u32) -> Option<(usize, usize)> {
    let lo = coords
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
        .ceil()
        .max(0.0);
    let hi = coords
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max)
        .floor()
        .min(size as f64 - 1.0);
    (lo <= hi).then_some((lo as usize, hi as usize))
}

/// Axis-aligned bounds of the ground footprint of the view between altitudes `z_lo` and
/// `z_hi` (the image corners' rays cut at both), for culling buildings.
fn footprint(view: &CameraView, z_lo: f64, z_hi: f64) -> ([f64; 2], [f64; 2]) {
    let [a, b, c] = view.ray_basis();
    let (w, h) = (view.width as f64 - 1.0, view.height as f64 - 1.0);
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for (u, v) in [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)] {
        let d = a + b * u + c * v;
        for z in [z_lo, z_hi] {
            let t = if d.z < -1e-9 {
                (z - view.position.z) / d.z
            } else {
                1e4
            };
            let t = if t > 0.0 { t } else { 1e4 };
            for k in 0..2 {
                let x = view.position[k] + t * d[k];
                lo[k] = lo[k].min(x);
                hi[k] = hi[k].max(x);
            }
        }
    }
    (lo, hi)
}
