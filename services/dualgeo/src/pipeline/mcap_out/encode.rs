//! Plain data → the JSON messages of the MCAP channels (`schemas.rs`), and a frame →
//! JPEG. Pure functions (the JPEG through OpenCV), tested here; the recorder thread
//! only moves samples into them.
//!
//! Times: a message's `timestamp` and its MCAP log time are the frame's capture time on
//! the stream's clock (`t_s`: the recording's or the flight's clock, the simulator's
//! scenario time), so the images, poses, detections and estimate of one pair sit at one
//! instant when a user scrubs the run. Its MCAP publish time is the CLOCK_MONOTONIC
//! moment the message was published in the pipeline.

use super::super::live_out::TargetFix;
use acquisition::recording::Origin;
use base64::Engine;
use nalgebra::{Rotation3, UnitQuaternion};
use opencv::core as cv;
use opencv::prelude::*;
use serde_json::{json, Value};
use shared_types::conventions::{camera_to_world, Attitude};
use shared_types::messages::{DetectionMsg, EstimateMsg, EstimateStatus, FrameHeader};

/// The frame id of the world (ENU about the source's origin) in poses.
pub const WORLD_FRAME: &str = "enu";

/// A stream time as MCAP nanoseconds and Foxglove's `{sec, nsec}`; `None` for a time
/// that is not a finite, non-negative number of seconds (such a message is not written).
pub fn stamp(t_s: f64) -> Option<(u64, Value)> {
    if !(0.0..1.8e10).contains(&t_s) {
        return None;
    }
    let ns = (t_s * 1e9).round() as u64;
    Some((
        ns,
        json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000}),
    ))
}

/// The frame id of a UAV's camera (`left_camera`, `right_camera`).
pub fn camera_frame(uav: usize) -> &'static str {
    if uav == 0 {
        "left_camera"
    } else {
        "right_camera"
    }
}

/// foxglove.CompressedImage of a JPEG.
pub fn image_message(time: &Value, uav: usize, jpeg: &[u8]) -> Value {
    json!({
        "timestamp": time,
        "frame_id": camera_frame(uav),
        "data": base64::engine::general_purpose::STANDARD.encode(jpeg),
        "format": "jpeg",
    })
}

/// foxglove.PoseInFrame of a frame's measured camera pose: its position and the
/// rotation camera → world (eq. 1's `C_w^c`, nadir mount) as a quaternion. `None` when
/// the pose is not finite.
pub fn camera_pose_message(time: &Value, h: &FrameHeader) -> Option<Value> {
    if !h.pose.is_finite() {
        return None;
    }
    let p = &h.pose;
    let r = camera_to_world(Attitude::from_degrees(p.yaw_deg, p.pitch_deg, p.roll_deg));
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Some(json!({
        "timestamp": time,
        "frame_id": WORLD_FRAME,
        "pose": {
            "position": {"x": p.x_m, "y": p.y_m, "z": p.z_m},
            "orientation": {"x": q.i, "y": q.j, "z": q.k, "w": q.w},
        },
    }))
}

/// foxglove.ImageAnnotations of a detection: the target's box as a closed polygon
/// (red; none when it was not found or the box is not finite) and every other object
/// the detector published (thin, yellow).
pub fn detection_message(time: &Value, d: &DetectionMsg) -> Value {
    let outline = |bbox: [f64; 4], rgb: [f64; 3], thickness: f64| -> Option<Value> {
        let [x, y, w, h] = bbox;
        bbox.iter().all(|v| v.is_finite()).then(|| {
            let corners = [(x, y), (x + w, y), (x + w, y + h), (x, y + h)];
            json!({
                "timestamp": time,
                "type": 2, // LINE_LOOP
                "points": corners.map(|(x, y)| json!({"x": x, "y": y})),
                "outline_color": {"r": rgb[0], "g": rgb[1], "b": rgb[2], "a": 1.0},
                "outline_colors": [],
                "fill_color": {"r": 0.0, "g": 0.0, "b": 0.0, "a": 0.0},
                "thickness": thickness,
            })
        })
    };
    let target = (d.found == 1)
        .then(|| outline(d.bbox, [1.0, 0.2, 0.1], 2.0))
        .flatten();
    let others = d
        .candidates()
        .iter()
        .filter_map(|c| outline(c.bbox, [1.0, 0.85, 0.1], 1.0));
    let points: Vec<Value> = target.into_iter().chain(others).collect();
    json!({"circles": [], "points": points, "texts": []})
}

