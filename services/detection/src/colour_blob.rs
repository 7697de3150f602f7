//! The classical detector: the largest blob of the target's colour. The default
//! configuration finds a saturated red vehicle (the simulator's, and a red car on real
//! footage); every threshold lives in [`ColourBlobConfig`].
//!
//! The target point is the blob's centroid. The default brightness floor keeps only the
//! sunlit roof, whose centre is the recording format's target point (the centre of the
//! vehicle's top face); the darker sides would pull the centroid sideways.

use super::{check_bgr, DetectError, Detection, Detector, PartialViewConfig, TrackHint};
use crate::constellation;
use crate::hue_mask::Scratch;
use crate::prediction_gate::{Gate, GateConfig};
use opencv::core as cv;
use opencv::prelude::*;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ColourBlobConfig {
    /// Hue intervals in OpenCV's 0–180 scale (red wraps: two intervals).
    pub hue_ranges: Vec<[u8; 2]>,
    pub saturation_min: u8,
    pub value_min: u8,
    /// Blobs outside this area (pixels) are ignored.
    pub min_area_px: i32,
    pub max_area_px: i32,
    /// When nothing passes `value_min`, look once more with `value_min` scaled by the
    /// frame's exposure: the 99th percentile of its brightness over 255 (an
    /// under-exposed camera darkens the target and everything else alike, so the ratio
    /// between the target's lit roof and its dark sides is kept). Counted by the caller
    /// through [`ColourBlobDetector::exposure_retries`].
    pub adapt_to_exposure: bool,
    /// Dropping detections of a partly hidden target (`partial_view.rs`), applied per
    /// camera by whoever streams frames through the detector.
    pub partial_view: PartialViewConfig,
    /// With a fresh hint (where this camera last saw the target,
    /// [`ColourBlobDetector::detect_near`]), the blob nearest it within this share of
    /// the image width (growing with the hint's age up to twice that at 0.2 s: at a
    /// turn the target crosses ~50 px of a 640 px image in 0.1 s) is the target, and
    /// no blob there is no detection (unless it is the only blob of the target's
    /// colour in the frame): another
    /// vehicle of the target's colour elsewhere in the frame is not taken for it. With a
    /// stale hint, the nearest blob however far; without one, the largest.
    pub track_radius_frac: f64,
    /// With a fresh hint, search a window of twice the track radius around it first
    /// and the whole frame only when the window cannot answer (issue #15: the same
    /// answer from about a fifth of the pixels; counted as `window_looks` and
    /// `window_misses`).
    pub window_search: bool,
    /// With window search, every this many frames of a camera are looked at whole
    /// anyway, so blobs of the target's colour beyond the window (look-alikes) are
    /// known (0: never).
    pub whole_frame_every: u32,
    /// A lone blob of the target's colour far from a fresh hint, with no gate to vouch
    /// for it, is taken for the target (a UAV's attitude swing moved it) only if this
    /// camera has seen no other blob of that colour for this long, s: otherwise it may be
    /// a look-alike while the target hides.
    pub look_alike_memory_s: f64,
    /// Gating by the geolocation filter's prediction (`prediction_gate.rs`), applied
    /// per camera by whoever streams frames and estimates through the detector.
    pub gate: GateConfig,
}

/// Landmarks a track keeps: the blobs of the target's colour nearest it.
pub const MAX_LANDMARKS: usize = 8;

impl Default for ColourBlobConfig {
    fn default() -> Self {
        Self {
            hue_ranges: vec![[0, 8], [172, 180]],
            saturation_min: 150,
            value_min: 170,
            min_area_px: 12,
            max_area_px: 20_000,
            adapt_to_exposure: true,
            partial_view: PartialViewConfig::default(),
            track_radius_frac: 0.08,
            window_search: true,
            whole_frame_every: 15,
            look_alike_memory_s: 5.0,
            gate: GateConfig::default(),
        }
    }
}

