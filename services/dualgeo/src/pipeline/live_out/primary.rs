//! Which vehicle MAVLink's CAMERA_TRACKING_GEO_STATUS carries (`--mavlink-primary`):
//! the message has no target id, so one vehicle of the estimate is chosen. Pure.

use super::TargetFix;
use acquisition::recording::Origin;
use shared_types::messages::EstimateMsg;
use std::str::FromStr;

/// `--mavlink-primary`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Primary {
    /// The designated target (track 0), the default.
    Target,
    /// The vehicle with the lowest id the estimate holds: the target while it is
    /// located, else the oldest other track.
    First,
    /// The vehicle with this id (0 is the target); nothing while it is not located.
    Id(u32),
    /// The vehicle nearest this point (latitude, longitude, degrees).
    Nearest(f64, f64),
}

impl FromStr for Primary {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let bad =
            || format!("{s:?}: expected target, first, a track id, or nearest:LAT,LON (degrees)");
        match s {
            "target" => return Ok(Primary::Target),
            "first" => return Ok(Primary::First),
            _ => {}
        }
        if let Some(point) = s.strip_prefix("nearest:") {
            let (lat, lon) = point.split_once(',').ok_or_else(bad)?;
            let (lat, lon): (f64, f64) = (
                lat.trim().parse().map_err(|_| bad())?,
                lon.trim().parse().map_err(|_| bad())?,
            );
            if !(lat.abs() <= 90.0 && lon.abs() <= 180.0) {
                return Err(bad());
            }
            return Ok(Primary::Nearest(lat, lon));
        }
        s.parse::<u32>().map(Primary::Id).map_err(|_| bad())
    }
}

/// Every vehicle of `e` with a fix: the target (id 0) when its estimate is valid, then
/// the other tracks by id.
pub fn vehicles(e: &EstimateMsg, origin: &Origin) -> Vec<(u32, TargetFix)> {
    let mut out: Vec<(u32, TargetFix)> = TargetFix::of(e, origin)
        .map(|f| (0, f))
        .into_iter()
        .collect();
    out.extend(
        e.tracks()
            .iter()
            .map(|t| (t.id, TargetFix::of_track(e, t, origin))),
    );
    out
}

/// The primary vehicle among `vehicles` (as [`vehicles`] gives them), if any.
pub fn choose(rule: Primary, vehicles: &[(u32, TargetFix)]) -> Option<(u32, TargetFix)> {
    match rule {
        Primary::Target => vehicles.iter().find(|(id, _)| *id == 0).copied(),
        Primary::Id(want) => vehicles.iter().find(|(id, _)| *id == want).copied(),
        Primary::First => vehicles.iter().min_by_key(|(id, _)| *id).copied(),
        Primary::Nearest(lat, lon) => {
            // Local flat-earth metres: the vehicles are within a few km of each other.
            let metres = |f: &TargetFix| {
                let north = (f.lat_deg - lat).to_radians() * 6_371_000.0;
                let east = (f.lon_deg - lon).to_radians() * 6_371_000.0 * lat.to_radians().cos();
                north.hypot(east)
            };
            vehicles
                .iter()
                .filter(|(_, f)| metres(f).is_finite())
                .min_by(|a, b| metres(&a.1).total_cmp(&metres(&b.1)))
                .copied()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fix(lat: f64, lon: f64) -> TargetFix {
        TargetFix {
            pair_seq: 1,
            lat_deg: lat,
            lon_deg: lon,
            hae_m: 10.0,
            h_acc_m: 1.0,
            v_acc_m: 1.0,
            vel_north_mps: 0.0,
            vel_east_mps: 0.0,
            vel_acc_mps: f64::NAN,
            range_m: f64::NAN,
        }
    }

    #[test]
    fn the_rule_is_parsed_or_refused_with_what_it_takes() {
        assert_eq!("target".parse(), Ok(Primary::Target));
        assert_eq!("first".parse(), Ok(Primary::First));
        assert_eq!("3".parse(), Ok(Primary::Id(3)));
        assert_eq!(
            "nearest:30.5, 120.25".parse(),
            Ok(Primary::Nearest(30.5, 120.25))
        );
        for bad in ["", "nearest:91,0", "nearest:30", "-1", "car"] {
            let e = bad.parse::<Primary>().unwrap_err();
            assert!(e.contains("nearest:LAT,LON"), "{bad}: {e}");
        }
    }

    #[test]
    fn each_rule_picks_its_vehicle() {
        let all = vec![
            (0, fix(30.0, 120.0)),
            (2, fix(30.001, 120.0)),
            (5, fix(30.0, 120.002)),
        ];
        assert_eq!(choose(Primary::Target, &all).map(|v| v.0), Some(0));
        assert_eq!(choose(Primary::First, &all).map(|v| v.0), Some(0));
        assert_eq!(choose(Primary::First, &all[1..]).map(|v| v.0), Some(2));
        assert_eq!(choose(Primary::Target, &all[1..]).map(|v| v.0), None);
        assert_eq!(choose(Primary::Id(5), &all).map(|v| v.0), Some(5));
        assert_eq!(choose(Primary::Id(4), &all).map(|v| v.0), None);
        let near_five = Primary::Nearest(30.0, 120.0021);
        assert_eq!(choose(near_five, &all).map(|v| v.0), Some(5));
        assert_eq!(choose(near_five, &[]), None);
    }
}
