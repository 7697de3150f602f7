//! Cursor-on-Target out: one CoT 2.0 event per estimate, as a UDP datagram of XML (what
//! TAK clients listen for). The event's point carries lat, lon, hae (height above the
//! WGS84 ellipsoid) and ce / le, the schema's circular and linear 1σ errors (h_acc and
//! v_acc; 9999999 when unknown, the schema's "unknown"); `how` is `m-f` (machine,
//! fused: imagery and navigation). The track element carries course and speed when the
//! temporal filter gives a velocity. Every other vehicle's track gets events of its own
//! under a uid of its own (`<target uid>-vehicle-<track id>`), and one last event
//! stale at once when the track is deleted (a TAK client then drops it).

use super::udp::UdpSender;
use super::{LiveOutArgs, TargetFix};
use anyhow::{bail, Result};
use shared_types::stats::StageStats;
use std::time::{Duration, SystemTime};

/// CoT's value for an unknown error.
const UNKNOWN_ERROR: f64 = 9_999_999.0;

pub struct CotOut {
    udp: UdpSender,
    uid: String,
    cot_type: String,
    stale: Duration,
}

fn error_or_unknown(v: f64) -> f64 {
    if v.is_finite() && v >= 0.0 {
        v
    } else {
        UNKNOWN_ERROR
    }
}

/// The XML of one event at wall-clock time `now`.
pub fn cot_event(
    fix: &TargetFix,
    uid: &str,
    cot_type: &str,
    now: SystemTime,
    stale: Duration,
) -> String {
    let time = humantime::format_rfc3339_millis(now);
    let stale_at = humantime::format_rfc3339_millis(now + stale);
    let track = if fix.vel_north_mps.is_finite() && fix.vel_east_mps.is_finite() {
        // Course: degrees clockwise from true north.
        let course = fix
            .vel_east_mps
            .atan2(fix.vel_north_mps)
            .to_degrees()
            .rem_euclid(360.0);
        let speed = fix.vel_north_mps.hypot(fix.vel_east_mps);
        format!("<track course=\"{course:.1}\" speed=\"{speed:.2}\"/>")
    } else {
        String::new()
    };
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\" standalone=\"yes\"?>\
         <event version=\"2.0\" uid=\"{uid}\" type=\"{cot_type}\" how=\"m-f\" \
         time=\"{time}\" start=\"{time}\" stale=\"{stale_at}\">\
         <point lat=\"{:.7}\" lon=\"{:.7}\" hae=\"{:.2}\" ce=\"{:.2}\" le=\"{:.2}\"/>\
         <detail>{track}<remarks>dualgeo estimate of pair {}</remarks></detail></event>",
        fix.lat_deg,
        fix.lon_deg,
        fix.hae_m,
        error_or_unknown(fix.h_acc_m),
        error_or_unknown(fix.v_acc_m),
        fix.pair_seq,
    )
}

impl CotOut {
    /// `address` is `udp://HOST:PORT`.
    pub fn open(address: &str, args: &LiveOutArgs) -> Result<Self> {
        let Some(host_port) = address.strip_prefix("udp://") else {
            bail!("--cot-out {address:?}: expected udp://HOST:PORT");
        };
        if args.cot_type.is_empty()
            || !args
                .cot_type
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-')
        {
            bail!(
                "--cot-type {:?}: letters, digits and '-' only",
                args.cot_type
            );
        }
        Ok(Self {
            udp: UdpSender::open(host_port, "--cot-out", "cot")?,
            // One target per run: a uid per run keeps two runs apart on one map.
            uid: format!("dualgeo-target-{}", std::process::id()),
            cot_type: args.cot_type.clone(),
            stale: Duration::from_secs_f64(args.cot_stale_s),
        })
    }

    pub fn send_fix(&mut self, fix: &TargetFix, stats: &mut StageStats) {
        let xml = cot_event(
            fix,
            &self.uid,
            &self.cot_type,
            SystemTime::now(),
            self.stale,
        );
        if self.udp.send(xml.as_bytes(), stats) {
            stats.count("cot.sent", 1);
        }
    }

    /// The uid of other vehicle `id`'s events.
    pub fn track_uid(&self, id: u32) -> String {
        format!("{}-vehicle-{id}", self.uid)
    }

    /// Another vehicle's track (counted `cot.tracks_sent`).
    pub fn send_track(&mut self, id: u32, fix: &TargetFix, stats: &mut StageStats) {
        let uid = self.track_uid(id);
        let xml = cot_event(fix, &uid, &self.cot_type, SystemTime::now(), self.stale);
        if self.udp.send(xml.as_bytes(), stats) {
            stats.count("cot.tracks_sent", 1);
        }
    }

    /// A deleted track's last event, stale at once (counted `cot.tracks_stale`).
    pub fn send_stale(&mut self, id: u32, last: &TargetFix, stats: &mut StageStats) {
        let uid = self.track_uid(id);
        let xml = cot_event(
            last,
            &uid,
            &self.cot_type,
            SystemTime::now(),
            Duration::ZERO,
        );
        if self.udp.send(xml.as_bytes(), stats) {
            stats.count("cot.tracks_stale", 1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fix() -> TargetFix {
        TargetFix {
            pair_seq: 7,
            lat_deg: 47.1234567,
            lon_deg: 8.5,
            hae_m: 412.5,
            h_acc_m: 3.2,
            v_acc_m: f64::NAN,
            vel_north_mps: 0.0,
            vel_east_mps: 5.0,
            vel_acc_mps: 0.4,
            range_m: 120.0,
        }
    }

    #[test]
    fn an_event_has_the_point_the_errors_and_the_stale_time() {
        let now = SystemTime::UNIX_EPOCH + Duration::from_secs(1_700_000_000);
        let xml = cot_event(&fix(), "u1", "a-u-G-E-V", now, Duration::from_secs(5));
        assert!(xml.contains("time=\"2023-11-14T22:13:20.000Z\""), "{xml}");
        assert!(xml.contains("stale=\"2023-11-14T22:13:25.000Z\""), "{xml}");
        assert!(
            xml.contains("lat=\"47.1234567\" lon=\"8.5000000\" hae=\"412.50\""),
            "{xml}"
        );
        assert!(xml.contains("ce=\"3.20\" le=\"9999999.00\""), "{xml}");
        assert!(xml.contains("course=\"90.0\" speed=\"5.00\""), "{xml}");
    }
}
