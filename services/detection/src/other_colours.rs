//! The other vehicles of other colours than the target's (several targets): every
//! vehicle-sized blob of a vivid colour, published as candidates beside the blobs of
//! the target's own colour. `[detection.others]`.
//!
//! One mask over the saturated, bright pixels whose hue is none of the target's (by
//! default: the complement of `[detection] hue_ranges`, so a blue target makes red cars
//! candidates), its connected components within the area bounds, on the frame shrunk
//! `scale` times (2: a quarter of the pixels, ~1 ms less per frame on this machine; a
//! car still covers ~60 px there, and ±1 px at full size is well inside the cross-view
//! pairing's 12 px gate).
//!
//! White vehicles have no hue, but they are brighter than anything on a road except its
//! markings: `whites` adds the pixels with value ≥ `white_value_min` and saturation ≤
//! `white_saturation_max`, opened (eroded, then dilated) by a square
//! `white_min_width_px` wide, so that lane lines, dashes and zebra stripes (0.1–0.6 m:
//! 1–3 px at 0.2 m a pixel) vanish and a car's roof (1.9 m wide: ~10 px) stays. The
//! choice is in pixels, not metres, because detection knows no ground resolution: a
//! flight at another height or with another lens sets it (the default fits 0.1–0.35 m
//! a pixel). Greys and blacks are left out: they are the asphalt's own values (the
//! motion detector finds them when they move). Static blobs (a blue or white roof)
//! may pair across the views and be located; the tracks report only what has been
//! seen moving (`[tracks] min_speed_mps`).

use crate::hue_mask::Scratch;
use crate::{DetectError, Detection};
use opencv::core as cv;
use opencv::prelude::*;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OtherColoursConfig {
    /// Look for them at all (with `[detection] candidates`).
    pub enabled: bool,
    /// Hue intervals (OpenCV's 0–180). Absent: every hue the target's intervals leave.
    pub hue_ranges: Option<Vec<[u8; 2]>>,
    pub saturation_min: u8,
    pub value_min: u8,
    /// Blobs outside this area (pixels of the full frame) are not vehicles.
    pub min_area_px: i32,
    pub max_area_px: i32,
    /// Look at the frame shrunk this many times (1: full size).
    pub scale: u32,
    /// Also look for white vehicles (bright pixels with little saturation, opened).
    pub whites: bool,
    pub white_value_min: u8,
    pub white_saturation_max: u8,
    /// Side of the opening's square (pixels of the full frame): bright strokes
    /// narrower than this are road markings, not vehicles.
    pub white_min_width_px: u32,
}

impl Default for OtherColoursConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            hue_ranges: None,
            saturation_min: 150,
            value_min: 100,
            min_area_px: 30,
            max_area_px: 20_000,
            scale: 2,
            whites: true,
            white_value_min: 200,
            white_saturation_max: 40,
            white_min_width_px: 6,
        }
    }
}

impl OtherColoursConfig {
    pub fn validate(&self) -> Result<(), String> {
        if let Some(r) = &self.hue_ranges {
            if r.is_empty() || r.iter().any(|[lo, hi]| lo > hi || *hi > 180) {
                return Err("hue_ranges need lo <= hi <= 180 (and at least one)".into());
            }
        }
        if self.min_area_px < 1 || self.max_area_px < self.min_area_px {
            return Err("need 1 <= min_area_px <= max_area_px".into());
        }
        if !(1..=4).contains(&self.scale) {
            return Err("scale must be 1 to 4".into());
        }
        if self.whites && !(1..=64).contains(&self.white_min_width_px) {
            return Err("white_min_width_px must be 1 to 64".into());
        }
        Ok(())
    }

    /// The hue intervals to look in: the configured ones, or those `target` leaves.
    pub fn hues(&self, target: &[[u8; 2]]) -> Vec<[u8; 2]> {
        if let Some(r) = &self.hue_ranges {
            return r.clone();
        }
        let taken = |h: u8| target.iter().any(|[lo, hi]| (*lo..=*hi).contains(&h));
        let mut out: Vec<[u8; 2]> = Vec::new();
        for h in 0..=180u8 {
            if taken(h) {
                continue;
            }
            match out.last_mut() {
                Some(last) if last[1] + 1 == h => last[1] = h,
                _ => out.push([h, h]),
            }
        }
        out
    }
}

