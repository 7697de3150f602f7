//! Video in and out through OpenCV's videoio (Debian's libopencv-videoio, FFmpeg back
//! end). Reading decodes into OpenCV's own frame and copies it once into the
//! destination (the loaned shared-memory sample): videoio cannot decode into a
//! caller's buffer. The copy is timed with the decode in acquisition's `produce`
//! histogram.

use opencv::core as cv;
use opencv::prelude::*;
use opencv::videoio;

use super::x264::X264Writer;

/// A video file or stream, decoded frame by frame.
pub struct VideoReader {
    cap: videoio::VideoCapture,
    frame: cv::Mat,
    source: String,
    width: u32,
    height: u32,
    frame_rate_hz: f64,
    /// Frames decoded since opening.
    pub decoded: u64,
    last_t: f64,
}

fn err(source: &str, e: impl std::fmt::Display) -> String {
    format!("video {source}: {e}")
}

impl VideoReader {
    /// Opens `source` (a path or a URL) expecting `width × height` frames.
    pub fn open(source: &str, width: u32, height: u32, frame_rate_hz: f64) -> Result<Self, String> {
        let cap = videoio::VideoCapture::from_file(source, videoio::CAP_FFMPEG)
            .map_err(|e| err(source, e.message))?;
        if !cap.is_opened().map_err(|e| err(source, e.message))? {
            return Err(err(
                source,
                "cannot be opened (missing, or not a video FFmpeg reads)",
            ));
        }
        Ok(Self {
            cap,
            frame: cv::Mat::default(),
            source: source.to_string(),
            width,
            height,
            frame_rate_hz,
            decoded: 0,
            last_t: f64::NEG_INFINITY,
        })
    }

    /// Decodes the next frame into `dst` (packed BGR rows, `width × height × 3` bytes)
    /// and returns its time in seconds from the video's start: the container's
    /// timestamp, or `index / frame_rate_hz` when the container gives none that
    /// increases. `None` at the end of the video.
    pub fn next_into(&mut self, dst: &mut [u8]) -> Option<Result<f64, String>> {
        match self.cap.read(&mut self.frame) {
            Ok(true) => {}
            Ok(false) => return None,
            Err(e) => return Some(Err(err(&self.source, e.message))),
        }
        let index = self.decoded;
        self.decoded += 1;
        if self.frame.typ() != cv::CV_8UC3
            || (self.frame.cols() as u32, self.frame.rows() as u32) != (self.width, self.height)
        {
            return Some(Err(err(
                &self.source,
                format!(
                    "frame {index} is {}×{} (type {}), flight.toml says {}×{} BGR",
                    self.frame.cols(),
                    self.frame.rows(),
                    self.frame.typ(),
                    self.width,
                    self.height
                ),
            )));
        }
        let copied = self
            .frame
            .data_bytes()
            .map_err(|e| err(&self.source, e.message))
            .and_then(|bytes| {
                if bytes.len() == dst.len() {
                    dst.copy_from_slice(bytes);
                    Ok(())
                } else {
                    Err(err(&self.source, "frame size does not match the buffer"))
                }
            });
        if let Err(e) = copied {
            return Some(Err(e));
        }
        let pts = self.cap.get(videoio::CAP_PROP_POS_MSEC).unwrap_or(f64::NAN) / 1e3;
        let t = if pts.is_finite() && pts > self.last_t {
            pts
        } else {
            // No usable timestamp: the frame index, but never back in time.
            (index as f64 / self.frame_rate_hz).max(self.last_t + 1.0 / self.frame_rate_hz)
        };
        self.last_t = t;
        Some(Ok(t))
    }

    /// Frames in the container, when it says (a file; a stream does not).
    pub fn frame_count(&self) -> Option<f64> {
        self.cap
            .get(videoio::CAP_PROP_FRAME_COUNT)
            .ok()
            .filter(|n| n.is_finite() && *n > 0.0)
    }

    /// Skips one frame without converting it; false at the end.
    pub fn skip(&mut self) -> bool {
        self.decoded += 1;
        self.cap.grab().unwrap_or(false)
    }
}

