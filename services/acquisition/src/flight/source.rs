//! The flight source: per UAV a video and its MAVLink telemetry, named by flight.toml.
//!
//! Time alignment (docs/flight-io.md): both videos share time 0 (the flight's start);
//! left frame k and right frame k form a pair when their video times differ by less
//! than half a frame period (otherwise the earlier frame is dropped, `unpaired_frames`).
//! A frame's moment on its UAV's autopilot clock is `video time + time_offset_s`; its
//! pose is the telemetry interpolated there ([`NavTrack::pose_at`]) between samples at
//! most `max_telemetry_gap_s` apart, never extrapolated: a frame without a pose loses
//! its pair (`no_pose_position`, `no_pose_attitude`, `no_pose_gimbal`). The pair's stream time is the left
//! frame's video time.

use super::meta::{is_url, FlightMeta};
use super::nav_track::NavTrack;
use super::tlog::{parse_tlog, TlogCounts};
use super::video::VideoReader;
use crate::source::{FrameSource, PairInfo, SourceError};
use shared_types::conventions::{Intrinsics, Uav};
use std::path::{Path, PathBuf};

pub struct FlightSource {
    path: PathBuf,
    meta: FlightMeta,
    videos: [VideoReader; 2],
    tracks: [NavTrack; 2],
    counts: Vec<(&'static str, u64)>,
    /// Kinds of dropped pair already logged.
    warned: Vec<&'static str>,
}

fn open_videos(path: &Path, meta: &FlightMeta) -> Result<[VideoReader; 2], String> {
    let open = |uav: Uav| {
        let u = meta.uav(uav);
        let source = meta.resolve(path, &u.video);
        VideoReader::open(
            &source.to_string_lossy(),
            u.camera.width,
            u.camera.height,
            meta.frame_rate_hz,
        )
    };
    Ok([open(Uav::Left)?, open(Uav::Right)?])
}

impl FlightSource {
    /// Opens flight.toml, reads both telemetry logs whole and opens both videos.
    /// Refused before anything streams: a bad flight.toml, a missing file, a log with
    /// no usable samples, or a time offset that leaves no overlap between a video and
    /// its telemetry.
    pub fn open(path: &Path) -> Result<Self, String> {
        let meta = FlightMeta::read(path)?;
        let mut counts = Vec::new();
        let videos = open_videos(path, &meta)?;
        let mut tracks = [NavTrack::default(), NavTrack::default()];
        for uav in [Uav::Left, Uav::Right] {
            let u = meta.uav(uav);
            if is_url(&u.telemetry) {
                return Err(format!(
                    "[uav.{}] telemetry {:?} is live: a live flight is read by \
                     LiveFlightSource (acquisition::source::open chooses it)",
                    uav.name(),
                    u.telemetry
                ));
            }
            let log = meta.resolve(path, &u.telemetry);
            let bytes = std::fs::read(&log).map_err(|e| format!("{}: {e}", log.display()))?;
            let (all, c) = parse_tlog(&bytes);
            let mut systems: Vec<u8> = all.iter().map(|(s, _)| *s).collect();
            systems.sort_unstable();
            systems.dedup();
            let system = match (u.system_id, systems.as_slice()) {
                (Some(id), _) => id,
                (None, [one]) => *one,
                (None, []) => 0,
                (None, many) => {
                    return Err(format!(
                        "{}: navigation messages from systems {many:?}; set [uav.{}] \
                         system_id",
                        log.display(),
                        uav.name()
                    ))
                }
            };
            let samples: Vec<_> = all
                .into_iter()
                .filter(|(s, _)| *s == system)
                .map(|(_, sample)| sample)
                .collect();
            let TlogCounts {
                crc_errors,
                resyncs,
                truncated,
                ..
            } = c;
            if crc_errors + resyncs + truncated > 0 {
                tracing::warn!(
                    log = %log.display(), crc_errors, resyncs, truncated,
                    "telemetry log has damaged records (skipped)"
                );
            }
            counts.extend([
                ("tlog_crc_errors", crc_errors),
                ("tlog_resyncs", resyncs),
                ("tlog_truncated", truncated),
            ]);
            let (track, bad) = NavTrack::new(&samples, &meta.origin, meta.geoid_height_m);
            counts.push(("tlog_non_finite", bad));
            let Some((start, end)) = track.span() else {
                return Err(format!(
                    "{}: no ATTITUDE with GLOBAL_POSITION_INT (or GPS_RAW_INT) samples",
                    log.display()
                ));
            };
            tracks[uav.index()] = track;
            // A stream has no frame count: nothing to check before it plays.
            if let Some(frames) = videos[uav.index()].frame_count() {
                let video_end = u.time_offset_s + frames / meta.frame_rate_hz;
                if video_end < start || u.time_offset_s > end {
                    return Err(format!(
                        "[uav.{}] time_offset_s = {}: the video covers {:.3}–{:.3} s on the \
                         autopilot clock, the telemetry {start:.3}–{end:.3} s: no overlap",
                        uav.name(),
                        u.time_offset_s,
                        u.time_offset_s,
                        video_end
                    ));
                }
            }
        }
        Ok(Self {
            path: path.to_path_buf(),
            meta,
            videos,
            tracks,
            counts,
            warned: Vec::new(),
        })
    }

