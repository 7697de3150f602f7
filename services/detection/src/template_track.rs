//! Carrying a target between a slow detector's results: normalised cross-correlation
//! of the patch the detector boxed, searched in a window around where it was.
//!
//! The patch is cut from the very frame the detector saw (kept with its job), then
//! found in the newest frame of that camera ([`TemplateTrack::anchor`]); each later
//! frame is searched around the last position ([`TemplateTrack::follow`]). The patch is
//! not refreshed between detections: a tracker that re-learns its patch drifts off the
//! target one sub-pixel at a time. The peak is refined to a sub-pixel position by a
//! parabola through its neighbours in each axis.

use opencv::core as cv;
use opencv::prelude::*;

/// Below this correlation the patch is not there: the track is lost.
pub const MIN_SCORE: f64 = 0.6;

#[derive(Debug, Clone)]
struct Track {
    /// The patch's centre in the last frame (OpenCV pixel convention) and the box size.
    centre: [f64; 2],
    size: [f64; 2],
    template: cv::Mat,
    score: f64,
    /// The detector's target point less the patch's centre (the box is cut on whole
    /// pixels; the point need not be its centre).
    offset: [f64; 2],
}

/// One camera's track.
#[derive(Debug, Clone, Default)]
pub struct TemplateTrack {
    track: Option<Track>,
    /// Half the search window beyond the patch's own half-size, pixels.
    pub search_px: i32,
}

impl TemplateTrack {
    pub fn new(search_px: i32) -> Self {
        Self {
            track: None,
            search_px,
        }
    }

    pub fn is_tracking(&self) -> bool {
        self.track.is_some()
    }

    pub fn drop_track(&mut self) {
        self.track = None;
    }

    /// Starts the track from a box `[left, top, width, height]` around the target
    /// point `point` in `seen` (the grey frame the detector boxed it in) and finds it in
    /// `now` (the camera's newest grey frame). Returns the target point and the
    /// correlation in `now`.
    pub fn anchor(
        &mut self,
        seen: &cv::Mat,
        bbox: [f64; 4],
        point: [f64; 2],
        now: &cv::Mat,
    ) -> opencv::Result<Option<([f64; 2], f64)>> {
        if !self.learn(seen, bbox, point)? {
            return Ok(None);
        }
        self.follow(now)
    }

    /// Cuts the patch `bbox` (`[left, top, width, height]`, around the target point
    /// `point`) out of `seen` and tracks from there; false (no track) when the box is
    /// not wholly inside `seen`.
    pub fn learn(
        &mut self,
        seen: &cv::Mat,
        bbox: [f64; 4],
        point: [f64; 2],
    ) -> opencv::Result<bool> {
        self.track = None;
        let [x, y, w, h] = bbox;
        let rect = cv::Rect::new(
            x.round() as i32,
            y.round() as i32,
            (w.round() as i32).max(4),
            (h.round() as i32).max(4),
        );
        let inside = rect.x >= 0
            && rect.y >= 0
            && rect.x + rect.width <= seen.cols()
            && rect.y + rect.height <= seen.rows();
        if !inside {
            return Ok(false);
        }
        let template = cv::Mat::roi(seen, rect)?.try_clone()?;
        // The patch's own centre (pixel convention) in `seen`.
        let centre = [
            rect.x as f64 + (rect.width as f64 - 1.0) / 2.0,
            rect.y as f64 + (rect.height as f64 - 1.0) / 2.0,
        ];
        self.track = Some(Track {
            centre,
            size: [rect.width as f64, rect.height as f64],
            template,
            score: 1.0,
            offset: [point[0] - centre[0], point[1] - centre[1]],
        });
        Ok(true)
    }

