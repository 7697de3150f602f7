//! Writing a recording: images as PNG (lossless, the default) or JPEG, telemetry.csv and
//! optionally truth.csv,
//! with floats in Rust's shortest round-trip form so the reader gets back exactly what
//! was written.

use super::rows::{headers, telemetry_record, truth_record, TelemetryRow, TruthRow};
use super::{CameraMount, RecordingError, RecordingMeta, META_FILE, TELEMETRY_FILE, TRUTH_FILE};
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::conventions::Uav;
use shared_types::messages::PoseSample;
use std::fs::File;
use std::path::{Path, PathBuf};

/// The truth that goes with one image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthSample {
    pub pose: PoseSample,
    pub target: [f64; 3],
    pub target_px: Option<[f64; 2]>,
    /// The true gimbal angles (degrees), for a UAV with `mount = "gimbal"`.
    pub gimbal: Option<[f64; 3]>,
}

/// How a recording's images are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageEncoding {
    /// Lossless (the default).
    Png,
    /// JPEG at this quality (1–100): several times faster to decode on replay
    /// (docs/pipeline.md), at the cost of compression artefacts.
    Jpeg { quality: u8 },
}

impl ImageEncoding {
    fn extension(self) -> &'static str {
        match self {
            ImageEncoding::Png => "png",
            ImageEncoding::Jpeg { .. } => "jpg",
        }
    }

    fn params(self) -> cv::Vector<i32> {
        match self {
            ImageEncoding::Png => {
                cv::Vector::from_slice(&[opencv::imgcodecs::IMWRITE_PNG_COMPRESSION, 1])
            }
            ImageEncoding::Jpeg { quality } => cv::Vector::from_slice(&[
                opencv::imgcodecs::IMWRITE_JPEG_QUALITY,
                quality.clamp(1, 100) as i32,
            ]),
        }
    }
}

pub struct RecordingWriter {
    root: PathBuf,
    meta: RecordingMeta,
    telemetry: csv::Writer<File>,
    truth: Option<csv::Writer<File>>,
    next_frame: [u64; 2],
    last_t: [Option<f64>; 2],
    encoding: ImageEncoding,
    params: cv::Vector<i32>,
}

fn write_err(path: &Path, message: impl std::fmt::Display) -> RecordingError {
    RecordingError::Write {
        path: path.into(),
        message: message.to_string(),
    }
}

impl RecordingWriter {
    /// Creates `root` (which must not exist, or be an empty folder) with its metadata.
    pub fn create(
        root: impl AsRef<Path>,
        meta: &RecordingMeta,
        with_truth: bool,
    ) -> Result<Self, RecordingError> {
        let root = root.as_ref().to_path_buf();
        meta.validate().map_err(|m| write_err(&root, m))?;
        if root.exists() {
            let mut entries = std::fs::read_dir(&root).map_err(|e| RecordingError::io(&root, e))?;
            if entries.next().is_some() {
                return Err(write_err(&root, "output folder exists and is not empty"));
            }
        }
        for folder in [&meta.uav.left.frames, &meta.uav.right.frames] {
            let dir = root.join(folder);
            std::fs::create_dir_all(&dir).map_err(|e| RecordingError::io(&dir, e))?;
        }
        let meta_path = root.join(META_FILE);
        std::fs::write(&meta_path, meta.to_toml())
            .map_err(|e| RecordingError::io(&meta_path, e))?;
        let open = |name: &str, header: &[&str]| -> Result<csv::Writer<File>, RecordingError> {
            let path = root.join(name);
            let mut w = csv::Writer::from_path(&path).map_err(|e| write_err(&path, e))?;
            w.write_record(header).map_err(|e| write_err(&path, e))?;
            Ok(w)
        };
        let (telemetry_header, truth_header) = headers(meta.has_gimbal_columns());
        let telemetry = open(TELEMETRY_FILE, telemetry_header)?;
        let truth = with_truth
            .then(|| open(TRUTH_FILE, truth_header))
            .transpose()?;
        Ok(Self {
            root,
            meta: meta.clone(),
            telemetry,
            truth,
            next_frame: [0; 2],
            last_t: [None; 2],
            encoding: ImageEncoding::Png,
            params: ImageEncoding::Png.params(),
        })
    }

