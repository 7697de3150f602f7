//! `recording.toml`: cameras, frame rate and the optional geodetic origin.

use super::RecordingError;
use serde::{Deserialize, Serialize};
use shared_types::conventions::{Intrinsics, Mount, Uav};
use std::path::Path;

pub const FORMAT_NAME: &str = "dual-uav-recording";
/// The newest version this reader knows; it reads every version from 1.
pub const FORMAT_VERSION: u32 = 2;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordingMeta {
    pub format: String,
    pub version: u32,
    #[serde(default)]
    pub name: String,
    pub frame_rate_hz: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub origin: Option<Origin>,
    pub uav: UavPair,
}

/// WGS84 position of the ENU origin.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Origin {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UavPair {
    pub left: UavMeta,
    pub right: UavMeta,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UavMeta {
    /// Folder of this UAV's images, relative to the recording.
    pub frames: String,
    /// "nadir" (the only mount of version 1); version 2 adds "fixed" (with
    /// `mount_angles`) and "gimbal" (angles per image in telemetry.csv).
    pub mount: String,
    /// The fixed mount's gimbal frame relative to the body (degrees): only with
    /// `mount = "fixed"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mount_angles: Option<MountAngles>,
    pub camera: CameraMeta,
}

/// `[uav.NAME.mount_angles]`: aerospace Z-Y-X angles of the gimbal frame relative to
/// the body, degrees (nadir is pitch −90).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MountAngles {
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
}

/// How a UAV's camera is mounted (recording format v2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CameraMount {
    Nadir,
    /// Constant angles.
    Fixed(Mount),
    /// Angles per image (telemetry.csv's gimbal columns).
    Gimbal,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraMeta {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// k1 k2 p1 p2 k3, OpenCV model.
    pub distortion: [f64; 5],
}

impl CameraMeta {
    pub fn intrinsics(&self) -> Intrinsics {
        Intrinsics::new(self.fx, self.fy, self.cx, self.cy)
    }
}

impl RecordingMeta {
    /// A version-1 header with the same nadir camera on both UAVs, folders `left`/`right`.
    pub fn new(name: &str, frame_rate_hz: f64, camera: CameraMeta, origin: Option<Origin>) -> Self {
        let uav = |frames: &str| UavMeta {
            frames: frames.into(),
            mount: "nadir".into(),
            mount_angles: None,
            camera,
        };
        Self {
            format: FORMAT_NAME.into(),
            version: 1,
            name: name.into(),
            frame_rate_hz,
            origin,
            uav: UavPair {
                left: uav("left"),
                right: uav("right"),
            },
        }
    }

    pub fn uav(&self, uav: Uav) -> &UavMeta {
        match uav {
            Uav::Left => &self.uav.left,
            Uav::Right => &self.uav.right,
        }
    }

    pub fn uav_mut(&mut self, uav: Uav) -> &mut UavMeta {
        match uav {
            Uav::Left => &mut self.uav.left,
            Uav::Right => &mut self.uav.right,
        }
    }

    /// Gives `uav` a fixed tilted camera (`mount = "fixed"`, version 2).
    pub fn set_fixed_mount(&mut self, uav: Uav, angles: MountAngles) {
        let m = self.uav_mut(uav);
        (m.mount, m.mount_angles) = ("fixed".into(), Some(angles));
        self.version = 2;
    }

    /// Gives `uav` a gimballed camera (`mount = "gimbal"`, version 2): its angles go
    /// with each image ([`crate::recording::RecordingWriter::write_gimbal_frame`]).
    pub fn set_gimbal_mount(&mut self, uav: Uav) {
        let m = self.uav_mut(uav);
        (m.mount, m.mount_angles) = ("gimbal".into(), None);
        self.version = 2;
    }

    /// `uav`'s camera mount (the metadata is validated: an unknown mount reads nadir
    /// only on an unvalidated value).
    pub fn mount(&self, uav: Uav) -> CameraMount {
        let m = self.uav(uav);
        match (m.mount.as_str(), m.mount_angles) {
            ("fixed", Some(a)) => {
                CameraMount::Fixed(Mount::from_degrees(a.yaw_deg, a.pitch_deg, a.roll_deg))
            }
            ("gimbal", _) => CameraMount::Gimbal,
            _ => CameraMount::Nadir,
        }
    }