    /// Finds the patch in `now` around its last position: the target point and the
    /// correlation; none (and the track is dropped) when it is not there.
    pub fn follow(&mut self, now: &cv::Mat) -> opencv::Result<Option<([f64; 2], f64)>> {
        let Some(track) = &mut self.track else {
            return Ok(None);
        };
        let (tw, th) = (track.template.cols(), track.template.rows());
        let left = (track.centre[0] - (tw as f64 - 1.0) / 2.0).round() as i32 - self.search_px;
        let top = (track.centre[1] - (th as f64 - 1.0) / 2.0).round() as i32 - self.search_px;
        let x0 = left.max(0);
        let y0 = top.max(0);
        let x1 = (left + tw + 2 * self.search_px).min(now.cols());
        let y1 = (top + th + 2 * self.search_px).min(now.rows());
        if x1 - x0 < tw + 2 || y1 - y0 < th + 2 {
            self.track = None;
            return Ok(None);
        }
        let window = cv::Mat::roi(now, cv::Rect::new(x0, y0, x1 - x0, y1 - y0))?;
        let mut scores = cv::Mat::default();
        opencv::imgproc::match_template_def(
            &window,
            &track.template,
            &mut scores,
            opencv::imgproc::TM_CCOEFF_NORMED,
        )?;
        let mut best = 0.0;
        let mut at = cv::Point::default();
        cv::min_max_loc(
            &scores,
            None,
            Some(&mut best),
            None,
            Some(&mut at),
            &cv::no_array(),
        )?;
        if !(best.is_finite() && best >= MIN_SCORE) {
            self.track = None;
            return Ok(None);
        }
        let score_at = |x: i32, y: i32| -> f64 {
            scores
                .at_2d::<f32>(y, x)
                .map(|v| *v as f64)
                .unwrap_or(f64::NAN)
        };
        let refine = |minus: f64, centre: f64, plus: f64| {
            let d = minus - 2.0 * centre + plus;
            if d.is_finite() && d < 0.0 {
                (0.5 * (minus - plus) / d).clamp(-0.5, 0.5)
            } else {
                0.0
            }
        };
        let dx = if at.x > 0 && at.x + 1 < scores.cols() {
            refine(score_at(at.x - 1, at.y), best, score_at(at.x + 1, at.y))
        } else {
            0.0
        };
        let dy = if at.y > 0 && at.y + 1 < scores.rows() {
            refine(score_at(at.x, at.y - 1), best, score_at(at.x, at.y + 1))
        } else {
            0.0
        };
        track.centre = [
            (x0 + at.x) as f64 + dx + (tw as f64 - 1.0) / 2.0,
            (y0 + at.y) as f64 + dy + (th as f64 - 1.0) / 2.0,
        ];
        track.score = best;
        let point = [
            track.centre[0] + track.offset[0],
            track.centre[1] + track.offset[1],
        ];
        Ok(Some((point, best)))
    }

    /// How much the patch's levels spread: the standard deviation of its largest
    /// channel (0 without a patch).
    pub fn spread(&self) -> opencv::Result<f64> {
        let Some(t) = &self.track else {
            return Ok(0.0);
        };
        let (mut mean, mut sd) = (cv::Scalar::default(), cv::Scalar::default());
        cv::mean_std_dev(&t.template, &mut mean, &mut sd, &cv::no_array())?;
        Ok(sd.0.into_iter().fold(0.0, f64::max))
    }

    /// The box `[left, top, width, height]` around the track's centre.
    pub fn bbox(&self) -> Option<[f64; 4]> {
        self.track.as_ref().map(|t| {
            [
                t.centre[0] - (t.size[0] - 1.0) / 2.0,
                t.centre[1] - (t.size[1] - 1.0) / 2.0,
                t.size[0],
                t.size[1],
            ]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grey textured frame (a fixed pseudo-random pattern) with a bright car-sized
    /// patch whose top-left corner is at (x, y).
    fn frame(x: i32, y: i32) -> cv::Mat {
        let mut m =
            cv::Mat::new_rows_cols_with_default(240, 320, cv::CV_8UC1, cv::Scalar::all(0.0))
                .unwrap();
        for r in 0..240 {
            for c in 0..320 {
                *m.at_2d_mut::<u8>(r, c).unwrap() = ((r * 37 + c * 11) % 23 * 4 + 60) as u8;
            }
        }
        for r in 0..12 {
            for c in 0..26 {
                let v = if (4..8).contains(&r) { 90 } else { 230 };
                *m.at_2d_mut::<u8>(y + r, x + c).unwrap() = v;
            }
        }
        m
    }

    #[test]
    fn follows_a_moving_patch_to_the_pixel_and_drops_a_lost_one() {
        let mut t = TemplateTrack::new(24);
        let seen = frame(100, 80);
        // Anchored from the frame the detector saw; found 6 px right in the newest.
        let (c, score) = t
            .anchor(
                &seen,
                [100.0, 80.0, 26.0, 12.0],
                [112.5, 85.5],
                &frame(106, 81),
            )
            .unwrap()
            .unwrap();
        assert!(score > 0.95, "{score}");
        assert!(
            (c[0] - 118.5).abs() < 0.05 && (c[1] - 86.5).abs() < 0.05,
            "{c:?}"
        );
        for k in 1..10 {
            let (c, _) = t.follow(&frame(106 + 3 * k, 81 + k)).unwrap().unwrap();
            let want = [118.5 + 3.0 * k as f64, 86.5 + k as f64];
            assert!(
                (c[0] - want[0]).abs() < 0.05 && (c[1] - want[1]).abs() < 0.05,
                "{k}: {c:?} vs {want:?}"
            );
        }
        assert_eq!(t.bbox().map(|b| [b[2], b[3]]), Some([26.0, 12.0]));
        // Gone from the window: lost, and stays lost.
        assert!(t.follow(&frame(250, 200)).unwrap().is_none());
        assert!(!t.is_tracking());
        assert!(t.follow(&frame(136, 91)).unwrap().is_none());
        // A box outside the frame does not start a track.
        assert!(t
            .anchor(&seen, [310.0, 80.0, 26.0, 12.0], [322.5, 85.5], &seen)
            .unwrap()
            .is_none());
    }
}
