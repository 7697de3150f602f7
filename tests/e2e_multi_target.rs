//! End-to-end: several targets through the real service processes. A `multi_town`
//! recording (the red target, a second red car overtaking it, three other cars):
//! detection publishes the second red car, matching pairs it across the views and
//! carries it into the past images, geolocation tracks it with the target's yaw
//! biases, and `dualgeo score` finds its track near it. With the other vehicles
//! switched off the target's rows are the same to the last digit.

#[path = "support/scratch.rs"]
mod scratch;

use scratch::{json, Scratch};
use std::process::{Command, Output};

fn dualgeo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dualgeo"))
        .args(args)
        .output()
        .expect("spawn dualgeo")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The rows of a track.csv whose last column (track_id) is `id`, or every other one.
fn rows(track: &str, keep: impl Fn(&str) -> bool) -> Vec<String> {
    track
        .lines()
        .skip(1)
        .filter(|l| keep(l.rsplit(',').next().unwrap_or("")))
        .map(str::to_string)
        .collect()
}

#[test]
fn the_second_red_car_gets_a_track_of_its_own_and_the_target_is_untouched() {
    let dir = Scratch::new("multi-target");
    let rec = dir.s("rec");
    let o = dualgeo(&[
        "simulate",
        "--preset",
        "multi_town",
        "--duration-s",
        "12",
        "--out",
        &rec,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));

    let out = dir.s("run");
    let o = dualgeo(&["run", "--source", &rec, "--rate", "max", "--out", &out]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let score = dir.s("score.json");
    let o = dualgeo(&[
        "score",
        "--recording",
        &rec,
        "--track",
        &out,
        "--warm-up-s",
        "2",
        "--json",
        &score,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let s = json(std::path::Path::new(&score));
    let vehicle = |id: u64| {
        s["vehicles"]
            .as_array()
            .unwrap()
            .iter()
            .find(|v| v["id"] == id)
            .unwrap_or_else(|| panic!("vehicle {id} in {s}"))
            .clone()
    };
    // The colour detector sees the red cars only: the target (track 0) and the
    // second red car, which gets a track of its own, never track 0.
    let target = vehicle(0);
    assert!(target["located_share"].as_f64().unwrap() > 0.9, "{target}");
    assert_eq!(target["tracks"], serde_json::json!([0]), "{target}");
    let look_alike = vehicle(1);
    let share = look_alike["located_share"].as_f64().unwrap();
    assert!(
        share > 0.4,
        "the second red car located in {share} of its pairs: {look_alike}"
    );
    assert!(
        !look_alike["tracks"]
            .as_array()
            .unwrap()
            .contains(&serde_json::json!(0)),
        "{look_alike}"
    );
    let geo = json(&std::path::Path::new(&out).join("stats/geolocation.0.json"));
    let counters = &geo["counters"];
    assert!(
        counters["tracks_confirmed"].as_u64().unwrap() >= 1,
        "{counters}"
    );
    assert!(
        counters["others_located"].as_u64().unwrap() > 100,
        "{counters}"
    );

    // Other vehicles off: the target's rows are unchanged, and there are no others.
    let config = dir.join("single.toml");
    std::fs::write(
        &config,
        "[detection]\ncandidates = false\n[tracks]\nenabled = false\n",
    )
    .unwrap();
    let single = dir.s("single");
    let o = dualgeo(&[
        "run",
        "--source",
        &rec,
        "--rate",
        "max",
        "--config",
        config.to_str().unwrap(),
        "--out",
        &single,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let many = std::fs::read_to_string(std::path::Path::new(&out).join("track.csv")).unwrap();
    let one = std::fs::read_to_string(std::path::Path::new(&single).join("track.csv")).unwrap();
    assert_eq!(rows(&many, |id| id == "0"), rows(&one, |id| id == "0"));
    assert!(rows(&one, |id| id != "0").is_empty());
    assert!(!rows(&many, |id| id != "0").is_empty());
}
