//! Rendering a scenario into a recording (format v1) with truth.

use super::simulator::Simulator;
use super::SimError;
use crate::recording::{CameraMeta, RecordingMeta, RecordingWriter, TruthSample};
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

/// Renders every step of `sim` into a new recording at `out`; `progress(done, total)`
/// is called after each stereo pair.
pub fn record(
    sim: &mut Simulator,
    name: &str,
    out: &Path,
    mut progress: impl FnMut(u64, u64),
) -> Result<RecordSummary, SimError> {
    let config = sim.config().clone();
    let k = sim.intrinsics();
    let camera = CameraMeta {
        width: config.camera.width,
        height: config.camera.height,
        fx: k.fx,
        fy: k.fy,
        cx: k.cx,
        cy: k.cy,
        distortion: config.camera.distortion,
    };
    let meta = RecordingMeta::new(name, config.frame_rate_hz, camera, config.origin);
    let mut writer = RecordingWriter::create(out, &meta, true)?;
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
    let mut spent = [Duration::ZERO; 3]; // render, encode, write
    while let Some(step) = sim.step() {
        let t0 = Instant::now();
        {
            let l = left.data_bytes_mut().map_err(cv_err)?;
            let r = right.data_bytes_mut().map_err(cv_err)?;
            sim.render_pair(&step, l, r, stride);
        }
        let t1 = Instant::now();
        // PNG encoding costs more than rendering; encode both views at once.
        let (png_left, png_right) = std::thread::scope(|s| {
            let l = s.spawn(|| writer.encode(Uav::Left, &left));
            let r = writer.encode(Uav::Right, &right);
            (l.join().expect("encoder thread panicked"), r)
        });
        let t2 = Instant::now();
        for (frame, png) in step.frames.iter().zip([png_left?, png_right?]) {
            let truth = TruthSample {
                pose: frame.true_pose,
                target: frame.target,
                target_px: frame.target_px,
            };
            writer.write_encoded_frame(frame.uav, frame.t_s, frame.measured, &png, Some(&truth))?;
            summary.target_outside += u64::from(frame.target_px.is_none());
        }
        spent[0] += t1 - t0;
        spent[1] += t2 - t1;
        spent[2] += t2.elapsed();
        summary.frames_per_uav += 1;
        progress(summary.frames_per_uav, total);
    }
    writer.finish()?;
    let per_pair = |d: Duration| d.as_secs_f64() * 1e3 / summary.frames_per_uav.max(1) as f64;
    tracing::info!(
        render_ms = per_pair(spent[0]),
        encode_ms = per_pair(spent[1]),
        write_ms = per_pair(spent[2]),
        "mean time per stereo pair"
    );
    Ok(summary)
}
