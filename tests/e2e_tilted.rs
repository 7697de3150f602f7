//! End-to-end: recordings in format v2 with cameras tilted 30° forward of straight down
//! (`mount = "fixed"`) and on tracking gimbals 45° off nadir (`mount = "gimbal"`, the
//! angles per image), simulated, validated and geolocated by the four processes.
//! Without navigation errors the chain's geometry must hold for a tilted camera as it
//! does for a nadir one: after the start, the estimates are within a metre. The
//! estimator is told the recordings' noise (`EXACT_NAVIGATION`), as a user with a
//! precise navigation system would tell it.
//! (With the paper's errors the tilted start is not yet trustworthy: docs/evaluation
//! and the recording format's page give the Monte Carlo figures.)

#[path = "support/cli.rs"]
mod cli;
#[path = "support/scratch.rs"]
mod scratch;

use cli::{dualgeo, rows};
use scratch::Scratch;

const PRESETS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../acquisition/presets/scenarios.toml"
);

#[test]
fn a_tilted_camera_recording_is_geolocated_within_a_metre_after_the_start() {
    geolocated_within_a_metre("tilted", "", Output::Recording("mount = \"fixed\""));
}

/// The tracking gimbal's encoders without noise as well: the angles of each image are
/// exact, so any error is the chain's.
#[test]
fn a_gimbal_recording_is_geolocated_within_a_metre_after_the_start() {
    geolocated_within_a_metre(
        "gimbal",
        EXACT_GIMBAL,
        Output::Recording("mount = \"gimbal\""),
    );
}

/// The same gimbal flown as a flight: per UAV a (lossless) video and a `.tlog` whose
/// GIMBAL_DEVICE_ATTITUDE_STATUS messages carry the gimbal's angles beside ATTITUDE.
#[test]
fn a_gimbal_flight_is_geolocated_within_a_metre_after_the_start() {
    geolocated_within_a_metre("gimbal", EXACT_GIMBAL, Output::Flight);
}

const EXACT_GIMBAL: &str = "camera = { width = 640, height = 480, hfov_deg = 60.0, mount_angles_deg = [0.0, -45.0, 0.0], gimbal = { tau_s = 0.3, encoder_noise_deg = 0.0 } }\n";

/// The estimator's noise model for these recordings: σ 0.2 m and 0.2° on both UAVs
/// (the ±45° yaw-bias prior kept). With the default (σ 3 m, 2°) the filter is told
/// the rays could be that wrong, and the first seconds' exact rays cannot tell the
/// exact start hypothesis from its neighbours 33 m along the valley of near-equal
/// fits: the gimbal was 3.1–3.3 m off after 8 s, honestly stated (docs/temporal.md,
/// "Without navigation errors the start is slower").
const EXACT_NAVIGATION: &str = "[estimator.noise_left]\nsigma_position_m = [0.2, 0.2, 0.2]\nsigma_pitch_deg = 0.2\nsigma_roll_deg = 0.2\nsigma_yaw_deg = 0.2\n[estimator.noise_right]\nsigma_position_m = [0.2, 0.2, 0.2]\nsigma_pitch_deg = 0.2\nsigma_roll_deg = 0.2\nsigma_yaw_deg = 0.2\n";

/// What the simulator writes: a recording whose metadata must hold the given text, or
/// a flight.
enum Output {
    Recording(&'static str),
    Flight,
}

/// Simulates `preset` without navigation errors (plus `extra` TOML) as `output` and
/// geolocates it.
fn geolocated_within_a_metre(preset: &str, extra: &str, output: Output) {
    // Tests run in parallel: a scratch directory per preset and output kind.
    let kind = match output {
        Output::Recording(_) => "recording",
        Output::Flight => "flight",
    };
    let dir = Scratch::new(&format!("{preset}-{kind}"));
    let presets = dir.0.join("presets.toml");
    let builtin = std::fs::read_to_string(PRESETS).unwrap();
    std::fs::create_dir_all(&dir.0).unwrap();
    std::fs::write(
        &presets,
        format!(
            "{builtin}\n[exact]\nbase = \"{preset}\"\nnoise = {{ sigma_position_m = [0.0, 0.0, 0.0], sigma_attitude_deg = [0.0, 0.0, 0.0] }}\nbias = {{ kind = \"constant\", left_deg = 0.0, right_deg = 0.0 }}\n{extra}"
        ),
    )
    .unwrap();
    let (rec, out) = (dir.0.join("rec"), dir.0.join("out"));
    let (rec_s, out_s) = (rec.to_str().unwrap(), out.to_str().unwrap());
    let simulate = [
        "simulate",
        "--presets",
        presets.to_str().unwrap(),
        "--preset",
        "exact",
        "--duration-s",
        "12",
    ];
    let source = match output {
        Output::Recording(mount) => {
            dualgeo(&[&simulate[..], &["--jpeg-quality", "95", "--out", rec_s]].concat());
            let meta = std::fs::read_to_string(rec.join("recording.toml")).unwrap();
            assert!(
                meta.contains("version = 2") && meta.contains(mount),
                "{meta}"
            );
            dualgeo(&["validate", rec_s]);
            rec.clone()
        }
        Output::Flight => {
            dualgeo(
                &[
                    &simulate[..],
                    &["--flight-video", "lossless", "--flight-out", rec_s],
                ]
                .concat(),
            );
            rec.join("flight.toml")
        }
    };
    let source = source.to_str().unwrap();
    let config = dir.0.join("exact-navigation.toml");
    std::fs::write(&config, EXACT_NAVIGATION).unwrap();
    dualgeo(&[
        "run",
        "--source",
        source,
        "--rate",
        "max",
        "--config",
        config.to_str().unwrap(),
        "--out",
        out_s,
    ]);

    // The left camera's truth by time (a flight's stream times are the autopilot
    // clock's milliseconds: the nearest frame, within half a period).
    let truth: Vec<(f64, [f64; 3])> = rows(&rec.join("truth.csv"))
        .into_iter()
        .filter(|r| r["uav"] == "left")
        .map(|r| {
            let v = |k: &str| r[k].parse::<f64>().unwrap();
            (
                v("t_s"),
                [v("target_x_m"), v("target_y_m"), v("target_z_m")],
            )
        })
        .collect();
    let (mut h, mut z) = (Vec::new(), Vec::new());
    // The target's rows (track_id 0): the scenes' other vehicles have tracks of their
    // own.
    for r in rows(&out.join("track.csv"))
        .into_iter()
        .filter(|r| r.get("track_id").is_none_or(|id| id == "0"))
    {
        let t: f64 = r["t_s"].parse().unwrap();
        if t < 8.0 {
            continue;
        }
        let (dt, want) = truth
            .iter()
            .map(|(tt, p)| ((tt - t).abs(), *p))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .expect("truth rows");
        assert!(dt < 1.0 / 60.0, "no truth near t = {t}");
        let got = ["x_m", "y_m", "z_m"].map(|k| r[k].parse::<f64>().unwrap());
        h.push((got[0] - want[0]).hypot(got[1] - want[1]));
        z.push((got[2] - want[2]).abs());
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    eprintln!(
        "{preset}: {} estimates after 8 s: horizontal MAE {:.2} m, altitude MAE {:.2} m",
        h.len(),
        mean(&h),
        mean(&z)
    );
    // 4 s at 30 FPS: 120 pairs.
    assert!(h.len() >= 60, "{} estimates after 8 s", h.len());
    assert!(
        mean(&h) < 1.0 && mean(&z) < 1.0,
        "{preset}: MAE {} / {}",
        mean(&h),
        mean(&z)
    );
}
