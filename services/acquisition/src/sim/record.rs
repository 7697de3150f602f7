//! Rendering a scenario into a recording (format v1; v2 with a tilted or gimballed
//! camera) or a flight (videos + tlogs; a tilted or gimballed camera's angles as
//! GIMBAL_DEVICE_ATTITUDE_STATUS), with truth.

use super::simulator::{SimStep, Simulator, VehicleTruth};
use super::SimError;
use crate::flight::video::VideoCodec;
use crate::flight::writer::FlightWriter;
use crate::recording::{
    CameraMeta, ImageEncoding, MountAngles, RecordingMeta, RecordingWriter, TargetTruthRow,
    TargetsTruthWriter, TruthRow, TruthSample,
};
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::conventions::Uav;
use std::path::Path;
use std::time::{Duration, Instant};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordSummary {
    pub frames_per_uav: u64,
    /// Frames in which the target's true pixel lies outside the image.
    pub target_outside: u64,
}

/// Where rendered pairs go: a format-v1 recording or a flight (video + tlog).
trait PairSink {
    fn write_pair(
        &mut self,
        step: &SimStep,
        left: &cv::Mat,
        right: &cv::Mat,
    ) -> Result<(), SimError>;

    /// Every moving vehicle as each UAV's image of `step` shows it, for a sink that
    /// keeps them (a recording of a scene with moving traffic: truth_targets.csv).
    fn write_vehicles(
        &mut self,
        _step: &SimStep,
        _vehicles: [Vec<VehicleTruth>; 2],
    ) -> Result<(), SimError> {
        Ok(())
    }

    /// Whether [`PairSink::write_vehicles`] keeps anything (else it is not computed).
    fn wants_vehicles(&self) -> bool {
        false
    }
}

/// A recording being written, with its truth_targets.csv when the scene has moving
/// traffic.
struct RecordingSink {
    writer: RecordingWriter,
    vehicles: Option<TargetsTruthWriter>,
}

impl PairSink for RecordingSink {
    fn wants_vehicles(&self) -> bool {
        self.vehicles.is_some()
    }

    fn write_vehicles(
        &mut self,
        step: &SimStep,
        vehicles: [Vec<VehicleTruth>; 2],
    ) -> Result<(), SimError> {
        let Some(w) = self.vehicles.as_mut() else {
            return Ok(());
        };
        for (frame, seen) in step.frames.iter().zip(vehicles) {
            for v in seen {
                w.write(&TargetTruthRow {
                    uav: frame.uav,
                    frame: frame.seq,
                    t_s: frame.t_s,
                    target_id: v.id,
                    target: v.point,
                    target_px: v.px,
                })?;
            }
        }
        Ok(())
    }

    fn write_pair(
        &mut self,
        step: &SimStep,
        left: &cv::Mat,
        right: &cv::Mat,
    ) -> Result<(), SimError> {
        // PNG encoding costs more than rendering; encode both views at once.
        let writer = &self.writer;
        let (png_left, png_right) = std::thread::scope(|s| {
            let l = s.spawn(|| writer.encode(Uav::Left, left));
            let r = writer.encode(Uav::Right, right);
            (l.join().expect("encoder thread panicked"), r)
        });
        for (frame, png) in step.frames.iter().zip([png_left?, png_right?]) {
            // The body's poses: the recording states the mount in recording.toml.
            let truth = TruthSample {
                pose: frame.body_true,
                target: frame.target,
                target_px: frame.target_px,
                gimbal: frame.gimbal.map(|g| g.true_deg),
            };
            match frame.gimbal {
                Some(g) => self.writer.write_gimbal_frame(
                    frame.uav,
                    frame.t_s,
                    frame.body_measured,
                    g.measured_deg,
                    &png,
                    Some(&truth),
                )?,
                None => self.writer.write_encoded_frame(
                    frame.uav,
                    frame.t_s,
                    frame.body_measured,
                    &png,
                    Some(&truth),
                )?,
            };
        }
        Ok(())
    }
}

/// A flight being written, with the fixed mount's angles (yaw, pitch, roll, degrees)
/// of a tilted camera.
struct FlightSink {
    writer: FlightWriter,
    mount_angles: Option<[f64; 3]>,
}

impl PairSink for FlightSink {
    fn write_pair(
        &mut self,
        step: &SimStep,
        left: &cv::Mat,
        right: &cv::Mat,
    ) -> Result<(), SimError> {
        for (frame, image) in step.frames.iter().zip([left, right]) {
            let truth = TruthRow {
                uav: frame.uav,
                frame: frame.seq,
                t_s: frame.t_s,
                pose: frame.true_pose,
                target: frame.target,
                target_px: frame.target_px,
                gimbal: None,
            };
            // A tilted camera's fixed angles, or the gimbal's of this frame.
            let angles = frame.gimbal.map(|g| g.measured_deg).or(self.mount_angles);
            let gimbal = angles.map(|a| (frame.body_measured, a));
            self.writer
                .write_frame(frame.uav, frame.t_s, image, frame.measured, gimbal, &truth)
                .map_err(SimError::Config)?;
        }
        Ok(())
    }
}

