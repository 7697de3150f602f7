//! One function per fuzz target. Each feeds its bytes to the same library entry points
//! the services and the CLI call, and asserts what the product promises (no non-finite
//! estimate out, no estimate out of time order); anything else may be an error.

use crate::bytes::{segments, Cursor};
use acquisition::flight::nav_track::NavTrack;
use acquisition::flight::tlog::parse_tlog;
use acquisition::flight::FlightMeta;
use acquisition::recording::Origin;
use acquisition::recording::{
    declared_size, decode_bytes_into, parse_telemetry, parse_truth, Recording, RecordingMeta,
};
use acquisition::resume::StreamPosition;
use detection::frame_view::frame_mat;
use detection::config::DetectionConfig;
use detection::{ColourBlobConfig, TrackedDetector};
use geolocation::set_message::{coast_message, estimate_message, finite, is_stale, Resume, CHECKPOINT_KIND};
use geolocation::{EstimatorConfig, EstimatorMethod, TemporalEstimator};
use matching::intake::Intake;
use matching::ring_snapshot::{KeyframeSnapshot, RingIndex};
use matching::ring_store::{INDEX_KIND, KEYFRAME_KIND};
use matching::{MatchingConfig, VisionChain};
use shared_types::checkpoint;
use shared_types::conventions::Uav;
use shared_types::messages::{
    DetectionMsg, EstimateMsg, EstimateStatus, FrameHeader, ObservationSetMsg,
};
use shared_types::shell::parse_section;
use shared_types::stats::StageStats;
use std::path::Path;

/// Largest frame the `frames` target builds (a 640×480 BGR frame is 921 600 bytes).
const MAX_FRAME_BYTES: usize = 1 << 20;
/// Largest image the `image` target decodes into.
const MAX_IMAGE_SIDE: u32 = 512;

/// recording.toml, telemetry.csv and truth.csv (segments 0–2), each parsed and checked
/// as `Recording::open` does, then paired by time.
pub fn recording(data: &[u8]) {
    let parts = segments(data);
    let part = |i: usize| parts.get(i).copied().unwrap_or_default();
    let meta = std::str::from_utf8(part(0))
        .map_err(|e| e.to_string())
        .and_then(|text| {
            RecordingMeta::parse(text, Path::new("recording.toml")).map_err(|e| e.to_string())
        });
    let telemetry = parse_telemetry(part(1), Path::new("telemetry.csv"));
    let _ = parse_truth(part(2), Path::new("truth.csv"));
    if let (Ok(meta), Ok(rows)) = (meta, telemetry) {
        let recording = Recording {
            root: "fuzz".into(),
            meta,
            telemetry: rows.into_iter().map(|(_, r)| r).collect(),
            truth: None,
        };
        for pair in recording.pairs() {
            assert!(
                pair.left < recording.telemetry.len() && pair.right < recording.telemetry.len()
            );
        }
    }
}

/// An image file's bytes: the header's declared size, then a decode into a frame buffer
/// of that size (or of the size in the first four bytes when the header lies or is big).
pub fn image(data: &[u8]) {
    let mut c = Cursor::new(data);
    let fallback = (c.u8() as u32 + 1, c.u8() as u32 + 1);
    let file = c.take(usize::MAX);
    let (width, height) = match declared_size(file) {
        Ok((w, h)) if (1..=MAX_IMAGE_SIDE).contains(&w) && (1..=MAX_IMAGE_SIDE).contains(&h) => {
            (w, h)
        }
        _ => fallback,
    };
    let mut frame = vec![0u8; (width * height * 3) as usize];
    let _ = decode_bytes_into(file, Path::new("image"), width, height, &mut frame);
}

/// A configuration file: each section parsed and validated as `dualgeo run` does, then
/// each service's start-up from it.
pub fn config(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let matching = parse_section::<MatchingConfig>(text, "matching")
        .ok()
        .filter(|m| m.validate().is_ok());
    let estimator = parse_section::<EstimatorConfig>(text, "estimator")
        .ok()
        .filter(|e| e.validate().is_ok());
    // As the detection service reads it; a learned model is not loaded here (a model
    // file is not fuzz input).
    if let Ok(detection) = parse_section::<DetectionConfig>(text, "detection") {
        let _ = TrackedDetector::new(detection.colour);
    }
    if let Some(e) = estimator {
        if e.method == EstimatorMethod::Temporal {
            let _ = TemporalEstimator::new(e);
        }
        if let Some(m) = matching {
            let _ = Intake::new(m, e);
        }
    }
}

/// Checkpoint files (segments): acquisition's stream position, geolocation's filter,
/// matching's ring index, then keyframe files; each decoded and restored as a
/// restarted service does.
pub fn checkpoint(data: &[u8]) {
    let parts = segments(data);
    let part = |i: usize| parts.get(i).copied().unwrap_or_default();
    let _ = StreamPosition::decode(part(0));
    if let Ok(resume) = checkpoint::decode::<Resume>(CHECKPOINT_KIND, part(1)) {
        if let Some(snap) = &resume.filter {
            let _ = TemporalEstimator::restore(EstimatorConfig::default(), snap);
        }
        if let Some(snap) = &resume.tracks {
            let _ = geolocation::tracks::Tracks::restore(Default::default(), snap);
        }
    }
    if let Ok(index) = checkpoint::decode::<RingIndex>(INDEX_KIND, part(2)) {
        let Ok(mut chain) = VisionChain::new(MatchingConfig::default(), EstimatorConfig::default())
        else {
            return;
        };
        let keyframes: Vec<KeyframeSnapshot> = parts
            .iter()
            .skip(3)
            .filter_map(|p| checkpoint::decode(KEYFRAME_KIND, p).ok())
            .collect();
        let _ = chain.restore_rings(&index, |uav: Uav, seq| {
            keyframes
                .iter()
                .find(|k| k.uav as usize == uav.index() && k.seq == seq)
                .cloned()
                .ok_or_else(|| "missing".to_string())
        });
    }
}

