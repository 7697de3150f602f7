//! Writes the seed corpus (`seeds OUT_DIR`, one folder per target): a small recording
//! made by the project's writer, images of each kind, configuration files, checkpoints
//! of every kind taken from running services' state, and message sequences from the
//! synthetic scenario. Deterministic (fixed seeds); the committed corpus is its output
//! (tests/fuzz/corpus), regenerated when a format changes.

use acquisition::recording::{CameraMeta, RecordingMeta, RecordingWriter, TruthSample};
use acquisition::resume::StreamPosition;
use dualgeo_fuzz::{message_bytes, SEPARATOR};
use geolocation::set_message::{Resume, CHECKPOINT_KIND};
use geolocation::synthetic::SyntheticScenario;
use geolocation::{EstimatorConfig, EstimatorMethod, TemporalEstimator};
use matching::ring_store::{INDEX_KIND, KEYFRAME_KIND};
use matching::MatchingConfig;
use opencv::core as cv;
use opencv::prelude::*;
use rand::SeedableRng;
use shared_types::checkpoint;
use shared_types::conventions::Uav;
use shared_types::messages::{
    DetectionMsg, FrameHeader, ObservationSetMsg, PixelFormat, PoseSample, MAX_OBSERVATIONS,
};
use std::path::Path;

fn join(parts: &[Vec<u8>]) -> Vec<u8> {
    parts.join(SEPARATOR)
}

fn write(dir: &Path, target: &str, name: &str, data: &[u8]) {
    let folder = dir.join(target);
    std::fs::create_dir_all(&folder).expect("create the corpus folder");
    std::fs::write(folder.join(name), data).expect("write a seed");
}

fn image(width: i32, height: i32, channels: i32) -> cv::Mat {
    let mut m = cv::Mat::new_rows_cols_with_default(
        height,
        width,
        cv::CV_MAKETYPE(cv::CV_8U, channels),
        cv::Scalar::all(0.0),
    )
    .expect("allocate an image");
    for (i, b) in m.data_bytes_mut().expect("bytes").iter_mut().enumerate() {
        *b = ((i * 7) % 251) as u8;
    }
    m
}

fn encode(ext: &str, m: &cv::Mat) -> Vec<u8> {
    let mut out = cv::Vector::<u8>::new();
    opencv::imgcodecs::imencode_def(ext, m, &mut out).expect("encode");
    out.to_vec()
}

