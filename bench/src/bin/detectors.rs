//! Benchmark: the detectors on rendered frames, against the simulator's truth pixel.
//! Per preset (nadir `default`, 30° `tilted`, the tracking `gimbal`): recall (frames
//! with the target in view and not hidden where the detector's centre lies within `--hit-px` of the
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
//!   nearest the image centre, `motion (colour)` the one nearest it of the vehicle's
//!   paint (`acquire_bgr` set to the preset's colour: the operator names "the silver
//!   car"), `motion (designated)` the one nearest `acquire_px` set to
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

use acquisition::sim::texture::hash;
use acquisition::sim::{Presets, SimConfig, Simulator};
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
    /// `[detection.motion]` keys for the motion rows, TOML (e.g. `threshold = 25`).
    #[arg(long, default_value = "")]
    motion: String,
    /// Print, per frame and camera (`camera 0` left, `camera 1` right), the designated
    /// motion detector's movers against the truth pixel (stderr).
    #[arg(long)]
    trace: bool,
    /// Seeds per preset (0: the preset itself; more start the route elsewhere and
    /// draw other noise), pooled in each row.
    #[arg(long, default_value_t = 1)]
    seeds: u64,
    /// The first seed (`--first-seed 2 --seeds 1`: seed 2 alone).
    #[arg(long, default_value_t = 0)]
    first_seed: u64,
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
    let vehicles = yolo(
        &args,
        ["car", "bus", "truck"]
            .map(|c| ClassRef::Name(c.into()))
            .to_vec(),
    )?;
    let any = yolo(&args, Vec::new())?;
    println!(
        "| preset | detector | frames | recall | precision | wrong | centre error (px, median) | ms per frame (p50 / p90) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    let runs = |d: &str| args.detectors.iter().any(|x| x == d);
    let motion_config: MotionConfig = toml::from_str(&args.motion).context("--motion")?;
    let mut models = Models { vehicles, any };
    for preset in &args.presets {
        let mut t = Tallies::default();
        for seed in args.first_seed..args.first_seed + args.seeds.max(1) {
            let mut config = Presets::builtin().get(preset)?;
            config.duration_s = args.seconds;
            fly(
                seeded(config, seed),
                &args,
                motion_config,
                &mut models,
                &mut t,
            )?;
        }
        if runs("colour") {
            t.colour.row("colour", preset);
        }
        if runs("yolo") {
            t.yolo.row("yolo (car, bus, truck)", preset);
            t.any.row("yolo (any class)", preset);
        }
        if runs("motion") {
            t.centre.row("motion (centre)", preset);
            t.colour_named.row("motion (colour)", preset);
            t.designated.row("motion (designated)", preset);
        }
    }
    Ok(())
}

struct Models {
    vehicles: YoloDetector,
    any: YoloDetector,
}

#[derive(Default)]
struct Tallies {
    colour: Tally,
    yolo: Tally,
    any: Tally,
    centre: Tally,
    colour_named: Tally,
    designated: Tally,
}

/// Seed 0 is the preset itself; seed `s` > 0 starts the route up to 150 m further on and
/// draws other navigation noise (as the Monte Carlo varies a scene).
fn seeded(mut config: SimConfig, seed: u64) -> SimConfig {
    if seed > 0 {
        let h = hash(config.seed ^ hash(seed));
        config.seed = h;
        config.driving.start_m += 150.0 * ((hash(h ^ 1) >> 11) as f64 / (1u64 << 53) as f64);
    }
    config
}

