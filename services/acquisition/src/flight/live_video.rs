//! A live video stream (an RTSP or UDP URL FFmpeg opens), read by a thread of its own:
//! it decodes frame after frame as they come, stamps each with CLOCK_MONOTONIC when its
//! decoded pixels are handed over and with its presentation time in the stream, and
//! queues it for the source (at most [`QUEUE`]
//! frames; when the source falls behind, the oldest queued frame is dropped, counted as
//! `video_overruns`, so what the source gets is always recent). Left and right decode
//! in parallel, each on its own thread.
//!
//! A stream that stalls (no frame within `read_timeout`) or breaks is reopened, again
//! and again until the run ends: counted (`video_stalls`, `video_open_failures`) and
//! logged once each, never fatal. One copy more than a file: the thread decodes into
//! OpenCV's frame and copies into a recycled buffer; the source copies that into the
//! loaned shared-memory sample.

use crossbeam_channel::{bounded, Receiver, Sender, TrySendError};
use opencv::core as cv;
use opencv::prelude::*;
use opencv::videoio;
use shared_types::clock::monotonic_ns;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// Decoded frames queued for the source, per stream.
const QUEUE: usize = 3;

/// One decoded frame.
pub struct Frame {
    /// CLOCK_MONOTONIC when the decoder handed it over.
    pub host_ns: u64,
    /// Its presentation time in the stream, seconds (NaN when the stream gives none).
    pub pts_s: f64,
    /// Which opening of the stream it came from (a reopened stream's times restart).
    pub epoch: u32,
    /// Packed BGR rows.
    pub pixels: Vec<u8>,
}

#[derive(Debug, Default)]
struct Counters {
    frames: AtomicU64,
    overruns: AtomicU64,
    stalls: AtomicU64,
    open_failures: AtomicU64,
    wrong_size: AtomicU64,
}

pub struct LiveVideo {
    frames: Receiver<Frame>,
    recycle: Sender<Vec<u8>>,
    counters: Arc<Counters>,
    reported: [u64; 5],
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

struct Reader {
    url: String,
    width: u32,
    height: u32,
    read_timeout: Duration,
    frames: Sender<Frame>,
    /// The reader's own end of the queue, to drop the oldest frame when it is full.
    oldest: Receiver<Frame>,
    recycle: Receiver<Vec<u8>>,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
}

impl LiveVideo {
    /// Starts reading `url` (`width × height` BGR expected). The stream is opened by
    /// the thread (a stream not yet sending is retried, not refused).
    pub fn open(
        url: &str,
        width: u32,
        height: u32,
        read_timeout: Duration,
    ) -> Result<Self, String> {
        let (tx, rx) = bounded(QUEUE);
        let (recycle_tx, recycle_rx) = bounded(QUEUE + 2);
        let counters = Arc::new(Counters::default());
        let stop = Arc::new(AtomicBool::new(false));
        let reader = Reader {
            url: url.to_string(),
            width,
            height,
            read_timeout,
            frames: tx,
            oldest: rx.clone(),
            recycle: recycle_rx,
            counters: counters.clone(),
            stop: stop.clone(),
        };
        let thread = std::thread::Builder::new()
            .name("video-in".into())
            .spawn(move || reader.run())
            .map_err(|e| format!("video {url}: {e}"))?;
        Ok(Self {
            frames: rx,
            recycle: recycle_tx,
            counters,
            reported: [0; 5],
            stop,
            thread: Some(thread),
        })
    }

    /// The next frame, waiting at most `wait`.
    pub fn next(&self, wait: Duration) -> Option<Frame> {
        self.frames.recv_timeout(wait).ok()
    }

    /// Hands a frame's buffer back for reuse.
    pub fn give_back(&self, f: Frame) {
        let _ = self.recycle.try_send(f.pixels);
    }