/// What the simulator encodes a flight's videos as.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VideoCodec {
    /// H.264 in MP4 (x264's default quality, crf 23: OpenCV 4.6's writer sets no
    /// other), falling back to MPEG-4 part 2 when there is no H.264 encoder: what a
    /// UAV's video link delivers.
    H264,
    /// H.264 in MP4 at this crf (0–51), through FFmpeg's command-line tool
    /// ([`super::x264`]): a video link of a chosen quality.
    H264Crf(u8),
    /// FFV1 in Matroska: lossless, to measure the flight path without compression.
    Lossless,
}

impl VideoCodec {
    /// (name, FourCC, file extension) for OpenCV's writer, in order of preference.
    fn candidates(self) -> &'static [(&'static str, [char; 4], &'static str)] {
        match self {
            VideoCodec::H264 => &[
                ("h264", ['a', 'v', 'c', '1'], "mp4"),
                ("mpeg4", ['m', 'p', '4', 'v'], "mp4"),
            ],
            VideoCodec::Lossless => &[("ffv1", ['F', 'F', 'V', '1'], "mkv")],
            VideoCodec::H264Crf(_) => &[],
        }
    }
}

/// Who encodes a [`VideoSink`]'s frames.
enum Encoder {
    OpenCv(videoio::VideoWriter),
    Ffmpeg(X264Writer),
}

/// Writes a video file in the first encoding of a [`VideoCodec`] that OpenCV's FFmpeg
/// has (or FFmpeg's CLI for [`VideoCodec::H264Crf`]); [`VideoSink::codec`] says which,
/// [`VideoSink::file_name`] where.
pub struct VideoSink {
    encoder: Encoder,
    pub codec: &'static str,
    pub file_name: String,
}

fn file_name_of(path: &std::path::Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default()
}

impl VideoSink {
    /// `stem` is the file's path without its extension (the codec picks it).
    pub fn create(
        stem: &std::path::Path,
        codec: VideoCodec,
        width: u32,
        height: u32,
        frame_rate_hz: f64,
    ) -> Result<Self, String> {
        if let VideoCodec::H264Crf(crf) = codec {
            let path = stem.with_extension("mp4");
            let writer = X264Writer::create(&path, width, height, frame_rate_hz, crf)?;
            return Ok(Self {
                encoder: Encoder::Ffmpeg(writer),
                codec: "h264 (libx264 through ffmpeg)",
                file_name: file_name_of(&path),
            });
        }
        let size = cv::Size::new(width as i32, height as i32);
        let mut name = stem.to_string_lossy().to_string();
        for &(codec, fourcc, ext) in codec.candidates() {
            let path = stem.with_extension(ext);
            name = path.to_string_lossy().to_string();
            let fourcc = videoio::VideoWriter::fourcc(fourcc[0], fourcc[1], fourcc[2], fourcc[3])
                .map_err(|e| err(&name, e.message))?;
            let writer = videoio::VideoWriter::new_with_backend(
                &name,
                videoio::CAP_FFMPEG,
                fourcc,
                frame_rate_hz,
                size,
                true,
            )
            .map_err(|e| err(&name, e.message))?;
            if writer.is_opened().unwrap_or(false) {
                return Ok(Self {
                    encoder: Encoder::OpenCv(writer),
                    codec,
                    file_name: file_name_of(&path),
                });
            }
        }
        Err(err(&name, "no encoder for it in OpenCV's FFmpeg"))
    }

    pub fn write(&mut self, frame: &cv::Mat) -> Result<(), String> {
        match &mut self.encoder {
            Encoder::OpenCv(w) => w.write(frame).map_err(|e| e.message),
            Encoder::Ffmpeg(w) => {
                if frame.typ() != cv::CV_8UC3 || !frame.is_continuous() {
                    return Err(format!(
                        "video {}: frames must be continuous BGR (type {})",
                        self.file_name,
                        frame.typ()
                    ));
                }
                w.write(frame.data_bytes().map_err(|e| e.message)?)
            }
        }
    }