pub struct ColourBlobDetector {
    config: ColourBlobConfig,
    /// The whole frame's HSV pixels, thresholds and components.
    px: Scratch,
    /// The window search's own buffers, swapped in while it runs: each set keeps its
    /// size from frame to frame, so neither is reallocated when the detector switches
    /// between window and whole frame (the service's memory stays flat).
    window_px: Scratch,
    exposure_retries: u64,
    window_looks: u64,
    window_misses: u64,
    /// Where the target may be in the next frame: blobs outside are never it.
    gate: Option<Gate>,
    /// Blobs of the target's colour the gate excluded in the last whole-frame look.
    gated_blobs: usize,
    /// The blobs of the last look, and their centres (reused buffers).
    blobs: Vec<Blob>,
    centres: Vec<[f64; 2]>,
    /// The other blobs of the target's colour where the hint was taken
    /// (`constellation.rs`), the frame's pixels.
    landmarks: Vec<[f64; 2]>,
    /// See [`Self::set_vanished`].
    vanished: Vec<[f64; 2]>,
    /// Width of the frame being detected, px.
    frame_width: f64,
    /// The next detection looks at the whole frame (no window first).
    whole_next: bool,
    /// The last detection's answer came from a look at the whole frame.
    last_whole: bool,
    /// A lone blob far from the hint may be taken without a gate.
    lone_blob_ok: bool,
}

impl ColourBlobDetector {
    pub fn new(config: ColourBlobConfig) -> Result<Self, DetectError> {
        if config.hue_ranges.is_empty()
            || config
                .hue_ranges
                .iter()
                .any(|[lo, hi]| lo > hi || *hi > 180)
        {
            return Err(DetectError::Config(
                "hue_ranges need lo <= hi <= 180".into(),
            ));
        }
        config
            .partial_view
            .validate()
            .map_err(DetectError::Config)?;
        config.gate.validate().map_err(DetectError::Config)?;
        if !(config.track_radius_frac > 0.0 && config.track_radius_frac <= 1.0) {
            return Err(DetectError::Config(
                "track_radius_frac must be in (0, 1]".into(),
            ));
        }
        if !(config.look_alike_memory_s.is_finite() && config.look_alike_memory_s >= 0.0) {
            return Err(DetectError::Config(
                "look_alike_memory_s must be finite and >= 0".into(),
            ));
        }
        if config.min_area_px < 1 || config.max_area_px < config.min_area_px {
            return Err(DetectError::Config(
                "need 1 <= min_area_px <= max_area_px".into(),
            ));
        }
        Ok(Self {
            config,
            px: Scratch::default(),
            window_px: Scratch::default(),
            exposure_retries: 0,
            window_looks: 0,
            window_misses: 0,
            gate: None,
            gated_blobs: 0,
            blobs: Vec::with_capacity(16),
            centres: Vec::with_capacity(16),
            landmarks: Vec::with_capacity(MAX_LANDMARKS),
            vanished: Vec::new(),
            frame_width: 0.0,
            whole_next: false,
            last_whole: false,
            lone_blob_ok: true,
        })
    }

    /// Frames on which the exposure-scaled second look ran (since creation).
    pub fn exposure_retries(&self) -> u64 {
        self.exposure_retries
    }

    /// Frames looked at in a window around a fresh hint first, and of those the ones
    /// that needed the whole frame after all (since creation).
    pub fn window_counts(&self) -> (u64, u64) {
        (self.window_looks, self.window_misses)
    }

    /// The gate of the next detections (`None`: everywhere). A blob whose centre is
    /// outside it is not a candidate at all, not even the only one in the frame.
    pub fn set_gate(&mut self, gate: Option<Gate>) {
        self.gate = gate;
    }

    /// Blobs of the target's colour the gate excluded in the last whole-frame look.
    pub fn gated_blobs(&self) -> usize {
        self.gated_blobs
    }

    /// The other blobs of the target's colour in the frame the next hint comes from
    /// (at most [`MAX_LANDMARKS`] are kept): with two candidates near the hint, the one
    /// they moved with is the target (`constellation.rs`).
    pub fn set_landmarks(&mut self, landmarks: &[[f64; 2]]) {
        self.landmarks.clear();
        self.landmarks
            .extend(landmarks.iter().take(MAX_LANDMARKS).copied());
    }

    /// Where look-alikes that vanished near the target were last seen (the tracked
    /// detector's memory, `tracked.rs`): a blob there is that look-alike coming back,
    /// not the target.
    pub fn set_vanished(&mut self, vanished: &[[f64; 2]]) {
        self.vanished.clear();
        self.vanished.extend_from_slice(vanished);
    }

    /// Whether a lone blob of the target's colour far from a fresh hint may be taken
    /// with no gate (see `look_alike_memory_s`); taken with a gate that admits it.
    pub fn set_lone_blob_ok(&mut self, ok: bool) {
        self.lone_blob_ok = ok;
    }

    /// The next detection looks at the whole frame even with a fresh hint.
    pub fn look_at_whole_frame_next(&mut self) {
        self.whole_next = true;
    }

    /// Whether the last detection's blobs ([`Self::looked_at`]) are the whole frame's.
    pub fn last_look_was_whole(&self) -> bool {
        self.last_whole
    }

