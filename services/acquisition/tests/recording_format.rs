//! Recording format v1 (v2's tilted and gimballed cameras: recording_format_v2.rs): round trip, and one test per kind of bad input, each checking
//! that the error names the file (and for CSV the line and column).

use acquisition::recording::{
    CameraMeta, Origin, Recording, RecordingError, RecordingMeta, RecordingWriter, TruthSample,
};
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::conventions::Uav;
use shared_types::messages::PoseSample;
use std::path::{Path, PathBuf};
use tempfile::TempDir;

const W: u32 = 64;
const H: u32 = 48;

fn meta() -> RecordingMeta {
    let camera = CameraMeta {
        width: W,
        height: H,
        fx: 55.4,
        fy: 55.4,
        cx: 31.5,
        cy: 23.5,
        distortion: [0.0; 5],
    };
    let origin = Some(Origin {
        lat_deg: 30.2741,
        lon_deg: 120.1551,
        alt_m: 12.0,
    });
    RecordingMeta::new("unit", 30.0, camera, origin)
}

fn image(seed: u8, channels: i32) -> cv::Mat {
    let typ = if channels == 1 {
        cv::CV_8UC1
    } else {
        cv::CV_8UC3
    };
    let mut m =
        cv::Mat::new_rows_cols_with_default(H as i32, W as i32, typ, cv::Scalar::all(0.0)).unwrap();
    for (i, b) in m.data_bytes_mut().unwrap().iter_mut().enumerate() {
        *b = (i as u32)
            .wrapping_mul(2_654_435_761)
            .wrapping_add(seed as u32 * 97) as u8;
    }
    m
}

/// A valid 3-frame-per-UAV recording with truth; frames alternate grey and BGR.
fn write_valid() -> (TempDir, PathBuf) {
    let dir = TempDir::new().unwrap();
    let root = dir.path().join("rec");
    let mut w = RecordingWriter::create(&root, &meta(), true).unwrap();
    for k in 0..3u8 {
        for uav in [Uav::Left, Uav::Right] {
            let t = k as f64 / 30.0 + if uav == Uav::Right { 0.001 } else { 0.0 };
            let pose = PoseSample {
                x_m: if uav == Uav::Left { -35.02 } else { 34.88 } + k as f64 * 0.1,
                y_m: 0.41 * k as f64,
                z_m: 100.73,
                yaw_deg: 1.93,
                pitch_deg: 0.52,
                roll_deg: -0.1 / 3.0,
                mount: Default::default(),
            };
            let truth = TruthSample {
                pose: PoseSample {
                    yaw_deg: 0.0,
                    ..pose
                },
                target: [1.0, 2.0 + k as f64, 13.5],
                target_px: if k == 1 {
                    None
                } else {
                    Some([31.25, 20.0 / 3.0])
                },
                gimbal: None,
            };
            w.write_frame(
                uav,
                t,
                pose,
                &image(k * 2 + uav.index() as u8, 1 + 2 * (k as i32 % 2)),
                Some(&truth),
            )
            .unwrap();
        }
    }
    w.finish().unwrap();
    (dir, root)
}

fn open_err(root: &Path) -> String {
    let e = Recording::open(root).expect_err("recording should be rejected");
    e.to_string()
}

fn edit_line(path: &Path, line: usize, f: impl FnOnce(&str) -> String) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    lines[line - 1] = f(&lines[line - 1]);
    std::fs::write(path, lines.join("\n") + "\n").unwrap();
}

fn set_field(path: &Path, line: usize, column: usize, value: &str) {
    edit_line(path, line, |l| {
        let mut f: Vec<&str> = l.split(',').collect();
        f[column - 1] = value;
        f.join(",")
    });
}

#[test]
fn round_trip_is_identical() {
    let (_dir, root) = write_valid();
    let rec = Recording::open(&root).unwrap();
    assert_eq!(rec.meta, meta());
    assert_eq!(rec.telemetry.len(), 6);
    let truth = rec.truth.as_ref().unwrap();
    assert_eq!(truth[2].target_px, None);
    assert_eq!(truth[0].target_px, Some([31.25, 20.0 / 3.0]));
    assert_eq!(rec.telemetry[1].pose.roll_deg, -0.1 / 3.0);
    for (i, row) in rec.telemetry.iter().enumerate() {
        let k = row.frame as u8;
        let want = image(k * 2 + row.uav.index() as u8, 1 + 2 * (k as i32 % 2));
        let got = rec.read_image(i).unwrap();
        assert_eq!(
            got.data_bytes().unwrap(),
            want.data_bytes().unwrap(),
            "{}",
            row.file
        );
    }
    // Written again from what was read: byte-identical files.
    let dir2 = TempDir::new().unwrap();
    let root2 = dir2.path().join("rec");
    let mut w = RecordingWriter::create(&root2, &rec.meta, true).unwrap();
    for (i, row) in rec.telemetry.iter().enumerate() {
        let t = &truth[i];
        let sample = TruthSample {
            pose: t.pose,
            target: t.target,
            target_px: t.target_px,
            gimbal: None,
        };
        w.write_frame(
            row.uav,
            row.t_s,
            row.pose,
            &rec.read_image(i).unwrap(),
            Some(&sample),
        )
        .unwrap();
    }
    w.finish().unwrap();
    for f in [
        "recording.toml",
        "telemetry.csv",
        "truth.csv",
        "left/000002.png",
        "right/000001.png",
    ] {
        assert_eq!(
            std::fs::read(root.join(f)).unwrap(),
            std::fs::read(root2.join(f)).unwrap(),
            "{f}"
        );
    }
    assert_eq!(Recording::open(&root2).unwrap().telemetry, rec.telemetry);
    assert_eq!(rec.pairs().len(), 3);
}

