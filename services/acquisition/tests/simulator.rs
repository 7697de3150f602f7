//! The simulator: rendered target against truth, ORB epipolar geometry against the true
//! poses, determinism, the noise model, and a simulated recording through the reader.

use acquisition::recording::{ImageEncoding, Recording};
use acquisition::sim::render::{CameraView, Renderer, Surface, VEHICLE_TOP_BGR};
use acquisition::sim::{record, Presets, SimConfig, Simulator};
use nalgebra::Vector3;
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::conventions::Uav;
use std::sync::{Arc, OnceLock};
use tempfile::TempDir;

fn preset(name: &str) -> SimConfig {
    Presets::builtin().get(name).unwrap()
}

/// One town for every test in this file (building it takes about a second).
fn simulator(config: SimConfig) -> Simulator {
    static CITY: OnceLock<Arc<acquisition::sim::city::City>> = OnceLock::new();
    let city = CITY.get_or_init(|| {
        Arc::new(acquisition::sim::city::City::generate(
            preset("default").city,
        ))
    });
    assert_eq!(config.city, city.config, "tests share the default town");
    Simulator::with_city(config, city.clone()).unwrap()
}

fn buffers(config: &SimConfig) -> (Vec<u8>, Vec<u8>, usize) {
    let stride = 3 * config.camera.width as usize;
    let len = stride * config.camera.height as usize;
    (vec![0; len], vec![0; len], stride)
}

/// Centroid of the pixels that show the vehicle's top face, in `scale`-times-finer
/// pixels mapped back to native pixel coordinates.
fn top_centroid(renderer: &Renderer, w: usize, h: usize, scale: f64) -> (f64, f64, f64) {
    let (mut su, mut sv, mut n) = (0.0, 0.0, 0.0);
    for v in 0..h {
        for u in 0..w {
            if renderer.surface(u, v) == Surface::VehicleTop {
                su += u as f64;
                sv += v as f64;
                n += 1.0;
            }
        }
    }
    let back = |c: f64| (c / n + 0.5) / scale - 0.5;
    (back(su), back(sv), n)
}

/// The rendered target against truth's pixel. At native resolution the centroid of a
/// ~280-pixel blob with hard (un-antialiased) edges moves by up to ~0.5 px as its edges
/// cross pixel centres, so the geometry is checked on a 4×-supersampled render (same
/// camera, 4× finer pixels), and the native images for an unbiased, tight median.
#[test]
fn rendered_target_centre_matches_truth_within_half_a_pixel() {
    let config = preset("table1");
    let mut sim = simulator(config.clone());
    let (mut l, mut r, stride) = buffers(&config);
    let (w, h) = (config.camera.width as usize, config.camera.height as usize);
    let mut fine = Renderer::new();
    let mut fine_buf = vec![0u8; 16 * 3 * w * h];
    let (mut native, mut supersampled, mut bias) = (Vec::new(), Vec::new(), [0.0, 0.0]);
    for k in 0..600 {
        let step = sim.step().unwrap();
        if k % 25 != 0 {
            continue;
        }
        sim.render_pair(&step, &mut l, &mut r, stride);
        for (frame, image) in step.frames.iter().zip([&l, &r]) {
            let truth = frame.target_px.expect("target in view");
            let (u, v, n) = top_centroid(sim.renderer(frame.uav), w, h, 1.0);
            assert!(n > 50.0, "vehicle top hidden or tiny at step {k} ({n} px)");
            native.push(((u - truth[0]).powi(2) + (v - truth[1]).powi(2)).sqrt());
            bias[0] += u - truth[0];
            bias[1] += v - truth[1];
            let (tu, tv) = (truth[0].round() as usize, truth[1].round() as usize);
            assert_eq!(
                &image[tv * stride + 3 * tu..tv * stride + 3 * tu + 3],
                &VEHICLE_TOP_BGR,
                "pixel under the truth"
            );
            if k % 100 == 0 {
                let mut view = frame.view;
                let k4 = view.intrinsics;
                view.intrinsics = shared_types::conventions::Intrinsics::new(
                    4.0 * k4.fx,
                    4.0 * k4.fy,
                    4.0 * (k4.cx + 0.5) - 0.5,
                    4.0 * (k4.cy + 0.5) - 0.5,
                );
                (view.width, view.height) = (4 * view.width, 4 * view.height);
                fine.render(
                    sim.city(),
                    Some(&step.vehicle),
                    &view,
                    &mut fine_buf,
                    4 * stride,
                );
                let (u, v, _) = top_centroid(&fine, 4 * w, 4 * h, 4.0);
                supersampled.push(((u - truth[0]).powi(2) + (v - truth[1]).powi(2)).sqrt());
            }
        }
    }
    native.sort_by(f64::total_cmp);
    let count = native.len() as f64;
    let (median, worst) = (native[native.len() / 2], native[native.len() - 1]);
    let worst_fine = supersampled.iter().copied().fold(0.0, f64::max);
    eprintln!("centre error: native median {median:.3} px, max {worst:.3} px; 4x supersampled max {worst_fine:.3} px");
    assert!(native.len() >= 40 && supersampled.len() >= 10);
    assert!(
        worst_fine < 0.5,
        "supersampled centre error up to {worst_fine:.3} px"
    );
    assert!(
        median < 0.25 && worst < 0.75,
        "native centre error median {median:.3}, max {worst:.3} px"
    );
    assert!(
        (bias[0] / count).abs() < 0.1 && (bias[1] / count).abs() < 0.1,
        "biased: {bias:?}"
    );
}