fn recording_seeds(dir: &Path) {
    let tmp = std::env::temp_dir().join(format!("dualgeo-fuzz-seeds-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    let camera = CameraMeta {
        width: 64,
        height: 48,
        fx: 55.0,
        fy: 55.0,
        cx: 32.0,
        cy: 24.0,
        distortion: [-0.1, 0.01, 0.0, 0.0, 0.0],
    };
    let meta = RecordingMeta::new("fuzz", 30.0, camera, None);
    let mut w = RecordingWriter::create(&tmp, &meta, true).expect("create a recording");
    let frame = image(64, 48, 3);
    for k in 0..3 {
        for uav in [Uav::Left, Uav::Right] {
            let pose = PoseSample {
                x_m: k as f64 * 0.5,
                y_m: uav.index() as f64 * 70.0,
                z_m: 100.0,
                yaw_deg: 10.0,
                ..Default::default()
            };
            let truth = TruthSample {
                pose,
                target: [1.0, 2.0, 13.5],
                target_px: (k != 1).then_some([30.0, 20.0]),
                gimbal: None,
            };
            w.write_frame(uav, k as f64 / 30.0, pose, &frame, Some(&truth))
                .expect("write a frame");
        }
    }
    w.finish().expect("finish the recording");
    let read = |f: &str| std::fs::read(tmp.join(f)).expect("read back");
    let files = [
        read("recording.toml"),
        read("telemetry.csv"),
        read("truth.csv"),
    ];
    write(dir, "recording", "written", &join(&files));
    let mut with_origin = String::from_utf8(files[0].clone()).expect("utf-8");
    with_origin
        .push_str("\n[origin]\nlatitude_deg = 47.4\nlongitude_deg = 8.5\naltitude_m = 400.0\n");
    write(
        dir,
        "recording",
        "origin",
        &join(&[with_origin.into_bytes(), files[1].clone()]),
    );
    let _ = std::fs::remove_dir_all(&tmp);
}

fn image_seeds(dir: &Path) {
    write(
        dir,
        "image",
        "bgr.png",
        &[&[0u8, 0][..], &encode(".png", &image(64, 48, 3))].concat(),
    );
    write(
        dir,
        "image",
        "grey.png",
        &[&[0u8, 0][..], &encode(".png", &image(40, 30, 1))].concat(),
    );
    write(
        dir,
        "image",
        "bgr.jpg",
        &[&[0u8, 0][..], &encode(".jpg", &image(64, 48, 3))].concat(),
    );
    let mut lying = encode(".png", &image(16, 8, 3));
    lying[16..20].copy_from_slice(&60000u32.to_be_bytes());
    write(
        dir,
        "image",
        "lying.png",
        &[&[15u8, 7][..], &lying].concat(),
    );
}

fn config_seeds(dir: &Path) {
    let full = format!(
        "[matching]\n{}\n[estimator]\n{}\n[detection]\n{}",
        toml::to_string(&MatchingConfig::default()).expect("toml"),
        toml::to_string(&EstimatorConfig::default()).expect("toml"),
        toml::to_string(&detection::ColourBlobConfig::default()).expect("toml"),
    );
    write(dir, "config", "defaults.toml", full.as_bytes());
    write(
        dir,
        "config",
        "paper.toml",
        b"[estimator]\nmethod = \"paper\"\n",
    );
    write(dir, "config", "empty.toml", b"");
}

/// A header describing a `width × height` BGR frame of `uav` at pair `k`.
fn header(uav: Uav, k: u64, width: u32, height: u32) -> FrameHeader {
    FrameHeader {
        seq: k,
        t_s: k as f64 / 2.0,
        uav: uav.index() as u8,
        pixel_format: PixelFormat::Bgr8 as u32,
        width,
        height,
        stride: width * 3,
        pose: PoseSample {
            // 40 m and 0.5 s apart: past the baseline constraint, so each pair becomes
            // a keyframe and later pairs are matched against it.
            x_m: k as f64 * 40.0,
            y_m: uav.index() as f64 * 70.0,
            z_m: 100.0,
            ..Default::default()
        },
        intrinsics: [110.0, 110.0, width as f64 / 2.0, height as f64 / 2.0],
        ..Default::default()
    }
}

fn frames_seed(pairs: u64) -> Vec<u8> {
    let mut out = Vec::new();
    for k in 0..pairs {
        for uav in [Uav::Left, Uav::Right] {
            out.push(uav.index() as u8);
            out.extend(message_bytes(&header(uav, k, 320, 240)));
            out.push(1); // a texture of the header's size
                         // One texture for every frame: past images share features with the current.
            out.extend(7u64.to_le_bytes());
        }
        for uav in [Uav::Left, Uav::Right] {
            out.push(2);
            out.extend(message_bytes(&DetectionMsg {
                seq: k,
                t_s: k as f64 / 2.0,
                uav: uav.index() as u8,
                found: 1,
                centre: [160.0, 120.0],
                bbox: [156.0, 116.0, 8.0, 8.0],
                confidence: 0.9,
                ..Default::default()
            }));
        }
        out.push(3);
    }
    out
}

fn observation_sets(n: usize) -> Vec<ObservationSetMsg> {
    let scenario = SyntheticScenario::default();
    let mut rng = rand::rngs::StdRng::seed_from_u64(13);
    let interval = scenario.keyframe_interval_s();
    (0..n)
        .filter_map(|i| {
            let t_s = 8.0 + i as f64 * 0.5;
            let trial = scenario.trial(t_s, 4, &mut rng).ok()?;
            let mut set = ObservationSetMsg {
                pair_seq: i as u64,
                t_s,
                ..Default::default()
            };
            for (j, (slot, o)) in set.entries.iter_mut().zip(&trial.observations).enumerate() {
                *slot = o.to_entry();
                // Current images: this pair; past ones: the keyframe k intervals back.
                let k = if j < 2 { 0 } else { 1 + (j - 2) % 3 };
                slot.t_s = t_s - k as f64 * interval;
                slot.frame_seq = (slot.t_s * 2.0).round() as u64;
                set.count += 1;
            }
            assert!(set.count as usize <= MAX_OBSERVATIONS);
            Some(set)
        })
        .collect()
}

fn message_seeds(dir: &Path) {
    write(dir, "frames", "five-pairs", &frames_seed(5));
    for (method, name) in [(0u8, "temporal"), (1, "paper"), (2, "joint")] {
        let mut data = vec![method];
        for set in observation_sets(4) {
            data.extend(message_bytes(&set));
        }
        write(dir, "observations", name, &data);
    }
}

fn checkpoint_seeds(dir: &Path) {
    let position = StreamPosition {
        next_seq: 42,
        consumed: 42,
        loops: 1,
        t_offset: 4.0,
        t_first: Some(0.0),
        last_t: 1.4,
    };
    let stream = checkpoint::encode(1, &position).expect("encode");
    let config = EstimatorConfig {
        method: EstimatorMethod::Temporal,
        ..Default::default()
    };
    let mut temporal = TemporalEstimator::new(config).expect("temporal");
    let mut stats = shared_types::stats::StageStats::new("seeds");
    for set in observation_sets(6) {
        geolocation::set_message::estimate_message(&set, &config, Some(&mut temporal), &mut stats);
    }
    let resume = Resume {
        last_pair_seq: 5,
        last_t_s: 10.5,
        filter: Some(temporal.snapshot()),
        tracks: Some(tracks_snapshot()),
        segment: 0,
    };
    let filter = checkpoint::encode(CHECKPOINT_KIND, &resume).expect("encode");
    // Keyframes as matching admits them: run the frames target's pairs through an intake.
    let mut intake =
        matching::intake::Intake::new(MatchingConfig::default(), config).expect("intake");
    for k in 0..4u64 {
        let pixels: Vec<Vec<u8>> = [Uav::Left, Uav::Right]
            .iter()
            .map(|_| dualgeo_fuzz::targets::texture(128 * 96 * 3, 128, k))
            .collect();
        let headers = [
            header(Uav::Left, k, 128, 96),
            header(Uav::Right, k, 128, 96),
        ];
        intake.extract([
            Some((headers[0], pixels[0].as_slice())),
            Some((headers[1], pixels[1].as_slice())),
        ]);
        for uav in [Uav::Left, Uav::Right] {
            intake.on_detection(DetectionMsg {
                seq: k,
                uav: uav.index() as u8,
                found: 1,
                centre: [64.0, 48.0],
                ..Default::default()
            });
        }
        let _ = intake.next_set();
    }
    let index = checkpoint::encode(INDEX_KIND, &intake.chain.ring_index()).expect("encode");
    let mut parts = vec![stream, filter, index];
    for uav in [Uav::Left, Uav::Right] {
        if let Some(kf) = intake.chain.newest_keyframe(uav) {
            parts.push(checkpoint::encode(KEYFRAME_KIND, &kf).expect("encode"));
        }
    }
    assert!(
        parts.len() == 5,
        "the seed pairs must admit a keyframe per UAV"
    );
    write(dir, "checkpoint", "all-kinds", &join(&parts));
}

fn flight_seeds(dir: &Path) {
    use acquisition::flight::tlog::TlogWriter;
    use mavlink::dialects::common::{MavMessage, ATTITUDE_DATA, GLOBAL_POSITION_INT_DATA};
    let mut log = TlogWriter::new(Vec::new(), 1);
    for k in 0..20u32 {
        let at = 1_767_225_600_000_000 + k as u64 * 33_333;
        log.write(
            at,
            &MavMessage::ATTITUDE(ATTITUDE_DATA {
                time_boot_ms: 100_000 + k * 33,
                roll: 0.01,
                pitch: -0.02,
                yaw: 3.1 - k as f32 * 0.01,
                ..Default::default()
            }),
        )
        .expect("write");
        log.write(
            at,
            &MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                time_boot_ms: 100_000 + k * 33,
                lat: 470_000_000 + k as i32 * 30,
                lon: 80_000_000,
                alt: 500_000,
                ..Default::default()
            }),
        )
        .expect("write");
    }
    let toml = "format = \"dualgeo-flight\"\nversion = 1\nname = \"seed\"\nframe_rate_hz = 30.0\n\
        [origin]\nlat_deg = 47.0\nlon_deg = 8.0\nalt_m = 400.0\n\
        [uav.left]\nvideo = \"left.mp4\"\ntelemetry = \"left.tlog\"\ntime_offset_s = 100.0\n\
        [uav.left.camera]\nwidth = 64\nheight = 48\nfx = 50.0\nfy = 50.0\ncx = 32.0\ncy = 24.0\n\
        distortion = [0.0, 0.0, 0.0, 0.0, 0.0]\n\
        [uav.right]\nvideo = \"right.mp4\"\ntelemetry = \"right.tlog\"\n\
        [uav.right.camera]\nwidth = 64\nheight = 48\nfx = 50.0\nfy = 50.0\ncx = 32.0\ncy = 24.0\n\
        distortion = [0.0, 0.0, 0.0, 0.0, 0.0]\n";
    write(
        dir,
        "flight",
        "toml-and-tlog",
        &join(&[toml.as_bytes().to_vec(), log.into_inner()]),
    );
}

