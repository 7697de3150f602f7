//! Simulator configuration and the presets file (`presets/scenarios.toml`, built in;
//! users pass their own copy with `--presets`).

use super::city::{CityConfig, Occluder};
use super::degrade::ImageEffects;
use super::motion::{DrivingSpec, FlightSpec};
use super::SimError;
use crate::recording::Origin;
use serde::{Deserialize, Serialize};
use shared_types::conventions::Mount;
use shared_types::nav_noise::{BiasModel, NavNoise};
use std::path::PathBuf;

/// The presets shipped with dualgeo.
pub const BUILTIN_PRESETS: &str = include_str!("../../presets/scenarios.toml");

/// Largest frame the simulator renders (the transport benchmarks' 4K).
pub const MAX_WIDTH: u32 = 3840;
pub const MAX_HEIGHT: u32 = 2160;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    pub description: String,
    /// Seed of the navigation noise.
    pub seed: u64,
    pub duration_s: f64,
    pub frame_rate_hz: f64,
    pub camera: SimCamera,
    pub flight: FlightSpec,
    pub vehicle: VehicleSize,
    pub driving: DrivingSpec,
    pub city: CityConfig,
    pub noise: NavNoise,
    pub bias: BiasModel,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub origin: Option<Origin>,
    /// Optional orthophoto (PNG/JPEG) stretched over the town's ground instead of the
    /// procedural texture.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_image: Option<PathBuf>,
    /// Optional photograph (PNG/JPEG) tiled over every roof instead of the procedural
    /// roof texture, at `roof_metres_per_pixel`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roof_image: Option<PathBuf>,
    /// Decks (bridges, canopies) the target drives under and disappears.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub occluders: Vec<Occluder>,
    /// Other vehicles on the target's route (distractors for the detector).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub traffic: Vec<TrafficCar>,
    /// What the camera does to the image after the lens (all off by default).
    #[serde(default, skip_serializing_if = "ImageEffects::is_identity")]
    pub image: ImageEffects,
}

/// A vehicle driving the target's route, starting `lead_m` ahead of it (negative:
/// behind) in a lane `lane_m` to the right of the target's path, at `speed_factor` ×
/// the target's speed (so it can overtake or fall behind). Its roof is `colour_bgr`:
/// the target's own red ([36, 28, 214]) makes it a distractor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrafficCar {
    pub lead_m: f64,
    #[serde(default)]
    pub lane_m: f64,
    #[serde(default = "one")]
    pub speed_factor: f64,
    pub colour_bgr: [u8; 3],
}

fn one() -> f64 {
    1.0
}