/// The finder, with its buffers (kept from frame to frame: nothing is allocated per
/// frame once they have their size).
pub struct OtherColours {
    config: OtherColoursConfig,
    hues: Vec<[u8; 2]>,
    small: cv::Mat,
    px: Scratch,
    /// The white pixels before and after the opening.
    white: cv::Mat,
    opened: cv::Mat,
    /// The opening's square, on the frame as looked at (`white_min_width_px / scale`).
    kernel: cv::Mat,
}

impl OtherColours {
    /// `target_hues`: the target's `[detection] hue_ranges`.
    pub fn new(config: OtherColoursConfig, target_hues: &[[u8; 2]]) -> Result<Self, DetectError> {
        config.validate().map_err(DetectError::Config)?;
        // Rounded, then made odd so that the opening is centred (an even square
        // shifts the blob by a pixel): 6 px is 7 × 7 at full size and 3 × 3 at scale 2.
        let side = ((config.white_min_width_px as f64 / config.scale.max(1) as f64).round() as i32)
            .max(1)
            | 1;
        let kernel = opencv::imgproc::get_structuring_element_def(
            opencv::imgproc::MORPH_RECT,
            cv::Size::new(side, side),
        )?;
        Ok(Self {
            hues: config.hues(target_hues),
            config,
            small: cv::Mat::default(),
            px: Scratch::default(),
            white: cv::Mat::default(),
            opened: cv::Mat::default(),
            kernel,
        })
    }

    pub fn enabled(&self) -> bool {
        self.config.enabled && (!self.hues.is_empty() || self.config.whites)
    }