    /// Whether telemetry.csv (and truth.csv) carry the gimbal columns: exactly when a
    /// UAV has `mount = "gimbal"`.
    pub fn has_gimbal_columns(&self) -> bool {
        [Uav::Left, Uav::Right]
            .iter()
            .any(|u| self.mount(*u) == CameraMount::Gimbal)
    }

    pub fn read(path: &Path) -> Result<Self, RecordingError> {
        let text = std::fs::read_to_string(path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => RecordingError::MissingFile { path: path.into() },
            _ => RecordingError::io(path, e),
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates recording.toml's text (errors name `path`).
    pub fn parse(text: &str, path: &Path) -> Result<Self, RecordingError> {
        let meta: RecordingMeta = toml::from_str(text).map_err(|e| RecordingError::Metadata {
            path: path.into(),
            message: e.to_string().trim_end().to_string(),
        })?;
        meta.validate()
            .map_err(|message| RecordingError::Metadata {
                path: path.into(),
                message,
            })?;
        Ok(meta)
    }

    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("RecordingMeta always serialises")
    }

    /// Checks every rule of formats v1 and v2 that the TOML types alone do not.
    pub fn validate(&self) -> Result<(), String> {
        if self.format != FORMAT_NAME {
            return Err(format!(
                "format must be \"{FORMAT_NAME}\", got \"{}\"",
                self.format
            ));
        }
        if !(1..=FORMAT_VERSION).contains(&self.version) {
            return Err(format!(
                "unsupported version {} (this reader knows 1 to {FORMAT_VERSION})",
                self.version
            ));
        }
        if !(self.frame_rate_hz.is_finite() && self.frame_rate_hz > 0.0) {
            return Err(format!(
                "frame_rate_hz must be finite and > 0, got {}",
                self.frame_rate_hz
            ));
        }
        if let Some(o) = self.origin {
            let valid = o.lat_deg.is_finite()
                && o.lat_deg.abs() <= 90.0
                && o.lon_deg.is_finite()
                && o.lon_deg.abs() <= 180.0
                && o.alt_m.is_finite();
            if !valid {
                return Err(format!("origin is not a valid WGS84 position: {o:?}"));
            }
        }
        if self.uav.left.frames == self.uav.right.frames {
            return Err("uav.left.frames and uav.right.frames must be different folders".into());
        }
        for uav in [Uav::Left, Uav::Right] {
            let m = self.uav(uav);
            let name = uav.name();
            match (self.version, m.mount.as_str(), m.mount_angles) {
                (_, "nadir", None) => {}
                (1, other, _) if other != "nadir" => {
                    return Err(format!(
                        "uav.{name}.mount must be \"nadir\" in version 1, got \"{other}\" (tilted and gimballed cameras need version = 2)"
                    ))
                }
                (_, "fixed", Some(a)) => {
                    let finite = [a.yaw_deg, a.pitch_deg, a.roll_deg]
                        .iter()
                        .all(|v| v.is_finite());
                    if !finite {
                        return Err(format!("uav.{name}.mount_angles must be finite"));
                    }
                }
                (_, "fixed", None) => {
                    return Err(format!(
                        "uav.{name}.mount = \"fixed\" needs [uav.{name}.mount_angles] with yaw_deg, pitch_deg, roll_deg"
                    ))
                }
                (_, "gimbal", None) => {}
                (_, "nadir" | "gimbal", Some(_)) => {
                    return Err(format!(
                        "uav.{name}.mount_angles is only for mount = \"fixed\" (\"{}\" takes none)",
                        m.mount
                    ))
                }
                (_, other, _) => {
                    return Err(format!(
                        "uav.{name}.mount must be \"nadir\", \"fixed\" or \"gimbal\", got \"{other}\""
                    ))
                }
            }
            let folder = Path::new(&m.frames);
            if m.frames.is_empty()
                || folder.is_absolute()
                || folder.components().count() != 1
                || m.frames == ".."
                || m.frames == "."
            {
                return Err(format!(
                    "uav.{name}.frames must be one folder name inside the recording, got \"{}\"",
                    m.frames
                ));
            }
            let c = &m.camera;
            if c.width == 0 || c.height == 0 {
                return Err(format!("uav.{name}.camera width and height must be > 0"));
            }
            let finite = [c.fx, c.fy, c.cx, c.cy]
                .iter()
                .chain(&c.distortion)
                .all(|v| v.is_finite());
            if !finite || c.fx <= 0.0 || c.fy <= 0.0 {
                return Err(format!(
                    "uav.{name}.camera needs finite intrinsics with fx, fy > 0"
                ));
            }
        }
        Ok(())
    }
}
