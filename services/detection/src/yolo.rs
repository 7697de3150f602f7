//! YOLO through OpenCV DNN: an ONNX file (YOLOv5/v8 exports), or a Darknet model
//! (`.cfg` + `.weights`, e.g. the YOLOv2-tiny COCO model `scripts/setup.sh` installs).
//!
//! Pre-processing: letterbox to the model's square input (aspect kept, grey 114
//! padding, centred), BGR→RGB, scale 1/255. Outputs:
//! * **YOLOv5** `(1, N, 5 + classes)`: cx, cy, w, h, objectness, class scores;
//!   score = objectness × best class score.
//! * **YOLOv8** `(1, 4 + classes, N)`: cx, cy, w, h, class scores; score = best class
//!   score.
//! * **Darknet** (OpenCV's region layer) `(N, 5 + classes)`: cx, cy, w, h as fractions
//!   of the input, objectness, class scores already multiplied by the objectness;
//!   score = best class score.
//!
//! Classes to keep are given by index or, with a names file (one class per line, as
//! Darknet's `coco.names`), by name; a name the file does not have is an error when the
//! detector is built, before the run.
//!
//! Boxes are in input pixels with 0 at the image's left/top *edge* (YOLO's convention).
//! They map back to frame pixels through the letterbox, then shift by −0.5 to OpenCV's
//! convention (0 = centre of the first pixel). After the confidence threshold, an
//! optional class filter and NMS, the most confident box is the detection. Its centre
//! is the target point.

use super::{check_bgr, DetectError, Detection, Detector};
use opencv::core as cv;
use opencv::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum YoloLayout {
    /// Decide from the output shape: the larger of the last two axes is the candidates.
    Auto,
    V5,
    V8,
    Darknet,
}

/// A class to keep: its index in the model's output, or its name in `names`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ClassRef {
    Index(usize),
    Name(String),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct YoloConfig {
    /// The ONNX file, or the Darknet `.weights` with `config`.
    pub model: PathBuf,
    /// A Darknet model's `.cfg` (the model is then read as Darknet).
    #[serde(default)]
    pub config: Option<PathBuf>,
    /// The class names, one per line (Darknet's `coco.names`): lets `classes` name them.
    #[serde(default)]
    pub names: Option<PathBuf>,
    /// The model's square input size, pixels.
    #[serde(default = "default_input")]
    pub input_size: i32,
    #[serde(default = "default_layout")]
    pub layout: YoloLayout,
    #[serde(default = "default_confidence")]
    pub confidence_threshold: f32,
    #[serde(default = "default_iou")]
    pub nms_iou: f32,
    /// Classes to keep, by index or by name (with `names`); empty keeps every class.
    #[serde(default)]
    pub classes: Vec<ClassRef>,
    /// In the detection service: each camera's frames go to the model at most every
    /// this many frames, and a template tracker carries the target between
    /// (`learned.rs`). A model of ~70 ms a frame cannot see every frame of two 30 FPS
    /// cameras on two cores.
    #[serde(default = "default_every_frames")]
    pub every_frames: u32,
}

fn default_every_frames() -> u32 {
    8
}

impl YoloConfig {
    /// The class indices `classes` names, checked against the names file.
    pub fn class_indices(&self) -> Result<Vec<usize>, DetectError> {
        let names = match &self.names {
            Some(path) => Some(read_names(path)?),
            None => None,
        };
        self.classes
            .iter()
            .map(|c| match (c, &names) {
                (ClassRef::Index(i), Some(n)) if *i >= n.len() => {
                    Err(DetectError::Config(format!(
                        "class {i} is beyond the {} classes of the names file",
                        n.len()
                    )))
                }
                (ClassRef::Index(i), _) => Ok(*i),
                (ClassRef::Name(name), Some(n)) => {
                    n.iter().position(|m| m == name).ok_or_else(|| {
                        DetectError::Config(format!(
                            "class {name:?} is not in {} ({} classes: {}, …)",
                            self.names
                                .as_ref()
                                .map_or(String::new(), |p| p.display().to_string()),
                            n.len(),
                            n.iter().take(8).cloned().collect::<Vec<_>>().join(", ")
                        ))
                    })
                }
                (ClassRef::Name(name), None) => Err(DetectError::Config(format!(
                    "class {name:?} is given by name: set `names` to the model's class names file"
                ))),
            })
            .collect()
    }
}