#[test]
fn missing_metadata() {
    let (_d, root) = write_valid();
    std::fs::remove_file(root.join("recording.toml")).unwrap();
    let e = open_err(&root);
    assert!(e.contains("recording.toml") && e.contains("missing"), "{e}");
}

#[test]
fn missing_telemetry() {
    let (_d, root) = write_valid();
    std::fs::remove_file(root.join("telemetry.csv")).unwrap();
    let e = open_err(&root);
    assert!(e.contains("telemetry.csv") && e.contains("missing"), "{e}");
}

#[test]
fn missing_image() {
    let (_d, root) = write_valid();
    std::fs::remove_file(root.join("left/000001.png")).unwrap();
    let e = open_err(&root);
    assert!(
        e.contains("left/000001.png") && e.contains("missing"),
        "{e}"
    );
}

#[test]
fn extra_image_in_a_frames_folder() {
    let (_d, root) = write_valid();
    std::fs::copy(root.join("right/000000.png"), root.join("right/000099.png")).unwrap();
    let e = open_err(&root);
    assert!(
        e.contains("right/000099.png") && e.contains("unexpected file"),
        "{e}"
    );
}

#[test]
fn extra_top_level_file() {
    let (_d, root) = write_valid();
    std::fs::write(root.join("notes.txt"), "x").unwrap();
    let e = open_err(&root);
    assert!(
        e.contains("notes.txt") && e.contains("unexpected file"),
        "{e}"
    );
}

#[test]
fn bad_header() {
    let (_d, root) = write_valid();
    edit_line(&root.join("telemetry.csv"), 1, |l| {
        l.replace("yaw_deg", "heading")
    });
    let e = open_err(&root);
    assert!(
        e.contains("telemetry.csv line 1") && e.contains("bad or missing header"),
        "{e}"
    );
}

#[test]
fn missing_header() {
    let (_d, root) = write_valid();
    let p = root.join("truth.csv");
    let text = std::fs::read_to_string(&p).unwrap();
    std::fs::write(&p, text.split_once('\n').unwrap().1).unwrap();
    let e = open_err(&root);
    assert!(
        e.contains("truth.csv line 1") && e.contains("bad or missing header"),
        "{e}"
    );
}

#[test]
fn unknown_uav() {
    let (_d, root) = write_valid();
    set_field(&root.join("telemetry.csv"), 3, 1, "centre");
    let e = open_err(&root);
    assert!(
        e.contains("telemetry.csv line 3, column 1 (uav)") && e.contains("unknown uav \"centre\""),
        "{e}"
    );
}

#[test]
fn nan_in_telemetry() {
    let (_d, root) = write_valid();
    set_field(&root.join("telemetry.csv"), 4, 5, "NaN");
    let e = open_err(&root);
    assert!(
        e.contains("telemetry.csv line 4, column 5 (x_m)") && e.contains("not finite"),
        "{e}"
    );
}

#[test]
fn inf_in_truth() {
    let (_d, root) = write_valid();
    set_field(&root.join("truth.csv"), 5, 12, "inf");
    let e = open_err(&root);
    assert!(
        e.contains("truth.csv line 5, column 12 (target_z_m)") && e.contains("not finite"),
        "{e}"
    );
}

#[test]
fn not_a_number() {
    let (_d, root) = write_valid();
    set_field(&root.join("telemetry.csv"), 2, 9, "1.2.3");
    let e = open_err(&root);
    assert!(
        e.contains("line 2, column 9 (pitch_deg)") && e.contains("not a number"),
        "{e}"
    );
}

#[test]
fn timestamps_not_increasing() {
    let (_d, root) = write_valid();
    // Line 6 is the left UAV's third frame (lines: header, L0, R0, L1, R1, L2, R2).
    set_field(&root.join("telemetry.csv"), 6, 4, "0.01");
    let e = open_err(&root);
    assert!(
        e.contains("telemetry.csv line 6, column 4 (t_s)") && e.contains("does not increase"),
        "{e}"
    );
}

