//! Issue #14: the target goes out as MAVLink and Cursor-on-Target, and clients nobody
//! here wrote decode every message: pymavlink (from PyPI, in target/pyenv, installed by
//! scripts/py_test_env.sh) and Python's XML parser (tests/clients/listen.py). A short
//! live-simulator run; each decoded position must match track.csv row for row. The
//! `--mcap` recording is read back by Foxglove's `mcap` package (tests/clients/read_mcap.py).

#[path = "support/py_env.rs"]
mod py_env;
#[path = "support/scratch.rs"]
mod scratch;

use py_env::{python, root};
use scratch::Scratch;
use serde_json::Value;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::{Mutex, MutexGuard};

/// The two live runs below each need both of the machine's cores. Run side by side (the
/// harness's default), the MAVLink run made 12–16 estimates in 6 s instead of 51–54
/// alone, and 4 on a busy CI machine, below what it asks. They take turns.
static LIVE_RUN: Mutex<()> = Mutex::new(());

fn live_run_turn() -> MutexGuard<'static, ()> {
    // A test that failed holding the turn poisons it; the next one still runs.
    LIVE_RUN
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// (lat, lon, hae) of each of the target's rows of track.csv (track_id 0).
fn track(path: &Path) -> Vec<[f64; 3]> {
    let text = std::fs::read_to_string(path).expect("track.csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (lat, lon, alt, id) = (
        col("lat_deg"),
        col("lon_deg"),
        col("alt_m"),
        col("track_id"),
    );
    lines
        .filter(|l| l.split(',').nth(id) == Some("0"))
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            [lat, lon, alt].map(|i| f[i].parse::<f64>().expect("a geodetic column"))
        })
        .collect()
}

