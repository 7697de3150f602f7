//! Motion of the vehicle and of the two UAVs.
//!
//! The vehicle drives a closed route along road centrelines with rounded 90° turns,
//! slowing for each turn (v = min(v_max, √(v_turn² + 2·a·d)) with d the distance to the
//! nearest turn). The UAVs follow a low-passed copy of the vehicle's position and heading
//! (time constant τ): both fly 100 m above the ground, half the separation either side
//! of the track, nose along it, and bank and pitch with their accelerations.

use nalgebra::{Point2, Vector2};
use serde::{Deserialize, Serialize};
use shared_types::conventions::{wrap_angle, Uav};

#[derive(Debug, Clone, Copy)]
enum Segment {
    Line {
        from: Point2<f64>,
        dir: Vector2<f64>,
    },
    Arc {
        centre: Point2<f64>,
        radius: f64,
        start: f64,
        sweep: f64,
    },
}

impl Segment {
    fn length(&self, full: f64) -> f64 {
        match *self {
            Segment::Line { .. } => full,
            Segment::Arc { radius, sweep, .. } => radius * sweep.abs(),
        }
    }

    /// Position and heading (from north, clockwise) at distance `s` into the segment.
    fn at(&self, s: f64) -> (Point2<f64>, f64) {
        match *self {
            Segment::Line { from, dir } => (from + dir * s, dir.x.atan2(dir.y)),
            Segment::Arc {
                centre,
                radius,
                start,
                sweep,
            } => {
                let a = start + sweep.signum() * s / radius;
                let p = centre + Vector2::new(a.cos(), a.sin()) * radius;
                // Tangent of a counter-clockwise (math) arc is (−sin, cos); clockwise flips it.
                let t = Vector2::new(-a.sin(), a.cos()) * sweep.signum();
                (p, t.x.atan2(t.y))
            }
        }
    }
}

/// A closed route with its speed profile.
#[derive(Debug, Clone)]
pub struct Route {
    segments: Vec<(Segment, f64, f64)>, // (segment, start s, length)
    total: f64,
    v_max: f64,
    v_turn: f64,
    accel: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DrivingSpec {
    /// Route corners (ENU metres) on road intersections, driven in order and closed.
    pub waypoints: [[f64; 2]; 6],
    pub turn_radius_m: f64,
    pub speed_max_mps: f64,
    pub speed_turn_mps: f64,
    pub accel_mps2: f64,
    /// Where along the route the vehicle starts, metres.
    pub start_m: f64,
}

impl Route {
    pub fn new(spec: &DrivingSpec) -> Result<Self, String> {
        let pts: Vec<Point2<f64>> = spec
            .waypoints
            .iter()
            .map(|p| Point2::new(p[0], p[1]))
            .collect();
        let n = pts.len();
        let r = spec.turn_radius_m;
        if !(spec.speed_turn_mps > 0.0
            && spec.speed_max_mps >= spec.speed_turn_mps
            && spec.accel_mps2 > 0.0
            && r > 0.0)
        {
            return Err("driving: need 0 < speed_turn_mps <= speed_max_mps, accel_mps2 > 0, turn_radius_m > 0".into());
        }
        let mut segments = Vec::new();
        let mut s = 0.0;
        let dir = |a: Point2<f64>, b: Point2<f64>| (b - a).normalize();
        for i in 0..n {
            let (prev, here, next) = (pts[(i + n - 1) % n], pts[i], pts[(i + 1) % n]);
            let (d_in, d_out) = (dir(prev, here), dir(here, next));
            let turn = d_in.x * d_out.y - d_in.y * d_out.x; // > 0: left turn
            if (d_in.dot(&d_out)).abs() > 1e-6 || turn.abs() < 0.5 {
                return Err(format!(
                    "driving: waypoint {i} must be a 90° corner of the road grid"
                ));
            }
            // Line from the previous corner's arc end to this corner's arc start.
            let line_from = prev + d_in * r;
            let line_len = (here - prev).norm() - 2.0 * r;
            if line_len < 0.0 {
                return Err(format!(
                    "driving: leg into waypoint {i} is shorter than two turn radii"
                ));
            }
            segments.push((
                Segment::Line {
                    from: line_from,
                    dir: d_in,
                },
                s,
                line_len,
            ));
            s += line_len;
            let side = if turn > 0.0 {
                Vector2::new(-d_in.y, d_in.x)
            } else {
                Vector2::new(d_in.y, -d_in.x)
            };
            let centre = here - d_in * r + side * r;
            let start_point = here - d_in * r;
            let start = (start_point.y - centre.y).atan2(start_point.x - centre.x);
            let arc = Segment::Arc {
                centre,
                radius: r,
                start,
                sweep: turn.signum() * std::f64::consts::FRAC_PI_2,
            };
            let len = arc.length(0.0);
            segments.push((arc, s, len));
            s += len;
        }
        Ok(Self {
            segments,
            total: s,
            v_max: spec.speed_max_mps,
            v_turn: spec.speed_turn_mps,
            accel: spec.accel_mps2,
        })
    }