fn gray(bgr: &[u8], config: &SimConfig) -> cv::Mat {
    let (w, h) = (config.camera.width as i32, config.camera.height as i32);
    let m = cv::Mat::new_rows_cols_with_data(h, 3 * w, bgr).unwrap();
    let m = m.reshape(3, h).unwrap();
    let mut g = cv::Mat::default();
    opencv::imgproc::cvt_color_def(&m, &mut g, opencv::imgproc::COLOR_BGR2GRAY).unwrap();
    g
}

fn median_epipolar_error(
    a: &[u8],
    va: &CameraView,
    b: &[u8],
    vb: &CameraView,
    config: &SimConfig,
) -> (f64, usize) {
    let mut orb = opencv::features2d::ORB::create(
        2000,
        1.2,
        8,
        31,
        0,
        2,
        opencv::features2d::ORB_ScoreType::HARRIS_SCORE,
        31,
        20,
    )
    .unwrap();
    let mut detect = |img: &cv::Mat| {
        let mut kp = cv::Vector::<cv::KeyPoint>::new();
        let mut desc = cv::Mat::default();
        orb.detect_and_compute_def(img, &cv::no_array(), &mut kp, &mut desc)
            .unwrap();
        (kp, desc)
    };
    let (ka, da) = detect(&gray(a, config));
    let (kb, db) = detect(&gray(b, config));
    // Lowe's ratio test (independent of the true geometry) keeps distinctive matches.
    let matcher = opencv::features2d::BFMatcher::new(cv::NORM_HAMMING, false).unwrap();
    let mut knn = cv::Vector::<cv::Vector<cv::DMatch>>::new();
    matcher.knn_train_match_def(&da, &db, &mut knn, 2).unwrap();
    let matches: cv::Vector<cv::DMatch> = knn
        .iter()
        .filter(|m| m.len() == 2 && m.get(0).unwrap().distance < 0.75 * m.get(1).unwrap().distance)
        .map(|m| m.get(0).unwrap())
        .collect();
    let f = va.fundamental_to(vb).unwrap();
    let mut errors: Vec<f64> = matches
        .iter()
        .map(|m| {
            let p = ka.get(m.query_idx as usize).unwrap().pt();
            let q = kb.get(m.train_idx as usize).unwrap().pt();
            let line = f * Vector3::new(p.x as f64, p.y as f64, 1.0);
            (line.dot(&Vector3::new(q.x as f64, q.y as f64, 1.0))).abs() / line.xy().norm()
        })
        .collect();
    errors.sort_by(f64::total_cmp);
    (errors[errors.len() / 2], errors.len())
}

#[test]
fn orb_matches_agree_with_the_true_epipolar_geometry() {
    let config = preset("table1");
    let mut sim = simulator(config.clone());
    let steps: Vec<_> = (0..31).map(|_| sim.step().unwrap()).collect();
    let (mut a, mut b, stride) = buffers(&config);
    let mut renderer = Renderer::new();
    let city = sim.city().clone();
    // Static scene (no vehicle): the left UAV 1 s apart, and left vs right at one instant.
    for (va, vb) in [
        (steps[0].frames[0].view, steps[30].frames[0].view),
        (steps[10].frames[0].view, steps[10].frames[1].view),
    ] {
        renderer.render(&city, None, &va, &mut a, stride);
        renderer.render(&city, None, &vb, &mut b, stride);
        let (median, n) = median_epipolar_error(&a, &va, &b, &vb, &config);
        eprintln!("epipolar error against the true F: median {median:.3} px over {n} matches");
        assert!(n > 200, "only {n} ORB matches");
        assert!(
            median < 1.0,
            "median epipolar error {median:.3} px over {n} matches"
        );
    }
}

fn write(config: SimConfig, dir: &TempDir) -> std::path::PathBuf {
    write_as(config, dir, ImageEncoding::Png)
}

fn write_as(config: SimConfig, dir: &TempDir, encoding: ImageEncoding) -> std::path::PathBuf {
    let out = dir.path().join("rec");
    let mut sim = simulator(config);
    record(&mut sim, "test", &out, encoding, |_, _| {}).unwrap();
    out
}