/// Flies one seed of a preset through the chosen detectors, into `t`.
fn fly(
    config: SimConfig,
    args: &Args,
    motion_config: MotionConfig,
    models: &mut Models,
    t: &mut Tallies,
) -> Result<()> {
    let runs = |d: &str| args.detectors.iter().any(|x| x == d);
    let (w, h) = (config.camera.width as i32, config.camera.height as i32);
    let paint = config
        .vehicle
        .colour_bgr
        .unwrap_or(acquisition::sim::render::VEHICLE_TOP_BGR)
        .map(f64::from);
    let mut sim = Simulator::new(config)?;
    let mut colour = TrackedDetector::new(ColourBlobConfig::default())?;
    let mut motion = MotionDetector::new(motion_config)?;
    let mut named = MotionDetector::new(MotionConfig {
        acquire_bgr: Some(paint),
        ..motion_config
    })?;
    let mut designated = MotionDetector::new(motion_config)?;
    // The motion detector looks from the frame 2 × short_gap_frames on; its rows count
    // from there.
    let warm_up = 2 * u64::from(motion_config.short_gap_frames);
    let blank = || cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0));
    let mut frames = [blank()?, blank()?];
    let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
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
            // The truth pixel when the target is in view and not hidden (the bridge).
            let uav = step.frames[camera].uav;
            let truth = step.frames[camera]
                .target_px
                .filter(|_| sim.target_visible(&step, uav));
            if runs("colour") {
                let start = Instant::now();
                let found = colour.detect(camera, step.frames[camera].t_s, frame)?;
                t.colour.see(truth, found, args.hit_px, ms(start));
            }
            if runs("motion") {
                let start = Instant::now();
                let found = motion.detect(camera, frame, None)?;
                if k >= warm_up {
                    t.centre.see(truth, found, args.hit_px, ms(start));
                }
                let start = Instant::now();
                let found = named.detect(camera, frame, None)?;
                if k >= warm_up {
                    t.colour_named.see(truth, found, args.hit_px, ms(start));
                }
                // The operator's click when the detector first looks.
                if k == warm_up {
                    if let Some(px) = truth {
                        designated.designate(camera, px);
                    }
                }
                let start = Instant::now();
                let found = designated.detect(camera, frame, None)?;
                let cost = ms(start);
                // This camera's counts for this frame alone.
                let c = designated.take_counts();
                if args.trace {
                    if c.no_ground > 0 {
                        eprintln!(
                            "camera {camera} frame {k}: the ground's motion was not measured"
                        );
                    }
                    trace(camera, k, truth, found, c.held > 0, &designated);
                }
                if k >= warm_up {
                    t.designated.see(truth, found, args.hit_px, cost);
                }
            }
            if runs("yolo") && k.is_multiple_of(args.yolo_every.max(1)) {
                let start = Instant::now();
                let found = models.vehicles.detect(frame)?;
                t.yolo.see(truth, found, args.hit_px, ms(start));
                let start = Instant::now();
                let found = models.any.detect(frame)?;
                t.any.see(truth, found, args.hit_px, ms(start));
            }
        }
        k += 1;
    }
    Ok(())
}

/// One line per frame and camera of the designated motion detector (`--trace`).
fn trace(
    camera: usize,
    k: u64,
    truth: Option<[f64; 2]>,
    found: Option<Detection>,
    held: bool,
    d: &MotionDetector,
) {
    let near = |c: [f64; 2]| truth.map_or(f64::NAN, |t| (c[0] - t[0]).hypot(c[1] - t[1]));
    let round = |p: [f64; 2]| [p[0].round(), p[1].round()];
    eprintln!(
        "camera {camera} frame {k}: truth {:?} track (image, ground, missed) {:?} found at {:.1} px {:?}{}; movers (distance, area) {:?}",
        truth.map(round),
        d.track_state(camera).map(|([a, b], n)| (round(a), round(b), n)),
        found.map_or(f64::NAN, |f| near(f.centre)),
        found.zip(truth).map(|(f, t)| [
            (f.centre[0] - t[0]) as f32,
            (f.centre[1] - t[1]) as f32
        ]),
        if held { " (held by its patch)" } else { "" },
        d.last_movers()
            .iter()
            .map(|m| (near(m.centre).round(), m.area_px))
            .collect::<Vec<_>>()
    );
}
