//! MAVLink out: CAMERA_TRACKING_GEO_STATUS (id 276) per estimate and a HEARTBEAT at
//! 1 Hz, MAVLink 2, encoded by the `mavlink` crate (common dialect) and sent over UDP.
//! dualgeo appears as its own component (`--mavlink-system-id`,
//! `--mavlink-component-id`), a camera (MAV_TYPE_CAMERA) without an autopilot.

use super::udp::UdpSender;
use super::{LiveOutArgs, TargetFix};
use anyhow::{bail, Result};
use mavlink::dialects::common::{
    CameraTrackingStatusFlags, MavAutopilot, MavMessage, MavModeFlag, MavState, MavType,
    CAMERA_TRACKING_GEO_STATUS_DATA, HEARTBEAT_DATA,
};
use mavlink::{MavHeader, MavlinkVersion};
use shared_types::stats::StageStats;

pub struct MavlinkOut {
    udp: UdpSender,
    system_id: u8,
    component_id: u8,
    geoid_height_m: f64,
    sequence: u8,
    buf: Vec<u8>,
}

/// degE7 as MAVLink's int32, or `None` out of range.
fn deg_e7(deg: f64) -> Option<i32> {
    let v = (deg * 1e7).round();
    (v.is_finite() && v.abs() <= i32::MAX as f64).then_some(v as i32)
}

impl MavlinkOut {
    /// `address` is `udpout:HOST:PORT` (the address syntax of MAVLink tools).
    pub fn open(address: &str, args: &LiveOutArgs, geoid_height_m: f64) -> Result<Self> {
        let Some(host_port) = address.strip_prefix("udpout:") else {
            bail!("--mavlink-out {address:?}: expected udpout:HOST:PORT");
        };
        Ok(Self {
            udp: UdpSender::open(host_port, "--mavlink-out", "mavlink")?,
            system_id: args.mavlink_system_id,
            component_id: args.mavlink_component_id,
            geoid_height_m,
            sequence: 0,
            buf: Vec::with_capacity(300),
        })
    }

    fn send(&mut self, msg: &MavMessage, stats: &mut StageStats) -> bool {
        let header = MavHeader {
            system_id: self.system_id.into(),
            component_id: self.component_id,
            sequence: self.sequence,
        };
        self.buf.clear();
        if let Err(e) = mavlink::write_versioned_msg(&mut self.buf, MavlinkVersion::V2, header, msg)
        {
            stats.count("mavlink.encode_failed", 1);
            tracing::warn!("MAVLink encoding failed: {e}");
            return false;
        }
        self.sequence = self.sequence.wrapping_add(1);
        self.udp.send(&self.buf, stats)
    }

    pub fn send_fix(&mut self, fix: &TargetFix, stats: &mut StageStats) {
        let (Some(lat), Some(lon)) = (deg_e7(fix.lat_deg), deg_e7(fix.lon_deg)) else {
            stats.count("mavlink.unsendable", 1);
            return;
        };
        let msg = MavMessage::CAMERA_TRACKING_GEO_STATUS(CAMERA_TRACKING_GEO_STATUS_DATA {
            tracking_status: CameraTrackingStatusFlags::CAMERA_TRACKING_STATUS_FLAGS_ACTIVE,
            lat,
            lon,
            alt: (fix.hae_m - self.geoid_height_m) as f32,
            h_acc: fix.h_acc_m as f32,
            v_acc: fix.v_acc_m as f32,
            vel_n: fix.vel_north_mps as f32,
            vel_e: fix.vel_east_mps as f32,
            // The filter models no vertical velocity.
            vel_d: f32::NAN,
            vel_acc: fix.vel_acc_mps as f32,
            dist: fix.range_m as f32,
            hdg: f32::NAN,
            hdg_acc: f32::NAN,
        });
        if self.send(&msg, stats) {
            stats.count("mavlink.sent", 1);
        }
    }

    pub fn send_heartbeat(&mut self, stats: &mut StageStats) {
        let msg = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_CAMERA,
            autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        });
        if self.send(&msg, stats) {
            stats.count("mavlink.heartbeats", 1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degrees_become_mavlink_int32_or_nothing() {
        assert_eq!(deg_e7(47.3976597), Some(473_976_597));
        assert_eq!(deg_e7(-8.5), Some(-85_000_000));
        assert_eq!(deg_e7(f64::NAN), None);
        assert_eq!(deg_e7(400.0), None);
    }
}
