//! The target, live, to ground-control software (issue #14): every valid estimate as a
//! MAVLink CAMERA_TRACKING_GEO_STATUS (`--mavlink-out`, with a 1 Hz HEARTBEAT) and as a
//! Cursor-on-Target event (`--cot-out`), over UDP. The other vehicles' tracks go out
//! as CoT events of their own (a uid per track, stale when it is deleted) and, with
//! the target, as MAVLink ADSB_VEHICLE messages (an ICAO address per id,
//! `mavlink_out.rs`); CAMERA_TRACKING_GEO_STATUS carries one vehicle, the one
//! `--mavlink-primary` chooses (`primary.rs`). Sending never stops the run: a send
//! that fails or would block is dropped and counted (`mavlink.send_failed`,
//! `cot.send_failed`); what was sent is counted (`mavlink.sent`,
//! `mavlink.vehicles_sent`, `mavlink.heartbeats`, `cot.sent`) in the supervisor's
//! counters.
//!
//! Both need the source's geodetic origin (recording.toml's `[origin]`; the built-in
//! simulator has one): without it the run is refused before anything starts.

mod cot_out;
mod mavlink_out;
pub mod primary;
mod udp;

use super::track::{geodetic, one_sigma};
use acquisition::recording::Origin;
use anyhow::{bail, Result};
use clap::Args;
use shared_types::messages::{EstimateMsg, EstimateStatus, TrackEstimate};
use shared_types::stats::StageStats;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

pub use cot_out::CotOut;
pub use mavlink_out::MavlinkOut;

#[derive(Args, Debug, Clone)]
pub struct LiveOutArgs {
    /// Send the target as MAVLink 2 CAMERA_TRACKING_GEO_STATUS (id 276) with a 1 Hz
    /// HEARTBEAT to this address, e.g. udpout:127.0.0.1:14550 (QGroundControl's port).
    #[arg(long, value_name = "udpout:HOST:PORT")]
    pub mavlink_out: Option<String>,
    /// MAVLink system id of dualgeo's component (255: the ground station's usual id).
    #[arg(long, default_value_t = 255)]
    pub mavlink_system_id: u8,
    /// MAVLink component id (100: MAV_COMP_ID_CAMERA, the id a tracking camera uses).
    #[arg(long, default_value_t = 100)]
    pub mavlink_component_id: u8,
    /// The vehicle CAMERA_TRACKING_GEO_STATUS carries: `target` (the designated one,
    /// track 0), `first` (the lowest id located), a track id, or `nearest:LAT,LON`.
    #[arg(long, default_value = "target", value_parser = clap::value_parser!(primary::Primary))]
    pub mavlink_primary: primary::Primary,
    /// Do not send an ADSB_VEHICLE per vehicle (the target and every other track).
    #[arg(long)]
    pub no_mavlink_vehicles: bool,
    /// ICAO address of vehicle 0 in ADSB_VEHICLE; vehicle N is this + N (24 bits).
    #[arg(long, default_value_t = 0xF0_0000, value_parser = parse_icao)]
    pub mavlink_icao_base: u32,
    /// Geoid height N (m) at the origin: MAVLink's altitude is AMSL = ellipsoidal − N.
    /// Default: a flight's `geoid_height_m`, else 0 (dualgeo carries no geoid model, so
    /// then the ellipsoidal height is sent).
    #[arg(long)]
    pub geoid_height_m: Option<f64>,
    /// Send a Cursor-on-Target event per estimate to this address, e.g.
    /// udp://239.2.3.1:6969 (TAK's SA multicast) or udp://127.0.0.1:4242.
    #[arg(long, value_name = "udp://HOST:PORT")]
    pub cot_out: Option<String>,
    /// CoT type of the target (a-u-G-E-V: unknown ground vehicle).
    #[arg(long, default_value = "a-u-G-E-V")]
    pub cot_type: String,
    /// Seconds after which a TAK client greys the target out if no newer event came.
    #[arg(long, default_value_t = 5.0)]
    pub cot_stale_s: f64,
}

/// A 24-bit ICAO address, decimal or `0x` hexadecimal.
fn parse_icao(s: &str) -> Result<u32, String> {
    let v = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16),
        None => s.parse(),
    }
    .map_err(|e| format!("{s:?}: {e}"))?;
    if v > 0xFF_FFFF {
        return Err(format!(
            "{s:?}: an ICAO address has 24 bits (at most 0xFFFFFF)"
        ));
    }
    Ok(v)
}

