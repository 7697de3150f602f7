//! The UAV's navigation state at a frame's moment, from telemetry samples: positions
//! (WGS84, converted to the project's ENU about the flight's origin) and attitudes,
//! each interpolated on its own to the frame's time on the autopilot clock.
//!
//! The rule that keeps a pose honest: a frame gets a pose only when each of position
//! and attitude has a sample within `max_gap` (one frame period) on *both* sides of
//! the frame's time (then it is interpolated), or one within [`SAME_INSTANT_S`] (then
//! it is used as it is). Otherwise the frame has no pose and is dropped and counted:
//! never extrapolated across a telemetry gap.
//!
//! A log with gimbal attitudes (GIMBAL_DEVICE_ATTITUDE_STATUS) is a gimballed camera's:
//! the gimbal's angles are interpolated the same way (a frame without them is dropped,
//! `no_pose_gimbal`), and the pose given is the camera's, the body's on that mount
//! (`PoseSample::on_mount`, recording format v2's convention). A gimbal that reports
//! its yaw in the earth frame is turned into the body frame with the body's attitude at
//! the same moment: the autopilot derives that yaw from the same AHRS, so the camera
//! keeps the AHRS's yaw bias.

use super::tlog::NavSample;
use crate::recording::Origin;
use shared_types::conventions::{body_to_ned, Attitude, Mount};
use shared_types::messages::{MountSample, PoseSample};

/// Samples this close to a frame's time are taken as taken at it (the autopilot clock
/// is in milliseconds).
pub const SAME_INSTANT_S: f64 = 0.0015;

/// Why a frame has no pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoPose {
    /// No position sample close enough on both sides.
    Position,
    /// No attitude sample close enough on both sides.
    Attitude,
    /// A gimballed camera's log, without a gimbal sample close enough on both sides.
    Gimbal,
}

impl NoPose {
    /// The counter a pair dropped for this is counted in.
    pub fn counter(self) -> &'static str {
        match self {
            NoPose::Position => "no_pose_position",
            NoPose::Attitude => "no_pose_attitude",
            NoPose::Gimbal => "no_pose_gimbal",
        }
    }
}

#[derive(Debug, Clone, Default)]
pub struct NavTrack {
    /// (t, [x, y, z] ENU m), time-sorted.
    positions: Vec<(f64, [f64; 3])>,
    /// (t, [roll, pitch, yaw] rad), time-sorted.
    attitudes: Vec<(f64, [f64; 3])>,
    /// The gimbal's (t, [roll, pitch, yaw] rad), time-sorted; empty for a fixed camera.
    gimbals: Vec<(f64, [f64; 3])>,
    /// Whether the gimbal reports its yaw in the earth frame (its newest sample's flag:
    /// a gimbal keeps one frame).
    gimbal_earth_frame: bool,
}

fn enu(origin: &Origin, lat_deg: f64, lon_deg: f64, hae_m: f64) -> [f64; 3] {
    let (x, y, z) = map_3d::geodetic2enu(
        lat_deg.to_radians(),
        lon_deg.to_radians(),
        hae_m,
        origin.lat_deg.to_radians(),
        origin.lon_deg.to_radians(),
        origin.alt_m,
        map_3d::Ellipsoid::WGS84,
    );
    [x, y, z]
}