/// foxglove.LocationFix of a valid estimate. Covariance (ENU, m², row-major): the
/// estimator's x/y block, σ_z² of the altitude (eq. 9's multi-view midpoints), no
/// cross terms with z (the estimator keeps none), hence APPROXIMATED (1).
pub fn fix_message(time: &Value, fix: &TargetFix, e: &EstimateMsg) -> Value {
    let c = &e.covariance;
    let vz = e.altitude_std_error_m * e.altitude_std_error_m;
    let cov = [c[0], c[1], 0.0, c[4], c[5], 0.0, 0.0, 0.0, vz];
    let cov: Vec<Value> = cov.iter().map(|&v| finite_or_null(v)).collect();
    json!({
        "timestamp": time,
        "frame_id": WORLD_FRAME,
        "latitude": fix.lat_deg,
        "longitude": fix.lon_deg,
        "altitude": fix.hae_m,
        "position_covariance": cov,
        "position_covariance_type": 1,
    })
}

/// dualgeo.TargetQuality of a valid estimate: its quality state (issue #23) and the
/// accuracy it states.
pub fn quality_message(time: &Value, e: &EstimateMsg) -> Value {
    let quality = geolocation::Quality::from_index(e.quality).map_or("converging", |q| q.name());
    let h_acc = (e.covariance[0] + e.covariance[5]).max(0.0).sqrt();
    json!({
        "timestamp": time,
        "pair_seq": e.pair_seq,
        "quality": quality,
        "h_acc_m": finite_or_null(h_acc),
        "v_acc_m": finite_or_null(e.altitude_std_error_m),
        "yaw_bias_left_deg": finite_or_null(e.yaw_bias_deg[0]),
        "yaw_bias_right_deg": finite_or_null(e.yaw_bias_deg[1]),
    })
}

/// dualgeo.Targets of one pair: the target as id 0 when its estimate is valid, then
/// every other vehicle's track, geodetic (ellipsoidal height) with 1σ accuracies.
pub fn targets_message(time: &Value, e: &EstimateMsg, origin: &Origin) -> Value {
    let quality = |q: u64| geolocation::Quality::from_index(q).map_or("converging", |q| q.name());
    let target = TargetFix::of(e, origin).map(|f| {
        json!({
            "track_id": 0,
            "latitude": f.lat_deg,
            "longitude": f.lon_deg,
            "altitude": f.hae_m,
            "h_acc_m": finite_or_null(f.h_acc_m),
            "v_acc_m": finite_or_null(f.v_acc_m),
            "quality": quality(e.quality),
        })
    });
    let others = e.tracks().iter().map(|t| {
        let f = TargetFix::of_track(e, t, origin);
        json!({
            "track_id": t.id,
            "latitude": f.lat_deg,
            "longitude": f.lon_deg,
            "altitude": f.hae_m,
            "h_acc_m": finite_or_null(f.h_acc_m),
            "v_acc_m": finite_or_null(f.v_acc_m),
            "quality": quality(u64::from(t.quality)),
        })
    });
    let targets: Vec<Value> = target.into_iter().chain(others).collect();
    json!({"timestamp": time, "pair_seq": e.pair_seq, "targets": targets})
}

/// foxglove.PoseInFrame of a valid estimate's ENU position (no orientation is
/// estimated: identity).
pub fn target_pose_message(time: &Value, e: &EstimateMsg) -> Value {
    let [x, y, z] = e.position;
    json!({
        "timestamp": time,
        "frame_id": WORLD_FRAME,
        "pose": {
            "position": {"x": x, "y": y, "z": z},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
    })
}

/// When each stage of one pair published (CLOCK_MONOTONIC ns); `None` where the
/// recorder did not see that message.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimes {
    /// Both frames published by acquisition (the later of the two).
    pub frames_ns: Option<u64>,
    /// Both detections published (the later).
    pub detections_ns: Option<u64>,
    /// The observation set published by matching.
    pub observations_ns: Option<u64>,
}