    /// The centres of the blobs of the target's colour the last detection looked at
    /// (a window or the whole frame), the frame's pixels.
    pub fn looked_at(&self) -> impl Iterator<Item = [f64; 2]> + '_ {
        self.blobs.iter().map(|b| b.centre)
    }

    /// Swaps the whole-frame buffers with the window search's.
    fn swap_scratch(&mut self) {
        std::mem::swap(&mut self.px, &mut self.window_px);
    }

    /// The 99th percentile of the V channel of `self.px.hsv`, 0–255.
    fn bright_percentile(&self) -> Result<u8, DetectError> {
        let bytes = self.px.hsv.data_bytes()?;
        let mut histogram = [0u64; 256];
        for px in bytes.chunks_exact(3) {
            histogram[px[2] as usize] += 1;
        }
        let total: u64 = histogram.iter().sum();
        let mut above = 0u64;
        for v in (0..256).rev() {
            above += histogram[v];
            if above * 100 >= total {
                return Ok(v as u8);
            }
        }
        Ok(0)
    }

    /// The blob of the target's colour with `value_min`: with a hint, among the blobs
    /// within its radius the one the landmarks agree on, else the nearest
    /// (`constellation.rs`); without one, the largest; (label, area).
    ///
    /// In a `window` of the frame (`Some(origin)`), any blob touching the window's edge
    /// (which may be cut, so its centroid and area are not the whole blob's) gives
    /// `None`, and so do two candidates with landmarks to weigh (a landmark may have
    /// moved outside the window): the caller looks at the whole frame.
    fn pick_blob(
        &mut self,
        value_min: f64,
        near: Option<Near>,
        window: Option<[f64; 2]>,
    ) -> Result<Option<(i32, i32)>, DetectError> {
        // Pixels here are the frame's; the buffers' (0, 0) is the window's origin.
        let origin = window.unwrap_or([0.0, 0.0]);
        let in_window = window.is_some();
        let n = self.px.label(
            &self.config.hue_ranges,
            self.config.saturation_min as f64,
            value_min,
        )?;
        let (cols, rows) = (self.px.mask.cols(), self.px.mask.rows());
        self.blobs.clear();
        for label in 1..n {
            let stat = |k| self.px.stats.at_2d::<i32>(label, k).copied();
            if in_window {
                let (x, y) = (
                    stat(opencv::imgproc::CC_STAT_LEFT)?,
                    stat(opencv::imgproc::CC_STAT_TOP)?,
                );
                let (w, h) = (
                    stat(opencv::imgproc::CC_STAT_WIDTH)?,
                    stat(opencv::imgproc::CC_STAT_HEIGHT)?,
                );
                if x == 0 || y == 0 || x + w >= cols || y + h >= rows {
                    return Ok(None);
                }
            }
            let area = stat(opencv::imgproc::CC_STAT_AREA)?;
            if area < self.config.min_area_px || area > self.config.max_area_px {
                continue;
            }
            let centre = [
                *self.px.centroids.at_2d::<f64>(label, 0)? + origin[0],
                *self.px.centroids.at_2d::<f64>(label, 1)? + origin[1],
            ];
            let in_gate = self.gate.is_none_or(|g| g.contains(centre));
            self.blobs.push(Blob {
                label,
                area,
                centre,
                in_gate,
            });
        }
        let candidates = self.blobs.iter().filter(|b| b.in_gate).count();
        if !in_window {
            self.gated_blobs = self.blobs.len() - candidates;
        }
        let best = match near {
            None => self
                .blobs
                .iter()
                .filter(|b| b.in_gate)
                .max_by_key(|b| b.area)
                .map(|b| (b.label, b.area)),
            Some(near) => {
                let in_radius = |b: &Blob| {
                    b.in_gate
                        && (b.centre[0] - near.centre[0]).hypot(b.centre[1] - near.centre[1])
                            <= near.radius
                };
                let close = self.blobs.iter().filter(|b| in_radius(b)).count();
                if close > 1 && !self.landmarks.is_empty() && in_window {
                    return Ok(None);
                }
                self.centres.clear();
                self.centres.extend(self.blobs.iter().map(|b| b.centre));
                let tolerance = constellation::alignment_tolerance_px(self.frame_width, near.age_s);
                let (blobs, centres, vanished) = (&self.blobs, &self.centres, &self.vanished);
                let picked = constellation::pick(
                    near.centre,
                    near.radius,
                    &self.landmarks,
                    centres,
                    |k| {
                        blobs[k].in_gate
                            && !constellation::is_a_landmark(centres[k], near.centre, vanished)
                    },
                    tolerance,
                );
                // A window answers only when no blob outside it could do better: every
                // landmark in line (so no candidate can align more, and any outside is
                // farther).
                if in_window && picked.is_some_and(|p| p.aligned < self.landmarks.len()) {
                    return Ok(None);
                }
                picked.map(|p| (blobs[p.index].label, blobs[p.index].area))
            }
        };
        // Nothing near the hint, but a single candidate in the frame that the filter's
        // gate admits: the target (a UAV's attitude swing can move it farther than the
        // radius in one frame, and the gate, drawn with this frame's measured attitude,
        // moves with it). Without a gate, only when this camera has seen no other blob
        // of the target's colour lately (`look_alike_memory_s`): the target hidden under
        // a bridge leaves a red look-alike elsewhere as the only blob of its colour
        // (measured on `suite_traffic`: 5 of 8 seeds took it).
        // Nor is one that is where a landmark was (the look-alike the target had
        // beside it before it was hidden).
        if best.is_none()
            && candidates == 1
            && !in_window
            && (self.gate.is_some() || self.lone_blob_ok)
        {
            let lone = self.blobs.iter().find(|b| b.in_gate);
            let known = |b: &&Blob| {
                near.is_some_and(|n| {
                    constellation::is_a_landmark(b.centre, n.centre, &self.landmarks)
                        || constellation::is_a_landmark(b.centre, n.centre, &self.vanished)
                })
            };
            return Ok(lone.filter(|b| !known(b)).map(|b| (b.label, b.area)));
        }
        Ok(best)
    }
}