    pub fn finish(self) -> Result<(), String> {
        match self.encoder {
            Encoder::OpenCv(mut w) => w.release().map_err(|e| e.message),
            Encoder::Ffmpeg(w) => w.finish().map(|_| ()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_written_video_reads_back_with_each_frames_own_time() {
        let dir = tempfile::tempdir().unwrap();
        let mut sink =
            VideoSink::create(&dir.path().join("v"), VideoCodec::H264, 64, 48, 30.0).unwrap();
        let path = dir.path().join(&sink.file_name);
        for k in 0..6 {
            let frame = cv::Mat::new_rows_cols_with_default(
                48,
                64,
                cv::CV_8UC3,
                cv::Scalar::all(k as f64 * 40.0),
            )
            .unwrap();
            sink.write(&frame).unwrap();
        }
        sink.finish().unwrap();
        let mut reader = VideoReader::open(&path.to_string_lossy(), 64, 48, 30.0).unwrap();
        let mut buf = vec![0u8; 64 * 48 * 3];
        let mut times = Vec::new();
        while let Some(t) = reader.next_into(&mut buf) {
            times.push(t.unwrap());
            let mean = buf.iter().map(|&b| b as f64).sum::<f64>() / buf.len() as f64;
            let k = times.len() - 1;
            assert!(
                (mean - k as f64 * 40.0).abs() < 12.0,
                "frame {k} has mean {mean}"
            );
        }
        assert_eq!(times.len(), 6);
        for (k, t) in times.iter().enumerate() {
            assert!(
                (t - k as f64 / 30.0).abs() < 1e-3,
                "frame {k} at {t} s: {times:?}"
            );
        }
    }

    #[test]
    fn a_frame_of_the_wrong_size_is_an_error_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let mut sink =
            VideoSink::create(&dir.path().join("v"), VideoCodec::H264, 64, 48, 30.0).unwrap();
        let path = dir.path().join(&sink.file_name);
        let frame =
            cv::Mat::new_rows_cols_with_default(48, 64, cv::CV_8UC3, cv::Scalar::all(9.0)).unwrap();
        sink.write(&frame).unwrap();
        sink.finish().unwrap();
        let mut reader = VideoReader::open(&path.to_string_lossy(), 32, 48, 30.0).unwrap();
        let mut buf = vec![0u8; 32 * 48 * 3];
        assert!(reader.next_into(&mut buf).unwrap().is_err());
        assert!(VideoReader::open("/nonexistent.mp4", 64, 48, 30.0).is_err());
    }

    /// A frame of `w × h` BGR that moves with `k` (compression has work to do).
    fn gradient(k: usize, w: usize, h: usize) -> cv::Mat {
        let mut m = cv::Mat::new_rows_cols_with_default(
            h as i32,
            w as i32,
            cv::CV_8UC3,
            cv::Scalar::all(0.0),
        )
        .unwrap();
        let bytes = m.data_bytes_mut().unwrap();
        for y in 0..h {
            for x in 0..w {
                let i = 3 * (y * w + x);
                bytes[i] = ((x + 3 * k) % 256) as u8;
                bytes[i + 1] = ((y * 2) % 256) as u8;
                bytes[i + 2] = 200;
            }
        }
        m
    }

    /// Writes 20 frames at `crf` and reads them back: the mean absolute pixel error.
    fn crf_round_trip(crf: u8) -> f64 {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (96usize, 64usize);
        let mut sink = VideoSink::create(
            &dir.path().join("v"),
            VideoCodec::H264Crf(crf),
            w as u32,
            h as u32,
            30.0,
        )
        .unwrap();
        assert_eq!(sink.file_name, "v.mp4");
        for k in 0..20 {
            sink.write(&gradient(k, w, h)).unwrap();
        }
        sink.finish().unwrap();
        let path = dir.path().join("v.mp4");
        let mut reader =
            VideoReader::open(&path.to_string_lossy(), w as u32, h as u32, 30.0).unwrap();
        let mut buf = vec![0u8; w * h * 3];
        let (mut error, mut k) = (0.0, 0);
        while let Some(t) = reader.next_into(&mut buf) {
            assert!((t.unwrap() - k as f64 / 30.0).abs() < 1e-3, "frame {k}");
            let want = gradient(k, w, h);
            let want = want.data_bytes().unwrap();
            error += buf
                .iter()
                .zip(want)
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .sum::<f64>()
                / buf.len() as f64;
            k += 1;
        }
        assert_eq!(k, 20, "every frame written is read back, none dropped");
        error / k as f64
    }

    #[test]
    fn a_crf_video_reads_back_frame_for_frame_and_a_higher_crf_loses_more() {
        let fine = crf_round_trip(12);
        let coarse = crf_round_trip(40);
        assert!(fine < 3.0, "crf 12: mean abs error {fine}");
        assert!(coarse > fine, "crf 40: {coarse}, crf 12: {fine}");
    }
}