#[test]
fn mavlink_and_cot_outputs_are_decoded_by_outside_clients() {
    let python = match python() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("SKIPPED: pymavlink could not be installed from PyPI: {e}");
            return;
        }
    };
    let mut listener = Command::new(&python)
        .arg(root().join("tests/clients/listen.py"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("start the listener");
    let mut out_lines = BufReader::new(listener.stdout.take().expect("stdout"));
    let mut ports = String::new();
    out_lines.read_line(&mut ports).expect("PORTS line");
    let ports: Vec<&str> = ports.split_whitespace().skip(1).collect();
    assert_eq!(ports.len(), 2, "listener said {ports:?}");

    let _turn = live_run_turn();
    let dir = Scratch::new("live-out");
    let out = dir.0.join("out");
    let run = Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args(["run", "--duration-s", "6", "--out"])
        .arg(&out)
        .arg("--mavlink-out")
        .arg(format!("udpout:127.0.0.1:{}", ports[0]))
        .arg("--cot-out")
        .arg(format!("udp://127.0.0.1:{}", ports[1]))
        .output()
        .expect("run dualgeo");
    assert!(
        run.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    drop(listener.stdin.take()); // the listener reports when its stdin closes
    let mut report = String::new();
    out_lines.read_to_string(&mut report).expect("report");
    assert!(listener.wait().expect("listener exit").success());
    let report: Value = serde_json::from_str(report.trim()).expect("the listener's JSON");

    let rows = track(&out.join("track.csv"));
    eprintln!("{} estimates in 6 s", rows.len()); // the figure to look at when it fails
                                                  // Enough rows to compare (the count depends on the load: the simulator skips the
                                                  // pairs it renders too late, issue #15); each row is checked below.
    assert!(rows.len() > 10, "only {} estimates in 6 s", rows.len());
    assert_eq!(report["mavlink_bad"], 0, "undecodable MAVLink datagrams");
    assert_eq!(report["cot_bad"], 0, "events that are not CoT 2.0");

    let messages = report["mavlink"].as_array().expect("mavlink list");
    let of_type = |t: &str| -> Vec<&Value> {
        messages
            .iter()
            .filter(|m| m["mavpackettype"] == t)
            .collect()
    };
    let tracking = of_type("CAMERA_TRACKING_GEO_STATUS");
    let heartbeats = of_type("HEARTBEAT");
    let vehicles = of_type("ADSB_VEHICLE");
    assert_eq!(
        tracking.len() + heartbeats.len() + vehicles.len(),
        messages.len()
    );
    assert_eq!(
        tracking.len(),
        rows.len(),
        "one MAVLink message per estimate"
    );
    assert!(
        heartbeats.len() >= 5,
        "{} heartbeats in a 6 s run",
        heartbeats.len()
    );
    for m in messages {
        assert_eq!(m["srcSystem"], 255);
        assert_eq!(m["srcComponent"], 100);
    }
    assert_eq!(heartbeats[0]["type"], 30, "MAV_TYPE_CAMERA");
    // A message's degE7 position and altitude (`alt_key`, in `alt_unit` metres) against
    // a track.csv row.
    let same_place = |m: &Value, row: &[f64; 3], alt_key: &str, alt_unit: f64| {
        let lat = m["lat"].as_f64().unwrap() / 1e7;
        let lon = m["lon"].as_f64().unwrap() / 1e7;
        let alt = m[alt_key].as_f64().unwrap() * alt_unit;
        assert!(
            (lat - row[0]).abs() < 2e-7 && (lon - row[1]).abs() < 2e-7,
            "{m} vs {row:?}"
        );
        assert!((alt - row[2]).abs() < 0.01, "{m} vs {row:?}");
    };
    for (m, row) in tracking.iter().zip(&rows) {
        same_place(m, row, "alt", 1.0);
        assert!(m["h_acc"].as_f64().is_some_and(|h| h > 0.0), "{m}");
        // The default estimator is the temporal filter: its velocity is known.
        assert!(
            m["vel_n"].as_f64().is_some() && m["vel_acc"].as_f64().is_some(),
            "{m}"
        );
        assert!(
            m["vel_d"].is_null(),
            "no vertical velocity is modelled: NaN"
        );
        assert!(m["dist"].as_f64().is_some_and(|d| d > 50.0), "{m}");
    }

    // Every vehicle as an ADSB_VEHICLE with its id in the ICAO address: the default
    // scene has the target alone (id 0, address 0xF00000, callsign DGV0).
    assert_eq!(vehicles.len(), rows.len(), "one ADSB_VEHICLE per estimate");
    for (m, row) in vehicles.iter().zip(&rows) {
        assert_eq!(m["ICAO_address"], 0xF0_0000, "{m}");
        assert_eq!(m["callsign"], "DGV0", "{m}");
        assert_eq!(
            m["emitter_type"], 18,
            "ADSB_EMITTER_TYPE_SERVICE_SURFACE: {m}"
        );
        same_place(m, row, "altitude", 1e-3);
    }

    let events = report["cot"].as_array().expect("cot list");
    assert_eq!(events.len(), rows.len(), "one CoT event per estimate");
    let uid = &events[0]["uid"];
    for (ev, row) in events.iter().zip(&rows) {
        assert_eq!(&ev["uid"], uid, "one target, one uid");
        assert_eq!(ev["type"], "a-u-G-E-V");
        let p = &ev["point"];
        assert!((p["lat"].as_f64().unwrap() - row[0]).abs() < 1e-6, "{ev}");
        assert!((p["lon"].as_f64().unwrap() - row[1]).abs() < 1e-6, "{ev}");
        assert!(p["ce"].as_f64().unwrap() < 1000.0, "{ev}");
        assert!(ev["stale"].as_str() > ev["time"].as_str());
    }

    let counters: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("counters.json")).unwrap()).unwrap();
    assert_eq!(counters["supervisor.mavlink.sent"], rows.len());
    assert_eq!(counters["supervisor.mavlink.vehicles_sent"], rows.len());
    assert_eq!(counters["supervisor.cot.sent"], rows.len());
    assert!(counters.get("supervisor.mavlink.send_failed").is_none());
}

#[test]
fn an_output_address_that_is_wrong_is_refused_before_anything_starts() {
    let dir = Scratch::new("live-out-bad");
    for (flag, value, says) in [
        ("--mavlink-out", "udp:127.0.0.1:14550", "udpout:HOST:PORT"),
        ("--cot-out", "tcp://127.0.0.1:1", "udp://HOST:PORT"),
        (
            "--mavlink-out",
            "udpout:no-such-host.invalid:1",
            "cannot resolve",
        ),
        ("--mcap", "/no/such/dir/run.mcap", "no directory"),
        ("--mavlink-primary", "nearest:95,0", "nearest:LAT,LON"),
        ("--mavlink-icao-base", "0x1000000", "24 bits"),
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_dualgeo"))
            .args(["run", "--duration-s", "1", "--out"])
            .arg(dir.0.join("out"))
            .args([flag, value])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .output()
            .expect("run dualgeo");
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{flag} {value} was accepted");
        assert!(stderr.contains(says), "{flag} {value}: {stderr}");
        assert!(!dir.0.join("out/track.csv").exists(), "something started");
    }
}

