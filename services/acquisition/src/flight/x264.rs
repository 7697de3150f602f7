//! H.264 at a chosen quality through FFmpeg's command-line tool (`ffmpeg`, libx264).
//!
//! OpenCV 4.6's `VideoWriter` passes no x264 options, so its H.264 is always x264's
//! default (crf 23). A video link is set by its quality: [`X264Writer`] pipes packed BGR
//! frames into `ffmpeg … -c:v libx264 -crf N` and writes an MP4 that
//! [`super::video::VideoReader`] reads back.
//!
//! Choices, written here because the encoder's settings decide what the chain sees:
//! - `-tune zerolatency`: what a UAV's downlink encoder runs (no B-frames, no look-ahead:
//!   each frame leaves the encoder as it is made), so a frame's artefacts are those a
//!   ground station receives live.
//! - `-preset veryfast`: an airborne encoder's speed class; the crf sets the quality.
//! - `-pix_fmt yuv420p`: the chroma subsampling every H.264 link uses (the red target's
//!   edges blur in chroma as they do over a real link).
//! - `-fps_mode passthrough`: one encoded frame per frame written, none dropped or
//!   duplicated, so frame k of the file is frame k written.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};

/// The encoder's crf range (x264's 8-bit scale): 0 lossless … 51 worst.
pub const CRF_RANGE: std::ops::RangeInclusive<u8> = 0..=51;

/// Writes packed BGR frames as H.264 (libx264 at a crf) in MP4 through `ffmpeg`.
pub struct X264Writer {
    child: Child,
    stdin: Option<ChildStdin>,
    path: PathBuf,
    frame_bytes: usize,
    /// Frames written so far.
    pub frames: u64,
}

fn err(path: &Path, e: impl std::fmt::Display) -> String {
    format!("video {}: {e}", path.display())
}

impl X264Writer {
    /// Starts `ffmpeg` writing `path` (an `.mp4`) from `width × height` BGR frames at
    /// `frame_rate_hz`, encoded at `crf`.
    pub fn create(
        path: &Path,
        width: u32,
        height: u32,
        frame_rate_hz: f64,
        crf: u8,
    ) -> Result<Self, String> {
        if !CRF_RANGE.contains(&crf) {
            return Err(err(path, format!("crf {crf} is outside 0–51")));
        }
        if width == 0 || height == 0 || width % 2 == 1 || height % 2 == 1 {
            return Err(err(
                path,
                format!("{width}×{height}: H.264 in 4:2:0 needs even, non-zero sizes"),
            ));
        }
        if !(frame_rate_hz.is_finite() && frame_rate_hz > 0.0) {
            return Err(err(path, format!("frame rate {frame_rate_hz} Hz")));
        }
        let mut child = Command::new("ffmpeg")
            .args(["-hide_banner", "-loglevel", "error", "-nostdin", "-y"])
            .args(["-f", "rawvideo", "-pix_fmt", "bgr24"])
            .args(["-s", &format!("{width}x{height}")])
            .args(["-framerate", &format!("{frame_rate_hz}")])
            .args(["-i", "-"])
            .args([
                "-c:v",
                "libx264",
                "-preset",
                "veryfast",
                "-tune",
                "zerolatency",
            ])
            .args(["-crf", &crf.to_string(), "-pix_fmt", "yuv420p"])
            .args(["-fps_mode", "passthrough", "-an"])
            .arg(path)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| {
                err(
                    path,
                    format!("cannot start ffmpeg ({e}); install it (scripts/setup.sh does)"),
                )
            })?;
        let stdin = child.stdin.take();
        Ok(Self {
            child,
            stdin,
            path: path.to_path_buf(),
            frame_bytes: width as usize * height as usize * 3,
            frames: 0,
        })
    }

    /// Writes one frame: packed BGR rows, `width × height × 3` bytes.
    pub fn write(&mut self, bgr: &[u8]) -> Result<(), String> {
        if bgr.len() != self.frame_bytes {
            return Err(err(
                &self.path,
                format!(
                    "a frame of {} bytes, the video's are {}",
                    bgr.len(),
                    self.frame_bytes
                ),
            ));
        }
        let Some(stdin) = self.stdin.as_mut() else {
            return Err(err(&self.path, "written after finish"));
        };
        if let Err(e) = stdin.write_all(bgr) {
            // ffmpeg stopped: its own words say why.
            self.stdin = None;
            let why = self.wait_for_reason();
            return Err(err(&self.path, format!("ffmpeg stopped ({e}): {why}")));
        }
        self.frames += 1;
        Ok(())
    }

    /// Closes the input and waits for ffmpeg to write the file's end.
    pub fn finish(mut self) -> Result<u64, String> {
        self.stdin = None;
        let status = self.child.wait().map_err(|e| err(&self.path, e))?;
        if !status.success() {
            let why = self.stderr_text();
            return Err(err(&self.path, format!("ffmpeg failed ({status}): {why}")));
        }
        Ok(self.frames)
    }

    fn wait_for_reason(&mut self) -> String {
        let _ = self.child.wait();
        self.stderr_text()
    }

    fn stderr_text(&mut self) -> String {
        let mut text = String::new();
        if let Some(mut e) = self.child.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut e, &mut text);
        }
        let text = text.trim();
        if text.is_empty() {
            "no message".into()
        } else {
            text.lines().take(4).collect::<Vec<_>>().join("; ")
        }
    }
}

impl Drop for X264Writer {
    fn drop(&mut self) {
        // Never leave an ffmpeg behind (a writer dropped on an error path).
        self.stdin = None;
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_settings_and_frames_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v.mp4");
        assert!(X264Writer::create(&path, 64, 48, 30.0, 52).is_err());
        assert!(X264Writer::create(&path, 63, 48, 30.0, 23).is_err());
        assert!(X264Writer::create(&path, 64, 48, f64::NAN, 23).is_err());
        let mut w = X264Writer::create(&path, 64, 48, 30.0, 23).unwrap();
        assert!(w.write(&[0u8; 10]).is_err());
        w.write(&[0u8; 64 * 48 * 3]).unwrap();
        assert_eq!(w.finish().unwrap(), 1);
    }
}
