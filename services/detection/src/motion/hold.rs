//! Holding the target where it stops differing from the ground.
//!
//! A mover is what differs from the ground warped from 10 and 20 frames back. A silver
//! car over light concrete, or a car whose old place and new place look alike, drops
//! out of those differences for a few frames although it still drives on: measured on
//! `tilted45_silver` (11 m/s throughout), the designated track was lost for 12–18
//! frames at a time, and the picks after such gaps are where wrong objects come from.
//! So each frame the target is found as a mover, its patch (the outline's box, colour)
//! is cut from that frame; on a frame without the mover the patch is looked for by
//! normalised cross-correlation ([`TemplateTrack`]) around where it was, and taken
//! when it correlates at `hold_min_score` or better, lies within [`HOLD_RADIUS_PX`] of
//! the track's place against the ground and inside the geolocation filter's gate. The
//! patch is only cut from a mover where the track expected it ([`LEARN_RADIUS_PX`]) and
//! with the contrast to correlate ([`MIN_PATCH_SD`]). The patch is not
//! re-cut from a held frame (a patch re-learned from its own matches drifts off the
//! car), so a hold lasts at most `hold_frames` frames after the last mover.

use super::config::MotionConfig;
use super::movers::Mover;
use crate::prediction_gate::Gate;
use crate::template_track::TemplateTrack;
use opencv::core as cv;

/// Beyond the patch's own half-size, how far the patch is looked for from where it
/// was last frame, pixels (a car and its camera move a few pixels a frame).
const SEARCH_PX: i32 = 16;

/// How far a held patch may lie from where the track's last mover, carried by the
/// ground's motion and moved on at the track's own ground velocity, should be now,
/// pixels. A patch that slid along the road (a lane line, the car's edge against
/// concrete) moves with the ground, not with the car, and leaves this.
const HOLD_RADIUS_PX: f64 = 6.0;

/// A mover is learnt from only when it is where the track expected it, within this
/// many pixels of a prediction, with the previous frame found too (a pick after a gap,
/// or a jump, may be another car: holding it would keep the wrong one).
const LEARN_RADIUS_PX: f64 = 6.0;

/// A patch whose grey levels spread less than this (standard deviation, the largest
/// colour channel's) has no shape to correlate: a uniform roof matches any edge.
const MIN_PATCH_SD: f64 = 12.0;

/// One camera's patch of the target, cut where it was last found as a mover.
#[derive(Debug, Clone)]
pub(super) struct Hold {
    patch: TemplateTrack,
    /// The mover the patch was cut from (its area and colour go with the held target).
    from: Option<Mover>,
    /// Frames held since the last mover.
    frames: u32,
}

impl Default for Hold {
    fn default() -> Self {
        Self {
            patch: TemplateTrack::new(SEARCH_PX),
            from: None,
            frames: 0,
        }
    }
}

impl Hold {
    /// The target was found as the mover `m` in `frame`; `expected`: where the track
    /// expected it, when it was found in the previous frame too. The patch is cut
    /// there when the mover is within [`LEARN_RADIUS_PX`] of that and has the contrast
    /// to correlate; otherwise there is no patch until the next such mover.
    pub(super) fn learn(
        &mut self,
        frame: &cv::Mat,
        m: &Mover,
        expected: Option<[[f64; 2]; 2]>,
    ) -> opencv::Result<()> {
        self.forget();
        let near = |p: &[f64; 2]| (m.centre[0] - p[0]).hypot(m.centre[1] - p[1]) <= LEARN_RADIUS_PX;
        if !expected.is_some_and(|e| e.iter().any(near)) {
            return Ok(());
        }
        if self.patch.learn(frame, m.bbox, m.centre)? && self.patch.spread()? >= MIN_PATCH_SD {
            self.from = Some(*m);
        } else {
            self.forget();
        }
        Ok(())
    }

    pub(super) fn forget(&mut self) {
        self.patch.drop_track();
        self.from = None;
        self.frames = 0;
    }