/// A hint as [`ColourBlobDetector::pick_blob`] uses it, in the frame's pixels.
#[derive(Debug, Clone, Copy)]
struct Near {
    centre: [f64; 2],
    radius: f64,
    age_s: f64,
}

/// One blob of the target's colour in the last look.
#[derive(Debug, Clone, Copy)]
struct Blob {
    label: i32,
    area: i32,
    /// Centroid, the frame's pixels.
    centre: [f64; 2],
    /// Inside the gate (or no gate): a candidate.
    in_gate: bool,
}

impl Detector for ColourBlobDetector {
    fn detect(&mut self, frame: &cv::Mat) -> Result<Option<Detection>, DetectError> {
        self.detect_near(frame, None)
    }
}

impl ColourBlobDetector {
    /// [`Detector::detect`] with a hint: where this camera last saw the target (see
    /// `track_radius_frac`).
    pub fn detect_near(
        &mut self,
        frame: &cv::Mat,
        hint: Option<TrackHint>,
    ) -> Result<Option<Detection>, DetectError> {
        check_bgr(frame)?;
        self.gated_blobs = 0;
        self.frame_width = frame.cols() as f64;
        let near = hint.map(|h| Near {
            centre: h.centre,
            radius: if h.fresh {
                let growth = (1.0 + h.age_s / 0.2).min(2.0);
                self.config.track_radius_frac * frame.cols() as f64 * growth
            } else {
                f64::INFINITY
            },
            age_s: h.age_s,
        });
        let value_min = self.config.value_min as f64;
        // A fresh hint first: only a window around it (issue #15: a fifth of the
        // pixels). The answer is the whole frame's whenever the window has one: a blob
        // wholly inside the window has its whole-frame centroid and area, and a blob
        // outside it is farther than `radius` from the hint.
        let mut best = None;
        let whole = std::mem::take(&mut self.whole_next);
        self.last_whole = false;
        let windowed = near.filter(|n| n.radius.is_finite() && self.config.window_search && !whole);
        if let Some(n) = windowed {
            if let Some(rect) = window(n.centre, 2.0 * n.radius, frame.cols(), frame.rows()) {
                self.window_looks += 1;
                self.swap_scratch();
                let look = cv::Mat::roi(frame, rect)
                    .and_then(|part| {
                        opencv::imgproc::cvt_color_def(
                            &part,
                            &mut self.px.hsv,
                            opencv::imgproc::COLOR_BGR2HSV,
                        )
                    })
                    .map_err(DetectError::from)
                    .and_then(|()| {
                        let origin = [rect.x as f64, rect.y as f64];
                        self.pick_blob(value_min, Some(n), Some(origin))
                    });
                match look {
                    Ok(Some(found)) => {
                        let detection = self.detection(found, [rect.x as f64, rect.y as f64]);
                        self.swap_scratch();
                        return detection.map(Some);
                    }
                    Ok(None) => {
                        self.swap_scratch();
                        self.window_misses += 1;
                    }
                    Err(e) => {
                        self.swap_scratch();
                        return Err(e);
                    }
                }
            }
        }
        if best.is_none() {
            self.last_whole = true;
            opencv::imgproc::cvt_color_def(
                frame,
                &mut self.px.hsv,
                opencv::imgproc::COLOR_BGR2HSV,
            )?;
            best = self.pick_blob(value_min, near, None)?;
        }
        if best.is_none() && self.config.adapt_to_exposure {
            let exposure = self.bright_percentile()? as f64 / 255.0;
            if exposure < 0.95 {
                self.exposure_retries += 1;
                best = self.pick_blob((value_min * exposure).max(1.0), near, None)?;
            }
        }
        let Some(found) = best else {
            return Ok(None);
        };
        self.detection(found, [0.0, 0.0]).map(Some)
    }