impl TrafficCar {
    pub fn is_valid(&self) -> bool {
        self.lead_m.is_finite()
            && self.lane_m.is_finite()
            && self.lane_m.abs() < 20.0
            && (0.0..=5.0).contains(&self.speed_factor)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimCamera {
    pub width: u32,
    pub height: u32,
    pub hfov_deg: f64,
    /// OpenCV's k1, k2, p1, p2, k3, rendered into the pixels (zeros = a pinhole). The
    /// recording carries it as `distortion`, the live source in each frame's header.
    #[serde(default, skip_serializing_if = "is_pinhole")]
    pub distortion: [f64; 5],
    /// A fixed tilted camera (recording format v2, `mount = "fixed"`): the gimbal
    /// frame's yaw, pitch and roll relative to the body, degrees; none: nadir (pitch
    /// −90). The UAVs then fly where the camera's optical axis meets the ground at the
    /// vehicle, and recordings are written as version 2.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mount_angles_deg: Option<[f64; 3]>,
    /// A tracking gimbal (recording format v2, `mount = "gimbal"`): the camera turns
    /// toward the vehicle every frame; `mount_angles_deg` is then its nominal pointing,
    /// which places the UAVs. None: the mount is fixed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gimbal: Option<TrackingGimbal>,
}

/// A gimbal that keeps the vehicle near the image centre (`[camera] gimbal`).
///
/// Each frame its yaw and pitch (roll stays 0) move toward the angles that put the
/// target point on the optical axis, through a first-order lag of time constant
/// `tau_s`: a real tracking loop trails a turning vehicle, so the target sits near the
/// centre, not on it. The angles it reports (telemetry.csv) are the true ones plus
/// Gaussian encoder noise of `encoder_noise_deg` on each of the three; truth.csv has the
/// true ones. The body's attitude errors and yaw bias are the AHRS's, as for any mount.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackingGimbal {
    #[serde(default = "default_gimbal_tau_s")]
    pub tau_s: f64,
    #[serde(default = "default_encoder_noise_deg")]
    pub encoder_noise_deg: f64,
}

fn default_gimbal_tau_s() -> f64 {
    0.3
}

fn default_encoder_noise_deg() -> f64 {
    0.2
}

impl SimCamera {
    /// The camera's mount; none for nadir.
    pub fn mount(&self) -> Option<Mount> {
        self.mount_angles_deg
            .map(|[y, p, r]| Mount::from_degrees(y, p, r))
    }
}

fn is_pinhole(d: &[f64; 5]) -> bool {
    d.iter().all(|c| *c == 0.0)
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleSize {
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    /// The target's roof colour (BGR), its sides the same darkened; none: the red the
    /// colour detector looks for. Another colour is for the learned and motion
    /// detectors (`[detection] kind`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour_bgr: Option<[u8; 3]>,
}

impl SimConfig {
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |m: String| Err(SimError::Config(m));
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let non_negative = |v: f64| v.is_finite() && v >= 0.0;
        if !positive(self.duration_s) || !positive(self.frame_rate_hz) {
            return bad("duration_s and frame_rate_hz must be > 0".into());
        }
        let c = &self.camera;
        if !(16..=MAX_WIDTH).contains(&c.width) || !(16..=MAX_HEIGHT).contains(&c.height) {
            return bad(format!(
                "camera size {}x{} outside 16x16 ..= {MAX_WIDTH}x{MAX_HEIGHT}",
                c.width, c.height
            ));
        }
        let hfov_ok = c.hfov_deg > 5.0 && c.hfov_deg < 150.0;
        if !hfov_ok {
            return bad(format!("camera hfov_deg {} outside (5, 150)", c.hfov_deg));
        }
        if let Some(m) = c.mount() {
            // The optical axis must be within 60° of straight down on a level body, so
            // that the vehicle stays in view from the flight altitude.
            let down = (m.camera_to_body() * nalgebra::Vector3::z()).z;
            if !(down.is_finite() && down >= 0.5) {
                return bad(format!(
                    "camera mount_angles_deg {:?} must point the camera within 60° of straight down",
                    c.mount_angles_deg
                ));
            }
        }
        if let Some(g) = c.gimbal {
            if c.mount_angles_deg.is_none() {
                return bad(
                    "camera gimbal needs mount_angles_deg: its nominal pointing, which places the UAVs"
                        .into(),
                );
            }
            let ok = |v: f64| v.is_finite() && (0.0..=10.0).contains(&v);
            if !ok(g.tau_s) || !ok(g.encoder_noise_deg) {
                return bad(format!(
                    "camera gimbal tau_s {} and encoder_noise_deg {} must be within [0, 10]",
                    g.tau_s, g.encoder_noise_deg
                ));
            }
        }
        if !c.distortion.iter().all(|k| k.is_finite() && k.abs() < 10.0) {
            return bad(format!(
                "camera distortion {:?} must be finite and within ±10",
                c.distortion
            ));
        }
        self.image.validate()?;
        if !self.traffic.iter().all(TrafficCar::is_valid) {
            return bad(
                "traffic needs finite lead_m and lane_m, |lane_m| < 20, 0 <= speed_factor <= 5"
                    .into(),
            );
        }
        if !self.occluders.iter().all(Occluder::is_valid) {
            return bad("occluders need finite centres, sizes > 0 and height_m > 0".into());
        }
        let f = &self.flight;
        let flight_ok = positive(f.altitude_agl_m)
            && non_negative(f.separation_m)
            && positive(f.follow_time_constant_s)
            && f.wobble_deg.abs() < 10.0;
        if !flight_ok {
            return bad("flight needs altitude_agl_m > 0, separation_m >= 0, follow_time_constant_s > 0, |wobble_deg| < 10".into());
        }
        let v = &self.vehicle;
        if !positive(v.length_m)
            || !positive(v.width_m)
            || !positive(v.height_m)
            || v.height_m >= f.altitude_agl_m
        {
            return bad("vehicle dimensions must be > 0 and below the UAVs".into());
        }
        if !self.noise.is_valid() {
            return bad("noise σ's must be finite and >= 0".into());
        }
        let city = &self.city;
        let city_ok = positive(city.block_m)
            && positive(city.half_extent_m)
            && positive(city.ground_metres_per_texel)
            && non_negative(city.road_width_m)
            && non_negative(city.sidewalk_m)
            && city.ground_z_m.is_finite();
        if !city_ok {
            return bad("city dimensions must be finite and > 0".into());
        }
        city.validate_layout().map_err(SimError::Config)?;
        if (2.0 * city.half_extent_m / city.ground_metres_per_texel) > 8192.0 {
            return bad("city ground texture would exceed 8192 texels a side: raise ground_metres_per_texel".into());
        }
        Ok(())
    }

    /// Frames per UAV over the duration.
    pub fn frame_count(&self) -> u64 {
        (self.duration_s * self.frame_rate_hz).round() as u64
    }
}

/// A presets file: named tables, each a full [`SimConfig`] or a `base` plus overrides.
pub struct Presets {
    table: toml::Table,
    source: String,
}

impl Presets {
    pub fn builtin() -> Self {
        Self::parse(BUILTIN_PRESETS, "built-in presets").expect("built-in presets parse")
    }

