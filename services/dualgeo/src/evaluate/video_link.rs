//! A compressed video link between the simulator and the chain (issue #23 item 5): the
//! Monte Carlo flies the `default` scene through H.264 at several crf values to show
//! what compression costs, against the same seeds' uncompressed pixels.
//!
//! The whole flight is rendered first by a simulator of its own (the same config and
//! seed, so the same frames: the image noise is seeded per frame), every frame of each
//! UAV at the camera's rate, as a UAV's encoder sees its video, and encoded by
//! `ffmpeg`/libx264 ([`acquisition::flight::x264`]: zero-latency tuning, 4:2:0). The
//! stream then decodes each video frame by frame in step with the simulator and hands
//! the decoded pixels to the detector and the chain instead of the rendered ones; the
//! frames between two streamed pairs are decoded and dropped (an H.264 decoder needs
//! them as references). Truth, poses and visibility still come from the stream's own simulator.

use acquisition::flight::video::VideoReader;
use acquisition::flight::x264::X264Writer;
use acquisition::sim::city::City;
use acquisition::sim::{SimConfig, Simulator};
use anyhow::{Context, Result};
use std::sync::Arc;

/// Both UAVs' videos, encoded, read back in frame order.
pub struct VideoLink {
    readers: [VideoReader; 2],
    /// Holds the two MP4s until the link is dropped.
    _dir: tempfile::TempDir,
    frame_bytes: usize,
}

impl VideoLink {
    /// Renders and encodes `config`'s flight at `crf` in `city` (the stream's town,
    /// not built a second time).
    pub fn encode(config: &SimConfig, city: Arc<City>, crf: u8) -> Result<Self> {
        let dir = tempfile::Builder::new()
            .prefix("dualgeo-video-link-")
            .tempdir()
            .context("a folder for the video link")?;
        let (w, h) = (config.camera.width, config.camera.height);
        let frame_bytes = 3 * w as usize * h as usize;
        let rate = config.frame_rate_hz;
        let paths = ["left.mp4", "right.mp4"].map(|n| dir.path().join(n));
        let writer = |i: usize| {
            X264Writer::create(&paths[i], w, h, rate, crf).map_err(|e| anyhow::anyhow!(e))
        };
        let mut writers = [writer(0)?, writer(1)?];
        let mut sim = Simulator::with_city(config.clone(), city)?;
        let mut images = [vec![0u8; frame_bytes], vec![0u8; frame_bytes]];
        while let Some(step) = sim.step() {
            let [l, r] = &mut images;
            sim.render_pair(&step, l, r, 3 * w as usize);
            for (writer, image) in writers.iter_mut().zip(&images) {
                writer.write(image).map_err(|e| anyhow::anyhow!(e))?;
            }
        }
        let [wl, wr] = writers;
        let written = [wl.finish(), wr.finish()];
        let open = |i: usize| -> Result<VideoReader> {
            let n = written[i].clone().map_err(|e| anyhow::anyhow!(e))?;
            anyhow::ensure!(
                n == sim.frame_count(),
                "{} frames encoded of {}",
                n,
                sim.frame_count()
            );
            VideoReader::open(&paths[i].to_string_lossy(), w, h, rate)
                .map_err(|e| anyhow::anyhow!(e))
        };
        Ok(Self {
            readers: [open(0)?, open(1)?],
            _dir: dir,
            frame_bytes,
        })
    }

    /// Decodes the next frame of both videos into `left` and `right`.
    pub fn read_pair(&mut self, left: &mut [u8], right: &mut [u8]) -> Result<()> {
        for (reader, out) in self.readers.iter_mut().zip([left, right]) {
            anyhow::ensure!(out.len() == self.frame_bytes, "frame buffer size");
            match reader.next_into(out) {
                Some(Ok(_)) => {}
                Some(Err(e)) => anyhow::bail!(e),
                None => anyhow::bail!("the video link ended before the flight"),
            }
        }
        Ok(())
    }

    /// Decodes the next frame of both videos and drops it (not converted to BGR).
    pub fn skip_pair(&mut self) -> Result<()> {
        for reader in &mut self.readers {
            anyhow::ensure!(reader.skip(), "the video link ended before the flight");
        }
        Ok(())
    }
}