/// One estimate as the outside world wants it: geodetic, with 1σ accuracies; NaN
/// where unknown (MAVLink's convention).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetFix {
    pub pair_seq: u64,
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// Height above the WGS84 ellipsoid, m.
    pub hae_m: f64,
    pub h_acc_m: f64,
    pub v_acc_m: f64,
    pub vel_north_mps: f64,
    pub vel_east_mps: f64,
    pub vel_acc_mps: f64,
    pub range_m: f64,
}

impl TargetFix {
    /// Another vehicle's track `t` of estimate `e` (its range unknown).
    pub fn of_track(e: &EstimateMsg, t: &TrackEstimate, origin: &Origin) -> Self {
        let (lat_deg, lon_deg, hae_m) = geodetic(origin, &t.position);
        let h_acc_m = (t.covariance_xy[0] + t.covariance_xy[3]).max(0.0).sqrt();
        Self {
            pair_seq: e.pair_seq,
            lat_deg,
            lon_deg,
            hae_m,
            h_acc_m,
            v_acc_m: t.altitude_std_error_m,
            vel_north_mps: t.velocity_mps[1],
            vel_east_mps: t.velocity_mps[0],
            vel_acc_mps: f64::NAN,
            range_m: f64::NAN,
        }
    }

    /// The fix of a valid estimate; `None` for a rejection.
    pub fn of(e: &EstimateMsg, origin: &Origin) -> Option<Self> {
        if e.status != EstimateStatus::Ok as u32 {
            return None;
        }
        let (lat_deg, lon_deg, hae_m) = geodetic(origin, &e.position);
        let (h_acc_m, v_acc_m) = one_sigma(e).unwrap_or((f64::NAN, f64::NAN));
        // ENU: x east, y north (docs/conventions.md).
        Some(Self {
            pair_seq: e.pair_seq,
            lat_deg,
            lon_deg,
            hae_m,
            h_acc_m,
            v_acc_m,
            vel_north_mps: e.velocity_mps[1],
            vel_east_mps: e.velocity_mps[0],
            vel_acc_mps: e.velocity_acc_mps,
            range_m: e.range_m,
        })
    }
}

/// The live outputs of a run (none, one or both).
pub struct LiveOutputs {
    origin: Option<Origin>,
    mavlink: Option<MavlinkOut>,
    cot: Option<CotOut>,
    last_heartbeat: Option<Instant>,
    /// The other vehicles' tracks of the last estimate, with their last fix.
    tracks: BTreeMap<u32, TargetFix>,
    primary: primary::Primary,
    vehicles: bool,
}

impl LiveOutputs {
    /// Opens the sockets; refuses a bad address, or an output without an origin.
    /// `source_geoid_m` is the source's own geoid height (a flight's), used unless
    /// `--geoid-height-m` is given.
    pub fn open(args: &LiveOutArgs, origin: Option<Origin>, source_geoid_m: f64) -> Result<Self> {
        let wanted = args.mavlink_out.is_some() || args.cot_out.is_some();
        if wanted && origin.is_none() {
            bail!(
                "--mavlink-out and --cot-out send latitude and longitude, but the source has \
                 no geodetic origin (add an [origin] section to its recording.toml)"
            );
        }
        if !(args.cot_stale_s.is_finite() && args.cot_stale_s > 0.0 && args.cot_stale_s <= 86_400.0)
        {
            bail!("--cot-stale-s must be a number of seconds in (0, 86400]");
        }
        let geoid_height_m = args.geoid_height_m.unwrap_or(source_geoid_m);
        if !geoid_height_m.is_finite() {
            bail!("--geoid-height-m must be finite");
        }
        Ok(Self {
            origin,
            mavlink: args
                .mavlink_out
                .as_deref()
                .map(|a| MavlinkOut::open(a, args, geoid_height_m))
                .transpose()?,
            cot: args
                .cot_out
                .as_deref()
                .map(|a| CotOut::open(a, args))
                .transpose()?,
            last_heartbeat: None,
            tracks: BTreeMap::new(),
            primary: args.mavlink_primary,
            vehicles: !args.no_mavlink_vehicles,
        })
    }

