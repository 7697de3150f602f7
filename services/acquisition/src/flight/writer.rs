//! Writing a flight as a real one arrives (the simulator's `--flight-out`): per UAV a
//! video ([`VideoSink`]: H.264 in MP4 where OpenCV's FFmpeg has the encoder) and a
//! `.tlog` with one ATTITUDE and one GLOBAL_POSITION_INT per frame, carrying the
//! *measured* (noisy, yaw-biased) navigation state exactly as a format-v1 recording's
//! telemetry.csv does; plus `flight.toml`, and for evaluation only the format-v1
//! `truth.csv` and `telemetry.csv` of the same frames.
//!
//! Clocks: each autopilot booted [`BOOT_OFFSET_S`] before the flight's start, so
//! `time_boot_ms = (t + BOOT_OFFSET_S)·1000` and flight.toml's `time_offset_s` is
//! `BOOT_OFFSET_S`; a record's receive time is [`EPOCH_US`] + t.

use super::meta::{FlightMeta, FlightUav, FlightUavPair, FLIGHT_FORMAT, FLIGHT_VERSION};
use super::tlog::TlogWriter;
use super::video::{VideoCodec, VideoSink};
use crate::recording::rows::{telemetry_record, truth_record};
use crate::recording::{
    CameraMeta, Origin, TelemetryRow, TruthRow, TELEMETRY_HEADER, TRUTH_HEADER,
};
use mavlink::dialects::common::{MavMessage, ATTITUDE_DATA, GLOBAL_POSITION_INT_DATA};
use opencv::core as cv;
use shared_types::conventions::Uav;
use shared_types::messages::PoseSample;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

pub const BOOT_OFFSET_S: f64 = 100.0;
/// 2026-01-01T00:00:00Z: the receive clock of the written logs.
pub const EPOCH_US: u64 = 1_767_225_600_000_000;

pub struct FlightWriter {
    dir: PathBuf,
    meta: FlightMeta,
    videos: [VideoSink; 2],
    logs: [TlogWriter<BufWriter<File>>; 2],
    truth: csv::Writer<File>,
    telemetry: csv::Writer<File>,
    frames: [u64; 2],
}

fn io(path: &Path, e: impl std::fmt::Display) -> String {
    format!("{}: {e}", path.display())
}

/// Wraps degrees into (−180, 180] and returns radians (ATTITUDE's yaw range).
fn wrapped_rad(deg: f64) -> f32 {
    let w = (deg + 180.0).rem_euclid(360.0) - 180.0;
    (if w == -180.0 { 180.0 } else { w }).to_radians() as f32
}

impl FlightWriter {
    /// Creates `dir` (absent or empty) with both videos and logs opened.
    pub fn create(
        dir: &Path,
        name: &str,
        frame_rate_hz: f64,
        camera: CameraMeta,
        origin: Origin,
        codec: VideoCodec,
    ) -> Result<Self, String> {
        if dir.exists()
            && std::fs::read_dir(dir)
                .map_err(|e| io(dir, e))?
                .next()
                .is_some()
        {
            return Err(io(dir, "output folder exists and is not empty"));
        }
        std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
        let sink = |uav: Uav| {
            VideoSink::create(
                &dir.join(uav.name()),
                codec,
                camera.width,
                camera.height,
                frame_rate_hz,
            )
        };
        let videos = [sink(Uav::Left)?, sink(Uav::Right)?];
        let log = |uav: Uav| -> Result<TlogWriter<BufWriter<File>>, String> {
            let path = dir.join(format!("{}.tlog", uav.name()));
            let file = File::create(&path).map_err(|e| io(&path, e))?;
            // System ids 1 and 2: two vehicles.
            Ok(TlogWriter::new(BufWriter::new(file), uav.index() as u8 + 1))
        };
        let logs = [log(Uav::Left)?, log(Uav::Right)?];
        let csv_file = |name: &str, header: &[&str]| -> Result<csv::Writer<File>, String> {
            let path = dir.join(name);
            let mut w = csv::Writer::from_path(&path).map_err(|e| io(&path, e))?;
            w.write_record(header).map_err(|e| io(&path, e))?;
            Ok(w)
        };
        let uav = |u: Uav| FlightUav {
            video: videos[u.index()].file_name.clone(),
            telemetry: format!("{}.tlog", u.name()),
            time_offset_s: BOOT_OFFSET_S,
            video_latency_s: 0.0,
            system_id: Some(u.index() as u8 + 1),
            camera,
        };
        let meta = FlightMeta {
            format: FLIGHT_FORMAT.into(),
            version: FLIGHT_VERSION,
            name: name.into(),
            frame_rate_hz,
            truth: Some("truth.csv".into()),
            geoid_height_m: 0.0,
            max_telemetry_gap_s: 0.5,
            origin,
            uav: FlightUavPair {
                left: uav(Uav::Left),
                right: uav(Uav::Right),
            },
        };
        meta.validate()?;
        Ok(Self {
            dir: dir.to_path_buf(),
            meta,
            videos,
            logs,
            truth: csv_file("truth.csv", &TRUTH_HEADER)?,
            telemetry: csv_file("telemetry.csv", &TELEMETRY_HEADER)?,
            frames: [0; 2],
        })
    }

