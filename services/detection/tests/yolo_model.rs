//! The YOLO load-and-decode path on a real ONNX file: `tests/data/tiny_yolov8.onnx`,
//! built by `scripts/make_test_yolo_onnx.py` (its docstring gives the exact outputs).

use detection::yolo::{YoloConfig, YoloDetector, YoloLayout};
use detection::Detector;
use opencv::core as cv;
use opencv::prelude::*;

fn config() -> YoloConfig {
    YoloConfig {
        model: concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/tiny_yolov8.onnx").into(),
        config: None,
        names: None,
        input_size: 64,
        // 4 candidates < 6 channels: too few for `auto` to tell; real models are not.
        layout: YoloLayout::V8,
        confidence_threshold: 0.5,
        nms_iou: 0.45,
        classes: vec![],
        every_frames: 1,
    }
}

/// A 128 × 128 black frame with one white quadrant (rows, cols of 64).
fn frame(white_row: i32, white_col: i32) -> cv::Mat {
    let mut m =
        cv::Mat::new_rows_cols_with_default(128, 128, cv::CV_8UC3, cv::Scalar::all(0.0)).unwrap();
    let rect = cv::Rect::new(64 * white_col, 64 * white_row, 64, 64);
    opencv::imgproc::rectangle(
        &mut m,
        rect,
        cv::Scalar::all(255.0),
        -1,
        opencv::imgproc::LINE_8,
        0,
    )
    .unwrap();
    m
}

#[test]
fn loads_a_real_onnx_file_and_decodes_its_output() {
    let mut yolo = YoloDetector::new(config()).unwrap();
    let det = yolo
        .detect(&frame(0, 1))
        .unwrap()
        .expect("the white quadrant is a detection");
    // Model box (48, 16, 20, 10) in the 64-px input; the frame is 2× larger, and the
    // centre shifts by −0.5 to OpenCV's pixel-centre convention.
    assert!(
        (det.centre[0] - 95.5).abs() < 1e-3 && (det.centre[1] - 31.5).abs() < 1e-3,
        "{det:?}"
    );
    assert!(
        (det.bbox[2] - 40.0).abs() < 1e-3 && (det.bbox[3] - 20.0).abs() < 1e-3,
        "{det:?}"
    );
    assert!((det.confidence - 0.9).abs() < 1e-4);

    // All black: every candidate scores 0 (class 0) or 0.05 (class 1): nothing found.
    let black =
        cv::Mat::new_rows_cols_with_default(128, 128, cv::CV_8UC3, cv::Scalar::all(0.0)).unwrap();
    assert!(yolo.detect(&black).unwrap().is_none());

    // Keeping only class 1 drops the class-0 box.
    let mut only_class_1 = YoloDetector::new(YoloConfig {
        classes: vec![detection::yolo::ClassRef::Index(1)],
        ..config()
    })
    .unwrap();
    assert!(only_class_1.detect(&frame(0, 1)).unwrap().is_none());
}