/// A names file: one class per line, blank lines at the end ignored.
fn read_names(path: &std::path::Path) -> Result<Vec<String>, DetectError> {
    let text = std::fs::read_to_string(path).map_err(|e| DetectError::Model {
        path: path.display().to_string(),
        reason: e.to_string(),
    })?;
    let names: Vec<String> = text.lines().map(|l| l.trim().to_string()).collect();
    let end = names
        .iter()
        .rposition(|n| !n.is_empty())
        .map_or(0, |i| i + 1);
    Ok(names[..end].to_vec())
}

fn default_input() -> i32 {
    640
}
fn default_layout() -> YoloLayout {
    YoloLayout::Auto
}
fn default_confidence() -> f32 {
    0.25
}
fn default_iou() -> f32 {
    0.45
}

/// A decoded box in model-input pixels (edge convention).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    pub cx: f32,
    pub cy: f32,
    pub w: f32,
    pub h: f32,
    pub score: f32,
    pub class: usize,
}

/// How a frame was fitted into the model input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Letterbox {
    pub scale: f64,
    pub pad_x: f64,
    pub pad_y: f64,
}

impl Letterbox {
    /// For a `width × height` frame into a `size × size` input.
    pub fn new(width: i32, height: i32, size: i32) -> (Self, cv::Size) {
        let scale = (size as f64 / width as f64).min(size as f64 / height as f64);
        let resized = cv::Size::new(
            ((width as f64 * scale).round() as i32).max(1),
            ((height as f64 * scale).round() as i32).max(1),
        );
        let pad_x = ((size - resized.width) / 2) as f64;
        let pad_y = ((size - resized.height) / 2) as f64;
        (
            Self {
                scale,
                pad_x,
                pad_y,
            },
            resized,
        )
    }

    /// Model-input (edge convention) → frame pixel (OpenCV centre convention).
    pub fn to_frame(&self, x: f64, y: f64) -> [f64; 2] {
        [
            (x - self.pad_x) / self.scale - 0.5,
            (y - self.pad_y) / self.scale - 0.5,
        ]
    }
}

/// Decodes a raw output tensor of shape `dims` (batch 1) into candidates above
/// `threshold` whose class is in `classes` (all when empty), in input pixels of a
/// `input_size` square input.
pub fn decode(
    data: &[f32],
    dims: [usize; 3],
    layout: YoloLayout,
    threshold: f32,
    classes: &[usize],
    input_size: f32,
) -> Result<Vec<Candidate>, DetectError> {
    let [batch, a, b] = dims;
    if batch != 1 || data.len() != a * b {
        return Err(DetectError::Config(format!(
            "YOLO output of shape {dims:?} does not hold {} values",
            data.len()
        )));
    }
    let layout = match layout {
        YoloLayout::Auto if a > b => YoloLayout::V5,
        YoloLayout::Auto => YoloLayout::V8,
        l => l,
    };
    let row_major = layout != YoloLayout::V8;
    let (count, width) = if row_major { (a, b) } else { (b, a) };
    // Value k of candidate i.
    let value = |i: usize, k: usize| {
        if row_major {
            data[i * b + k]
        } else {
            data[k * b + i]
        }
    };
    let first_class = if layout == YoloLayout::V8 { 4 } else { 5 };
    if width <= first_class {
        return Err(DetectError::Config(format!(
            "YOLO output of shape {dims:?} has no class scores for layout {layout:?}"
        )));
    }
    let mut out = Vec::new();
    for i in 0..count {
        let (class, best) = (first_class..width)
            .map(|k| (k - first_class, value(i, k)))
            .fold(
                (0, f32::NEG_INFINITY),
                |acc, c| if c.1 > acc.1 { c } else { acc },
            );
        let score = if layout == YoloLayout::V5 {
            value(i, 4) * best
        } else {
            best
        };
        if score.is_nan() || score < threshold || (!classes.is_empty() && !classes.contains(&class))
        {
            continue;
        }
        // Darknet's boxes are fractions of the input.
        let unit = if layout == YoloLayout::Darknet {
            input_size
        } else {
            1.0
        };
        let c = Candidate {
            cx: value(i, 0) * unit,
            cy: value(i, 1) * unit,
            w: value(i, 2) * unit,
            h: value(i, 3) * unit,
            score,
            class,
        };
        if [c.cx, c.cy, c.w, c.h].iter().all(|v| v.is_finite()) && c.w > 0.0 && c.h > 0.0 {
            out.push(c);
        }
    }
    Ok(out)
}