    /// The video codec used (`h264`, `mpeg4` or `ffv1`).
    pub fn codec(&self) -> &'static str {
        self.videos[0].codec
    }

    /// One frame of `uav` at stream time `t_s`: its image, its measured pose (to the
    /// log) and its truth (to truth.csv). `measured` is the camera's pose (its
    /// equivalent nadir one, as telemetry.csv and truth.csv carry it); a camera on a
    /// mount gives `gimbal`: the body's measured pose and the gimbal's measured angles
    /// (yaw, pitch, roll, degrees), which the log carries as ATTITUDE and
    /// GIMBAL_DEVICE_ATTITUDE_STATUS (yaw in the vehicle frame).
    pub fn write_frame(
        &mut self,
        uav: Uav,
        t_s: f64,
        image: &cv::Mat,
        measured: PoseSample,
        gimbal: Option<(PoseSample, [f64; 3])>,
        truth: &TruthRow,
    ) -> Result<(), String> {
        let i = uav.index();
        self.videos[i].write(image)?;
        let time_boot_ms = ((t_s + BOOT_OFFSET_S) * 1e3).round() as u32;
        let (lat, lon, hae) = map_3d::enu2geodetic(
            measured.x_m,
            measured.y_m,
            measured.z_m,
            self.meta.origin.lat_deg.to_radians(),
            self.meta.origin.lon_deg.to_radians(),
            self.meta.origin.alt_m,
            map_3d::Ellipsoid::WGS84,
        );
        let body = gimbal.map_or(measured, |(body, _)| body);
        let attitude = MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms,
            roll: body.roll_deg.to_radians() as f32,
            pitch: body.pitch_deg.to_radians() as f32,
            yaw: wrapped_rad(body.yaw_deg),
            ..Default::default()
        });
        let gimbal = gimbal.map(|(_, [yaw, pitch, roll])| {
            super::tlog::gimbal_message(
                time_boot_ms,
                [roll.to_radians(), pitch.to_radians(), yaw.to_radians()],
            )
        });
        let position = MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            time_boot_ms,
            lat: (lat.to_degrees() * 1e7).round() as i32,
            lon: (lon.to_degrees() * 1e7).round() as i32,
            // AMSL in mm; the written flight's geoid height is 0 (ellipsoidal).
            alt: (hae * 1e3).round() as i32,
            relative_alt: (measured.z_m * 1e3).round() as i32,
            hdg: u16::MAX,
            ..Default::default()
        });
        let receive_us = EPOCH_US + (t_s * 1e6).round() as u64;
        let log_path = self.dir.join(format!("{}.tlog", uav.name()));
        for msg in [Some(&attitude), Some(&position), gimbal.as_ref()]
            .into_iter()
            .flatten()
        {
            self.logs[i]
                .write(receive_us, msg)
                .map_err(|e| io(&log_path, e))?;
        }
        let frame = self.frames[i];
        self.frames[i] += 1;
        let row = TelemetryRow {
            uav,
            frame,
            file: format!("{}#{frame}", self.meta.uav(uav).video),
            t_s,
            pose: measured,
            gimbal: None,
        };
        let path = self.dir.join("telemetry.csv");
        self.telemetry
            .write_record(telemetry_record(&row, false))
            .map_err(|e| io(&path, e))?;
        let truth = TruthRow {
            frame,
            ..truth.clone()
        };
        let path = self.dir.join("truth.csv");
        self.truth
            .write_record(truth_record(&truth, false))
            .map_err(|e| io(&path, e))
    }

    /// Closes the videos and logs and writes flight.toml (last: a folder with a
    /// flight.toml is complete).
    pub fn finish(self) -> Result<PathBuf, String> {
        let Self {
            dir,
            meta,
            videos,
            logs,
            mut truth,
            mut telemetry,
            ..
        } = self;
        for v in videos {
            v.finish()?;
        }
        for l in logs {
            use std::io::Write;
            l.into_inner().flush().map_err(|e| io(&dir, e))?;
        }
        truth.flush().map_err(|e| io(&dir, e))?;
        telemetry.flush().map_err(|e| io(&dir, e))?;
        let path = dir.join("flight.toml");
        let text = toml::to_string(&meta).map_err(|e| io(&path, e))?;
        std::fs::write(&path, text).map_err(|e| io(&path, e))?;
        Ok(path)
    }
}