/// `a + (b − a)·f` for angles, the short way round.
fn lerp_angle(a: f64, b: f64, f: f64) -> f64 {
    let d = (b - a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    a + d * f
}

/// The value at `t` of a time-sorted series, by the rule in the module's comment.
fn at(
    series: &[(f64, [f64; 3])],
    t: f64,
    max_gap: f64,
    mix: impl Fn(&[f64; 3], &[f64; 3], f64) -> [f64; 3],
) -> Option<[f64; 3]> {
    let i = series.partition_point(|(ts, _)| *ts < t);
    let before = i.checked_sub(1).map(|j| &series[j]);
    let after = series.get(i);
    for s in [before, after].into_iter().flatten() {
        if (s.0 - t).abs() <= SAME_INSTANT_S {
            return Some(s.1);
        }
    }
    let ((ta, a), (tb, b)) = (before?, after?);
    if t - ta > max_gap || tb - t > max_gap || tb <= ta {
        return None;
    }
    Some(mix(a, b, (t - ta) / (tb - ta)))
}

impl NavTrack {
    /// The track of `samples` (any order); non-finite samples are left out and counted.
    /// `geoid_height_m` turns the messages' AMSL altitude into the ellipsoidal height
    /// the origin uses.
    pub fn new(samples: &[NavSample], origin: &Origin, geoid_height_m: f64) -> (Self, u64) {
        let mut track = Self::default();
        let bad = samples
            .iter()
            .filter(|s| !track.push(s, origin, geoid_height_m))
            .count() as u64;
        track.positions.sort_by(|a, b| a.0.total_cmp(&b.0));
        track.attitudes.sort_by(|a, b| a.0.total_cmp(&b.0));
        track.gimbals.sort_by(|a, b| a.0.total_cmp(&b.0));
        (track, bad)
    }

    /// Appends one sample (unsorted); `false` when it is not usable (left out).
    fn push(&mut self, s: &NavSample, origin: &Origin, geoid_height_m: f64) -> bool {
        match *s {
            NavSample::Position {
                t_s,
                lat_deg,
                lon_deg,
                alt_m,
                ..
            } => {
                let p = enu(origin, lat_deg, lon_deg, alt_m + geoid_height_m);
                // 0/0 is what an autopilot sends before it has a fix.
                let plausible = lat_deg.abs() <= 90.0
                    && lon_deg.abs() <= 180.0
                    && (lat_deg, lon_deg) != (0.0, 0.0);
                let ok = plausible && t_s.is_finite() && p.iter().all(|v| v.is_finite());
                if ok {
                    self.positions.push((t_s, p));
                }
                ok
            }
            NavSample::Attitude { t_s, rpy_rad } => {
                let ok = t_s.is_finite() && rpy_rad.iter().all(|v| v.is_finite());
                if ok {
                    self.attitudes.push((t_s, rpy_rad));
                }
                ok
            }
            NavSample::Gimbal {
                t_s,
                rpy_rad,
                earth_frame,
            } => {
                let ok = t_s.is_finite() && rpy_rad.iter().all(|v| v.is_finite());
                if ok {
                    self.gimbals.push((t_s, rpy_rad));
                    self.gimbal_earth_frame = earth_frame;
                }
                ok
            }
        }
    }

    /// Adds a sample as it arrives live, kept in time order (a late datagram is put in
    /// its place); `false` when it is not usable.
    pub fn insert(&mut self, s: &NavSample, origin: &Origin, geoid_height_m: f64) -> bool {
        if !self.push(s, origin, geoid_height_m) {
            return false;
        }
        for series in [&mut self.positions, &mut self.attitudes, &mut self.gimbals] {
            let n = series.len();
            if n >= 2 && series[n - 2].0 > series[n - 1].0 {
                let last = series.remove(n - 1);
                let i = series.partition_point(|(t, _)| *t <= last.0);
                series.insert(i, last);
            }
        }
        true
    }

    /// Forgets samples older than `t`, keeping the last one before it (what an
    /// interpolation at `t` needs): a live track's memory stays flat.
    pub fn forget_before(&mut self, t: f64) {
        for series in [&mut self.positions, &mut self.attitudes, &mut self.gimbals] {
            let i = series.partition_point(|(ts, _)| *ts < t);
            if i > 1 {
                series.drain(..i - 1);
            }
        }
    }

    /// The newest time both series reach (a live pose at `t` waits until this ≥ `t`).
    pub fn newest(&self) -> Option<f64> {
        Some(self.positions.last()?.0.min(self.attitudes.last()?.0))
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty() || self.attitudes.is_empty()
    }

    /// First and last time both series cover.
    pub fn span(&self) -> Option<(f64, f64)> {
        let start = self.positions.first()?.0.max(self.attitudes.first()?.0);
        let end = self.positions.last()?.0.min(self.attitudes.last()?.0);
        (start <= end).then_some((start, end))
    }

    /// The pose at `t` (autopilot clock), or why there is none.
    pub fn pose_at(&self, t: f64, max_gap: f64) -> Result<PoseSample, NoPose> {
        let p = at(&self.positions, t, max_gap, |a, b, f| {
            [0, 1, 2].map(|i| a[i] + (b[i] - a[i]) * f)
        })
        .ok_or(NoPose::Position)?;
        let angles =
            |a: &[f64; 3], b: &[f64; 3], f: f64| [0, 1, 2].map(|i| lerp_angle(a[i], b[i], f));
        let r = at(&self.attitudes, t, max_gap, angles).ok_or(NoPose::Attitude)?;
        let body = PoseSample {
            x_m: p[0],
            y_m: p[1],
            z_m: p[2],
            roll_deg: r[0].to_degrees(),
            pitch_deg: r[1].to_degrees(),
            // ATTITUDE's yaw is in (−π, π]; the project's in degrees, any turn.
            yaw_deg: r[2].to_degrees(),
            mount: MountSample::default(),
        };
        if self.gimbals.is_empty() {
            return Ok(body);
        }
        let [roll, pitch, yaw] = at(&self.gimbals, t, max_gap, angles).ok_or(NoPose::Gimbal)?;
        let g = Attitude { yaw, pitch, roll };
        let mount = if self.gimbal_earth_frame {
            // C_b^G = C_n^b(body)ᵀ · C_n^G.
            let b = Attitude {
                yaw: r[2],
                pitch: r[1],
                roll: r[0],
            };
            let relative = body_to_ned(b).transpose() * body_to_ned(g);
            let (roll, pitch, yaw) =
                nalgebra::Rotation3::from_matrix_unchecked(relative).euler_angles();
            Mount(Attitude { yaw, pitch, roll })
        } else {
            Mount(g)
        };
        Ok(body.on_mount(mount))
    }

    /// Whether the log carries a gimbal's attitude (the camera is gimballed).
    pub fn has_gimbal(&self) -> bool {
        !self.gimbals.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const ORIGIN: Origin = Origin {
        lat_deg: 47.0,
        lon_deg: 8.0,
        alt_m: 400.0,
    };

    fn position(t_s: f64, north_m: f64) -> NavSample {
        NavSample::Position {
            t_s,
            lat_deg: 47.0 + north_m / 111_195.0,
            lon_deg: 8.0,
            alt_m: 500.0,
            from_gps_raw: false,
        }
    }

    fn attitude(t_s: f64, yaw: f64) -> NavSample {
        NavSample::Attitude {
            t_s,
            rpy_rad: [0.0, 0.0, yaw],
        }
    }

    #[test]
    fn interpolates_between_samples_and_converts_to_enu() {
        let (track, bad) = NavTrack::new(
            &[
                position(0.0, 0.0),
                position(0.1, 10.0),
                attitude(0.0, 0.0),
                attitude(0.1, 0.2),
            ],
            &ORIGIN,
            0.0,
        );
        assert_eq!(bad, 0);
        let p = track.pose_at(0.05, 0.1).unwrap();
        assert!((p.y_m - 5.0).abs() < 0.05 && p.x_m.abs() < 1e-6, "{p:?}");
        assert!((p.z_m - 100.0).abs() < 0.01, "{p:?}");
        assert!((p.yaw_deg - 0.1f64.to_degrees()).abs() < 1e-9);
    }

    #[test]
    fn yaw_interpolates_the_short_way_round() {
        let pi = std::f64::consts::PI;
        let (track, _) = NavTrack::new(
            &[
                position(0.0, 0.0),
                position(1.0, 0.0),
                attitude(0.0, pi - 0.1),
                attitude(1.0, -pi + 0.1),
            ],
            &ORIGIN,
            0.0,
        );
        let yaw = track.pose_at(0.5, 1.0).unwrap().yaw_deg.to_radians();
        assert!((yaw.abs() - pi).abs() < 1e-9, "{yaw}");
    }

    /// A gimballed camera's log: the pose is the camera's on the gimbal of that moment;
    /// a gimbal reporting its yaw in the earth frame gives the same camera once its yaw
    /// is the body's plus the vehicle-frame yaw; a frame without a gimbal sample near
    /// has no pose.
    #[test]
    fn a_gimbal_log_gives_the_cameras_pose() {
        let gimbal = |t_s: f64, yaw: f64, earth_frame: bool| NavSample::Gimbal {
            t_s,
            rpy_rad: [0.0, -0.8, yaw],
            earth_frame,
        };
        let body_yaw = 0.3;
        let samples = |earth: bool| {
            let offset = if earth { body_yaw } else { 0.0 };
            vec![
                position(0.0, 0.0),
                position(1.0, 0.0),
                attitude(0.0, body_yaw),
                attitude(1.0, body_yaw),
                gimbal(0.0, 0.1 + offset, earth),
                gimbal(1.0, 0.3 + offset, earth),
            ]
        };
        let (vehicle, _) = NavTrack::new(&samples(false), &ORIGIN, 0.0);
        assert!(vehicle.has_gimbal());
        let pose = vehicle.pose_at(0.5, 1.0).unwrap();
        let body = PoseSample {
            yaw_deg: body_yaw.to_degrees(),
            ..pose
        };
        let body = PoseSample {
            roll_deg: 0.0,
            pitch_deg: 0.0,
            ..body
        };
        let want = body.on_mount(Mount(Attitude {
            yaw: 0.2,
            pitch: -0.8,
            roll: 0.0,
        }));
        for (got, want) in [
            (pose.yaw_deg, want.yaw_deg),
            (pose.pitch_deg, want.pitch_deg),
            (pose.roll_deg, want.roll_deg),
        ] {
            assert!((got - want).abs() < 1e-9, "{pose:?} vs {want:?}");
        }
        let (earth, _) = NavTrack::new(&samples(true), &ORIGIN, 0.0);
        let same = earth.pose_at(0.5, 1.0).unwrap();
        for (a, b) in [
            (same.yaw_deg, pose.yaw_deg),
            (same.pitch_deg, pose.pitch_deg),
            (same.roll_deg, pose.roll_deg),
        ] {
            assert!((a - b).abs() < 1e-9, "{same:?} vs {pose:?}");
        }
        // Gimbal samples stop at 1 s; the body's go on.
        let (mut gap, _) = NavTrack::new(&samples(false), &ORIGIN, 0.0);
        gap.insert(&position(2.0, 0.0), &ORIGIN, 0.0);
        gap.insert(&attitude(2.0, body_yaw), &ORIGIN, 0.0);
        assert_eq!(gap.pose_at(1.5, 0.6), Err(NoPose::Gimbal));
    }

    #[test]
    fn never_across_a_gap_nor_beyond_the_ends() {
        let (track, _) = NavTrack::new(
            &[
                position(0.0, 0.0),
                position(1.0, 0.0),
                attitude(0.0, 0.0),
                attitude(1.0, 0.0),
            ],
            &ORIGIN,
            0.0,
        );
        assert_eq!(track.pose_at(0.5, 0.033), Err(NoPose::Position));
        assert!(track.pose_at(1.0005, 0.033).is_ok(), "the same instant");
        assert_eq!(track.pose_at(1.01, 0.033), Err(NoPose::Position));
        assert_eq!(track.pose_at(-0.01, 0.033), Err(NoPose::Position));
    }

    #[test]
    fn non_finite_samples_are_left_out() {
        let (track, bad) = NavTrack::new(
            &[position(f64::NAN, 0.0), attitude(0.0, f64::INFINITY)],
            &ORIGIN,
            0.0,
        );
        assert_eq!(bad, 2);
        assert!(track.is_empty());
    }

    #[test]
    fn a_live_track_keeps_time_order_and_forgets_the_past() {
        let mut track = NavTrack::default();
        for s in [attitude(0.0, 0.0), attitude(0.2, 0.2), attitude(0.1, 0.1)] {
            assert!(track.insert(&s, &ORIGIN, 0.0));
        }
        for t in [0.0, 0.1, 0.2] {
            assert!(track.insert(&position(t, 10.0 * t), &ORIGIN, 0.0));
        }
        assert!(!track.insert(&attitude(f64::NAN, 0.0), &ORIGIN, 0.0));
        assert_eq!(track.newest(), Some(0.2));
        let yaw = track.pose_at(0.15, 0.1).unwrap().yaw_deg.to_radians();
        assert!(
            (yaw - 0.15).abs() < 1e-9,
            "{yaw}: the late sample is in its place"
        );
        track.forget_before(0.15);
        assert!(
            track.pose_at(0.15, 0.1).is_ok(),
            "the sample before is kept"
        );
        assert_eq!(track.pose_at(0.05, 0.1), Err(NoPose::Position));
    }

    proptest! {
        /// Between two samples no interpolated value leaves their range.
        #[test]
        fn interpolation_stays_between_its_samples(
            y0 in -100.0f64..100.0, y1 in -100.0f64..100.0, f in 0.0f64..1.0,
        ) {
            let (track, _) = NavTrack::new(
                &[position(0.0, y0), position(0.03, y1), attitude(0.0, 0.0), attitude(0.03, 0.0)],
                &ORIGIN,
                0.0,
            );
            let p = track.pose_at(0.03 * f, 0.034).unwrap();
            // The samples' own ENU values (the same-instant rule returns them as they are).
            let (a, b) = (track.pose_at(0.0, 0.034).unwrap().y_m, track.pose_at(0.03, 0.034).unwrap().y_m);
            let (lo, hi) = (a.min(b) - 1e-9, a.max(b) + 1e-9);
            prop_assert!(p.y_m >= lo && p.y_m <= hi, "{} not in [{lo}, {hi}]", p.y_m);
        }
    }
}