/// dualgeo.StageLatency of one estimate: each stage's share of its end-to-end time
/// (capture → estimate published), ms; a stage the recorder did not see is null.
pub fn latency_message(time: &Value, e: &EstimateMsg, s: &StageTimes) -> Value {
    let ms = |from: Option<u64>, to: Option<u64>| match (from, to) {
        (Some(a), Some(b)) if b >= a => json!((b - a) as f64 / 1e6),
        _ => Value::Null,
    };
    let capture = Some(e.capture_ns);
    let published = Some(e.published_ns);
    json!({
        "timestamp": time,
        "pair_seq": e.pair_seq,
        "status": e.status,
        "acquisition_ms": ms(capture, s.frames_ns),
        "detection_ms": ms(s.frames_ns, s.detections_ns),
        "matching_ms": ms(s.detections_ns, s.observations_ns),
        "geolocation_ms": ms(s.observations_ns, published),
        "end_to_end_ms": ms(capture, published),
    })
}

/// Whether an estimate carries a position.
pub fn is_valid(e: &EstimateMsg) -> bool {
    e.status == EstimateStatus::Ok as u32
}

fn finite_or_null(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// A frame's pixels as JPEG at `quality` (1–100).
pub fn jpeg(h: &FrameHeader, payload: &[u8], quality: i32) -> Result<Vec<u8>, String> {
    let mat = detection::frame_view::frame_mat(h, payload).map_err(|e| e.to_string())?;
    let mut out = cv::Vector::<u8>::new();
    let params = cv::Vector::<i32>::from_slice(&[opencv::imgcodecs::IMWRITE_JPEG_QUALITY, quality]);
    opencv::imgcodecs::imencode(".jpg", &*mat, &mut out, &params).map_err(|e| e.message)?;
    Ok(out.to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;
    use shared_types::messages::{PixelFormat, PoseSample};

    fn time() -> Value {
        stamp(1.5).unwrap().1
    }

    #[test]
    fn stamps_split_seconds_and_refuse_what_is_no_time() {
        let (ns, v) = stamp(12.000_000_25).unwrap();
        assert_eq!(ns, 12_000_000_250);
        assert_eq!(v, json!({"sec": 12, "nsec": 250}));
        for bad in [f64::NAN, f64::INFINITY, -0.1, 1e300] {
            assert!(stamp(bad).is_none(), "{bad}");
        }
    }

    #[test]
    fn a_level_camera_heading_north_looks_down_with_image_x_east() {
        let h = FrameHeader {
            pose: PoseSample {
                x_m: 1.0,
                y_m: 2.0,
                z_m: 100.0,
                ..Default::default()
            },
            ..Default::default()
        };
        let m = camera_pose_message(&time(), &h).unwrap();
        let o = &m["pose"]["orientation"];
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            o["w"].as_f64().unwrap(),
            o["x"].as_f64().unwrap(),
            o["y"].as_f64().unwrap(),
            o["z"].as_f64().unwrap(),
        ));
        // Optical axis (camera z) straight down; image x = body right = east.
        let down = q * nalgebra::Vector3::z();
        let right = q * nalgebra::Vector3::x();
        assert!(
            (down - nalgebra::Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12,
            "{down}"
        );
        assert!((right - nalgebra::Vector3::x()).norm() < 1e-12, "{right}");
        assert_eq!(m["pose"]["position"]["z"], 100.0);
        let mut bad = h;
        bad.pose.yaw_deg = f64::NAN;
        assert!(camera_pose_message(&time(), &bad).is_none());
    }

    #[test]
    fn a_detection_is_its_box_and_a_miss_is_nothing() {
        let mut d = DetectionMsg {
            found: 1,
            bbox: [10.0, 20.0, 4.0, 6.0],
            ..Default::default()
        };
        let m = detection_message(&time(), &d);
        let p = &m["points"][0]["points"];
        assert_eq!(p[2], json!({"x": 14.0, "y": 26.0}));
        assert_eq!(m["points"][0]["type"], 2);
        d.found = 0;
        assert_eq!(detection_message(&time(), &d)["points"], json!([]));
        d.found = 1;
        d.bbox[0] = f64::NAN;
        assert_eq!(detection_message(&time(), &d)["points"], json!([]));
        // Other objects follow the target's box, thinner.
        d.bbox[0] = 10.0;
        d.candidate_count = 1;
        d.candidates[0].bbox = [30.0, 20.0, 4.0, 6.0];
        d.candidates[1].bbox = [50.0, 20.0, 4.0, 6.0]; // beyond the count: not drawn
        let m = detection_message(&time(), &d);
        assert_eq!(m["points"].as_array().unwrap().len(), 2);
        assert_eq!(m["points"][1]["points"][0], json!({"x": 30.0, "y": 20.0}));
        assert_eq!(m["points"][1]["thickness"], 1.0);
    }

    #[test]
    fn the_fix_carries_the_estimators_covariance_in_enu() {
        let mut e = EstimateMsg {
            altitude_std_error_m: 2.0,
            ..Default::default()
        };
        e.covariance[0] = 0.25;
        e.covariance[1] = 0.01;
        e.covariance[4] = 0.01;
        e.covariance[5] = 0.36;
        let fix = TargetFix {
            pair_seq: 3,
            lat_deg: 30.0,
            lon_deg: 120.0,
            hae_m: 12.0,
            h_acc_m: 0.0,
            v_acc_m: 0.0,
            vel_north_mps: f64::NAN,
            vel_east_mps: f64::NAN,
            vel_acc_mps: f64::NAN,
            range_m: 0.0,
        };
        let m = fix_message(&time(), &fix, &e);
        assert_eq!(
            m["position_covariance"],
            json!([0.25, 0.01, 0.0, 0.01, 0.36, 0.0, 0.0, 0.0, 4.0])
        );
        assert_eq!(m["latitude"], 30.0);
        e.altitude_std_error_m = f64::NAN;
        assert!(fix_message(&time(), &fix, &e)["position_covariance"][8].is_null());
    }

    #[test]
    fn the_quality_message_names_the_state_and_the_stated_accuracy() {
        let mut e = EstimateMsg {
            pair_seq: 7,
            altitude_std_error_m: 0.8,
            quality: 1,
            yaw_bias_deg: [2.0, -3.0],
            ..Default::default()
        };
        e.covariance[0] = 0.09;
        e.covariance[5] = 0.16;
        let m = quality_message(&time(), &e);
        assert_eq!(m["quality"], "tracking");
        assert!((m["h_acc_m"].as_f64().unwrap() - 0.5).abs() < 1e-12);
        assert_eq!(m["v_acc_m"], 0.8);
        assert_eq!(m["yaw_bias_right_deg"], -3.0);
        e.quality = 0;
        assert_eq!(quality_message(&time(), &e)["quality"], "converging");
        e.altitude_std_error_m = f64::NAN;
        assert!(quality_message(&time(), &e)["v_acc_m"].is_null());
    }

    #[test]
    fn stage_latencies_add_up_to_the_end_to_end_time() {
        let e = EstimateMsg {
            capture_ns: 1_000_000,
            published_ns: 21_000_000,
            ..Default::default()
        };
        let s = StageTimes {
            frames_ns: Some(3_000_000),
            detections_ns: Some(8_000_000),
            observations_ns: Some(18_000_000),
        };
        let m = latency_message(&time(), &e, &s);
        let parts: f64 = [
            "acquisition_ms",
            "detection_ms",
            "matching_ms",
            "geolocation_ms",
        ]
        .iter()
        .map(|k| m[k].as_f64().unwrap())
        .sum();
        assert_eq!(parts, 20.0);
        assert_eq!(m["end_to_end_ms"], 20.0);
        let unseen = latency_message(&time(), &e, &StageTimes::default());
        assert!(unseen["detection_ms"].is_null() && unseen["acquisition_ms"].is_null());
    }

    #[test]
    fn a_frame_encodes_to_a_jpeg() {
        let h = FrameHeader {
            width: 16,
            height: 8,
            stride: 48,
            pixel_format: PixelFormat::Bgr8 as u32,
            ..Default::default()
        };
        let pixels = vec![128u8; 48 * 8];
        let j = jpeg(&h, &pixels, 80).unwrap();
        assert_eq!(&j[..2], &[0xFF, 0xD8]);
        assert!(
            jpeg(&h, &pixels[..10], 80).is_err(),
            "a short payload is refused"
        );
    }
}