    /// The target in `frame`, which showed no mover for it: the patch, where it
    /// correlates at `hold_min_score` or better within [`HOLD_RADIUS_PX`] of `ground`
    /// (the track's place against the ground) and inside `gate`. None ends the hold
    /// until the next mover.
    pub(super) fn find(
        &mut self,
        frame: &cv::Mat,
        ground: [f64; 2],
        gate: Option<&Gate>,
        c: &MotionConfig,
    ) -> opencv::Result<Option<Mover>> {
        let Some(from) = self.from else {
            return Ok(None);
        };
        if self.frames >= c.hold_frames {
            self.forget();
            return Ok(None);
        }
        let near = |p: [f64; 2]| {
            (p[0] - ground[0]).hypot(p[1] - ground[1]) <= HOLD_RADIUS_PX
                && gate.is_none_or(|g| g.contains(p))
        };
        let held = match (self.patch.follow(frame)?, self.patch.bbox()) {
            (Some((centre, score)), Some(bbox)) if score >= c.hold_min_score && near(centre) => {
                Mover {
                    centre,
                    bbox,
                    ..from
                }
            }
            _ => {
                self.forget();
                return Ok(None);
            }
        };
        self.frames += 1;
        Ok(Some(held))
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_scene;
    use super::*;

    fn mover_at(x: f64, y: f64) -> Mover {
        Mover {
            centre: [x + 11.5, y + 4.5],
            bbox: [x, y, 24.0, 10.0],
            area_px: 240.0,
            bgr: [170.0, 170.0, 175.0],
        }
    }

    /// Where the track expected the mover: right there.
    fn expected(m: &Mover) -> Option<[[f64; 2]; 2]> {
        Some([m.centre; 2])
    }

    /// A silver car (its roof, a shaded side below) on the blurred test ground at `x`,
    /// the ground shifted by `shift`; `roof` paints the side as the roof.
    fn car(x: i32, shift: f64, side: [f64; 3]) -> cv::Mat {
        let mut out = test_scene::shifted(&test_scene::ground(320, 240, 3), shift, 0.0);
        test_scene::draw_box(
            &mut out,
            cv::Rect::new(x, 100, 24, 7),
            [170.0, 170.0, 175.0],
        );
        test_scene::draw_box(&mut out, cv::Rect::new(x, 107, 24, 3), side);
        out
    }

    fn frame(x: i32, shift: f64) -> cv::Mat {
        car(x, shift, [90.0, 90.0, 95.0])
    }

    #[test]
    fn the_patch_holds_the_car_where_the_track_is_for_at_most_hold_frames() {
        let c = MotionConfig {
            hold_frames: 3,
            ..MotionConfig::default()
        };
        let mut hold = Hold::default();
        let m = mover_at(100.0, 100.0);
        hold.learn(&frame(100, 0.0), &m, expected(&m)).unwrap();
        let mut found = Vec::new();
        for k in 1..=4 {
            let x = 100 + 3 * k;
            let ground = [x as f64 + 11.5 + 2.0, 104.5];
            found.push(
                hold.find(&frame(x, 2.0 * k as f64), ground, None, &c)
                    .unwrap()
                    .map(|m| m.centre),
            );
        }
        // Three frames held, each at the car's centre; the fourth is beyond hold_frames.
        for (k, f) in found.iter().take(3).enumerate() {
            let x = 100.0 + 3.0 * (k + 1) as f64 + 11.5;
            let f = f.unwrap_or_else(|| panic!("frame {}: not held", k + 1));
            assert!(
                (f[0] - x).abs() < 0.5 && (f[1] - 104.5).abs() < 0.5,
                "{f:?}"
            );
        }
        assert_eq!(found[3], None);
    }

    #[test]
    fn a_patch_away_from_the_track_or_outside_the_gate_is_not_taken() {
        let c = MotionConfig::default();
        let mut hold = Hold::default();
        let m = mover_at(100.0, 100.0);
        hold.learn(&frame(100, 0.0), &m, expected(&m)).unwrap();
        // The car is there, but against the ground the track should be 10 px on.
        let away = [121.5, 104.5];
        assert_eq!(hold.find(&frame(100, 1.0), away, None, &c).unwrap(), None);
        // Once refused, the hold ends until the next mover.
        let there = [111.5, 104.5];
        assert_eq!(hold.find(&frame(100, 1.0), there, None, &c).unwrap(), None);
        hold.learn(&frame(100, 0.0), &m, expected(&m)).unwrap();
        let gate = Gate {
            centre: [200.0, 104.5],
            radius_px: 20.0,
            sigma_px: 10.0,
            prefer_centre: false,
        };
        let found = hold.find(&frame(100, 1.0), there, Some(&gate), &c);
        assert_eq!(found.unwrap(), None);
        // Inside the gate it is held.
        hold.learn(&frame(100, 0.0), &m, expected(&m)).unwrap();
        let gate = Gate {
            centre: there,
            ..gate
        };
        let found = hold.find(&frame(100, 1.0), there, Some(&gate), &c);
        assert!(found.unwrap().is_some());
    }

    #[test]
    fn no_patch_from_a_jump_or_a_uniform_car() {
        let c = MotionConfig::default();
        let m = mover_at(100.0, 100.0);
        let there = [111.5, 104.5];
        let mut hold = Hold::default();
        // The mover is 10 px from where the track expected it: maybe another car.
        let jumped = Some([[121.5, 104.5]; 2]);
        hold.learn(&frame(100, 0.0), &m, jumped).unwrap();
        assert_eq!(hold.find(&frame(100, 1.0), there, None, &c).unwrap(), None);
        // A track not found in the last frame expects nothing.
        hold.learn(&frame(100, 0.0), &m, None).unwrap();
        assert_eq!(hold.find(&frame(100, 1.0), there, None, &c).unwrap(), None);
        // A roof without a shaded side: nothing to correlate.
        let roof = [170.0, 170.0, 175.0];
        hold.learn(&car(100, 0.0, roof), &m, expected(&m)).unwrap();
        assert_eq!(
            hold.find(&car(100, 1.0, roof), there, None, &c).unwrap(),
            None
        );
    }
}
