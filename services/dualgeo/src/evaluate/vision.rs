//! The vision pass: the `table1` scenario (no navigation noise) rendered and run
//! through the whole chain (detector, ORB, E, epipolar transfer, filter, iteration)
//! once for 4 images (N = 2) and once for 8 (N = 4). It gives Table 1 and records every
//! matched observation set (image ids, true poses, pixels) for the noise passes.

use acquisition::sim::{Presets, Simulator};
use anyhow::Result;
use detection::{ColourBlobConfig, TrackedDetector};
use geolocation::EstimatorConfig;
use matching::{ChainOutcome, FrameInput, MatchingConfig, VisionChain};
use nalgebra::Point3;
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::conventions::{Intrinsics, Uav};
use shared_types::messages::PoseSample;
use std::collections::HashMap;

/// One image of a matched set: which frame, its true pose, the target's pixel.
#[derive(Debug, Clone, Copy)]
pub struct ImageRef {
    pub uav: Uav,
    pub seq: u64,
    pub t_s: f64,
    pub true_pose: PoseSample,
    pub pixel: [f64; 2],
    pub intrinsics: Intrinsics,
}

/// A matched observation set of the vision pass.
#[derive(Debug, Clone)]
pub struct Record {
    pub target: Point3<f64>,
    pub current: [ImageRef; 2],
    pub past: Vec<ImageRef>,
    /// True distance from the current left camera to the target (one-shot's range).
    pub range_left_m: f64,
}

/// Table 1 errors (estimate − truth, per axis) and the records, per N.
#[derive(Default)]
pub struct VisionPass {
    pub records: HashMap<usize, Vec<Record>>,
    /// N → [before filter, after filter] → per-axis errors.
    pub table1: HashMap<usize, [[Vec<f64>; 3]; 2]>,
    /// The path of Figure 8: (truth, after-filter estimate) for N = 4.
    pub path: Vec<([f64; 2], [f64; 2])>,
    pub geolocations: usize,
}

pub fn run(every: u64, progress: &indicatif::ProgressBar) -> Result<VisionPass> {
    let config = Presets::builtin().get("table1")?;
    let (w, h) = (config.camera.width as i32, config.camera.height as i32);
    let mut sim = Simulator::new(config)?;
    progress.set_length(sim.frame_count() / every);
    let mut detector = TrackedDetector::new(ColourBlobConfig::default())?;
    let ns = [2usize, 4];
    let mut chains = ns
        .iter()
        .map(|&n| {
            // The paper's protocol: a pair is matched once each UAV has its N − 1 past
            // images (the product starts with one, `min_past_images`).
            let m = MatchingConfig {
                images_per_uav: n,
                min_past_images: n - 1,
                ..MatchingConfig::default()
            };
            VisionChain::new(m, EstimatorConfig::default())
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut images = [
        cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0))?,
        cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0))?,
    ];
    let mut poses: HashMap<(usize, u64), (f64, PoseSample)> = HashMap::new();
    let mut pass = VisionPass::default();
    let mut k = 0;
    while let Some(step) = sim.step() {
        k += 1;
        if k % every != 0 {
            continue;
        }
        progress.inc(1);
        {
            let [l, r] = &mut images;
            sim.render_pair(
                &step,
                l.data_bytes_mut()?,
                r.data_bytes_mut()?,
                3 * w as usize,
            );
        }
        for f in &step.frames {
            poses.insert((f.uav.index(), f.seq), (f.t_s, f.true_pose));
        }
        let inputs: Vec<FrameInput> = step
            .frames
            .iter()
            .zip(&images)
            .map(|(f, image)| {
                Ok(FrameInput {
                    seq: f.seq,
                    t_s: f.t_s,
                    pose: f.measured,
                    image,
                    detection: detector
                        .detect(f.uav.index(), f.t_s, image)?
                        .map(|d| d.centre),
                    intrinsics: sim.intrinsics(),
                    distortion: sim.distortion(),
                    width: w as u32,
                    height: h as u32,
                })
            })
            .collect::<Result<_>>()?;
        let target = Point3::from(step.frames[0].target);
        for (chain, &n) in chains.iter_mut().zip(&ns) {
            let result = chain.process(&inputs[0], &inputs[1])?;
            let ChainOutcome::Located(located) = result.outcome else {
                continue;
            };
            let t1 = pass.table1.entry(n).or_default();
            if let Ok(e) = &located.unfiltered {
                (0..3).for_each(|i| t1[0][i].push(e.position[i] - target[i]));
            }
            if let Ok(f) = &located.filtered {
                let p = f.estimate.position;
                (0..3).for_each(|i| t1[1][i].push(p[i] - target[i]));
                if n == 4 {
                    pass.path.push(([target.x, target.y], [p.x, p.y]));
                    pass.geolocations += 1;
                }
            }
            let image = |uav: Uav, seq: u64, pixel: [f64; 2]| {
                let &(t_s, true_pose) = poses.get(&(uav.index(), seq))?;
                Some(ImageRef {
                    uav,
                    seq,
                    t_s,
                    true_pose,
                    pixel,
                    intrinsics: sim.intrinsics(),
                })
            };
            let (Some(cl), Some(cr)) = (
                inputs[0]
                    .detection
                    .and_then(|d| image(Uav::Left, inputs[0].seq, d)),
                inputs[1]
                    .detection
                    .and_then(|d| image(Uav::Right, inputs[1].seq, d)),
            ) else {
                continue;
            };
            let current = [cl, cr];
            let Some(past) = located
                .past
                .iter()
                .map(|m| image(m.uav, m.seq, m.pixel))
                .collect::<Option<Vec<_>>>()
            else {
                continue;
            };
            let left = step.frames[0].true_pose.position();
            pass.records.entry(n).or_default().push(Record {
                target,
                current,
                past,
                range_left_m: (target - left).norm(),
            });
        }
    }
    Ok(pass)
}