#[test]
fn the_mcap_recording_is_read_back_by_the_mcap_reader() {
    let python = match python() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("SKIPPED: the mcap package could not be installed from PyPI: {e}");
            return;
        }
    };
    let _turn = live_run_turn();
    let dir = Scratch::new("mcap-out");
    let out = dir.0.join("out");
    let file = dir.0.join("run.mcap");
    let run = Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args([
            "run",
            "--duration-s",
            "5",
            "--mcap-image-every",
            "2",
            "--out",
        ])
        .arg(&out)
        .arg("--mcap")
        .arg(&file)
        .output()
        .expect("run dualgeo");
    assert!(
        run.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    let read = Command::new(&python)
        .arg(root().join("tests/clients/read_mcap.py"))
        .arg(&file)
        .output()
        .expect("run the reader");
    assert!(
        read.status.success(),
        "{}",
        String::from_utf8_lossy(&read.stderr)
    );
    let report: Value = serde_json::from_slice(&read.stdout).expect("the reader's JSON");
    let counters: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("counters.json")).unwrap()).unwrap();
    let counter = |name: &str| counters[name].as_u64().unwrap_or(0);

    let expected = [
        ("/left/image", "foxglove.CompressedImage"),
        ("/right/image", "foxglove.CompressedImage"),
        ("/left/pose", "foxglove.PoseInFrame"),
        ("/right/pose", "foxglove.PoseInFrame"),
        ("/left/detection", "foxglove.ImageAnnotations"),
        ("/right/detection", "foxglove.ImageAnnotations"),
        ("/target/fix", "foxglove.LocationFix"),
        ("/target/pose", "foxglove.PoseInFrame"),
        ("/latency", "dualgeo.StageLatency"),
        ("/target/quality", "dualgeo.TargetQuality"),
        ("/targets", "dualgeo.Targets"),
    ];
    let channels = report["channels"].as_object().expect("channels");
    assert_eq!(channels.len(), expected.len(), "{channels:?}");
    for (topic, schema) in expected {
        let c = &channels[topic];
        assert_eq!(c["schema"], schema, "{topic}");
        assert_eq!(c["schema_encoding"], "jsonschema", "{topic}");
        assert_eq!(c["message_encoding"], "json", "{topic}");
        assert_eq!(
            c["read"], c["summary_count"],
            "{topic}: read back vs summary"
        );
        let n = c["read"].as_u64().unwrap();
        assert!(n > 0, "{topic} is empty");
        let key = format!("supervisor.mcap{}", topic.replace('/', "."));
        assert_eq!(n, counter(&key), "{topic}: in the file vs counted");
    }
    assert_eq!(report["bad_json"], 0);
    assert_eq!(report["bad_images"], 0);

    // Every frame the recorder saw has its pose and its detection; every second one its
    // image (sequence numbers start at 0); frames it missed are counted.
    let n = |topic: &str| channels[topic]["read"].as_u64().unwrap();
    let lost = counter("supervisor.mcap.frames_lost");
    assert_eq!(
        n("/left/pose") + n("/right/pose") + lost,
        counter("acquisition.frames_in"),
        "frames: recorded + lost = streamed"
    );
    for uav in ["left", "right"] {
        let poses = n(&format!("/{uav}/pose"));
        assert_eq!(n(&format!("/{uav}/detection")), poses, "{uav}");
        let images = n(&format!("/{uav}/image"));
        assert!(
            images.abs_diff(poses.div_ceil(2)) <= lost,
            "{uav}: {images} images of {poses} frames"
        );
    }

    // The target: one fix per track.csv row, at its position; a latency record per
    // estimate message whose stages add up to its end-to-end time.
    let rows = track(&out.join("track.csv"));
    let fixes = report["fixes"].as_array().expect("fixes");
    assert!(rows.len() > 10, "only {} estimates", rows.len());
    assert_eq!(fixes.len(), rows.len());
    for (f, row) in fixes.iter().zip(&rows) {
        for (i, tol) in [(0, 2e-7), (1, 2e-7), (2, 0.01)] {
            assert!(
                (f[i].as_f64().unwrap() - row[i]).abs() < tol,
                "{f} vs {row:?}"
            );
        }
    }
    assert!(n("/latency") >= n("/target/fix"));
    // Every estimate says how far it can be trusted (issue #23).
    assert_eq!(n("/target/quality"), n("/target/pose"));
    // One vehicle in this scene: /targets lists the target alone, once per fix.
    assert_eq!(n("/targets"), n("/target/fix"));
    assert_eq!(
        report["target_ids"],
        serde_json::json!({"0": n("/target/fix")})
    );
    let qualities = report["qualities"].as_object().expect("qualities");
    assert!(
        qualities
            .keys()
            .all(|q| ["converging", "tracking", "coasting"].contains(&q.as_str())),
        "{qualities:?}"
    );
    assert!(report["latency_sum_error_ms"].as_f64().unwrap() < 1e-3);
}
