//! `[detection.motion]`: the motion detector's settings (`motion/mod.rs` says what
//! each stage does with them).

use serde::{Deserialize, Serialize};

/// `[detection.motion]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotionConfig {
    /// The frame is scaled down by this factor for the ground's motion and the movers
    /// (the outline is found at full resolution).
    pub scale: u32,
    /// The double difference's gap, frames (0.33 s at 30 FPS: a car at 6 m/s moves
    /// 2 m).
    pub short_gap_frames: u32,
    /// The outline's gap, frames (1 s at 30 FPS: the car has left its old place).
    pub long_gap_frames: u32,
    /// A pixel has changed when one colour channel lies this far outside the old
    /// frame's 3 × 3 range.
    pub threshold: f64,
    /// Blobs thinner than this (full-resolution pixels) are not movers (a building's
    /// parallax leaves thin strips).
    pub min_side_px: u32,
    /// Smallest mover, full-resolution pixels.
    pub min_area_px: u32,
    /// How far from the track's prediction the target may be, pixels.
    pub track_radius_px: f64,
    /// Frames the track coasts without the target before its radius starts to grow
    /// (to 3× over as many frames again; four times this before it is dropped).
    pub coast_frames: u32,
    /// Where the target is when the detector first looks (frame `2 ×
    /// short_gap_frames` of each camera: it needs that many frames behind it), per
    /// camera (left, right), full-resolution pixels: the operator's designation. The
    /// mover nearest it within `acquire_radius_px` starts the track. None: the mover
    /// nearest the image centre, at any distance. It serves once; a track dropped later
    /// is looked for where it was (or at [`super::MotionDetector::designate`]'s pixel).
    pub acquire_px: Option<[[f64; 2]; 2]>,
    pub acquire_radius_px: f64,
    /// The target's colour (BGR, 0–255) as the operator names it ("the silver car"):
    /// a track starts only on a mover whose mean colour is within 2 ×
    /// `colour_tolerance` of it in every channel (a mover's mean mixes its roof with
    /// its darker sides). None: any colour.
    pub acquire_bgr: Option<[f64; 3]>,
    /// A mover is the track's only if its mean colour is within this of the track's
    /// in every channel (a white car beside a silver one is not it).
    pub colour_tolerance: f64,
    /// On a frame where the target shows no mover (it looks like the ground it is on,
    /// for a moment), its patch from the last frame it did is looked for near the
    /// track, for at most this many frames (`hold.rs`); 0: off.
    pub hold_frames: u32,
    /// ... and taken where it correlates (normalised, zero-mean) at least this well.
    pub hold_min_score: f64,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            scale: 2,
            short_gap_frames: 10,
            long_gap_frames: 30,
            threshold: 30.0,
            min_side_px: 4,
            min_area_px: 32,
            track_radius_px: 30.0,
            coast_frames: 15,
            acquire_px: None,
            acquire_radius_px: 60.0,
            acquire_bgr: None,
            colour_tolerance: 25.0,
            hold_frames: 30,
            hold_min_score: 0.8,
        }
    }
}

impl MotionConfig {
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=8).contains(&self.scale) {
            return Err(format!("scale {} outside 1..=8", self.scale));
        }
        if self.short_gap_frames == 0 || self.long_gap_frames < self.short_gap_frames {
            return Err("short_gap_frames must be ≥ 1 and long_gap_frames ≥ it".into());
        }
        if 2 * self.short_gap_frames.max(self.long_gap_frames) > 240 {
            return Err("the gaps keep more than 240 frames".into());
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.threshold)
            || self.threshold > 255.0
            || !positive(self.track_radius_px)
            || !positive(self.acquire_radius_px)
            || !positive(self.colour_tolerance)
        {
            return Err(
                "threshold must be in (0, 255]; track_radius_px, acquire_radius_px and colour_tolerance > 0".into(),
            );
        }
        let min = crate::template_track::MIN_SCORE;
        if !(self.hold_min_score.is_finite() && (min..=1.0).contains(&self.hold_min_score)) {
            return Err(format!("hold_min_score must be in [{min}, 1]"));
        }
        if self
            .acquire_px
            .is_some_and(|a| a.iter().flatten().any(|v| !v.is_finite()))
        {
            return Err("acquire_px must be finite".into());
        }
        if self
            .acquire_bgr
            .is_some_and(|c| c.iter().any(|v| !(0.0..=255.0).contains(v)))
        {
            return Err("acquire_bgr must be three values in 0..=255".into());
        }
        Ok(())
    }
}
