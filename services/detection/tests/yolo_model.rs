//! The YOLO load-and-decode path on a real ONNX file: `tests/data/tiny_yolov8.onnx`,
//! built by `scripts/make_test_yolo_onnx.py` (its docstring gives the exact outputs).

use detection::yolo::{YoloConfig, YoloDetector, YoloLayout};
use detection::Detector;
use opencv::core as cv;

fn config() -> YoloConfig {
    YoloConfig {
        model: concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/tiny_yolov8.onnx").into(),
        input_size: 64,
        // 4 candidates < 6 channels: too few for `auto` to tell; real models are not.
        layout: YoloLayout::V8,
        confidence_threshold: 0.5,
        nms_iou: 0.45,
        classes: vec![],
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
        classes: vec![1],
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
