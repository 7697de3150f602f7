//! A live flight: per UAV a video stream ([`LiveVideo`], decoded on its own thread) and
//! MAVLink telemetry over UDP ([`LiveTelemetry`]), as flight.toml names them
//! (`telemetry = "udpin:HOST:PORT"`, `video = "udp://..."` or `rtsp://...`).
//!
//! Time alignment, live (docs/flight-io.md): a frame is stamped when its decoded pixels
//! arrive (CLOCK_MONOTONIC), and carries its presentation time (PTS) in the stream.
//! `arrival − PTS` is least for the frames that came through fastest; that least value
//! over a window ([`ClockOffset`], as for telemetry) maps the PTS onto the host clock:
//! a frame's *moment* is `PTS + least`, when it would have arrived without queueing. A
//! frame that arrived more than one frame period after its moment (the backlog after
//! a stall) is dropped and counted (`late_frames`): its pose would be the wrong one.
//! Its capture on the UAV was `video_latency_s` before its moment, and on the
//! autopilot clock that is `moment − video_latency_s − offset`, where the clock offset
//! is measured from the telemetry itself (again [`ClockOffset`]). A stream without
//! usable PTS is stamped by arrival alone. Left and right frames
//! pair when they arrived within half a frame period (otherwise the earlier is dropped,
//! `unpaired_frames`). The pose is interpolated as for a recorded flight, never
//! extrapolated: a frame whose moment is newer than the newest telemetry waits for the
//! next sample (at most `max_telemetry_gap_s`), then is dropped (`no_pose_*`).
//!
//! A live stream has no end: the run ends by a signal or `--run-for-s`. A stalled stream
//! is reopened and counted; a silent telemetry link drops pairs and counts them; neither
//! ends the run. `--loop` and restart positions do not apply (a restarted acquisition
//! takes the stream where it is).

use super::clock_offset::ClockOffset;
use super::live_telemetry::LiveTelemetry;
use super::live_video::{Frame, LiveVideo};
use super::meta::FlightMeta;
use super::nav_track::{NavTrack, NoPose};
use crate::source::{FrameSource, PairInfo, SourceError};
use shared_types::clock::monotonic_ns;
use shared_types::conventions::{Intrinsics, Uav};
use shared_types::messages::PoseSample;
use std::time::Duration;

/// How long one call waits for frames before it lets the service look for a stop.
const WAIT: Duration = Duration::from_millis(100);
/// A stream with no frame for this long is stalled (reopened by its reader).
const READ_TIMEOUT: Duration = Duration::from_secs(2);
/// The clock offset is the least delay over this window.
const OFFSET_WINDOW_S: f64 = 10.0;
/// Telemetry kept behind the newest frame.
const KEEP_S: f64 = 5.0;

pub struct LiveFlightSource {
    meta: FlightMeta,
    videos: [LiveVideo; 2],
    telemetry: [LiveTelemetry; 2],
    tracks: [NavTrack; 2],
    offsets: [ClockOffset; 2],
    /// Per UAV: host − PTS of its video, and the stream opening it is for.
    video_offsets: [(ClockOffset, u32); 2],
    /// A frame waiting for its partner, with its moment.
    pending: [Option<(Frame, u64)>; 2],
    start_ns: Option<u64>,
    consumed: u64,
    counts: Vec<(&'static str, u64)>,
    warned: Vec<&'static str>,
}

fn seconds(ns: u64) -> f64 {
    ns as f64 / 1e9
}

impl LiveFlightSource {
    /// Binds both telemetry sockets and starts both video readers. Refused before
    /// anything streams: an address that cannot be bound.
    pub fn open(meta: FlightMeta) -> Result<Self, String> {
        let video = |uav: Uav| {
            let u = meta.uav(uav);
            LiveVideo::open(&u.video, u.camera.width, u.camera.height, READ_TIMEOUT)
        };
        let telemetry = |uav: Uav| LiveTelemetry::bind(&meta.uav(uav).telemetry);
        Ok(Self {
            videos: [video(Uav::Left)?, video(Uav::Right)?],
            telemetry: [telemetry(Uav::Left)?, telemetry(Uav::Right)?],
            tracks: Default::default(),
            offsets: [
                ClockOffset::new(OFFSET_WINDOW_S),
                ClockOffset::new(OFFSET_WINDOW_S),
            ],
            video_offsets: [
                (ClockOffset::new(OFFSET_WINDOW_S), 0),
                (ClockOffset::new(OFFSET_WINDOW_S), 0),
            ],
            pending: [None, None],
            start_ns: None,
            consumed: 0,
            counts: Vec::new(),
            warned: Vec::new(),
            meta,
        })
    }