#[test]
fn a_corrupt_model_file_is_a_clear_error() {
    let dir = std::env::temp_dir().join(format!("dualgeo-yolo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("broken.onnx");
    std::fs::write(&path, b"not a protobuf").unwrap();
    let result = YoloDetector::new(YoloConfig {
        model: path.clone(),
        ..config()
    });
    let _ = std::fs::remove_dir_all(&dir);
    let e = result
        .err()
        .expect("a corrupt model must be rejected")
        .to_string();
    assert!(e.contains("broken.onnx"), "{e}");
}

/// The Darknet YOLOv2-tiny COCO model `scripts/setup.sh` installs (scripts/fetch_models.sh).
fn darknet(classes: Vec<detection::yolo::ClassRef>) -> YoloConfig {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/models/yolov2-tiny");
    YoloConfig {
        model: format!("{dir}/yolov2-tiny.weights").into(),
        config: Some(format!("{dir}/yolov2-tiny.cfg").into()),
        names: Some(format!("{dir}/coco.names").into()),
        input_size: 416,
        layout: YoloLayout::Auto,
        confidence_threshold: 0.25,
        nms_iou: 0.45,
        classes,
        every_frames: 8,
    }
}

#[test]
fn the_installed_darknet_model_loads_and_names_its_classes() {
    use detection::yolo::ClassRef;
    let names = ["car", "bus", "truck"]
        .map(|c| ClassRef::Name(c.into()))
        .to_vec();
    let config = darknet(names);
    assert_eq!(config.class_indices().unwrap(), vec![2, 5, 7]);
    let mut yolo = YoloDetector::new(config).expect("run scripts/fetch_models.sh");
    // A grey frame holds no vehicle.
    let grey =
        cv::Mat::new_rows_cols_with_default(480, 640, cv::CV_8UC3, cv::Scalar::all(128.0)).unwrap();
    assert!(yolo.detect(&grey).unwrap().is_none());
    // A class the names file does not have, and an index beyond the model's 80.
    let e = YoloDetector::new(darknet(vec![ClassRef::Name("cars".into())]))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("\"cars\"") && e.contains("coco.names"), "{e}");
    let e = YoloDetector::new(darknet(vec![ClassRef::Index(80)]))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("80"), "{e}");
    // A Darknet config that is not there.
    let mut missing = darknet(Vec::new());
    missing.config = Some("/nonexistent/yolo.cfg".into());
    let e = YoloDetector::new(missing).err().unwrap().to_string();
    assert!(e.contains("/nonexistent/yolo.cfg"), "{e}");
}

/// A 128 × 128 frame of texture, its top-right quadrant bright, everything moved
/// `shift` pixels to the right.
fn textured(shift: i32) -> cv::Mat {
    let mut m =
        cv::Mat::new_rows_cols_with_default(128, 128, cv::CV_8UC3, cv::Scalar::all(0.0)).unwrap();
    for r in 0..128 {
        for c in 0..128 {
            let x = c - shift;
            // A fixed hash: texture without a period for the correlation to slip on.
            let hash = (r as u32).wrapping_mul(73_856_093) ^ (x as u32).wrapping_mul(19_349_663);
            let texture = (hash.wrapping_mul(2_654_435_761) >> 26) as u8;
            let bright = (64..128).contains(&x) && r < 64;
            let v = if bright { 180 + texture } else { 20 + texture };
            *m.at_2d_mut::<cv::Vec3b>(r, c).unwrap() = cv::Vec3b::from([v, v, v]);
        }
    }
    m
}

/// The learned detector in a stream: the model's box on the frame it saw, then the
/// template tracker carrying it, to the pixel, until the model's next turn.
#[test]
fn the_learned_detector_tracks_the_models_box_between_its_runs() {
    use detection::learned::LearnedDetector;
    let config = YoloConfig {
        every_frames: 8,
        confidence_threshold: 0.3,
        ..config()
    };
    let direct = YoloDetector::new(config.clone())
        .unwrap()
        .detect(&textured(0))
        .unwrap()
        .expect("the bright quadrant is a box");
    let mut learned = LearnedDetector::new(config, true).unwrap();
    let first = learned.detect(0, &textured(0)).unwrap().expect("found");
    for axis in 0..2 {
        assert!(
            // The NCC peak's parabola on a self-match: within a quarter pixel.
            (first.centre[axis] - direct.centre[axis]).abs() <= 0.25,
            "{first:?} vs {direct:?}"
        );
    }
    for k in 1..6 {
        let d = learned
            .detect(0, &textured(2 * k))
            .unwrap()
            .expect("tracked");
        let moved = d.centre[0] - first.centre[0];
        assert!(
            (moved - 2.0 * k as f64).abs() < 0.2,
            "frame {k}: moved {moved}"
        );
        assert!((d.centre[1] - first.centre[1]).abs() < 0.2);
    }
    let counts = learned.take_counts();
    assert_eq!((counts.model_runs, counts.model_found), (1, 1));
    assert_eq!((counts.tracked, counts.track_lost), (5, 0));
    // The other camera has its own track: nothing yet, so the model sees its frame.
    assert!(learned.detect(1, &textured(0)).unwrap().is_some());
    assert_eq!(learned.take_counts().model_runs, 1);
}
