//! End-to-end: `dualgeo simulate` as a user runs it.

use std::process::{Command, Output};

fn dualgeo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args(args)
        .output()
        .expect("spawn dualgeo")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A scratch folder removed when dropped, even if the test fails.
struct Scratch(std::path::PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let p = std::env::temp_dir().join(format!("dualgeo-e2e-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        Self(p)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn simulate_writes_a_valid_recording() {
    let out = Scratch::new("sim");
    let o = dualgeo(&[
        "simulate",
        "--preset",
        "default",
        "--duration-s",
        "0.5",
        "--out",
        out.0.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("15 stereo pairs"), "{}", stdout(&o));
    let telemetry = std::fs::read_to_string(out.0.join("telemetry.csv")).unwrap();
    assert_eq!(telemetry.lines().count(), 31);
    assert!(telemetry.starts_with("uav,frame,file,t_s,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg\n"));
    let meta = std::fs::read_to_string(out.0.join("recording.toml")).unwrap();
    assert!(
        meta.contains("format = \"dual-uav-recording\"") && meta.contains("[origin]"),
        "{meta}"
    );
    assert!(out.0.join("left/000014.png").is_file() && out.0.join("right/000014.png").is_file());

    let v = dualgeo(&["validate", out.0.to_str().unwrap()]);
    assert!(v.status.success(), "{}", stderr(&v));
    assert!(
        stdout(&v).contains("15 left and 15 right images, 15 stereo pairs")
            && stdout(&v).contains("truth yes"),
        "{}",
        stdout(&v)
    );

    // A corrupt image is found by validate, named, and the exit code says so.
    let png = out.0.join("right/000007.png");
    let original = std::fs::read(&png).unwrap();
    std::fs::write(&png, &original[..original.len() / 3]).unwrap();
    let v = dualgeo(&["validate", out.0.to_str().unwrap()]);
    assert!(!v.status.success());
    assert!(
        stderr(&v).contains("right/000007.png") && stderr(&v).contains("truncated PNG"),
        "{}",
        stderr(&v)
    );
    std::fs::write(&png, original).unwrap();

    // Writing into the same, now non-empty, folder is refused and nothing is lost.
    let again = dualgeo(&[
        "simulate",
        "--duration-s",
        "0.2",
        "--out",
        out.0.to_str().unwrap(),
    ]);
    assert!(!again.status.success());
    assert!(stderr(&again).contains("not empty"), "{}", stderr(&again));
    assert!(out.0.join("left/000014.png").is_file());
}

#[test]
fn presets_can_be_listed_printed_and_are_checked() {
    let o = dualgeo(&["simulate", "--list"]);
    assert!(o.status.success());
    for name in [
        "default",
        "table1",
        "table2",
        "fig9_att5",
        "fig10_pos1",
        "fig11_both3",
        "fig12_bias30",
    ] {
        assert!(
            stdout(&o).lines().any(|l| l.starts_with(name)),
            "{name} missing from:\n{}",
            stdout(&o)
        );
    }
    let o = dualgeo(&["simulate", "--preset", "fig12_bias25", "--print"]);
    assert!(o.status.success());
    assert!(stdout(&o).contains("delta0_deg = 25.0"), "{}", stdout(&o));

    let o = dualgeo(&["simulate", "--preset", "nope", "--out", "/nonexistent"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("no preset \"nope\""), "{}", stderr(&o));

    let bad = Scratch::new("presets.toml");
    std::fs::write(&bad.0, "[mine]\nbase = \"default\"\n").unwrap();
    let o = dualgeo(&[
        "simulate",
        "--presets",
        bad.0.to_str().unwrap(),
        "--preset",
        "mine",
        "--print",
    ]);
    assert!(
        !o.status.success(),
        "a preset file without the base it names must fail"
    );
    assert!(
        stderr(&o).contains("no preset \"default\""),
        "{}",
        stderr(&o)
    );
}

/// Issue #23 item 5: `--crf` encodes the flight's H.264 at that quality through
/// `ffmpeg`; it is refused where it means nothing (a recording, a lossless flight) or
/// outside x264's range, before anything is rendered.
#[test]
fn a_flight_is_encoded_at_the_crf_asked_and_bad_crfs_are_refused() {
    let dir = Scratch::new("crf-flight");
    let o = dualgeo(&[
        "simulate",
        "--preset",
        "default",
        "--duration-s",
        "0.5",
        "--flight-out",
        dir.0.to_str().unwrap(),
        "--crf",
        "28",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("libx264 through ffmpeg"),
        "{}",
        stderr(&o)
    );
    for uav in ["left", "right"] {
        let video = dir.0.join(format!("{uav}.mp4"));
        let bytes = std::fs::read(&video).unwrap_or_default();
        // An MP4 starts with its `ftyp` box.
        assert!(
            bytes.len() > 1000 && &bytes[4..8] == b"ftyp",
            "{}",
            video.display()
        );
    }
    let recording = Scratch::new("crf-recording");
    let refused = [
        vec!["--out", recording.0.to_str().unwrap(), "--crf", "18"],
        vec![
            "--flight-out",
            recording.0.to_str().unwrap(),
            "--flight-video",
            "lossless",
            "--crf",
            "18",
        ],
        vec!["--flight-out", recording.0.to_str().unwrap(), "--crf", "52"],
    ];
    for args in refused {
        let mut all = vec!["simulate", "--preset", "default", "--duration-s", "0.5"];
        all.extend(&args);
        let o = dualgeo(&all);
        assert!(!o.status.success(), "{args:?} was taken");
        assert!(stderr(&o).contains("crf"), "{args:?}: {}", stderr(&o));
        assert!(
            !recording.0.join("left.mp4").exists(),
            "{args:?} wrote a video"
        );
    }
}
