//! Benchmark: the detectors on rendered frames, against the simulator's truth pixel.
//! Per preset (nadir `default`, 30° `tilted`, the tracking `gimbal`): recall (frames
//! with the target in view where the detector's centre lies within `--hit-px` of the
//! target's pixel), precision (of its detections, the share that are such hits), the
//! median centre error of the hits, and the cost per frame (median, p90).
//!
//! - `colour`: the colour detector with each camera's track, as the detection service
//!   runs it on every frame.
//! - `yolo`: the learned model (default: the YOLOv2-tiny COCO model `scripts/setup.sh`
//!   installs) on every `--yolo-every`-th frame, alone (no tracker): what the model
//!   itself sees, with `classes` car, bus, truck; `yolo any` counts a box of any class.
//! - `motion`: the motion detector (`[detection] kind = "motion"`, defaults) on every
//!   frame, without the geolocation filter's gate: `motion (centre)` acquires the mover
//!   nearest the image centre, `motion (designated)` the one nearest `acquire_px` set to
//!   the target's pixel in the first frame (what an operator's click on the target
//!   gives; the detector reads nothing else of the truth). It looks from frame
//!   `2 × short_gap_frames` on (it needs that many frames behind it): its rows count
//!   from there.
//!
//! `wrong` is the share of frames where the detector named something other than the
//! target (a detection farther than `--hit-px` from the truth pixel, or any detection
//! while the target is out of view).
//!
//! Run: `cargo run --release -p dualgeo-bench --bin detectors [-- --seconds 10
//! --presets default,silver_parked --detectors colour,motion]`

use acquisition::sim::{Presets, Simulator};
use anyhow::{Context, Result};
use clap::Parser;
use detection::motion::{MotionConfig, MotionDetector};
use detection::yolo::{ClassRef, YoloConfig, YoloDetector, YoloLayout};
use detection::{ColourBlobConfig, Detection, Detector, TrackedDetector};
use opencv::core as cv;
use opencv::prelude::*;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Parser)]
struct Args {
    /// Presets to render.
    #[arg(long, value_delimiter = ',', default_value = "default,tilted,gimbal")]
    presets: Vec<String>,
    /// Seconds of each preset's flight.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// The learned model runs on every this many frames of each camera.
    #[arg(long, default_value_t = 5)]
    yolo_every: u64,
    /// A detection within this many pixels of the truth pixel is a hit.
    #[arg(long, default_value_t = 8.0)]
    hit_px: f64,
    /// The model's directory (Darknet `.cfg`, `.weights`, `coco.names`).
    #[arg(long, default_value = "data/models/yolov2-tiny")]
    model_dir: PathBuf,
    /// The model's input size.
    #[arg(long, default_value_t = 416)]
    input_size: i32,
    /// Which detectors to run: colour, yolo, motion.
    #[arg(long, value_delimiter = ',', default_value = "colour,yolo,motion")]
    detectors: Vec<String>,
}

#[derive(Default)]
struct Tally {
    visible: u64,
    detections: u64,
    hits: u64,
    wrong: u64,
    errors_px: Vec<f64>,
    costs_ms: Vec<f64>,
}

impl Tally {
    fn see(&mut self, truth: Option<[f64; 2]>, found: Option<Detection>, hit_px: f64, ms: f64) {
        self.costs_ms.push(ms);
        self.visible += truth.is_some() as u64;
        let Some(d) = found else { return };
        self.detections += 1;
        if let Some([u, v]) = truth {
            let e = (d.centre[0] - u).hypot(d.centre[1] - v);
            if e <= hit_px {
                self.hits += 1;
                self.errors_px.push(e);
                return;
            }
        }
        self.wrong += 1;
    }

    fn row(&self, name: &str, preset: &str) {
        let share = |a: u64, b: u64| {
            if b == 0 {
                "—".to_string()
            } else {
                format!("{:.1} %", 100.0 * a as f64 / b as f64)
            }
        };
        let error = quantile(&self.errors_px, 0.5).map_or("—".into(), |e| format!("{e:.2}"));
        let cost = match (quantile(&self.costs_ms, 0.5), quantile(&self.costs_ms, 0.9)) {
            (Some(a), Some(b)) => format!("{a:.1} / {b:.1}"),
            _ => "—".into(),
        };
        println!(
            "| {preset} | {name} | {} | {} | {} | {} | {error} | {cost} |",
            self.costs_ms.len(),
            share(self.hits, self.visible),
            share(self.hits, self.detections),
            share(self.wrong, self.costs_ms.len() as u64),
        );
    }
}