/// The model's input for `frame` (letterboxed to `size` × `size`, RGB, scaled): the one
/// copy of the frame's pixels the network needs; with the letterbox used. `resized` and
/// `padded` are buffers kept between frames.
pub fn model_input(
    frame: &cv::Mat,
    size: i32,
    resized: &mut cv::Mat,
    padded: &mut cv::Mat,
) -> Result<(cv::Mat, Letterbox), DetectError> {
    check_bgr(frame)?;
    let (lb, inner) = Letterbox::new(frame.cols(), frame.rows(), size);
    opencv::imgproc::resize(
        frame,
        resized,
        inner,
        0.0,
        0.0,
        opencv::imgproc::INTER_LINEAR,
    )?;
    let (left, top) = (lb.pad_x as i32, lb.pad_y as i32);
    cv::copy_make_border(
        &*resized,
        padded,
        top,
        size - inner.height - top,
        left,
        size - inner.width - left,
        cv::BORDER_CONSTANT,
        cv::Scalar::all(114.0),
    )?;
    let blob = opencv::dnn::blob_from_image(
        &*padded,
        1.0 / 255.0,
        cv::Size::new(size, size),
        cv::Scalar::all(0.0),
        true,
        false,
        cv::CV_32F,
    )?;
    Ok((blob, lb))
}

/// The number of classes an output of shape `dims` holds under `layout`.
fn class_count(dims: [usize; 3], layout: YoloLayout) -> usize {
    let [_, a, b] = dims;
    match layout {
        YoloLayout::V8 => a.saturating_sub(4),
        YoloLayout::Auto if a <= b => a.saturating_sub(4),
        _ => b.saturating_sub(5),
    }
}

/// Non-maximum suppression (OpenCV `NMSBoxes`); survivors, most confident first.
pub fn suppress(
    candidates: &[Candidate],
    threshold: f32,
    iou: f32,
) -> Result<Vec<Candidate>, DetectError> {
    let boxes: cv::Vector<cv::Rect2d> = candidates
        .iter()
        .map(|c| {
            cv::Rect2d::new(
                (c.cx - c.w / 2.0) as f64,
                (c.cy - c.h / 2.0) as f64,
                c.w as f64,
                c.h as f64,
            )
        })
        .collect();
    let scores: cv::Vector<f32> = candidates.iter().map(|c| c.score).collect();
    let mut keep = cv::Vector::<i32>::new();
    opencv::dnn::nms_boxes_f64(&boxes, &scores, threshold, iou, &mut keep, 1.0, 0)?;
    let mut out: Vec<Candidate> = keep.iter().map(|i| candidates[i as usize]).collect();
    out.sort_by(|a, b| b.score.total_cmp(&a.score));
    Ok(out)
}

pub struct YoloDetector {
    config: YoloConfig,
    /// `config.classes` as indices.
    classes: Vec<usize>,
    net: opencv::dnn::Net,
    padded: cv::Mat,
    resized: cv::Mat,
}

impl YoloDetector {
    pub fn new(config: YoloConfig) -> Result<Self, DetectError> {
        let path = config.model.display().to_string();
        let model_err = |reason: String| DetectError::Model {
            path: path.clone(),
            reason,
        };
        if !config.model.is_file() {
            return Err(model_err("no such file".into()));
        }
        if config.input_size < 32
            || !(0.0..=1.0).contains(&config.confidence_threshold)
            || !(0.0..=1.0).contains(&config.nms_iou)
            || config.every_frames == 0
        {
            return Err(DetectError::Config(
                "need input_size >= 32, thresholds in [0, 1] and every_frames >= 1".into(),
            ));
        }
        let classes = config.class_indices()?;
        let mut net = match &config.config {
            Some(cfg) => {
                if !cfg.is_file() {
                    return Err(DetectError::Model {
                        path: cfg.display().to_string(),
                        reason: "no such file".into(),
                    });
                }
                opencv::dnn::read_net_from_darknet(
                    cfg.display().to_string().as_str(),
                    path.as_str(),
                )
            }
            None => opencv::dnn::read_net_from_onnx(&path),
        }
        .map_err(|e| model_err(e.message))?;
        if net.empty().map_err(|e| model_err(e.message))? {
            return Err(model_err("OpenCV read an empty network".into()));
        }
        net.set_preferable_backend(opencv::dnn::DNN_BACKEND_OPENCV)?;
        net.set_preferable_target(opencv::dnn::DNN_TARGET_CPU)?;
        let mut config = config;
        if config.config.is_some() && config.layout == YoloLayout::Auto {
            config.layout = YoloLayout::Darknet;
        }
        let mut detector = Self {
            config,
            classes,
            net,
            padded: cv::Mat::default(),
            resized: cv::Mat::default(),
        };
        // One forward on a blank frame: a model whose output cannot be decoded is an
        // error now, before the run, not at the first frame.
        let size = detector.config.input_size;
        let blank =
            cv::Mat::new_rows_cols_with_default(size, size, cv::CV_8UC3, cv::Scalar::all(0.0))?;
        let (data, dims, _) = detector
            .forward(&blank)
            .map_err(|e| model_err(e.to_string()))?;
        let c = &detector.config;
        decode(&data, dims, c.layout, 2.0, &[], size as f32)
            .map_err(|e| model_err(e.to_string()))?;
        if let Some(&beyond) = detector
            .classes
            .iter()
            .find(|&&i| i >= class_count(dims, c.layout))
        {
            return Err(model_err(format!(
                "class {beyond} is beyond the model's {} classes",
                class_count(dims, c.layout)
            )));
        }
        Ok(detector)
    }