    /// Encodes the images from now on as `encoding` (PNG until told otherwise).
    pub fn with_encoding(mut self, encoding: ImageEncoding) -> Self {
        self.encoding = encoding;
        self.params = encoding.params();
        self
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Writes one image of `uav` taken at `t_s` with its measured pose (and truth).
    pub fn write_frame(
        &mut self,
        uav: Uav,
        t_s: f64,
        measured: PoseSample,
        image: &cv::Mat,
        truth: Option<&TruthSample>,
    ) -> Result<TelemetryRow, RecordingError> {
        let png = self.encode(uav, image)?;
        self.write_encoded_frame(uav, t_s, measured, &png, truth)
    }

    /// [`RecordingWriter::write_encoded_frame`] for a UAV with `mount = "gimbal"`: with
    /// the gimbal's measured angles (degrees; the truth's in `truth.gimbal`).
    pub fn write_gimbal_frame(
        &mut self,
        uav: Uav,
        t_s: f64,
        measured: PoseSample,
        gimbal: [f64; 3],
        png: &[u8],
        truth: Option<&TruthSample>,
    ) -> Result<TelemetryRow, RecordingError> {
        self.write_row(uav, t_s, measured, Some(gimbal), png, truth)
    }

    /// Checks `image` against `uav`'s camera and encodes it. Takes `&self`, so
    /// both UAVs' frames can be encoded at once on two threads.
    pub fn encode(&self, uav: Uav, image: &cv::Mat) -> Result<Vec<u8>, RecordingError> {
        let camera = self.meta.uav(uav).camera;
        let path = self.root.join(&self.meta.uav(uav).frames);
        if (image.cols() as u32, image.rows() as u32) != (camera.width, camera.height)
            || image.depth() != cv::CV_8U
            || !(image.channels() == 1 || image.channels() == 3)
        {
            return Err(write_err(
                &path,
                format!(
                    "image must be 8-bit grey or BGR {}x{}, got {}x{} with {} channels",
                    camera.width,
                    camera.height,
                    image.cols(),
                    image.rows(),
                    image.channels()
                ),
            ));
        }
        let mut bytes = cv::Vector::<u8>::new();
        let extension = format!(".{}", self.encoding.extension());
        opencv::imgcodecs::imencode(&extension, image, &mut bytes, &self.params)
            .map_err(|e| write_err(&path, e.message))?;
        Ok(bytes.to_vec())
    }

    /// [`RecordingWriter::write_frame`] for an image already encoded by
    /// [`RecordingWriter::encode`].
    pub fn write_encoded_frame(
        &mut self,
        uav: Uav,
        t_s: f64,
        measured: PoseSample,
        png: &[u8],
        truth: Option<&TruthSample>,
    ) -> Result<TelemetryRow, RecordingError> {
        self.write_row(uav, t_s, measured, None, png, truth)
    }

    fn write_row(
        &mut self,
        uav: Uav,
        t_s: f64,
        measured: PoseSample,
        gimbal: Option<[f64; 3]>,
        png: &[u8],
        truth: Option<&TruthSample>,
    ) -> Result<TelemetryRow, RecordingError> {
        let frame = self.next_frame[uav.index()];
        let extension = self.encoding.extension();
        let file = format!("{}/{frame:06}.{extension}", self.meta.uav(uav).frames);
        let path = self.root.join(&file);
        if !t_s.is_finite() || self.last_t[uav.index()].is_some_and(|last| t_s <= last) {
            return Err(write_err(
                &path,
                format!("timestamp {t_s} does not increase"),
            ));
        }
        if !measured.is_finite()
            || truth.is_some_and(|t| {
                !t.pose.is_finite()
                    || !t
                        .target
                        .iter()
                        .chain(t.target_px.iter().flatten())
                        .all(|v| v.is_finite())
            })
        {
            return Err(write_err(&path, "pose or truth is not finite"));
        }
        let is_gimbal = self.meta.mount(uav) == CameraMount::Gimbal;
        let truth_gimbal = truth.and_then(|t| t.gimbal);
        let all_finite = |g: Option<[f64; 3]>| g.is_none_or(|g| g.iter().all(|v| v.is_finite()));
        if is_gimbal != gimbal.is_some()
            || (truth.is_some() && is_gimbal != truth_gimbal.is_some())
            || !all_finite(gimbal)
            || !all_finite(truth_gimbal)
        {
            return Err(write_err(
                &path,
                "gimbal angles (finite) are given exactly for a UAV with mount = \"gimbal\"",
            ));
        }
        if truth.is_some() != self.truth.is_some() {
            return Err(write_err(
                &path,
                "truth given to a writer created without truth.csv, or missing",
            ));
        }
        std::fs::write(&path, png).map_err(|e| RecordingError::io(&path, e))?;

        let row = TelemetryRow {
            uav,
            frame,
            file,
            t_s,
            pose: measured,
            gimbal,
        };
        let columns = self.meta.has_gimbal_columns();
        let telemetry_path = self.root.join(TELEMETRY_FILE);
        self.telemetry
            .write_record(telemetry_record(&row, columns))
            .map_err(|e| write_err(&telemetry_path, e))?;
        if let (Some(w), Some(t)) = (self.truth.as_mut(), truth) {
            let truth_row = TruthRow {
                uav,
                frame,
                t_s,
                pose: t.pose,
                target: t.target,
                target_px: t.target_px,
                gimbal: truth_gimbal,
            };
            w.write_record(truth_record(&truth_row, columns))
                .map_err(|e| write_err(&self.root.join(TRUTH_FILE), e))?;
        }
        self.next_frame[uav.index()] += 1;
        self.last_t[uav.index()] = Some(t_s);
        Ok(row)
    }

    /// Flushes the CSV files. Dropping the writer without `finish` may lose rows.
    pub fn finish(mut self) -> Result<(), RecordingError> {
        let telemetry_path = self.root.join(TELEMETRY_FILE);
        self.telemetry
            .flush()
            .map_err(|e| RecordingError::io(&telemetry_path, e))?;
        if let Some(w) = self.truth.as_mut() {
            w.flush()
                .map_err(|e| RecordingError::io(self.root.join(TRUTH_FILE), e))?;
        }
        Ok(())
    }
}