    pub fn from_file(path: &std::path::Path) -> Result<Self, SimError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| SimError::Config(format!("{}: {e}", path.display())))?;
        Self::parse(&text, &path.display().to_string())
    }

    fn parse(text: &str, source: &str) -> Result<Self, SimError> {
        let table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| SimError::Config(format!("{source}: {e}")))?;
        Ok(Self {
            table,
            source: source.into(),
        })
    }

    pub fn names(&self) -> Vec<&str> {
        self.table.keys().map(String::as_str).collect()
    }

    /// The preset `name`, with its `base` chain merged, as TOML.
    pub fn resolved_toml(&self, name: &str) -> Result<toml::Table, SimError> {
        let mut chain = vec![name.to_string()];
        let mut current = self.lookup(name)?;
        let mut layers = vec![current.clone()];
        while let Some(base) = current.get("base") {
            let base = base
                .as_str()
                .ok_or_else(|| self.err(name, "`base` must be a preset name"))?
                .to_string();
            if chain.contains(&base) {
                return Err(self.err(
                    name,
                    &format!("`base` chain loops: {} -> {base}", chain.join(" -> ")),
                ));
            }
            chain.push(base.clone());
            current = self.lookup(&base)?;
            layers.push(current.clone());
        }
        let mut merged = toml::Table::new();
        for layer in layers.into_iter().rev() {
            merge(&mut merged, layer);
        }
        merged.remove("base");
        Ok(merged)
    }

    pub fn get(&self, name: &str) -> Result<SimConfig, SimError> {
        let merged = self.resolved_toml(name)?;
        let config: SimConfig = toml::Value::Table(merged)
            .try_into()
            .map_err(|e: toml::de::Error| self.err(name, e.message()))?;
        config
            .validate()
            .map_err(|e| self.err(name, &e.to_string()))?;
        Ok(config)
    }

    fn lookup(&self, name: &str) -> Result<toml::Table, SimError> {
        match self.table.get(name) {
            Some(toml::Value::Table(t)) => Ok(t.clone()),
            Some(_) => Err(self.err(name, "is not a table")),
            None => Err(SimError::Config(format!(
                "{}: no preset \"{name}\" (have: {})",
                self.source,
                self.names().join(", ")
            ))),
        }
    }

    fn err(&self, name: &str, message: &str) -> SimError {
        SimError::Config(format!("{} preset \"{name}\": {message}", self.source))
    }
}

/// Overlays `top` on `into`: tables merge key by key, except tagged tables (with a
/// `kind` key, e.g. `bias`), which replace the base's table whole.
fn merge(into: &mut toml::Table, top: toml::Table) {
    for (k, v) in top {
        match (into.get_mut(&k), v) {
            (Some(toml::Value::Table(base)), toml::Value::Table(over))
                if !over.contains_key("kind") =>
            {
                merge(base, over)
            }
            (_, v) => {
                into.insert(k, v);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_preset_resolves_and_validates() {
        let p = Presets::builtin();
        assert!(p.names().len() >= 23);
        for name in p.names() {
            p.get(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        }
        let t1 = p.get("table1").unwrap();
        assert_eq!(t1.noise, NavNoise::NONE);
        assert_eq!(t1.bias, BiasModel::NONE);
        assert_eq!(t1.city, p.get("default").unwrap().city);
        let f12 = p.get("fig12_bias30").unwrap();
        assert_eq!(
            f12.bias,
            BiasModel::Eq34 {
                delta0_deg: 30.0,
                rate_deg_s: 0.2
            }
        );
        assert_eq!(f12.noise, NavNoise::isotropic(3.0, 2.0));
    }

    #[test]
    fn unknown_keys_missing_presets_and_loops_are_errors() {
        let p = Presets::parse("[a]\nbase = \"b\"\n[b]\nbase = \"a\"\n", "test").unwrap();
        assert!(p.get("a").unwrap_err().to_string().contains("loops"));
        assert!(Presets::builtin()
            .get("nope")
            .unwrap_err()
            .to_string()
            .contains("no preset \"nope\""));
        let text = format!("{BUILTIN_PRESETS}\n[typo]\nbase = \"default\"\nduration = 3.0\n");
        let p = Presets::parse(&text, "test").unwrap();
        let e = p.get("typo").unwrap_err().to_string();
        assert!(e.contains("typo") && e.contains("duration"), "{e}");
    }
}
