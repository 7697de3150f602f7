//! `flight.toml`: what a flight source reads, per UAV a video and its telemetry, the
//! camera, and how their clocks line up (docs/flight-io.md).
//!
//! ```toml
//! format = "dualgeo-flight"
//! version = 1
//! name = "demo"
//! frame_rate_hz = 30.0          # the videos' rate: the pairing window
//! max_telemetry_gap_s = 0.5     # interpolate poses across at most this (default 0.5)
//! truth = "truth.csv"           # optional, evaluation only: format v1's truth.csv and
//!                               # telemetry.csv beside flight.toml
//! geoid_height_m = 0.0          # N: ellipsoidal height = MAVLink AMSL altitude + N
//!
//! [origin]                      # the ENU origin (required): WGS84, ellipsoidal height
//! lat_deg = 47.0
//! lon_deg = 8.0
//! alt_m = 400.0
//!
//! [uav.left]
//! video = "left.mp4"            # a file (relative to flight.toml) or a stream URL
//! telemetry = "left.tlog"       # a .tlog file, or udpin:HOST:PORT live (then the
//!                               # video is a stream URL too)
//! time_offset_s = 100.0         # autopilot clock (time_boot_ms) at video time 0
//!                               # (recorded flights; live, the offset is measured)
//! video_latency_s = 0.0         # live only: capture → decoded frame on the ground
//! system_id = 1                 # optional: the autopilot's system id in the log
//! [uav.left.camera]             # as recording.toml's camera
//! width = 640
//! ...
//! ```

use crate::recording::{CameraMeta, Origin};
use serde::{Deserialize, Serialize};
use shared_types::conventions::Uav;
use std::path::{Path, PathBuf};

