//! MAVLink out: CAMERA_TRACKING_GEO_STATUS (id 276) per estimate for the primary
//! vehicle, ADSB_VEHICLE (id 246) per vehicle and estimate, and a HEARTBEAT at 1 Hz,
//! MAVLink 2, encoded by the `mavlink` crate (common dialect) and sent over UDP.
//! dualgeo appears as its own component (`--mavlink-system-id`,
//! `--mavlink-component-id`), a camera (MAV_TYPE_CAMERA) without an autopilot.
//!
//! Per vehicle: the common dialect's only position message with an id of its own is
//! ADSB_VEHICLE (ICAO_address, callsign), and QGroundControl and Mission Planner draw
//! it on their maps as traffic. The development dialect's TARGET_ABSOLUTE (id 510)
//! carries a target id too, but that dialect is not stable and ground stations do not
//! read it. So each vehicle is an ADSB_VEHICLE of emitter type SERVICE_SURFACE, ICAO
//! address `--mavlink-icao-base` + its id (0 the target), callsign `DGV<id>`, flagged
//! SIMULATED (it is no transponder), altitude GEOMETRIC (AMSL from the estimate).

use super::udp::UdpSender;
use super::{LiveOutArgs, TargetFix};
use anyhow::{bail, Result};
use mavlink::dialects::common::{
    AdsbAltitudeType, AdsbEmitterType, AdsbFlags, CameraTrackingStatusFlags, MavAutopilot,
    MavMessage, MavModeFlag, MavState, MavType, ADSB_VEHICLE_DATA, CAMERA_TRACKING_GEO_STATUS_DATA,
    HEARTBEAT_DATA,
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
    icao_base: u32,
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
            icao_base: args.mavlink_icao_base,
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

    /// Vehicle `id`'s fix as an ADSB_VEHICLE (see the module's note).
    pub fn send_vehicle(&mut self, id: u32, fix: &TargetFix, stats: &mut StageStats) {
        let msg = match adsb_vehicle(id, fix, self.icao_base, self.geoid_height_m) {
            Some(msg) => msg,
            None => {
                stats.count("mavlink.unsendable", 1);
                return;
            }
        };
        if self.send(&msg, stats) {
            stats.count("mavlink.vehicles_sent", 1);
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

/// The ADSB_VEHICLE of vehicle `id`, or `None` when its position does not fit the
/// message (an id beyond the 24-bit address space, a latitude out of range).
fn adsb_vehicle(id: u32, fix: &TargetFix, icao_base: u32, geoid_m: f64) -> Option<MavMessage> {
    let (lat, lon) = (deg_e7(fix.lat_deg)?, deg_e7(fix.lon_deg)?);
    let icao = icao_base.checked_add(id).filter(|a| *a <= 0xFF_FFFF)?;
    let alt_mm = ((fix.hae_m - geoid_m) * 1000.0).round();
    if !(alt_mm.is_finite() && alt_mm.abs() < i32::MAX as f64) {
        return None;
    }
    let speed = fix.vel_north_mps.hypot(fix.vel_east_mps);
    let mut flags = AdsbFlags::ADSB_FLAGS_VALID_COORDS
        | AdsbFlags::ADSB_FLAGS_VALID_ALTITUDE
        | AdsbFlags::ADSB_FLAGS_VALID_CALLSIGN
        | AdsbFlags::ADSB_FLAGS_SIMULATED;
    let (heading, hor_velocity) = if speed.is_finite() {
        flags |= AdsbFlags::ADSB_FLAGS_VALID_HEADING | AdsbFlags::ADSB_FLAGS_VALID_VELOCITY;
        let course = fix
            .vel_east_mps
            .atan2(fix.vel_north_mps)
            .to_degrees()
            .rem_euclid(360.0);
        (
            ((course * 100.0).round() as u16).min(35_999),
            (speed * 100.0).round().min(65_534.0) as u16,
        )
    } else {
        (u16::MAX, u16::MAX)
    };
    Some(MavMessage::ADSB_VEHICLE(ADSB_VEHICLE_DATA {
        ICAO_address: icao,
        lat,
        lon,
        altitude: alt_mm as i32,
        heading,
        hor_velocity,
        ver_velocity: i16::MAX,
        flags,
        squawk: 0,
        altitude_type: AdsbAltitudeType::ADSB_ALTITUDE_TYPE_GEOMETRIC,
        callsign: format!("DGV{id}").as_str().into(),
        emitter_type: AdsbEmitterType::ADSB_EMITTER_TYPE_SERVICE_SURFACE,
        tslc: 0,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_vehicle_is_an_adsb_vehicle_with_its_id_in_the_address() {
        let fix = TargetFix {
            pair_seq: 1,
            lat_deg: 30.5,
            lon_deg: 120.25,
            hae_m: 15.0,
            h_acc_m: 1.0,
            v_acc_m: 1.0,
            vel_north_mps: 0.0,
            vel_east_mps: 10.0,
            vel_acc_mps: f64::NAN,
            range_m: f64::NAN,
        };
        let Some(MavMessage::ADSB_VEHICLE(m)) = adsb_vehicle(3, &fix, 0xF0_0000, 5.0) else {
            panic!("no message");
        };
        assert_eq!(m.ICAO_address, 0xF0_0003);
        assert_eq!((m.lat, m.lon), (305_000_000, 1_202_500_000));
        assert_eq!(m.altitude, 10_000);
        assert_eq!((m.heading, m.hor_velocity), (9_000, 1_000));
        assert_eq!(m.callsign.to_str(), Ok("DGV3"));
        assert!(adsb_vehicle(0x10, &fix, 0xFF_FFF8, 0.0).is_none());
        let nowhere = TargetFix {
            lat_deg: f64::NAN,
            ..fix
        };
        assert!(adsb_vehicle(1, &nowhere, 0xF0_0000, 0.0).is_none());
    }

    #[test]
    fn degrees_become_mavlink_int32_or_nothing() {
        assert_eq!(deg_e7(47.3976597), Some(473_976_597));
        assert_eq!(deg_e7(-8.5), Some(-85_000_000));
        assert_eq!(deg_e7(f64::NAN), None);
        assert_eq!(deg_e7(400.0), None);
    }
}