    /// Sends `e` to every output: the target when its estimate is valid, the other
    /// vehicles' tracks over CoT (and a stale event for each track gone since the last
    /// estimate).
    pub fn push(&mut self, e: &EstimateMsg, stats: &mut StageStats) {
        let Some(origin) = self.origin.as_ref() else {
            return;
        };
        if let Some(m) = &mut self.mavlink {
            let all = primary::vehicles(e, origin);
            if let Some((_, fix)) = primary::choose(self.primary, &all) {
                m.send_fix(&fix, stats);
            }
            if self.vehicles {
                for (id, fix) in &all {
                    m.send_vehicle(*id, fix, stats);
                }
            }
        }
        if let (Some(c), Some(fix)) = (&mut self.cot, TargetFix::of(e, origin)) {
            c.send_fix(&fix, stats);
        }
        let Some(c) = &mut self.cot else {
            return;
        };
        let now: BTreeMap<u32, TargetFix> = e
            .tracks()
            .iter()
            .map(|t| (t.id, TargetFix::of_track(e, t, origin)))
            .collect();
        for (id, fix) in &now {
            c.send_track(*id, fix, stats);
        }
        for (id, last) in self.tracks.iter().filter(|(id, _)| !now.contains_key(id)) {
            c.send_stale(*id, last, stats);
        }
        self.tracks = now;
    }

    /// The 1 Hz HEARTBEAT (called on the supervisor's 25 ms tick).
    pub fn tick(&mut self, stats: &mut StageStats) {
        let Some(m) = &mut self.mavlink else { return };
        if self
            .last_heartbeat
            .is_none_or(|t| t.elapsed() >= Duration::from_secs(1))
        {
            self.last_heartbeat = Some(Instant::now());
            m.send_heartbeat(stats);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn origin() -> Origin {
        Origin {
            lat_deg: 30.0,
            lon_deg: 120.0,
            alt_m: 10.0,
        }
    }

    fn estimate(pair_seq: u64, ids: &[u32]) -> EstimateMsg {
        let mut e = EstimateMsg {
            pair_seq,
            t_s: pair_seq as f64 / 30.0,
            position: [1.0, 2.0, 13.0],
            ..Default::default()
        };
        for (slot, id) in e.tracks.iter_mut().zip(ids) {
            *slot = TrackEstimate {
                id: *id,
                quality: 1,
                position: [10.0 * f64::from(*id), 0.0, 13.0],
                covariance_xy: [0.25, 0.0, 0.0, 0.25],
                altitude_std_error_m: 0.5,
                velocity_mps: [1.0, 0.0],
            };
        }
        e.track_count = ids.len() as u64;
        e
    }

    /// Every other vehicle's track is an event of its own uid; a track gone is sent
    /// once more, stale at once.
    #[test]
    fn tracks_go_out_as_their_own_cot_events_and_go_stale_when_deleted() {
        let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        socket
            .set_read_timeout(Some(Duration::from_secs(2)))
            .unwrap();
        let port = socket.local_addr().unwrap().port();
        let args = LiveOutArgs {
            mavlink_out: None,
            mavlink_system_id: 255,
            mavlink_component_id: 100,
            mavlink_primary: primary::Primary::Target,
            no_mavlink_vehicles: false,
            mavlink_icao_base: 0xF0_0000,
            geoid_height_m: None,
            cot_out: Some(format!("udp://127.0.0.1:{port}")),
            cot_type: "a-u-G-E-V".into(),
            cot_stale_s: 5.0,
        };
        let mut live = LiveOutputs::open(&args, Some(origin()), 0.0).unwrap();
        let mut stats = StageStats::new("t");
        let receive = || {
            let mut buf = [0u8; 4096];
            let n = socket.recv(&mut buf).unwrap();
            String::from_utf8_lossy(&buf[..n]).into_owned()
        };
        // The target's estimate is valid: its event first, then the tracks'.
        let mut e = estimate(1, &[1, 2]);
        live.push(&e, &mut stats);
        let target = receive();
        assert!(!target.contains("-vehicle-"), "{target}");
        let one = receive();
        assert!(one.contains("-vehicle-1\""), "{one}");
        assert!(receive().contains("-vehicle-2\""));
        // Track 2 gone, the target rejected: track 1's event, then track 2 stale.
        e = estimate(2, &[1]);
        e.status = EstimateStatus::Rejected as u32;
        live.push(&e, &mut stats);
        assert!(receive().contains("-vehicle-1\""));
        let gone = receive();
        assert!(gone.contains("-vehicle-2\""), "{gone}");
        let attr = |xml: &str, name: &str| {
            let at = xml.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
            xml[at..at + 24].to_string()
        };
        assert_eq!(attr(&gone, "time"), attr(&gone, "stale"), "{gone}");
        assert_eq!(stats.counter("cot.sent"), 1);
        assert_eq!(stats.counter("cot.tracks_sent"), 3);
        assert_eq!(stats.counter("cot.tracks_stale"), 1);
    }
}