    /// Takes the telemetry that arrived into each UAV's track and clock offset.
    fn take_telemetry(&mut self) {
        for uav in [Uav::Left, Uav::Right] {
            let i = uav.index();
            let want = self.meta.uav(uav).system_id;
            let (origin, geoid) = (self.meta.origin, self.meta.geoid_height_m);
            let (track, offset) = (&mut self.tracks[i], &mut self.offsets[i]);
            let mut bad = 0;
            self.telemetry[i].drain(|a| {
                if want.is_some_and(|w| w != a.system) {
                    return;
                }
                if track.insert(&a.sample, &origin, geoid) {
                    offset.observe(seconds(a.host_ns), a.sample.t_s());
                } else {
                    bad += 1;
                }
            });
            if bad > 0 {
                self.counts.push(("tlog_non_finite", bad));
            }
        }
    }

    /// A frame's moment on the host clock (ns) and whether it came late (queued more
    /// than a frame period behind its stream).
    fn moment(&mut self, i: usize, f: &Frame) -> (u64, bool) {
        let (offset, epoch) = &mut self.video_offsets[i];
        if *epoch != f.epoch {
            *offset = ClockOffset::new(OFFSET_WINDOW_S);
            *epoch = f.epoch;
        }
        if !f.pts_s.is_finite() {
            return (f.host_ns, false);
        }
        let host_s = seconds(f.host_ns);
        offset.observe(host_s, f.pts_s);
        let Some(least) = offset.offset() else {
            return (f.host_ns, false);
        };
        let moment_s = f.pts_s + least;
        let late = host_s - moment_s > 1.0 / self.meta.frame_rate_hz;
        ((moment_s * 1e9).max(0.0) as u64, late)
    }

    /// A left and a right frame that arrived within half a period of each other, or
    /// `None` after [`WAIT`].
    fn next_frames(&mut self) -> Option<[(Frame, u64); 2]> {
        let deadline = monotonic_ns() + WAIT.as_nanos() as u64;
        let half_period_ns = (0.5e9 / self.meta.frame_rate_hz) as u64;
        loop {
            for i in 0..2 {
                while self.pending[i].is_none() {
                    let left = deadline.saturating_sub(monotonic_ns());
                    let f = self.videos[i].next(Duration::from_nanos(left))?;
                    let (moment, late) = self.moment(i, &f);
                    if late {
                        self.consumed += 1;
                        self.counts.push(("late_frames", 1));
                        self.videos[i].give_back(f);
                    } else {
                        self.pending[i] = Some((f, moment));
                    }
                }
            }
            let [Some((_, tl)), Some((_, tr))] = &self.pending else {
                return None;
            };
            if tl.abs_diff(*tr) < half_period_ns {
                let [l, r] = std::mem::take(&mut self.pending);
                return l.zip(r).map(|(l, r)| [l, r]);
            }
            let older = usize::from(tr < tl);
            if let Some((f, _)) = self.pending[older].take() {
                self.videos[older].give_back(f);
            }
            self.consumed += 1;
            self.counts.push(("unpaired_frames", 1));
            if monotonic_ns() > deadline {
                return None;
            }
        }
    }