fn camera_of(sim: &Simulator) -> CameraMeta {
    let config = sim.config();
    let k = sim.intrinsics();
    CameraMeta {
        width: config.camera.width,
        height: config.camera.height,
        fx: k.fx,
        fy: k.fy,
        cx: k.cx,
        cy: k.cy,
        distortion: config.camera.distortion,
    }
}

/// Renders every step of `sim` into a new recording at `out`, its images encoded as
/// `encoding`; `progress(done, total)`
/// is called after each stereo pair.
pub fn record(
    sim: &mut Simulator,
    name: &str,
    out: &Path,
    encoding: ImageEncoding,
    progress: impl FnMut(u64, u64),
) -> Result<RecordSummary, SimError> {
    let config = sim.config().clone();
    let mut meta = RecordingMeta::new(name, config.frame_rate_hz, camera_of(sim), config.origin);
    if config.camera.gimbal.is_some() {
        for uav in [Uav::Left, Uav::Right] {
            meta.set_gimbal_mount(uav);
        }
    } else if let Some([yaw_deg, pitch_deg, roll_deg]) = config.camera.mount_angles_deg {
        for uav in [Uav::Left, Uav::Right] {
            let angles = MountAngles {
                yaw_deg,
                pitch_deg,
                roll_deg,
            };
            meta.set_fixed_mount(uav, angles);
        }
    }
    let writer = RecordingWriter::create(out, &meta, true)?.with_encoding(encoding);
    let moving_traffic = config.traffic.iter().any(|car| car.speed_factor > 0.0);
    let vehicles = moving_traffic
        .then(|| TargetsTruthWriter::create(out))
        .transpose()?;
    let mut sink = RecordingSink { writer, vehicles };
    let summary = render_into(sim, &mut sink, progress)?;
    sink.writer.finish()?;
    if let Some(w) = sink.vehicles {
        w.finish()?;
    }
    Ok(summary)
}

/// Renders every step of `sim` into a flight at `out` (two videos, two tlogs,
/// flight.toml, truth): what a real flight's ground station records. Returns the
/// summary and the video codec used.
pub fn record_flight(
    sim: &mut Simulator,
    name: &str,
    out: &Path,
    codec: VideoCodec,
    progress: impl FnMut(u64, u64),
) -> Result<(RecordSummary, &'static str), SimError> {
    let config = sim.config().clone();
    let origin = config.origin.ok_or_else(|| {
        SimError::Config(
            "a flight needs the scenario's geodetic origin (the preset has none)".into(),
        )
    })?;
    let writer = FlightWriter::create(
        out,
        name,
        config.frame_rate_hz,
        camera_of(sim),
        origin,
        codec,
    )
    .map_err(SimError::Config)?;
    // A tilted or gimballed camera's angles go to the logs as the gimbal's attitude.
    let mut sink = FlightSink {
        writer,
        mount_angles: config.camera.mount_angles_deg,
    };
    let summary = render_into(sim, &mut sink, progress)?;
    let codec = sink.writer.codec();
    sink.writer.finish().map_err(SimError::Config)?;
    Ok((summary, codec))
}

fn render_into(
    sim: &mut Simulator,
    sink: &mut impl PairSink,
    mut progress: impl FnMut(u64, u64),
) -> Result<RecordSummary, SimError> {
    let config = sim.config().clone();
    let (w, h) = (config.camera.width as i32, config.camera.height as i32);
    let blank = || cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0));
    let cv_err = |e: opencv::Error| SimError::OpenCv(e.message);
    let (mut left, mut right) = (blank().map_err(cv_err)?, blank().map_err(cv_err)?);
    let stride = 3 * w as usize;
    let total = sim.frame_count();
    let mut summary = RecordSummary {
        frames_per_uav: 0,
        target_outside: 0,
    };
    let mut spent = [Duration::ZERO; 2]; // render, encode + write
    while let Some(step) = sim.step() {
        let t0 = Instant::now();
        {
            let l = left.data_bytes_mut().map_err(cv_err)?;
            let r = right.data_bytes_mut().map_err(cv_err)?;
            sim.render_pair(&step, l, r, stride);
        }
        let t1 = Instant::now();
        if sink.wants_vehicles() {
            let seen = [Uav::Left, Uav::Right].map(|uav| sim.moving_vehicles(&step, uav));
            sink.write_vehicles(&step, seen)?;
        }
        sink.write_pair(&step, &left, &right)?;
        summary.target_outside +=
            step.frames.iter().filter(|f| f.target_px.is_none()).count() as u64;
        spent[0] += t1 - t0;
        spent[1] += t1.elapsed();
        summary.frames_per_uav += 1;
        progress(summary.frames_per_uav, total);
    }
    let per_pair = |d: Duration| d.as_secs_f64() * 1e3 / summary.frames_per_uav.max(1) as f64;
    tracing::info!(
        render_ms = per_pair(spent[0]),
        write_ms = per_pair(spent[1]),
        "mean time per stereo pair"
    );
    Ok(summary)
}