    /// Appends to `out` every blob of the colours in the BGR `frame`.
    pub fn find(&mut self, frame: &cv::Mat, out: &mut Vec<Detection>) -> Result<(), DetectError> {
        crate::check_bgr(frame)?;
        if !self.enabled() {
            return Ok(());
        }
        let k = self.config.scale.max(1) as i32;
        if k > 1 {
            let size = cv::Size::new((frame.cols() / k).max(1), (frame.rows() / k).max(1));
            opencv::imgproc::resize(
                frame,
                &mut self.small,
                size,
                0.0,
                0.0,
                opencv::imgproc::INTER_AREA,
            )?;
            opencv::imgproc::cvt_color_def(
                &self.small,
                &mut self.px.hsv,
                opencv::imgproc::COLOR_BGR2HSV,
            )?;
        } else {
            opencv::imgproc::cvt_color_def(
                frame,
                &mut self.px.hsv,
                opencv::imgproc::COLOR_BGR2HSV,
            )?;
        }
        let c = &self.config;
        // A pixel here is k × k of the frame; its centre is at k·x + (k − 1)/2.
        let (kf, half) = (k as f64, (k as f64 - 1.0) / 2.0);
        self.px
            .threshold(&self.hues, c.saturation_min as f64, c.value_min as f64)?;
        if c.whites {
            cv::in_range(
                &self.px.hsv,
                &cv::Scalar::new(0.0, 0.0, c.white_value_min as f64, 0.0),
                &cv::Scalar::new(180.0, c.white_saturation_max as f64, 255.0, 0.0),
                &mut self.white,
            )?;
            opencv::imgproc::morphology_ex_def(
                &self.white,
                &mut self.opened,
                opencv::imgproc::MORPH_OPEN,
                &self.kernel,
            )?;
            self.px.add_to_mask(&self.opened)?;
        }
        let n = self.px.components()?;
        for label in 1..n {
            let stat = |k| self.px.stats.at_2d::<i32>(label, k).copied();
            let area = stat(opencv::imgproc::CC_STAT_AREA)? * k * k;
            if area < c.min_area_px || area > c.max_area_px {
                continue;
            }
            let bbox = [
                stat(opencv::imgproc::CC_STAT_LEFT)? as f64 * kf,
                stat(opencv::imgproc::CC_STAT_TOP)? as f64 * kf,
                stat(opencv::imgproc::CC_STAT_WIDTH)? as f64 * kf,
                stat(opencv::imgproc::CC_STAT_HEIGHT)? as f64 * kf,
            ];
            let centre = [
                *self.px.centroids.at_2d::<f64>(label, 0)? * kf + half,
                *self.px.centroids.at_2d::<f64>(label, 1)? * kf + half,
            ];
            out.push(Detection {
                bbox,
                centre,
                confidence: 1.0,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_hues_are_those_the_target_leaves() {
        let c = OtherColoursConfig::default();
        assert_eq!(c.hues(&[[0, 8], [172, 180]]), vec![[9, 171]]);
        assert_eq!(c.hues(&[[100, 120]]), vec![[0, 99], [121, 180]]);
        let set = OtherColoursConfig {
            hue_ranges: Some(vec![[20, 30]]),
            ..c
        };
        assert_eq!(set.hues(&[[0, 8]]), vec![[20, 30]]);
        assert!(OtherColoursConfig {
            hue_ranges: Some(vec![]),
            ..OtherColoursConfig::default()
        }
        .validate()
        .is_err());
        assert!(OtherColoursConfig {
            min_area_px: 0,
            ..OtherColoursConfig::default()
        }
        .validate()
        .is_err());
    }

    const RED_HUES: [[u8; 2]; 2] = [[0, 8], [172, 180]];

    /// The test street with filled rectangles of the given colours (BGR).
    fn street_with(rects: &[(cv::Rect, [f64; 3])]) -> cv::Mat {
        let mut frame = crate::colour_blob::tests::street(&[]);
        for (rect, c) in rects {
            let colour = cv::Scalar::new(c[0], c[1], c[2], 0.0);
            opencv::imgproc::rectangle(&mut frame, *rect, colour, -1, opencv::imgproc::LINE_8, 0)
                .unwrap();
        }
        frame
    }

    fn found(frame: &cv::Mat, config: OtherColoursConfig) -> Vec<Detection> {
        let mut out = Vec::new();
        OtherColours::new(config, &RED_HUES)
            .unwrap()
            .find(frame, &mut out)
            .unwrap();
        out
    }

    /// At full size and halved, exactly one blob is found, centred within a pixel of
    /// `centre`.
    fn finds_one_at(frame: &cv::Mat, centre: [f64; 2]) {
        for scale in [1, 2] {
            let out = found(
                frame,
                OtherColoursConfig {
                    scale,
                    ..OtherColoursConfig::default()
                },
            );
            assert_eq!(out.len(), 1, "scale {scale}: {out:?}");
            assert!((out[0].centre[0] - centre[0]).abs() < 1.0, "{out:?}");
            assert!((out[0].centre[1] - centre[1]).abs() < 1.0, "{out:?}");
        }
    }

    /// A blue car is found, a red one (the target's colour) and a grey one are not, nor a
    /// blue speck below the area bound.
    #[test]
    fn vivid_blobs_of_other_colours_are_found() {
        let blue = [200.0, 120.0, 40.0];
        let frame = street_with(&[
            (cv::Rect::new(100, 50, 20, 10), blue),
            (cv::Rect::new(300, 200, 20, 10), [36.0, 28.0, 214.0]),
            (cv::Rect::new(400, 200, 20, 10), [128.0, 128.0, 128.0]),
            (cv::Rect::new(500, 300, 4, 4), blue),
        ]);
        finds_one_at(&frame, [109.5, 54.5]);
        let off = OtherColoursConfig {
            enabled: false,
            ..OtherColoursConfig::default()
        };
        assert!(found(&frame, off).is_empty());
    }

    /// A white car is found, at full size and halved; a lane line (2 px), a dash
    /// (3 px) and zebra stripes (3 px, 3 px apart) of the same white are not, nor a
    /// grey car; with `whites = false` nothing is.
    #[test]
    fn white_cars_are_found_and_road_markings_are_not() {
        let white = [230.0, 230.0, 230.0];
        let mut rects = vec![
            (cv::Rect::new(200, 100, 24, 11), white),
            (cv::Rect::new(50, 300, 2, 150), white),
            (cv::Rect::new(300, 400, 40, 3), white),
            (cv::Rect::new(500, 100, 24, 11), [150.0, 150.0, 150.0]),
        ];
        for k in 0..6 {
            rects.push((cv::Rect::new(400 + 6 * k, 300, 3, 30), white));
        }
        let frame = street_with(&rects);
        finds_one_at(&frame, [211.5, 105.0]);
        // A target of every hue leaves only the whites to look for.
        let mut out = Vec::new();
        OtherColours::new(OtherColoursConfig::default(), &[[0, 180]])
            .unwrap()
            .find(&frame, &mut out)
            .unwrap();
        assert_eq!(out.len(), 1, "{out:?}");
        let no_whites = OtherColoursConfig {
            whites: false,
            ..OtherColoursConfig::default()
        };
        let out = found(&frame, no_whites);
        assert!(out.is_empty(), "{out:?}");
        assert!(OtherColoursConfig {
            white_min_width_px: 0,
            ..OtherColoursConfig::default()
        }
        .validate()
        .is_err());
    }
}