    pub fn length(&self) -> f64 {
        self.total
    }

    fn find(&self, s: f64) -> usize {
        let s = s.rem_euclid(self.total);
        self.segments
            .iter()
            .rposition(|(_, start, _)| *start <= s)
            .unwrap_or(0)
    }

    /// Position and heading at arc length `s` (wraps around the loop).
    pub fn at(&self, s: f64) -> (Point2<f64>, f64) {
        let i = self.find(s);
        let (seg, start, _) = self.segments[i];
        seg.at(s.rem_euclid(self.total) - start)
    }

    /// Speed at arc length `s`.
    pub fn speed(&self, s: f64) -> f64 {
        let s = s.rem_euclid(self.total);
        let mut nearest = f64::INFINITY;
        for (seg, start, len) in &self.segments {
            if let Segment::Arc { .. } = seg {
                let d = if s >= *start && s <= start + len {
                    0.0
                } else {
                    let ahead = (start - s).rem_euclid(self.total);
                    let behind = (s - (start + len)).rem_euclid(self.total);
                    ahead.min(behind)
                };
                nearest = nearest.min(d);
            }
        }
        (self.v_turn * self.v_turn + 2.0 * self.accel * nearest)
            .sqrt()
            .min(self.v_max)
    }
}

/// Where the UAVs fly relative to the vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlightSpec {
    pub altitude_agl_m: f64,
    pub separation_m: f64,
    /// τ of the low-pass by which the UAVs follow the vehicle, seconds.
    pub follow_time_constant_s: f64,
    /// Amplitude of the attitude wobble on top of the manoeuvre, degrees.
    pub wobble_deg: f64,
}

/// True state of the vehicle and both UAVs at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrueState {
    pub t_s: f64,
    /// The vehicle's arc length along its route, metres.
    pub vehicle_s_m: f64,
    pub vehicle_xy: [f64; 2],
    pub vehicle_heading: f64,
    /// Per UAV (left, right): ENU position and (yaw, pitch, roll) in radians.
    pub uav_position: [[f64; 3]; 2],
    pub uav_attitude: [[f64; 3]; 2],
}

/// Steps vehicle and UAVs forward at a fixed frame period.
#[derive(Debug, Clone)]
pub struct Motion {
    route: Route,
    flight: FlightSpec,
    ground_z: f64,
    t: f64,
    s: f64,
    centre: Vector2<f64>,
    heading: f64,
    history: Vec<[Vector2<f64>; 2]>, // last two UAV horizontal positions, for accelerations
    dt: f64,
    /// Where each UAV flies relative to its nadir station, in the body's (forward,
    /// right) metres: behind and beside it by what a tilted camera looks ahead.
    camera_offset: Vector2<f64>,
}

const G: f64 = 9.81;

impl Motion {
    /// Starts at `start_m` along the route, with the UAVs settled on the vehicle; each
    /// [`Motion::next_state`] advances by the frame period `dt`.
    pub fn new(route: Route, flight: FlightSpec, ground_z: f64, start_m: f64, dt: f64) -> Self {
        let (p, h) = route.at(start_m);
        Self {
            route,
            flight,
            ground_z,
            t: 0.0,
            s: start_m,
            centre: p.coords,
            heading: h,
            history: Vec::new(),
            dt,
            camera_offset: Vector2::zeros(),
        }
    }

    /// Flies each UAV so that a camera whose optical axis is `boresight` in the body
    /// frame (FRD, pointing down) meets the ground where a nadir camera would: offset
    /// by −altitude × (forward, right) / down.
    pub fn with_camera_boresight(mut self, boresight: nalgebra::Vector3<f64>) -> Self {
        if boresight.z > 0.0 {
            let agl = self.flight.altitude_agl_m;
            self.camera_offset = -agl * Vector2::new(boresight.x, boresight.y) / boresight.z;
        }
        self
    }

    /// The route the vehicle (and any traffic) drives.
    pub fn route(&self) -> &Route {
        &self.route
    }

    /// The state now, then advances one frame period.
    pub fn next_state(&mut self) -> TrueState {
        let state = self.state();
        self.step();
        state
    }

    fn uav_xy(&self, uav: Uav) -> Vector2<f64> {
        let fwd = Vector2::new(self.heading.sin(), self.heading.cos());
        let right = Vector2::new(self.heading.cos(), -self.heading.sin());
        let side = if uav == Uav::Left { -0.5 } else { 0.5 };
        let off = self.camera_offset;
        self.centre + right * (side * self.flight.separation_m + off.y) + fwd * off.x
    }