    /// Every blob of the target's colour in `frame`, the gate not applied (several
    /// targets): the last look's when it was of the whole frame, else from a look at
    /// the whole frame now (~1 ms at 640 × 480). Call it after the frame's detection:
    /// what the next detection depends on (gate, gated count) is left as it was.
    pub fn all_blobs(
        &mut self,
        frame: &cv::Mat,
        out: &mut Vec<Detection>,
    ) -> Result<(), DetectError> {
        out.clear();
        check_bgr(frame)?;
        if !self.last_whole {
            let (gate, gated) = (self.gate.take(), self.gated_blobs);
            let look = opencv::imgproc::cvt_color_def(
                frame,
                &mut self.px.hsv,
                opencv::imgproc::COLOR_BGR2HSV,
            )
            .map_err(DetectError::from)
            .and_then(|()| self.pick_blob(self.config.value_min as f64, None, None));
            (self.gate, self.gated_blobs) = (gate, gated);
            if let Err(e) = look {
                // The blob list may be half the old look's: list nothing.
                self.blobs.clear();
                return Err(e);
            }
            self.last_whole = true;
        }
        for b in &self.blobs {
            out.push(self.detection((b.label, b.area), [0.0, 0.0])?);
        }
        Ok(())
    }

    /// The detection of blob `label` (of `area` px) in the current buffers, whose
    /// pixel (0, 0) is the frame's `origin`.
    fn detection(
        &self,
        (label, area): (i32, i32),
        origin: [f64; 2],
    ) -> Result<Detection, DetectError> {
        let stat = |k| self.px.stats.at_2d::<i32>(label, k).map(|v| *v as f64);
        let (left, top) = (
            stat(opencv::imgproc::CC_STAT_LEFT)? + origin[0],
            stat(opencv::imgproc::CC_STAT_TOP)? + origin[1],
        );
        let (w, h) = (
            stat(opencv::imgproc::CC_STAT_WIDTH)?,
            stat(opencv::imgproc::CC_STAT_HEIGHT)?,
        );
        let centre = [
            *self.px.centroids.at_2d::<f64>(label, 0)? + origin[0],
            *self.px.centroids.at_2d::<f64>(label, 1)? + origin[1],
        ];
        // Confidence: how well the blob fills its box (a car roof fills most of it),
        // scaled so a rotated rectangle (fill ≥ 0.5) still scores high.
        let fill = area as f64 / (w * h);
        Ok(Detection {
            bbox: [left, top, w, h],
            centre,
            confidence: (fill * 1.5).min(1.0) as f32,
        })
    }
}