/// The `q` quantile (nearest rank) of `values`.
fn quantile(values: &[f64], q: f64) -> Option<f64> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let i = ((v.len() as f64 - 1.0) * q).round() as usize;
    v.get(i).copied()
}

fn yolo(args: &Args, classes: Vec<ClassRef>) -> Result<YoloDetector> {
    let dir = &args.model_dir;
    YoloDetector::new(YoloConfig {
        model: dir.join("yolov2-tiny.weights"),
        config: Some(dir.join("yolov2-tiny.cfg")),
        names: Some(dir.join("coco.names")),
        input_size: args.input_size,
        layout: YoloLayout::Auto,
        confidence_threshold: 0.25,
        nms_iou: 0.45,
        classes,
        every_frames: 1,
    })
    .with_context(|| format!("the model in {} (scripts/fetch_models.sh)", dir.display()))
}

fn main() -> Result<()> {
    let args = Args::parse();
    let mut vehicles = yolo(
        &args,
        ["car", "bus", "truck"]
            .map(|c| ClassRef::Name(c.into()))
            .to_vec(),
    )?;
    let mut any = yolo(&args, Vec::new())?;
    println!(
        "| preset | detector | frames | recall | precision | wrong | centre error (px, median) | ms per frame (p50 / p90) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    let runs = |d: &str| args.detectors.iter().any(|x| x == d);
    for preset in &args.presets {
        let mut config = Presets::builtin().get(preset)?;
        config.duration_s = args.seconds;
        let (w, h) = (config.camera.width as i32, config.camera.height as i32);
        let mut sim = Simulator::new(config)?;
        let mut colour = TrackedDetector::new(ColourBlobConfig::default())?;
        let mut motion = MotionDetector::new(MotionConfig::default())?;
        let mut designated: Option<MotionDetector> = None;
        // The motion detector looks from the frame 2 × short_gap_frames on; its rows
        // count from there.
        let warm_up = 2 * u64::from(MotionConfig::default().short_gap_frames);
        let (mut m_tally, mut d_tally) = (Tally::default(), Tally::default());
        let blank = || cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0));
        let mut frames = [blank()?, blank()?];
        let (mut c_tally, mut y_tally, mut any_tally) =
            (Tally::default(), Tally::default(), Tally::default());
        let mut k = 0u64;
        while let Some(step) = sim.step() {
            let [l, r] = &mut frames;
            sim.render_pair(
                &step,
                l.data_bytes_mut()?,
                r.data_bytes_mut()?,
                3 * w as usize,
            );
            for (camera, frame) in frames.iter().enumerate() {
                let truth = step.frames[camera].target_px;
                if runs("colour") {
                    let t = Instant::now();
                    let found = colour.detect(camera, step.frames[camera].t_s, frame)?;
                    c_tally.see(truth, found, args.hit_px, t.elapsed().as_secs_f64() * 1e3);
                }
                if runs("motion") {
                    let t = Instant::now();
                    let found = motion.detect(camera, frame, None)?;
                    if k >= warm_up {
                        m_tally.see(truth, found, args.hit_px, t.elapsed().as_secs_f64() * 1e3);
                    }
                    let d = designated.get_or_insert_with(|| {
                        MotionDetector::new(MotionConfig::default()).expect("default config")
                    });
                    // The operator's click when the detector first looks.
                    if k == warm_up {
                        if let Some(px) = truth {
                            d.designate(camera, px);
                        }
                    }
                    {
                        let t = Instant::now();
                        let found = d.detect(camera, frame, None)?;
                        if k >= warm_up {
                            d_tally.see(truth, found, args.hit_px, t.elapsed().as_secs_f64() * 1e3);
                        }
                    }
                }
                if runs("yolo") && k.is_multiple_of(args.yolo_every.max(1)) {
                    let t = Instant::now();
                    let found = vehicles.detect(frame)?;
                    y_tally.see(truth, found, args.hit_px, t.elapsed().as_secs_f64() * 1e3);
                    let t = Instant::now();
                    let found = any.detect(frame)?;
                    any_tally.see(truth, found, args.hit_px, t.elapsed().as_secs_f64() * 1e3);
                }
            }
            k += 1;
        }
        if runs("colour") {
            c_tally.row("colour", preset);
        }
        if runs("yolo") {
            y_tally.row("yolo (car, bus, truck)", preset);
            any_tally.row("yolo (any class)", preset);
        }
        if runs("motion") {
            m_tally.row("motion (centre)", preset);
            d_tally.row("motion (designated)", preset);
        }
    }
    Ok(())
}