    /// The pose of a frame of moment `moment_ns`, waiting (bounded) for telemetry newer
    /// than it.
    fn pose(&mut self, uav: Uav, moment_ns: u64) -> Result<PoseSample, NoPose> {
        let i = uav.index();
        let max_gap = self.meta.max_telemetry_gap_s;
        let latency = self.meta.uav(uav).video_latency_s;
        loop {
            let Some(offset) = self.offsets[i].offset() else {
                return Err(NoPose::Position);
            };
            let t = seconds(moment_ns) - latency - offset;
            let result = self.tracks[i].pose_at(t, max_gap);
            let behind = self.tracks[i].newest().is_none_or(|n| n < t);
            let waited_s = seconds(monotonic_ns().saturating_sub(moment_ns));
            if result.is_ok() || !behind || waited_s > max_gap {
                self.tracks[i].forget_before(t - KEEP_S);
                return result;
            }
            std::thread::sleep(Duration::from_millis(1));
            self.take_telemetry();
        }
    }
}

impl FrameSource for LiveFlightSource {
    fn size(&self) -> (u32, u32) {
        let c = &self.meta.uav.left.camera;
        (c.width, c.height)
    }

    fn intrinsics(&self, uav: Uav) -> Intrinsics {
        self.meta.uav(uav).camera.intrinsics()
    }

    fn distortion(&self, uav: Uav) -> [f64; 5] {
        self.meta.uav(uav).camera.distortion
    }

    fn period_s(&self) -> f64 {
        1.0 / self.meta.frame_rate_hz
    }

    fn consumed(&self) -> u64 {
        self.consumed
    }

    /// A live stream resumes where it is: nothing to skip.
    fn skip(&mut self, _n: u64) {}

    fn rewind(&mut self) -> Result<(), SourceError> {
        Err(SourceError::Invalid(
            "a live flight cannot be streamed again (--loop)".into(),
        ))
    }

    fn next_pair(
        &mut self,
        left: &mut [u8],
        right: &mut [u8],
        _stride: usize,
    ) -> Option<Result<PairInfo, SourceError>> {
        self.take_telemetry();
        let Some([(l, ml), (r, mr)]) = self.next_frames() else {
            return Some(Err(SourceError::Waiting));
        };
        self.consumed += 1;
        let start = *self.start_ns.get_or_insert(ml);
        let mut poses = [PoseSample::default(); 2];
        let mut missing = None;
        for (uav, moment) in [(Uav::Left, ml), (Uav::Right, mr)] {
            match self.pose(uav, moment) {
                Ok(p) => poses[uav.index()] = p,
                Err(why) => missing = Some((uav, why)),
            }
        }
        let copied = left.len() == l.pixels.len() && right.len() == r.pixels.len();
        if copied {
            left.copy_from_slice(&l.pixels);
            right.copy_from_slice(&r.pixels);
        }
        let info = PairInfo {
            t_s: seconds(ml.saturating_sub(start)),
            poses,
            truth: None,
            captured_ns: Some(ml.max(mr)),
        };
        self.videos[0].give_back(l);
        self.videos[1].give_back(r);
        if !copied {
            return Some(Err(SourceError::Flight(
                "a decoded frame does not match the frame buffer".into(),
            )));
        }
        if let Some((uav, why)) = missing {
            let name = why.counter();
            if !self.warned.contains(&name) {
                self.warned.push(name);
                tracing::warn!(
                    uav = uav.name(),
                    "a live frame without telemetry around its moment ({why:?}): its pair \
                     is dropped (counted as {name} from now on)"
                );
            }
            self.counts.push((name, 1));
            return Some(Err(SourceError::Dropped));
        }
        Some(Ok(info))
    }

    fn take_counts(&mut self) -> Vec<(&'static str, u64)> {
        let mut out = std::mem::take(&mut self.counts);
        for v in &mut self.videos {
            out.extend(v.take_counts());
        }
        for t in &mut self.telemetry {
            out.extend(t.take_counts());
        }
        out
    }
}