#[test]
fn a_jpeg_recording_reads_back_close_to_its_png_twin() {
    let mut config = preset("default");
    config.duration_s = 0.2;
    let (d1, d2) = (TempDir::new().unwrap(), TempDir::new().unwrap());
    let png = Recording::open(write(config.clone(), &d1)).unwrap();
    let jpeg = write_as(config, &d2, ImageEncoding::Jpeg { quality: 95 });
    assert!(jpeg.join("left/000002.jpg").exists());
    assert!(!jpeg.join("left/000002.png").exists());
    let jpeg = Recording::open(&jpeg).unwrap();
    assert_eq!(jpeg.telemetry.len(), png.telemetry.len());
    let (a, b) = (png.read_image(2).unwrap(), jpeg.read_image(2).unwrap());
    assert_eq!((b.cols(), b.rows(), b.channels()), (640, 480, 3));
    let (a, b) = (a.data_bytes().unwrap(), b.data_bytes().unwrap());
    let mean_abs = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum::<f64>()
        / a.len() as f64;
    assert!(
        mean_abs < 3.0,
        "JPEG 95 differs by {mean_abs} grey levels on average"
    );
}

#[test]
fn same_seed_same_recording_and_the_reader_accepts_it() {
    let mut config = preset("default");
    config.duration_s = 0.3;
    let (d1, d2, d3) = (
        TempDir::new().unwrap(),
        TempDir::new().unwrap(),
        TempDir::new().unwrap(),
    );
    let a = write(config.clone(), &d1);
    let b = write(config.clone(), &d2);
    for f in [
        "recording.toml",
        "telemetry.csv",
        "truth.csv",
        "left/000004.png",
        "right/000008.png",
    ] {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f}"
        );
    }
    config.seed += 1;
    let c = write(config.clone(), &d3);
    assert_ne!(
        std::fs::read(a.join("telemetry.csv")).unwrap(),
        std::fs::read(c.join("telemetry.csv")).unwrap()
    );
    assert_eq!(
        std::fs::read(a.join("truth.csv")).unwrap(),
        std::fs::read(c.join("truth.csv")).unwrap(),
        "truth does not depend on the noise seed"
    );

    let rec = Recording::open(&a).unwrap();
    assert_eq!(rec.telemetry.len(), 18);
    assert_eq!(rec.pairs().len(), 9);
    assert!(rec.meta.origin.is_some());
    let img = rec.read_image(3).unwrap();
    assert_eq!((img.cols(), img.rows(), img.channels()), (640, 480, 3));
    assert!(rec.truth.unwrap().iter().all(|t| t.target_px.is_some()));
}

#[test]
fn measured_states_follow_the_noise_model_and_eq34() {
    let mut config = preset("table2");
    config.duration_s = 40.0;
    let mut sim = simulator(config.clone());
    let mut pos = Vec::new();
    let mut yaw = [Vec::new(), Vec::new()];
    while let Some(step) = sim.step() {
        for f in &step.frames {
            pos.push(f.measured.x_m - f.true_pose.x_m);
            pos.push(f.measured.z_m - f.true_pose.z_m);
            let bias = config.bias.at(f.t_s)[f.uav.index()].to_degrees();
            let residual = shared_types::conventions::wrap_angle(
                (f.measured.yaw_deg - f.true_pose.yaw_deg - bias).to_radians(),
            )
            .to_degrees();
            yaw[f.uav.index()].push(residual);
        }
    }
    let stats = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        (
            m,
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt(),
        )
    };
    let (m, s) = stats(&pos);
    assert!(
        m.abs() < 0.2 && (s - 3.0).abs() < 0.15,
        "position noise mean {m}, σ {s}"
    );
    for (u, uav) in [Uav::Left, Uav::Right].iter().enumerate() {
        let (m, s) = stats(&yaw[u]);
        assert!(
            m.abs() < 0.15 && (s - 2.0).abs() < 0.1,
            "{uav:?} yaw residual after eq. (34): mean {m}, σ {s}"
        );
    }
}

#[test]
fn a_user_orthophoto_replaces_the_procedural_ground() {
    let dir = TempDir::new().unwrap();
    let photo = dir.path().join("ortho.png");
    let colour = cv::Scalar::new(10.0, 200.0, 30.0, 0.0);
    let img = cv::Mat::new_rows_cols_with_default(64, 64, cv::CV_8UC3, colour).unwrap();
    opencv::imgcodecs::imwrite_def(photo.to_str().unwrap(), &img).unwrap();
    let mut config = preset("table1");
    config.ground_image = Some(photo);
    let mut sim = Simulator::new(config.clone()).unwrap();
    let step = sim.step().unwrap();
    let (mut l, _, stride) = buffers(&config);
    sim.render(&step, Uav::Left, &mut l, stride);
    let renderer = sim.renderer(Uav::Left);
    let mut ground = 0;
    for v in (0..480).step_by(7) {
        for u in (0..640).step_by(7) {
            if renderer.surface(u, v) == Surface::Ground {
                assert_eq!(
                    &l[v * stride + 3 * u..v * stride + 3 * u + 3],
                    &[10, 200, 30]
                );
                ground += 1;
            }
        }
    }
    assert!(ground > 100);

    config.ground_image = Some(dir.path().join("missing.png"));
    let err = Simulator::new(config)
        .err()
        .expect("missing orthophoto must fail")
        .to_string();
    assert!(err.contains("missing.png"), "{err}");
}