    fn count(&mut self, name: &'static str) {
        self.counts.push((name, 1));
    }

    /// The next left and right frames whose video times pair (the earlier frame of a
    /// mismatched pair is dropped); their video times.
    fn next_frames(
        &mut self,
        left: &mut [u8],
        right: &mut [u8],
    ) -> Option<Result<(f64, f64), String>> {
        let period = self.period_s();
        let [lv, rv] = &mut self.videos;
        let mut tl = match lv.next_into(left)? {
            Ok(t) => t,
            Err(e) => return Some(Err(e)),
        };
        let mut tr = match rv.next_into(right)? {
            Ok(t) => t,
            Err(e) => return Some(Err(e)),
        };
        while (tl - tr).abs() >= period / 2.0 {
            self.counts.push(("unpaired_frames", 1));
            let next = if tl < tr {
                lv.next_into(left)?
            } else {
                rv.next_into(right)?
            };
            match next {
                Ok(v) if tl < tr => tl = v,
                Ok(v) => tr = v,
                Err(e) => return Some(Err(e)),
            }
        }
        Some(Ok((tl, tr)))
    }
}

impl FrameSource for FlightSource {
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

    /// Left frames read: pairs, and the frames dropped unpaired or without a pose.
    fn consumed(&self) -> u64 {
        self.videos[0].decoded
    }

    /// The next left frame's video time as its index says (the container's timestamp
    /// is known only once decoded; they agree for a constant-rate video).
    fn next_time_s(&self) -> Option<f64> {
        Some(self.videos[0].decoded as f64 / self.meta.frame_rate_hz)
    }

    /// Skips `n` frames of each video (approximate when the previous run dropped
    /// unpaired frames: the videos are assumed to start together).
    fn skip(&mut self, n: u64) {
        for v in &mut self.videos {
            for _ in 0..n {
                if !v.skip() {
                    break;
                }
            }
        }
    }

    fn rewind(&mut self) -> Result<(), SourceError> {
        self.videos = open_videos(&self.path, &self.meta).map_err(SourceError::Flight)?;
        Ok(())
    }

    /// The next pair, with a pose for both frames; a pair without is counted (the
    /// first logged) and returned as [`SourceError::Dropped`], so the service's loop
    /// keeps checking for a stop while a long gap goes by.
    fn next_pair(
        &mut self,
        left: &mut [u8],
        right: &mut [u8],
        _stride: usize,
    ) -> Option<Result<PairInfo, SourceError>> {
        let (tl, tr) = match self.next_frames(left, right)? {
            Ok(t) => t,
            Err(e) => return Some(Err(SourceError::Flight(e))),
        };
        let mut poses = [Default::default(); 2];
        let mut missing = None;
        for (uav, t) in [(Uav::Left, tl), (Uav::Right, tr)] {
            let at = t + self.meta.uav(uav).time_offset_s;
            match self.tracks[uav.index()].pose_at(at, self.meta.max_telemetry_gap_s) {
                Ok(p) => poses[uav.index()] = p,
                Err(why) => missing = Some((uav, t, why)),
            }
        }
        let Some((uav, t, why)) = missing else {
            return Some(Ok(PairInfo {
                t_s: tl,
                poses,
                truth: None,
                captured_ns: None,
            }));
        };
        let name = why.counter();
        if !self.warned.contains(&name) {
            self.warned.push(name);
            tracing::warn!(
                uav = uav.name(),
                video_time_s = t,
                "a frame in a telemetry gap ({why:?}): its pair is dropped (counted as \
                 {name} from now on)"
            );
        }
        self.count(name);
        Some(Err(SourceError::Dropped))
    }

    fn take_counts(&mut self) -> Vec<(&'static str, u64)> {
        std::mem::take(&mut self.counts)
    }
}
