//! The paper's Table 1 protocol on the simulator: no navigation noise, 8 images
//! (N = 4 per UAV), the whole chain on rendered frames (classical detector, ORB,
//! F/E estimation, epipolar transfer, consistency filter, iteration). Prints MAE/STD/MAX
//! per axis before and after the filter beside the paper's figures, and the per-step
//! time split of the chain (one thread).
//!
//! Run: `cargo run --release -p dualgeo-bench --bin table1 [-- --every 3 --method ground_plane]`

use acquisition::sim::{Presets, Simulator};
use anyhow::Result;
use clap::Parser;
use detection::{ColourBlobConfig, ColourBlobDetector, Detector};
use geolocation::evaluation::ErrorStats;
use geolocation::EstimatorConfig;
use matching::{ChainOutcome, FrameInput, FundamentalMethod, MatchingConfig, VisionChain};
use nalgebra::Point3;
use opencv::core as cv;
use opencv::prelude::*;
use std::collections::BTreeMap;

#[derive(Parser)]
struct Args {
    /// Process every k-th stereo pair of the 40 s route (1 = all 1200).
    #[arg(long, default_value_t = 3)]
    every: u64,
    /// ground_plane | essential | magsac | ransac8
    #[arg(long, default_value = "ground_plane")]
    method: String,
    /// ORB features per frame (default: MatchingConfig's).
    #[arg(long)]
    orb_features: Option<i32>,
    /// RANSAC/USAC iteration cap for F and E (default: MatchingConfig's).
    #[arg(long)]
    max_iterations: Option<i32>,
    /// USAC score: magsac | msac.
    #[arg(long)]
    score: Option<String>,
    /// USAC local optimisation: none | inner | inner_and_iterative | graph_cut | sigma.
    #[arg(long)]
    lo: Option<String>,
    /// USAC local-optimisation rounds.
    #[arg(long)]
    lo_iterations: Option<i32>,
    /// ORB keypoint ranking: fast | harris (default: MatchingConfig's).
    #[arg(long)]
    orb_score: Option<String>,
    /// Refine keypoints with cornerSubPix: true | false (default: MatchingConfig's).
    #[arg(long)]
    subpixel: Option<bool>,
    /// Ground-plane homography iteration cap (default: MatchingConfig's).
    #[arg(long)]
    homography_iterations: Option<i32>,
    /// Reject past images whose two epipolar lines meet at less than this, degrees
    /// (default: MatchingConfig's).
    #[arg(long)]
    min_line_angle: Option<f64>,
    /// Guided-matching window, pixels (0 = brute force always; default: MatchingConfig's).
    #[arg(long)]
    guided_radius: Option<f64>,
    /// Follow ground points between ORB frames: true | false (default:
    /// MatchingConfig's; false = ORB and matching on every frame).
    #[arg(long)]
    track: Option<bool>,
    /// ORB at least every N frames while tracking (default: MatchingConfig's).
    #[arg(long)]
    track_refresh: Option<u32>,
    /// Ground inliers tracked per past image (default: MatchingConfig's).
    #[arg(long)]
    track_points: Option<usize>,
    /// Also list the N geolocations with the largest 3-D error after the filter.
    #[arg(long, default_value_t = 0)]
    worst: usize,
}

/// One row of the time split: median / p90 / p99 of `v` (µs), in ms.
fn print_times(name: &str, v: &[f64]) {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return;
    }
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize] / 1e3;
    println!(
        "  {name:26} {:7.2} / {:7.2} / {:7.2}",
        q(0.5),
        q(0.9),
        q(0.99)
    );
}