    /// The raw output tensor for `frame`, with the letterbox used.
    fn forward(
        &mut self,
        frame: &cv::Mat,
    ) -> Result<(Vec<f32>, [usize; 3], Letterbox), DetectError> {
        let (blob, lb) = self.blob(frame)?;
        let (data, dims) = self.run(&blob)?;
        Ok((data, dims, lb))
    }

    /// The model's input for `frame` ([`model_input`]), with the letterbox used.
    pub fn blob(&mut self, frame: &cv::Mat) -> Result<(cv::Mat, Letterbox), DetectError> {
        model_input(
            frame,
            self.config.input_size,
            &mut self.resized,
            &mut self.padded,
        )
    }

    /// The network on a blob from [`Self::blob`]: the raw output and its shape.
    fn run(&mut self, blob: &cv::Mat) -> Result<(Vec<f32>, [usize; 3]), DetectError> {
        self.net.set_input_def(blob)?;
        let out = self.net.forward_single_def()?;
        let shape: Vec<usize> = out.mat_size().iter().map(|d| *d as usize).collect();
        let dims = match shape[..] {
            [a, b, c] => [a, b, c],
            [b, c] => [1, b, c],
            _ => {
                return Err(DetectError::Config(format!(
                    "unexpected YOLO output shape {shape:?}"
                )))
            }
        };
        let data = out.data_typed::<f32>()?.to_vec();
        Ok((data, dims))
    }

    /// The most confident box in a blob's output, in the frame's pixels.
    pub fn detect_blob(
        &mut self,
        blob: &cv::Mat,
        lb: &Letterbox,
    ) -> Result<Option<Detection>, DetectError> {
        let (data, dims) = self.run(blob)?;
        self.best(&data, dims, lb)
    }

    fn best(
        &self,
        data: &[f32],
        dims: [usize; 3],
        lb: &Letterbox,
    ) -> Result<Option<Detection>, DetectError> {
        let c = &self.config;
        let candidates = decode(
            data,
            dims,
            c.layout,
            c.confidence_threshold,
            &self.classes,
            c.input_size as f32,
        )?;
        let Some(best) = suppress(&candidates, c.confidence_threshold, c.nms_iou)?
            .into_iter()
            .next()
        else {
            return Ok(None);
        };
        let [x0, y0] = lb.to_frame(
            (best.cx - best.w / 2.0) as f64,
            (best.cy - best.h / 2.0) as f64,
        );
        let [x1, y1] = lb.to_frame(
            (best.cx + best.w / 2.0) as f64,
            (best.cy + best.h / 2.0) as f64,
        );
        Ok(Some(Detection {
            bbox: [x0 + 0.5, y0 + 0.5, x1 - x0, y1 - y0],
            centre: lb.to_frame(best.cx as f64, best.cy as f64),
            confidence: best.score.clamp(0.0, 1.0),
        }))
    }

    /// The configuration it was built with.
    pub fn config(&self) -> &YoloConfig {
        &self.config
    }
}

