//! End-to-end: a multi-vehicle scene's truth (`dualgeo simulate`, truth_targets.csv)
//! and `dualgeo score` on track files made from it, as a user runs them.

#[path = "support/scratch.rs"]
mod scratch;

use scratch::{json, Scratch};
use std::collections::BTreeMap;
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

/// (uav, frame, id) → (t, x, y, z, pixel shown).
type Vehicles = BTreeMap<(String, u64, u32), (f64, [f64; 3], bool)>;

fn read_vehicles(path: &std::path::Path) -> Vehicles {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("uav,frame,t_s,target_id,target_x_m,target_y_m,target_z_m,target_u_px,target_v_px")
    );
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let n = |i: usize| f[i].parse::<f64>().unwrap();
            (
                (
                    f[0].to_string(),
                    f[1].parse().unwrap(),
                    f[3].parse().unwrap(),
                ),
                (n(2), [n(4), n(5), n(6)], !f[7].is_empty()),
            )
        })
        .collect()
}

/// A track.csv with one row per vehicle both UAVs show, at the left image's time;
/// `edit(frame, id)` gives (track id, offset in x) or drops the row.
fn track_from_truth(
    v: &Vehicles,
    frames: u64,
    edit: impl Fn(u64, u32) -> Option<(u32, f64)>,
) -> String {
    let mut out = String::from("t_s,pair_seq,x_m,y_m,z_m,track_id\n");
    for frame in 0..frames {
        for id in 0..10 {
            let (Some(l), Some(r)) = (
                v.get(&("left".into(), frame, id)),
                v.get(&("right".into(), frame, id)),
            ) else {
                continue;
            };
            if !(l.2 && r.2) {
                continue;
            }
            if let Some((track, dx)) = edit(frame, id) {
                let [x, y, z] = l.1;
                out += &format!("{},{frame},{},{y},{z},{track}\n", l.0, x + dx);
            }
        }
    }
    out
}

#[test]
fn a_multi_vehicle_scene_lists_every_moving_vehicle_and_scores_tracks_against_them() {
    let dir = Scratch::new("score");
    let rec = dir.join("rec");
    let o = dualgeo(&[
        "simulate",
        "--preset",
        "multi_town",
        "--duration-s",
        "2",
        "--out",
        rec.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let frames = 60;

    // Five moving vehicles in every image (the parked one is not listed); id 0 is
    // truth.csv's target, at the same point and pixel unless hidden.
    let v = read_vehicles(&rec.join("truth_targets.csv"));
    assert_eq!(v.len() as u64, 2 * frames * 5);
    assert!(v.keys().all(|k| k.2 <= 4));
    let truth = std::fs::read_to_string(rec.join("truth.csv")).unwrap();
    for line in truth.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let key = (f[0].to_string(), f[1].parse().unwrap(), 0);
        let (_, p, shown) = v[&key];
        let tp: Vec<f64> = f[9..12].iter().map(|s| s.parse().unwrap()).collect();
        assert_eq!(p.to_vec(), tp, "{line}");
        assert!(!shown || !f[12].is_empty(), "{line}");
    }
    let shown_both = (0..frames)
        .flat_map(|k| (0..5).map(move |id| (k, id)))
        .filter(|(k, id)| v[&("left".into(), *k, *id)].2 && v[&("right".into(), *k, *id)].2)
        .count();
    assert!(
        shown_both >= 150,
        "{shown_both} vehicle-pairs in view of both"
    );

    let score = |name: &str, track: String, extra: &[&str]| -> serde_json::Value {
        let path = dir.join(&format!("{name}.csv"));
        std::fs::write(&path, track).unwrap();
        let out = dir.join(&format!("{name}.json"));
        let mut args = vec![
            "score",
            "--recording",
            rec.to_str().unwrap(),
            "--track",
            path.to_str().unwrap(),
            "--json",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = dualgeo(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        json(&out)
    };

    // Perfect tracks: nothing missed, nothing false, no switch.
    let s = score(
        "perfect",
        track_from_truth(&v, frames, |_, id| Some((10 + id, 0.0))),
        &["--switch-penalty-m", "0"],
    );
    assert_eq!(s["truth_file"], "truth_targets.csv");
    assert_eq!(s["clear"]["mota"], 1.0);
    assert_eq!(s["clear"]["truth"], shown_both as u64);
    assert_eq!(s["clear"]["id_switches"], 0);
    assert_eq!(s["id"]["idf1"], 1.0);
    assert_eq!(s["gospa"]["mean_m"], 0.0);
    assert_eq!(s["vehicles"].as_array().unwrap().len(), 5);

    // Tracks 0 and 1 swap their vehicles halfway: two identity switches.
    let s = score(
        "swapped",
        track_from_truth(&v, frames, |k, id| {
            let id = if k >= 30 && id < 2 { 1 - id } else { id };
            Some((id, 0.0))
        }),
        &[],
    );
    assert_eq!(s["clear"]["id_switches"], 2);
    // Each is listed: when, which vehicle, from which track to which.
    let events = s["switch_events"].as_array().unwrap();
    assert_eq!(events.len(), 2, "{events:?}");
    for e in events {
        let vehicle = e["vehicle"].as_u64().unwrap();
        assert!(vehicle < 2, "{e:?}");
        assert_eq!(e["from_track"].as_u64(), Some(vehicle), "{e:?}");
        assert_eq!(e["to_track"].as_u64(), Some(1 - vehicle), "{e:?}");
        assert!(
            e["t_s"].as_f64().unwrap() > 0.99,
            "frame 30 or later: {e:?}"
        );
    }
    assert!(s["id"]["idf1"].as_f64().unwrap() < 0.9);
    assert!(s["clear"]["mota"].as_f64().unwrap() < 1.0);

    // Vehicle 2 estimated 3 m off (beyond the 2 m threshold): never located, and
    // each of its rows is a false track; vehicle 3 never estimated: missed.
    let s = score(
        "off",
        track_from_truth(&v, frames, |_, id| match id {
            2 => Some((2, 3.0)),
            3 => None,
            _ => Some((id, 0.0)),
        }),
        &[],
    );
    let vehicle = |id: u64| {
        s["vehicles"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["id"] == id)
            .unwrap()
            .clone()
    };
    assert_eq!(vehicle(2)["located"], 0);
    assert_eq!(vehicle(3)["located"], 0);
    assert!(vehicle(3)["mae_m"].is_null());
    assert_eq!(vehicle(0)["located_share"], 1.0);
    let missed = vehicle(2)["in_view"].as_u64().unwrap() + vehicle(3)["in_view"].as_u64().unwrap();
    assert_eq!(s["clear"]["misses"], missed);
    assert_eq!(s["clear"]["false_positives"], vehicle(2)["in_view"]);

    // A bad track file is refused with its place.
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, "t_s,x_m,y_m,z_m\n0.0,1,oops,3\n").unwrap();
    let o = dualgeo(&[
        "score",
        "--recording",
        rec.to_str().unwrap(),
        "--track",
        bad.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("line 2") && stderr(&o).contains("y_m"),
        "{}",
        stderr(&o)
    );
}