/// Blocky pixels from a seed: corners for ORB, the same for the same seed.
pub fn texture(len: usize, width: usize, seed: u64) -> Vec<u8> {
    let block = |x: usize, y: usize, ch: usize| -> u8 {
        let mut h = seed
            ^ ((x / 8) as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ ((y / 8) as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
            ^ ch as u64;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        (h >> 56) as u8
    };
    let row = (width * 3).max(1);
    (0..len)
        .map(|i| block((i % row) / 3, i / row, i % 3))
        .collect()
}

/// Frame and detection messages as detection and matching read them, in any order:
/// each op is a frame of the left or right UAV (header bytes, then the pixels: raw
/// bytes or a texture of the size the header gives), a detection, or a matching step.
pub fn frames(data: &[u8]) {
    let (Ok(mut intake), Ok(mut detector)) = (
        Intake::new(MatchingConfig::default(), EstimatorConfig::default()),
        TrackedDetector::new(ColourBlobConfig::default()),
    ) else {
        panic!("the default configuration must start matching and detection");
    };
    let mut c = Cursor::new(data);
    for _ in 0..48 {
        if c.is_empty() {
            break;
        }
        match c.u8() % 4 {
            uav @ (0 | 1) => {
                let header: FrameHeader = c.message();
                let pixels = match c.u8() {
                    0 => {
                        let n = (c.u64() % (1 << 16)) as usize;
                        c.take(n).to_vec()
                    }
                    _ => {
                        let len = header.payload_len().filter(|n| *n <= MAX_FRAME_BYTES);
                        texture(len.unwrap_or(0), header.width as usize, c.u64())
                    }
                };
                if let Ok(mat) = frame_mat(&header, &pixels) {
                    let _ = detector.detect(uav as usize, header.t_s, &mat);
                }
                let mut views = [None, None];
                views[uav as usize] = Some((header, pixels.as_slice()));
                intake.extract(views);
            }
            2 => intake.on_detection(c.message::<DetectionMsg>()),
            _ => while intake.next_set().is_some() {},
        }
    }
    while let Some(set) = intake.next_set() {
        assert!(set.count as usize <= shared_types::messages::MAX_OBSERVATIONS);
    }
    // For seed authors: which matching states an input reached.
    if std::env::var_os("DUALGEO_FUZZ_DEBUG").is_some() {
        eprintln!("{:?}", intake.stats.counters);
    }
}

/// Observation-set messages as geolocation reads them (the method from the first
/// byte), then each estimate through the supervisor's guard.
pub fn observations(data: &[u8]) {
    let mut c = Cursor::new(data);
    let method = match c.u8() % 3 {
        0 => EstimatorMethod::Temporal,
        1 => EstimatorMethod::Paper,
        _ => EstimatorMethod::Joint,
    };
    let config = EstimatorConfig {
        method,
        ..Default::default()
    };
    let mut temporal = match method {
        EstimatorMethod::Temporal => Some(TemporalEstimator::new(config).expect("default config")),
        _ => None,
    };
    let mut stats = StageStats::new("fuzz");
    let mut last_t: Option<f64> = None;
    for _ in 0..16 {
        if c.is_empty() {
            break;
        }
        let set: ObservationSetMsg = c.message();
        // The service's own guard, then what the supervisor checks of its output.
        if is_stale(set.t_s, last_t) {
            continue;
        }
        // As the service: a refused set gives the filter's prediction.
        let msg = if set.refused != 0 {
            coast_message(&set, &config, temporal.as_mut(), &mut stats)
        } else {
            estimate_message(&set, &config, temporal.as_mut(), &mut stats)
        };
        if msg.status == EstimateStatus::Ok as u32 {
            assert!(
                finite(&msg),
                "a non-finite estimate left geolocation: {msg:?}"
            );
        }
        assert_eq!(
            msg.refusal(last_t),
            None,
            "geolocation published {msg:?} after {last_t:?}"
        );
        last_t = Some(msg.t_s);
    }
    let raw: EstimateMsg = c.message();
    let _ = raw.refusal(last_t);
}

/// A flight: flight.toml (segment 0) and a MAVLink telemetry log (segment 1), read as
/// the flight source reads them, then poses asked for across and beyond the log.
pub fn flight(data: &[u8]) {
    let parts = segments(data);
    let part = |i: usize| parts.get(i).copied().unwrap_or_default();
    if let Ok(text) = std::str::from_utf8(part(0)) {
        let _ = FlightMeta::parse(text, Path::new("flight.toml"));
    }
    let samples: Vec<_> = parse_tlog(part(1)).0.into_iter().map(|(_, s)| s).collect();
    let origin = Origin {
        lat_deg: 47.0,
        lon_deg: 8.0,
        alt_m: 400.0,
    };
    let (track, _) = NavTrack::new(&samples, &origin, 0.0);
    if let Some((start, end)) = track.span() {
        for k in 0..=8 {
            let t = start - 0.05 + (end - start + 0.1) * k as f64 / 8.0;
            if let Ok(p) = track.pose_at(t, 0.5) {
                assert!(p.is_finite(), "a non-finite pose at {t}: {p:?}");
            }
        }
    }
}