pub const FLIGHT_FORMAT: &str = "dualgeo-flight";
pub const FLIGHT_VERSION: u32 = 1;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlightUav {
    pub video: String,
    pub telemetry: String,
    #[serde(default)]
    pub time_offset_s: f64,
    /// Live only: seconds from a frame's capture on the UAV to its decoded pixels on
    /// the ground (encoder, radio, decoder), subtracted from its arrival time.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub video_latency_s: f64,
    /// The MAVLink system id of this UAV's autopilot in its log; needed only when the
    /// log holds navigation messages of more than one system.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub system_id: Option<u8>,
    pub camera: CameraMeta,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn default_max_telemetry_gap_s() -> f64 {
    0.5
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlightUavPair {
    pub left: FlightUav,
    pub right: FlightUav,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlightMeta {
    pub format: String,
    pub version: u32,
    pub name: String,
    pub frame_rate_hz: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truth: Option<String>,
    #[serde(default)]
    pub geoid_height_m: f64,
    /// Poses are interpolated between telemetry samples at most this far apart (each of
    /// position and attitude); a frame in a longer gap has no pose.
    #[serde(default = "default_max_telemetry_gap_s")]
    pub max_telemetry_gap_s: f64,
    pub origin: Origin,
    pub uav: FlightUavPair,
}

/// Is `s` a stream address rather than a file?
pub fn is_url(s: &str) -> bool {
    s.contains("://") || s.starts_with("udpin:")
}

impl FlightMeta {
    /// Live flight: telemetry from `udpin:` (then both UAVs' videos are streams).
    pub fn is_live(&self) -> bool {
        self.uav.left.telemetry.starts_with("udpin:")
    }

    pub fn uav(&self, uav: Uav) -> &FlightUav {
        match uav {
            Uav::Left => &self.uav.left,
            Uav::Right => &self.uav.right,
        }
    }

    /// Parses and checks flight.toml's text; errors name `path`.
    pub fn parse(text: &str, path: &Path) -> Result<Self, String> {
        let meta: FlightMeta = toml::from_str(text)
            .map_err(|e| format!("{}: {}", path.display(), e.to_string().trim_end()))?;
        meta.validate()
            .map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(meta)
    }

    pub fn read(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::parse(&text, path)
    }

    pub fn validate(&self) -> Result<(), String> {
        if self.format != FLIGHT_FORMAT || self.version != FLIGHT_VERSION {
            return Err(format!(
                "format {:?} version {} (this build reads {FLIGHT_FORMAT:?} version {FLIGHT_VERSION})",
                self.format, self.version
            ));
        }
        if !(self.frame_rate_hz.is_finite()
            && self.frame_rate_hz > 0.0
            && self.frame_rate_hz <= 1000.0)
        {
            return Err(format!(
                "frame_rate_hz {} must be in (0, 1000]",
                self.frame_rate_hz
            ));
        }
        let o = &self.origin;
        if !(o.lat_deg.abs() <= 90.0 && o.lon_deg.abs() <= 180.0 && o.alt_m.is_finite()) {
            return Err("[origin] must be a WGS84 latitude, longitude and finite height".into());
        }
        if !(self.max_telemetry_gap_s.is_finite()
            && self.max_telemetry_gap_s > 0.0
            && self.max_telemetry_gap_s <= 10.0)
        {
            return Err(format!(
                "max_telemetry_gap_s {} must be in (0, 10]",
                self.max_telemetry_gap_s
            ));
        }
        if !self.geoid_height_m.is_finite() || self.geoid_height_m.abs() > 200.0 {
            return Err(format!(
                "geoid_height_m {} must be within ±200 m",
                self.geoid_height_m
            ));
        }
        for uav in [Uav::Left, Uav::Right] {
            let u = self.uav(uav);
            let name = uav.name();
            if u.video.is_empty() || u.telemetry.is_empty() {
                return Err(format!("[uav.{name}] needs a video and a telemetry"));
            }
            if !u.time_offset_s.is_finite() {
                return Err(format!("[uav.{name}] time_offset_s must be finite"));
            }
            let live = u.telemetry.starts_with("udpin:");
            if live != self.is_live() {
                return Err(
                    "both UAVs' telemetry must be live (udpin:) or both .tlog files".into(),
                );
            }
            if live && !is_url(&u.video) {
                return Err(format!(
                    "[uav.{name}] live telemetry needs a live video: a stream URL, not the \
                     file {:?}",
                    u.video
                ));
            }
            if live && u.time_offset_s != 0.0 {
                return Err(format!(
                    "[uav.{name}] time_offset_s: a live flight measures the clock offset from \
                     the telemetry; give video_latency_s instead"
                ));
            }
            if !(u.video_latency_s.is_finite() && (0.0..=10.0).contains(&u.video_latency_s)) {
                return Err(format!("[uav.{name}] video_latency_s must be in [0, 10] s"));
            }
            if !live && u.video_latency_s != 0.0 {
                return Err(format!(
                    "[uav.{name}] video_latency_s is for live flights; a recorded one is \
                     aligned by time_offset_s"
                ));
            }
            let c = &u.camera;
            let finite = [c.fx, c.fy, c.cx, c.cy]
                .iter()
                .chain(&c.distortion)
                .all(|v| v.is_finite());
            if !(finite
                && c.fx > 0.0
                && c.fy > 0.0
                && c.width > 0
                && c.height > 0
                && c.width <= 16384
                && c.height <= 16384)
            {
                return Err(format!("[uav.{name}.camera] is not a usable camera"));
            }
        }
        if self.truth.as_deref().is_some_and(|t| t != "truth.csv") {
            return Err(format!(
                "truth = {:?}: the truth of a flight is truth.csv beside flight.toml, with \
                 its telemetry.csv (format v1, evaluation only)",
                self.truth.as_deref().unwrap_or_default()
            ));
        }
        let (l, r) = (&self.uav.left.camera, &self.uav.right.camera);
        if (l.width, l.height) != (r.width, r.height) {
            return Err("left and right cameras must have the same image size".into());
        }
        Ok(())
    }

    /// A file named in flight.toml, relative to its folder; a URL stays as it is.
    pub fn resolve(&self, flight_toml: &Path, name: &str) -> PathBuf {
        if is_url(name) {
            return PathBuf::from(name);
        }
        flight_toml.parent().unwrap_or(Path::new(".")).join(name)
    }
}
