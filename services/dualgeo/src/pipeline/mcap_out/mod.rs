//! `--mcap FILE`: the run recorded as MCAP (https://mcap.dev) with Foxglove's
//! well-known schemas, so a user can scrub it in Foxglove: each UAV's frames (JPEG), its
//! measured camera pose, its detection drawn on the image, the target as a location fix
//! with covariance and as an ENU position, and each estimate's stage latency
//! (`schemas.rs` lists the channels, `encode.rs` builds the messages). Written by the
//! `mcap` crate from a thread of the supervisor (`recorder.rs`), off the estimate's
//! path. Issue #14.

mod encode;
mod recorder;
mod schemas;

use acquisition::recording::Origin;
use anyhow::{anyhow, bail, Result};
use clap::Args;
use shared_types::stats::StageStats;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

pub use recorder::RecorderReport;
pub use schemas::CHANNELS;

#[derive(Args, Debug, Clone)]
pub struct McapArgs {
    /// Record the run as MCAP (Foxglove's schemas, JSON-encoded): frames, poses,
    /// detections, the target and per-stage latency. Off by default.
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// Write every N-th frame's image (poses and detections are always all written).
    /// JPEG encoding costs ~2 ms a frame on the supervisor's thread.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub mcap_image_every: u64,
    /// JPEG quality of the recorded images (1–100).
    #[arg(long, default_value_t = 80, value_parser = clap::value_parser!(u8).range(1..=100))]
    pub mcap_jpeg_quality: u8,
}

/// A running recorder.
pub struct McapRecording {
    stop: Arc<AtomicBool>,
    thread: JoinHandle<Result<RecorderReport>>,
    path: PathBuf,
}

impl McapRecording {
    /// Starts the recorder when `--mcap` is given and returns once it is subscribed
    /// (so it sees the stream from its first frame), or why it could not start.
    pub fn start(args: &McapArgs, run_id: &str, origin: Option<Origin>) -> Result<Option<Self>> {
        let Some(path) = args.mcap.clone() else {
            return Ok(None);
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            if !dir.is_dir() {
                bail!("--mcap {}: no directory {}", path.display(), dir.display());
            }
        }
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let thread = {
            let (stop, args, run_id, path) =
                (stop.clone(), args.clone(), run_id.to_string(), path.clone());
            std::thread::Builder::new()
                .name("mcap".into())
                .spawn(move || recorder::run(&run_id, &path, origin, &args, &stop, ready_tx))?
        };
        match ready_rx.recv_timeout(Duration::from_secs(10)) {
            Ok(Ok(())) => Ok(Some(Self { stop, thread, path })),
            Ok(Err(e)) => bail!("--mcap {}: {e}", path.display()),
            Err(_) => bail!("--mcap {}: the recorder did not start", path.display()),
        }
    }

    /// Number of subscribers the recorder adds to each data service.
    pub fn subscribers(recording: &Option<Self>) -> usize {
        usize::from(recording.is_some())
    }

    /// Stops the recorder after it has taken what is queued, finishes the file and
    /// adds its counters (`mcap.<channel>` messages, `mcap.*` losses) to `stats`.
    pub fn finish(self, stats: &mut StageStats) -> Result<()> {
        self.stop.store(true, Ordering::Release);
        let report = self
            .thread
            .join()
            .map_err(|_| anyhow!("the MCAP recorder panicked"))??;
        for (c, n) in CHANNELS.iter().zip(report.messages) {
            stats.count(&format!("mcap{}", c.topic.replace('/', ".")), n);
        }
        for (name, n) in report.counters {
            stats.count(name, n);
        }
        eprintln!(
            "MCAP: {} ({} messages on {} channels)",
            self.path.display(),
            report.messages.iter().sum::<u64>(),
            CHANNELS.len()
        );
        Ok(())
    }
}