    fn state(&self) -> TrueState {
        let (p, h) = self.route.at(self.s);
        let mut uav_position = [[0.0; 3]; 2];
        let mut uav_attitude = [[0.0; 3]; 2];
        for uav in [Uav::Left, Uav::Right] {
            let i = uav.index();
            let xy = self.uav_xy(uav);
            let phase = i as f64 * 1.7;
            let z =
                self.ground_z + self.flight.altitude_agl_m + 0.4 * (0.31 * self.t + phase).sin();
            // Acceleration from the last three positions (zero until there are three).
            let accel = match self.history.as_slice() {
                [.., a, b] => (xy - 2.0 * b[i] + a[i]) / (self.dt * self.dt),
                _ => Vector2::zeros(),
            };
            let fwd = Vector2::new(self.heading.sin(), self.heading.cos());
            let right = Vector2::new(self.heading.cos(), -self.heading.sin());
            let wobble = self.flight.wobble_deg.to_radians();
            let limit = 8f64.to_radians();
            let pitch = (-(accel.dot(&fwd) / G).atan()).clamp(-limit, limit)
                + wobble * (0.9 * self.t + phase).sin();
            let roll = (accel.dot(&right) / G).atan().clamp(-limit, limit)
                + wobble * (1.3 * self.t + 2.0 * phase).cos();
            uav_position[i] = [xy.x, xy.y, z];
            uav_attitude[i] = [wrap_angle(self.heading), pitch, roll];
        }
        TrueState {
            t_s: self.t,
            vehicle_s_m: self.s,
            vehicle_xy: [p.x, p.y],
            vehicle_heading: h,
            uav_position,
            uav_attitude,
        }
    }

    fn step(&mut self) {
        let dt = self.dt;
        // Vehicle: integrate ds/dt = v(s) with midpoint sub-steps.
        let sub = 10;
        let h = dt / sub as f64;
        for _ in 0..sub {
            let mid = self.s + 0.5 * h * self.route.speed(self.s);
            self.s += h * self.route.speed(mid);
        }
        let before = [self.uav_xy(Uav::Left), self.uav_xy(Uav::Right)];
        self.history.push(before);
        if self.history.len() > 2 {
            self.history.remove(0);
        }
        let (p, heading) = self.route.at(self.s);
        let alpha = 1.0 - (-dt / self.flight.follow_time_constant_s).exp();
        self.centre += (p.coords - self.centre) * alpha;
        self.heading += wrap_angle(heading - self.heading) * alpha;
        self.t += dt;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> DrivingSpec {
        DrivingSpec {
            waypoints: [
                [-90.0, -90.0],
                [90.0, -90.0],
                [90.0, 0.0],
                [0.0, 0.0],
                [0.0, 90.0],
                [-90.0, 90.0],
            ],
            turn_radius_m: 10.0,
            speed_max_mps: 11.0,
            speed_turn_mps: 6.0,
            accel_mps2: 1.5,
            start_m: 0.0,
        }
    }

    #[test]
    fn route_is_continuous_and_closed() {
        let r = Route::new(&spec()).unwrap();
        // 720 m of grid minus the corner cut: 6 corners × (2r − πr/2).
        let expected = 720.0 - 6.0 * (20.0 - 10.0 * std::f64::consts::FRAC_PI_2);
        assert!((r.length() - expected).abs() < 1e-9, "{}", r.length());
        let mut prev = r.at(0.0);
        let n = 5000;
        for k in 1..=n {
            let s = r.length() * k as f64 / n as f64;
            let p = r.at(s);
            let step = (p.0 - prev.0).norm();
            assert!(
                step < r.length() / n as f64 * 1.0001 + 1e-9,
                "jump at s={s}: {step}"
            );
            assert!(
                wrap_angle(p.1 - prev.1).abs() < 0.05,
                "heading jump at s={s}"
            );
            prev = p;
        }
    }

    #[test]
    fn speed_stays_between_turn_and_max() {
        let r = Route::new(&spec()).unwrap();
        for k in 0..1000 {
            let v = r.speed(r.length() * k as f64 / 1000.0);
            assert!((6.0..=11.0).contains(&v), "{v}");
        }
    }

    #[test]
    fn uavs_straddle_the_track_at_the_separation() {
        let flight = FlightSpec {
            altitude_agl_m: 100.0,
            separation_m: 70.0,
            follow_time_constant_s: 0.6,
            wobble_deg: 0.3,
        };
        let mut m = Motion::new(Route::new(&spec()).unwrap(), flight, 12.0, 30.0, 1.0 / 30.0);
        let s = m.next_state();
        let [l, r] = s.uav_position;
        let sep = ((l[0] - r[0]).powi(2) + (l[1] - r[1]).powi(2)).sqrt();
        assert!((sep - 70.0).abs() < 1e-9);
        assert!((l[2] - 112.0).abs() < 1.0);
        // Heading east on the first leg: the left UAV is north of the right one.
        assert!(l[1] > r[1]);
    }
}