    /// Counters since the last call.
    pub fn take_counts(&mut self) -> Vec<(&'static str, u64)> {
        let c = &self.counters;
        let now = [
            &c.frames,
            &c.overruns,
            &c.stalls,
            &c.open_failures,
            &c.wrong_size,
        ]
        .map(|a| a.load(Ordering::Relaxed));
        let names = [
            "video_frames",
            "video_overruns",
            "video_stalls",
            "video_open_failures",
            "video_wrong_size",
        ];
        super::increments(names, now, &mut self.reported)
    }
}

impl Drop for LiveVideo {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        // The reader sees `stop` within its read timeout.
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Reader {
    fn open(&self) -> Option<videoio::VideoCapture> {
        let ms = self.read_timeout.as_millis().min(i32::MAX as u128) as i32;
        let params = cv::Vector::<i32>::from_slice(&[
            videoio::CAP_PROP_OPEN_TIMEOUT_MSEC,
            ms.max(1000),
            videoio::CAP_PROP_READ_TIMEOUT_MSEC,
            ms,
        ]);
        let cap =
            videoio::VideoCapture::from_file_with_params(&self.url, videoio::CAP_FFMPEG, &params)
                .ok()
                .filter(|c| c.is_opened().unwrap_or(false));
        if cap.is_none() {
            let n = self.counters.open_failures.fetch_add(1, Ordering::Relaxed);
            if n == 0 {
                tracing::warn!(url = %self.url, "video stream not open yet: retrying (counted as video_open_failures)");
            }
        }
        cap
    }

    fn run(self) {
        let mut cap: Option<videoio::VideoCapture> = None;
        let mut epoch = 0u32;
        let mut mat = cv::Mat::default();
        let bytes = (self.width * self.height * 3) as usize;
        // When the stream last gave a frame (or was opened).
        let mut last_frame = std::time::Instant::now();
        while !self.stop.load(Ordering::Acquire) {
            let Some(c) = cap.as_mut() else {
                cap = self.open();
                if cap.is_some() {
                    epoch += 1;
                    last_frame = std::time::Instant::now();
                } else {
                    std::thread::sleep(Duration::from_millis(200));
                }
                continue;
            };
            if !matches!(c.read(&mut mat), Ok(true)) {
                // A packet that did not decode is not a stall; no frame for the read
                // timeout is.
                if last_frame.elapsed() < self.read_timeout {
                    std::thread::sleep(Duration::from_millis(5));
                    continue;
                }
                let n = self.counters.stalls.fetch_add(1, Ordering::Relaxed);
                if n == 0 {
                    tracing::warn!(url = %self.url, timeout = ?self.read_timeout, "video stream stalled: reopening (counted as video_stalls)");
                }
                cap = None;
                continue;
            }
            last_frame = std::time::Instant::now();
            let host_ns = monotonic_ns();
            let pts_s = c.get(videoio::CAP_PROP_POS_MSEC).unwrap_or(f64::NAN) / 1e3;
            let data = mat.data_bytes().ok().filter(|d| {
                mat.typ() == cv::CV_8UC3
                    && (mat.cols() as u32, mat.rows() as u32) == (self.width, self.height)
                    && d.len() == bytes
            });
            let Some(data) = data else {
                self.counters.wrong_size.fetch_add(1, Ordering::Relaxed);
                continue;
            };
            let mut pixels = self.recycle.try_recv().unwrap_or_default();
            pixels.clear();
            pixels.extend_from_slice(data);
            self.counters.frames.fetch_add(1, Ordering::Relaxed);
            let mut frame = Frame {
                host_ns,
                pts_s,
                epoch,
                pixels,
            };
            loop {
                match self.frames.try_send(frame) {
                    Ok(()) => break,
                    Err(TrySendError::Full(f)) => {
                        // The source is behind: the oldest frame goes, not this one.
                        if self.oldest.try_recv().is_ok() {
                            self.counters.overruns.fetch_add(1, Ordering::Relaxed);
                        }
                        frame = f;
                    }
                    Err(TrySendError::Disconnected(_)) => return,
                }
            }
        }
    }
}