fn main() {
    let Some(out) = std::env::args().nth(1) else {
        eprintln!("usage: seeds OUT_DIR");
        std::process::exit(2);
    };
    let dir = Path::new(&out);
    recording_seeds(dir);
    image_seeds(dir);
    config_seeds(dir);
    message_seeds(dir);
    checkpoint_seeds(dir);
    flight_seeds(dir);
    println!("seed corpus written to {}", dir.display());
}

/// Two vehicles' tracks, confirmed, and a third deleted and remembered for
/// re-identification, as the geolocation service checkpoints them.
fn tracks_snapshot() -> geolocation::tracks::TracksSnapshot {
    use geolocation::shared_bias::OtherFix;
    let mut tracks = geolocation::tracks::Tracks::new(Default::default()).expect("tracks");
    let fix = |x: f64| OtherFix {
        position: nalgebra::Point3::new(x, 5.0, 13.5),
        covariance_xy: nalgebra::Matrix2::identity() * 0.25,
        covariance_xy_given_biases: nalgebra::Matrix2::identity() * 0.25,
        bias_sensitivity: nalgebra::Matrix2::new(-12.0, 3.0, 5.0, 20.0),
        persistent_xy: nalgebra::Matrix2::new(0.3, 0.05, 0.05, 0.2),
        altitude_bias_sensitivity: [4.0, -6.0],
        persistent_z_var: 0.4,
        altitude_std_error_m: 0.5,
        reference_z: Some(14.0),
        colour_bgr: Some([0.0, 200.0, 220.0]),
        as_stated: false,
    };
    // The third goes out of view after 5 pairs; its track is deleted 3 s later.
    for k in 0..130 {
        let fixes = if k < 5 {
            vec![fix(0.0), fix(20.0), fix(40.0)]
        } else {
            vec![fix(0.0), fix(20.0)]
        };
        tracks.update(k as f64 / 30.0, &fixes, None);
    }
    let snapshot = tracks.snapshot();
    assert!(
        snapshot.tracks.len() == 2 && snapshot.lost.len() == 1,
        "the seed must hold two tracks and one remembered"
    );
    snapshot
}