fn main() -> Result<()> {
    let args = Args::parse();
    let config = Presets::builtin().get("table1")?;
    let (w, h) = (config.camera.width as i32, config.camera.height as i32);
    let mut sim = Simulator::new(config)?;
    let mut detector = ColourBlobDetector::new(ColourBlobConfig::default())?;
    let mut matching = MatchingConfig {
        fundamental: match args.method.as_str() {
            "magsac" => FundamentalMethod::Magsac,
            "ransac8" => FundamentalMethod::Ransac8Point,
            "essential" => FundamentalMethod::Essential,
            "ground_plane" => FundamentalMethod::GroundPlane,
            other => anyhow::bail!("unknown --method {other:?}"),
        },
        ..MatchingConfig::default()
    };
    // The paper's protocol: matched once each UAV has its N − 1 past images.
    matching.min_past_images = matching.images_per_uav.saturating_sub(1).max(1);
    // The time split is per step on one thread (CPU time per geolocation).
    matching.match_threads = 1;
    if let Some(n) = args.orb_features {
        matching.orb_features = n;
    }
    if let Some(n) = args.max_iterations {
        matching.ransac_max_iterations = n;
    }
    if let Some(s) = &args.score {
        matching.usac_score = toml::Value::String(s.clone()).try_into()?;
    }
    if let Some(s) = &args.lo {
        matching.usac_local_optimisation = toml::Value::String(s.clone()).try_into()?;
    }
    if let Some(n) = args.lo_iterations {
        matching.usac_lo_iterations = n;
    }
    if let Some(s) = &args.orb_score {
        matching.orb_score = toml::Value::String(s.clone()).try_into()?;
    }
    if let Some(b) = args.subpixel {
        matching.subpixel_keypoints = b;
    }
    if let Some(a) = args.min_line_angle {
        matching.min_line_angle_deg = a;
    }
    if let Some(r) = args.guided_radius {
        matching.guided_radius_px = r;
    }
    if let Some(n) = args.homography_iterations {
        matching.homography_max_iterations = n;
    }
    if let Some(b) = args.track {
        matching.track_between_orb = b;
    }
    if let Some(n) = args.track_refresh {
        matching.track_refresh_frames = n;
    }
    if let Some(n) = args.track_points {
        matching.track_points_per_image = n;
    }
    let mut chain = VisionChain::new(matching, EstimatorConfig::default())?;
    let mut images = [
        cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0))?,
        cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0))?,
    ];
    let mut before: [Vec<f64>; 3] = Default::default();
    let mut after: [Vec<f64>; 3] = Default::default();
    let mut steps: [Vec<f64>; 6] = Default::default();
    // The refreshes' work (the service's refresh thread), per pair that ran one.
    let mut refreshes: Vec<f64> = Vec::new();
    let mut outcomes = BTreeMap::<String, usize>::new();
    // (3-D error, t, error vector, past images kept by the filter, past points,
    // detector error in the current left and right images)
    type Worst = (f64, f64, nalgebra::Vector3<f64>, usize, usize, [f64; 2]);
    let mut worst = Vec::<Worst>::new();
    let mut k = 0;
    while let Some(step) = sim.step() {
        k += 1;
        if k % args.every != 0 {
            continue;
        }
        {
            let [l, r] = &mut images;
            sim.render_pair(
                &step,
                l.data_bytes_mut()?,
                r.data_bytes_mut()?,
                3 * w as usize,
            );
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
                    detection: detector.detect(image)?.map(|d| d.centre),
                    intrinsics: sim.intrinsics(),
                    distortion: sim.distortion(),
                    width: w as u32,
                    height: h as u32,
                })
            })
            .collect::<Result<_>>()?;
        let result = chain.process(&inputs[0], &inputs[1])?;
        if result.timing.refresh_us > 0.0 {
            refreshes.push(result.timing.refresh_us);
        }
        let target = Point3::from(step.frames[0].target);
        let key = match &result.outcome {
            ChainOutcome::NoDetection => "no detection".to_string(),
            ChainOutcome::NotEnoughHistory { .. } => "warming up".to_string(),
            ChainOutcome::TargetPairMismatch => "two vehicles".to_string(),
            ChainOutcome::Located(located) => {
                let (filtered, unfiltered) = (&located.filtered, &located.unfiltered);
                for model in located.past.iter().flat_map(|p| p.models).flatten() {
                    *outcomes.entry(format!("F model: {model:?}")).or_default() += 1;
                }
                let sides = located
                    .past
                    .iter()
                    .flat_map(|p| p.guided.into_iter().zip(p.chained));
                for (guided, chained) in sides {
                    let how = match (chained, guided) {
                        (true, _) => "by tracking",
                        (false, true) => "guided",
                        (false, false) => "brute force",
                    };
                    *outcomes.entry(format!("pairs matched {how}")).or_default() += 1;
                }
                if let Ok(e) = unfiltered {
                    let d = e.position - target;
                    (0..3).for_each(|i| before[i].push(d[i]));
                }
                match filtered {
                    Ok(f) => {
                        let d = f.estimate.position - target;
                        (0..3).for_each(|i| after[i].push(d[i]));
                        let kept = f.past_rejections.iter().filter(|r| r.is_none()).count();
                        // Detector error in each current image, pixels.
                        let det = [0, 1].map(|i| {
                            let truth = step.frames[i].view.project(&target);
                            match (inputs[i].detection, truth) {
                                (Some(p), Some(t)) => (p[0] - t[0]).hypot(p[1] - t[1]),
                                _ => f64::NAN,
                            }
                        });
                        worst.push((
                            d.norm(),
                            step.frames[0].t_s,
                            d,
                            kept,
                            located.past.len(),
                            det,
                        ));
                        let t = &result.timing;
                        for (i, v) in [
                            t.orb_us,
                            t.matching_us,
                            t.fundamental_us,
                            t.transfer_us,
                            t.estimate_us,
                            t.total_us(),
                        ]
                        .into_iter()
                        .enumerate()
                        {
                            steps[i].push(v);
                        }
                        "located".to_string()
                    }
                    Err(e) => format!("rejected: {}", e.kind()),
                }
            }
        };
        *outcomes.entry(key).or_default() += 1;
        for (uav, _, reason) in &result.rejections {
            *outcomes
                .entry(format!(
                    "past image rejected ({:?}): {}",
                    uav,
                    reason.kind()
                ))
                .or_default() += 1;
        }
    }
    println!("Table 1 protocol (no navigation noise, 8 images), F by {}, every {} pair(s) of the default route", args.method, args.every);
    for (k, v) in &outcomes {
        println!("  {k}: {v}");
    }
    let paper = [
        [
            "0.283 / 0.373 / 4.135",
            "0.274 / 0.408 / 6.335",
            "1.216 / 1.561 / 8.574",
        ],
        [
            "0.151 / 0.125 / 0.692",
            "0.173 / 0.164 / 1.135",
            "0.720 / 0.547 / 2.464",
        ],
    ];
    println!(
        "\n{:14} {:>6} | {:>24} | {:>24}",
        "", "axis", "ours MAE / STD / MAX (m)", "paper MAE / STD / MAX (m)"
    );
    for (label, data, p) in [
        ("before filter", &before, paper[0]),
        ("after filter", &after, paper[1]),
    ] {
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            let s = ErrorStats::from_errors(&data[i]);
            println!(
                "{label:14} {axis:>6} | {:6.3} / {:6.3} / {:7.3}    | {:>24}   (n={})",
                s.mae, s.std, s.max, p[i], s.count
            );
        }
    }
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    if args.worst > 0 {
        println!("\nworst geolocations after the filter:");
    }
    for (e, t, d, kept, points, det) in worst.iter().take(args.worst) {
        println!(
            "  t {t:6.2} s  error {e:6.3} m  (x {:6.3}, y {:6.3}, z {:6.3})  past images kept {kept} of {points}  detector error {:.2} / {:.2} px",
            d.x, d.y, d.z, det[0], det[1]
        );
    }
    println!("\ntime per geolocation, one thread, the pair's path (median / p90 / p99, ms):");
    for (i, name) in [
        "track (ORB, tracking off)",
        "matching (2 x 6)",
        "F / E estimation (2 x 6)",
        "epipolar transfer",
        "filter + iteration",
        "total",
    ]
    .iter()
    .enumerate()
    {
        print_times(name, &steps[i]);
    }
    println!(
        "the refresh thread's work (ORB, matching with past images), {} refreshes on {} pairs:",
        refreshes.len(),
        steps[5].len()
    );
    print_times("refresh, per pair that ran one", &refreshes);
    Ok(())
}