/// The window of `half` px around `centre`, clipped to the frame; `None` when it would
/// be most of the frame anyway.
fn window(centre: [f64; 2], half: f64, cols: i32, rows: i32) -> Option<cv::Rect> {
    if !(centre[0].is_finite() && centre[1].is_finite() && half.is_finite()) {
        return None;
    }
    let clip = |v: f64, max: i32| v.clamp(0.0, max as f64) as i32;
    let (x0, y0) = (clip(centre[0] - half, cols), clip(centre[1] - half, rows));
    let (x1, y1) = (
        clip(centre[0] + half + 1.0, cols),
        clip(centre[1] + half + 1.0, rows),
    );
    let (w, h) = (x1 - x0, y1 - y0);
    let small = w > 0 && h > 0 && (w as i64 * h as i64) * 2 < cols as i64 * rows as i64;
    small.then(|| cv::Rect::new(x0, y0, w, h))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn draw_rect(m: &mut cv::Mat, rect: cv::Rect, colour: cv::Scalar) {
        opencv::imgproc::rectangle(m, rect, colour, -1, opencv::imgproc::LINE_8, 0).unwrap();
    }

    /// A 160×120 grey-green frame with one filled rectangle (also the track tests').
    pub(crate) fn frame_with_rect(x: i32, y: i32, w: i32, h: i32, bgr: [f64; 3]) -> cv::Mat {
        let mut m = cv::Mat::new_rows_cols_with_default(
            120,
            160,
            cv::CV_8UC3,
            cv::Scalar::new(90.0, 110.0, 95.0, 0.0),
        )
        .unwrap();
        draw_rect(
            &mut m,
            cv::Rect::new(x, y, w, h),
            cv::Scalar::new(bgr[0], bgr[1], bgr[2], 0.0),
        );
        m
    }

    /// A 640×480 grey-green frame with 25×11 px cars of the target's colour centred
    /// at `cars` (also the track tests').
    pub(crate) fn street(cars: &[(i32, i32)]) -> cv::Mat {
        let mut m = cv::Mat::new_rows_cols_with_default(
            480,
            640,
            cv::CV_8UC3,
            cv::Scalar::new(90.0, 110.0, 95.0, 0.0),
        )
        .unwrap();
        let red = cv::Scalar::new(36.0, 28.0, 214.0, 0.0);
        for &(x, y) in cars {
            draw_rect(&mut m, cv::Rect::new(x - 12, y - 5, 25, 11), red);
        }
        m
    }

    /// After a window look (a fresh hint), every blob of the colour is still listed,
    /// those outside the gate too, and the next detection is the same as without the
    /// listing.
    #[test]
    fn every_blob_is_listed_after_a_window_look_and_nothing_else_changes() {
        let frame = street(&[(100, 100), (400, 300), (600, 50)]);
        let hint = Some(TrackHint {
            centre: [100.0, 100.0],
            fresh: true,
            age_s: 0.0,
        });
        let gate = Some(Gate {
            centre: [100.0, 100.0],
            radius_px: 40.0,
            sigma_px: 10.8,
            prefer_centre: false,
        });
        let run = |list: bool| {
            let mut d = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
            d.set_gate(gate);
            let first = d.detect_near(&frame, hint).unwrap().unwrap();
            assert!(!d.last_look_was_whole(), "the window answered");
            let mut all = Vec::new();
            if list {
                d.all_blobs(&frame, &mut all).unwrap();
            }
            let second = d.detect_near(&frame, hint).unwrap().unwrap();
            (first, second, all, d.gated_blobs(), d.window_counts())
        };
        let (plain, listed) = (run(false), run(true));
        assert_eq!((plain.0, plain.1), (listed.0, listed.1));
        assert_eq!((plain.3, plain.4), (listed.3, listed.4));
        let mut centres: Vec<[f64; 2]> = listed.2.iter().map(|d| d.centre).collect();
        centres.sort_by(|a, b| a[0].total_cmp(&b[0]));
        assert_eq!(centres, vec![[100.0, 100.0], [400.0, 300.0], [600.0, 50.0]]);
    }

    #[test]
    fn finds_a_red_roof_and_its_centre() {
        let mut d = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
        let f = frame_with_rect(40, 30, 20, 9, [36.0, 28.0, 214.0]);
        let det = d.detect(&f).unwrap().expect("found");
        assert_eq!(det.bbox, [40.0, 30.0, 20.0, 9.0]);
        assert!((det.centre[0] - 49.5).abs() < 1e-9 && (det.centre[1] - 34.0).abs() < 1e-9);
        assert!(det.confidence > 0.99);
    }

    #[test]
    fn ignores_other_colours_and_dark_sides() {
        let mut d = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
        assert!(d
            .detect(&frame_with_rect(40, 30, 20, 9, [200.0, 60.0, 40.0]))
            .unwrap()
            .is_none());
        // A dark side in a well-exposed frame (a white roof sets the exposure), so the
        // exposure retry keeps the threshold where it is.
        let mut side = frame_with_rect(40, 30, 20, 9, [24.0, 18.0, 140.0]);
        draw_rect(
            &mut side,
            cv::Rect::new(100, 60, 30, 30),
            cv::Scalar::all(250.0),
        );
        assert!(d.detect(&side).unwrap().is_none());
        let gray =
            cv::Mat::new_rows_cols_with_default(10, 10, cv::CV_8UC1, cv::Scalar::all(0.0)).unwrap();
        assert!(matches!(
            d.detect(&gray),
            Err(DetectError::BadFrame { channels: 1, .. })
        ));
        assert!(ColourBlobDetector::new(ColourBlobConfig {
            hue_ranges: vec![[9, 3]],
            ..Default::default()
        })
        .is_err());
    }

    /// A frame scaled by `gain` (an under-exposed camera).
    fn darkened(frame: &cv::Mat, gain: f64) -> cv::Mat {
        let mut out = cv::Mat::default();
        frame.convert_to(&mut out, -1, gain, 0.0).unwrap();
        out
    }

    #[test]
    fn an_under_exposed_camera_still_finds_the_target_but_not_its_dark_sides() {
        // A bright white patch (a roof) sets the frame's exposure.
        let mut frame = frame_with_rect(40, 30, 20, 9, [36.0, 28.0, 214.0]);
        draw_rect(
            &mut frame,
            cv::Rect::new(100, 60, 30, 30),
            cv::Scalar::all(250.0),
        );
        let dark = darkened(&frame, 0.6);
        let strict = ColourBlobConfig {
            adapt_to_exposure: false,
            ..Default::default()
        };
        assert!(ColourBlobDetector::new(strict)
            .unwrap()
            .detect(&dark)
            .unwrap()
            .is_none());
        let mut d = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
        let det = d
            .detect(&dark)
            .unwrap()
            .expect("found after the exposure retry");
        assert_eq!(det.bbox, [40.0, 30.0, 20.0, 9.0]);
        assert_eq!(d.exposure_retries(), 1);
        // The dark side of the same darkened frame stays below the scaled threshold.
        let mut side = frame_with_rect(40, 30, 20, 9, [24.0, 18.0, 140.0]);
        draw_rect(
            &mut side,
            cv::Rect::new(100, 60, 30, 30),
            cv::Scalar::all(250.0),
        );
        assert!(d.detect(&darkened(&side, 0.6)).unwrap().is_none());
        // A well-exposed frame is never retried.
        assert!(d.detect(&frame).unwrap().is_some());
        assert_eq!(d.exposure_retries(), 2);
    }

    #[test]
    fn a_hint_keeps_the_target_when_a_same_coloured_car_is_in_view() {
        // The target (left) and a larger car of its colour (right).
        let mut frame = frame_with_rect(20, 30, 20, 9, [36.0, 28.0, 214.0]);
        draw_rect(
            &mut frame,
            cv::Rect::new(110, 80, 24, 11),
            cv::Scalar::new(36.0, 28.0, 214.0, 0.0),
        );
        let mut d = ColourBlobDetector::new(ColourBlobConfig::default()).unwrap();
        // No hint: the largest.
        let largest = d.detect_near(&frame, None).unwrap().unwrap();
        assert_eq!(largest.bbox, [110.0, 80.0, 24.0, 11.0]);
        // Hint near the target (12.8 px radius at 160 px width): the target.
        let fresh = |centre| {
            Some(TrackHint {
                centre,
                fresh: true,
                age_s: 0.0,
            })
        };
        let tracked = d.detect_near(&frame, fresh([32.0, 36.0])).unwrap().unwrap();
        assert_eq!(tracked.bbox, [20.0, 30.0, 20.0, 9.0]);
        // Hint where nothing is: no detection rather than either car.
        assert!(d
            .detect_near(&frame, fresh([80.0, 10.0]))
            .unwrap()
            .is_none());
        // A single blob far from the hint: taken when nothing of its colour was seen
        // lately (the camera swung); not when a look-alike was (the target may be
        // hidden and this the look-alike), unless the filter's gate admits it.
        let alone = frame_with_rect(20, 30, 20, 9, [36.0, 28.0, 214.0]);
        assert!(d
            .detect_near(&alone, fresh([140.0, 100.0]))
            .unwrap()
            .is_some());
        d.set_lone_blob_ok(false);
        assert!(d
            .detect_near(&alone, fresh([140.0, 100.0]))
            .unwrap()
            .is_none());
        d.set_gate(Some(Gate {
            centre: [40.0, 40.0],
            radius_px: 30.0,
            sigma_px: 8.1,
            prefer_centre: false,
        }));
        assert!(d
            .detect_near(&alone, fresh([140.0, 100.0]))
            .unwrap()
            .is_some());
        d.set_gate(Some(Gate {
            centre: [140.0, 40.0],
            radius_px: 30.0,
            sigma_px: 8.1,
            prefer_centre: false,
        }));
        assert!(d
            .detect_near(&alone, fresh([140.0, 100.0]))
            .unwrap()
            .is_none());
        d.set_gate(None);
        // A stale hint (the target hidden a while): the nearest, however far.
        let stale = TrackHint {
            centre: [60.0, 40.0],
            fresh: false,
            age_s: 3.0,
        };
        let back = d.detect_near(&frame, Some(stale)).unwrap().unwrap();
        assert_eq!(back.bbox, [20.0, 30.0, 20.0, 9.0]);
    }

    #[test]
    fn landmarks_keep_the_target_when_the_camera_jumps_beside_a_look_alike() {
        // 640×480: the target and a look-alike one lane over; the camera then jumps so
        // that the look-alike lands nearer the target's last pixel than the target.
        let hint = Some(TrackHint {
            centre: [300.0, 200.0],
            fresh: true,
            age_s: 0.067,
        });
        // Before the jump: target at (300, 200), look-alike at (323, 241). After: both
        // moved by (-43, -3); the look-alike is now 41 px from (300, 200), the target 43.
        let after = street(&[(257, 197), (280, 238)]);
        for window_search in [true, false] {
            let mut d = ColourBlobDetector::new(ColourBlobConfig {
                window_search,
                ..Default::default()
            })
            .unwrap();
            let nearest = d.detect_near(&after, hint).unwrap().unwrap();
            assert_eq!(nearest.centre, [280.0, 238.0], "no landmarks: the nearest");
            d.set_landmarks(&[[323.0, 241.0]]);
            let kept = d.detect_near(&after, hint).unwrap().unwrap();
            assert_eq!(kept.centre, [257.0, 197.0], "window search {window_search}");
            let mut seen: Vec<_> = d.looked_at().collect();
            seen.sort_by(|a, b| a[0].total_cmp(&b[0]));
            assert_eq!(seen, vec![[257.0, 197.0], [280.0, 238.0]]);
        }
    }

    #[test]
    fn the_window_gives_the_whole_frames_answer() {
        // Seeded scenes of 640×480 with 1–4 cars of the target's colour, some cut by
        // the window's edge or the frame's, hints near and away from them, and
        // landmarks or none: the window never changes the answer, and most frames need
        // no second look.
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = |n: i32| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % n as u64) as i32
        };
        let config = |window_search| ColourBlobConfig {
            window_search,
            ..ColourBlobConfig::default()
        };
        let mut windowed = ColourBlobDetector::new(config(true)).unwrap();
        let mut whole = ColourBlobDetector::new(config(false)).unwrap();
        let mut found = 0;
        // Window looks and misses without landmarks (random landmarks seldom line up,
        // and then the window defers to the whole frame).
        let mut plain = (0, 0);
        for _ in 0..200 {
            let mut frame = cv::Mat::new_rows_cols_with_default(
                480,
                640,
                cv::CV_8UC3,
                cv::Scalar::new(90.0, 110.0, 95.0, 0.0),
            )
            .unwrap();
            let mut first = [0.0, 0.0];
            for car in 0..1 + next(4) {
                let (w, h) = (8 + next(40), 6 + next(30));
                let (x, y) = (next(640) - 10, next(480) - 10);
                draw_rect(
                    &mut frame,
                    cv::Rect::new(x, y, w, h),
                    cv::Scalar::new(36.0, 28.0, 214.0, 0.0),
                );
                if car == 0 {
                    first = [
                        x as f64 + (next(60) - 30) as f64,
                        y as f64 + (next(60) - 30) as f64,
                    ];
                }
            }
            let hint = Some(TrackHint {
                centre: first,
                fresh: true,
                age_s: next(300) as f64 / 1000.0,
            });
            // Half the frames with landmarks: where the other cars were, give or take.
            let landmarks: Vec<[f64; 2]> = (0..next(2) * (1 + next(3)))
                .map(|_| [next(640) as f64, next(480) as f64])
                .collect();
            windowed.set_landmarks(&landmarks);
            whole.set_landmarks(&landmarks);
            let before = windowed.window_counts();
            let a = windowed.detect_near(&frame, hint).unwrap();
            if landmarks.is_empty() {
                let after = windowed.window_counts();
                plain.0 += after.0 - before.0;
                plain.1 += after.1 - before.1;
            }
            let b = whole.detect_near(&frame, hint).unwrap();
            assert_eq!(a, b, "hint {first:?}");
            found += a.is_some() as usize;
        }
        let (looks, _) = windowed.window_counts();
        // A hint off the frame's edge leaves no window to look in.
        assert!(looks > 150, "{looks} windows");
        let (plain_looks, misses) = plain;
        assert!(
            found > 100 && plain_looks > 50 && misses < plain_looks / 2,
            "{found} found, {plain_looks} looks without landmarks, {misses} misses"
        );
        assert_eq!(whole.window_counts(), (0, 0));
    }
}