#[test]
fn wrong_field_count() {
    let (_d, root) = write_valid();
    edit_line(&root.join("telemetry.csv"), 3, |l| format!("{l},extra"));
    let e = open_err(&root);
    assert!(
        e.contains("telemetry.csv line 3") && e.contains("11 fields"),
        "{e}"
    );
}

#[test]
fn truth_disagrees_with_telemetry() {
    let (_d, root) = write_valid();
    set_field(&root.join("truth.csv"), 7, 3, "0.5");
    let e = open_err(&root);
    assert!(
        e.contains("truth.csv line 7, column 3 (t_s)") && e.contains("differs from telemetry.csv"),
        "{e}"
    );
}

#[test]
fn bad_metadata_version_and_unknown_key() {
    let (_d, root) = write_valid();
    let p = root.join("recording.toml");
    let text = std::fs::read_to_string(&p).unwrap();
    std::fs::write(&p, text.replace("version = 1", "version = 3")).unwrap();
    let e = open_err(&root);
    assert!(
        e.contains("recording.toml") && e.contains("unsupported version 3"),
        "{e}"
    );
    std::fs::write(
        &p,
        text.replace("name = \"unit\"", "name = \"unit\"\nfps = 3"),
    )
    .unwrap();
    let e = open_err(&root);
    assert!(e.contains("recording.toml") && e.contains("fps"), "{e}");
}

#[test]
fn image_size_differs_from_metadata() {
    let (_d, root) = write_valid();
    let small =
        cv::Mat::new_rows_cols_with_default(10, 10, cv::CV_8UC1, cv::Scalar::all(5.0)).unwrap();
    opencv::imgcodecs::imwrite_def(root.join("left/000002.png").to_str().unwrap(), &small).unwrap();
    let rec = Recording::open(&root).unwrap();
    let index = rec
        .telemetry
        .iter()
        .position(|r| r.file == "left/000002.png")
        .unwrap();
    let e = rec.read_image(index).unwrap_err();
    assert!(matches!(e, RecordingError::ImageSize { got_width: 10, .. }));
    assert!(
        e.to_string().contains("left/000002.png") && e.to_string().contains("64x48"),
        "{e}"
    );
}

#[test]
fn unreadable_and_truncated_images() {
    let (_d, root) = write_valid();
    let rec = Recording::open(&root).unwrap();
    let idx = |f: &str| rec.telemetry.iter().position(|r| r.file == f).unwrap();

    std::fs::write(root.join("left/000000.png"), b"definitely not an image").unwrap();
    let e = rec
        .read_image(idx("left/000000.png"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("left/000000.png") && e.contains("unreadable"),
        "{e}"
    );

    let p = root.join("right/000001.png");
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    let e = rec
        .read_image(idx("right/000001.png"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("right/000001.png") && e.contains("truncated PNG"),
        "{e}"
    );

    // A truncated JPEG decodes "successfully" in libjpeg; it must still be rejected.
    let mut jpg = cv::Vector::<u8>::new();
    opencv::imgcodecs::imencode_def(".jpg", &image(3, 3), &mut jpg).unwrap();
    let whole = jpg.to_vec();
    std::fs::write(root.join("right/000002.png"), &whole[..whole.len() - 40]).unwrap();
    let e = rec
        .read_image(idx("right/000002.png"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("truncated JPEG"), "{e}");
    std::fs::write(root.join("right/000002.png"), &whole).unwrap();
    assert!(rec.read_image(idx("right/000002.png")).is_ok());
}

#[test]
fn writer_refuses_non_empty_output_and_bad_frames() {
    let (_d, root) = write_valid();
    assert!(RecordingWriter::create(&root, &meta(), true).is_err());
    let dir = TempDir::new().unwrap();
    let mut w = RecordingWriter::create(dir.path().join("r"), &meta(), false).unwrap();
    let pose = PoseSample::default();
    let wrong =
        cv::Mat::new_rows_cols_with_default(5, 5, cv::CV_8UC1, cv::Scalar::all(0.0)).unwrap();
    assert!(w.write_frame(Uav::Left, 0.0, pose, &wrong, None).is_err());
    w.write_frame(Uav::Left, 0.0, pose, &image(1, 1), None)
        .unwrap();
    assert!(
        w.write_frame(Uav::Left, 0.0, pose, &image(1, 1), None)
            .is_err(),
        "time must increase"
    );
    let nan = PoseSample {
        x_m: f64::NAN,
        ..pose
    };
    assert!(w
        .write_frame(Uav::Left, 1.0, nan, &image(1, 1), None)
        .is_err());
}