impl Detector for YoloDetector {
    fn detect(&mut self, frame: &cv::Mat) -> Result<Option<Detection>, DetectError> {
        let (data, dims, lb) = self.forward(frame)?;
        self.best(&data, dims, &lb)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn v8_and_v5_layouts_decode_the_same_boxes() {
        // Two candidates, two classes. v8: (1, 6, 2) channel-major.
        let v8 = [
            10.0, 50.0, // cx
            20.0, 60.0, // cy
            4.0, 8.0, // w
            6.0, 2.0, // h
            0.9, 0.1, // class 0
            0.05, 0.7, // class 1
        ];
        let got = decode(&v8, [1, 6, 2], YoloLayout::V8, 0.5, &[], 1.0).unwrap();
        assert_eq!(got.len(), 2);
        assert_eq!((got[0].cx, got[0].class, got[0].score), (10.0, 0, 0.9));
        assert_eq!((got[1].cy, got[1].class, got[1].score), (60.0, 1, 0.7));
        // Class filter.
        assert_eq!(
            decode(&v8, [1, 6, 2], YoloLayout::V8, 0.5, &[1], 1.0)
                .unwrap()
                .len(),
            1
        );
        // v5: (1, 3, 7) row-major with objectness.
        let v5 = [
            10.0, 20.0, 4.0, 6.0, 1.0, 0.9, 0.05, //
            50.0, 60.0, 8.0, 2.0, 1.0, 0.1, 0.7, //
            30.0, 30.0, 5.0, 5.0, 0.2, 0.9, 0.0, // low objectness: 0.18
        ];
        let got5 = decode(&v5, [1, 3, 7], YoloLayout::V5, 0.5, &[], 1.0).unwrap();
        assert_eq!(got5, got);
        assert!(
            decode(&v5, [1, 4, 7], YoloLayout::V5, 0.5, &[], 1.0).is_err(),
            "shape must match data"
        );
    }

    #[test]
    fn auto_layout_takes_the_longer_axis_as_candidates() {
        // Real models have far more candidates than channels: v8 (1, 84, 8400), v5
        // (1, 25200, 85). Ten candidates with 2 classes, one confident at index 7.
        let n = 10;
        let mut v8 = vec![1.0f32; 6 * n];
        (0..n).for_each(|i| v8[4 * n + i] = if i == 7 { 0.8 } else { 0.0 });
        (0..n).for_each(|i| v8[5 * n + i] = 0.0);
        let got = decode(&v8, [1, 6, n], YoloLayout::Auto, 0.5, &[], 1.0).unwrap();
        assert_eq!((got.len(), got[0].score), (1, 0.8));
        let mut v5 = vec![1.0f32; n * 7];
        (0..n).for_each(|i| {
            v5[i * 7 + 5] = if i == 3 { 0.6 } else { 0.0 };
            v5[i * 7 + 6] = 0.0;
        });
        let got = decode(&v5, [1, n, 7], YoloLayout::Auto, 0.5, &[], 1.0).unwrap();
        assert_eq!((got.len(), got[0].score), (1, 0.6));
    }

    #[test]
    fn nms_keeps_the_best_of_overlapping_boxes() {
        let c = |cx: f32, score: f32| Candidate {
            cx,
            cy: 10.0,
            w: 10.0,
            h: 10.0,
            score,
            class: 0,
        };
        let kept = suppress(&[c(10.0, 0.6), c(11.0, 0.9), c(40.0, 0.7)], 0.25, 0.45).unwrap();
        assert_eq!(
            kept.iter().map(|k| k.score).collect::<Vec<_>>(),
            vec![0.9, 0.7]
        );
    }

    #[test]
    fn letterbox_maps_back_to_frame_pixels() {
        // 1280×720 into 640: scale 0.5, 140 px bands top and bottom.
        let (lb, size) = Letterbox::new(1280, 720, 640);
        assert_eq!((lb.scale, lb.pad_x, lb.pad_y), (0.5, 0.0, 140.0));
        assert_eq!((size.width, size.height), (640, 360));
        // Input point (320, 320) edge-convention = frame edge (640, 360) = pixel centre (639.5, 359.5).
        assert_eq!(lb.to_frame(320.0, 320.0), [639.5, 359.5]);
    }

    #[test]
    fn missing_model_is_a_clear_error() {
        let cfg = YoloConfig {
            model: "/nonexistent/yolo.onnx".into(),
            input_size: 640,
            config: None,
            names: None,
            layout: YoloLayout::Auto,
            confidence_threshold: 0.25,
            nms_iou: 0.45,
            classes: vec![],
            every_frames: 8,
        };
        let e = YoloDetector::new(cfg).err().unwrap().to_string();
        assert!(
            e.contains("/nonexistent/yolo.onnx") && e.contains("no such file"),
            "{e}"
        );
    }
}
