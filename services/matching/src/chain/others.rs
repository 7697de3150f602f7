//! Several targets: the other vehicles both current images show, paired across the
//! two views and carried into the pair's past images through the fundamental
//! matrices the target's matching fitted. They get no fit of their own: an extra
//! vehicle costs two line intersections per past image (eq. 27–28), not a matching.
//!
//! **Pairing across the views (a choice).** A ground-plane homography from the current
//! left image to the current right one, composed through a keyframe both current
//! images were fitted to on this pair (H_LR = H_R⁻¹ · H_L), then shifted by the
//! target's own residual (a roof as high above the ground as theirs: the shift takes
//! out the roof-height parallax). Left and right objects are then paired by the
//! optimal assignment on the distance from the mapped left pixel to the right one,
//! within `others_gate_px`, their colours within `others_colour_gate` per channel.
//! The measured poses are not used: a 20° yaw bias moves a ground point by tens of
//! metres, while the homography is fitted on the images themselves.
//!
//! **Without the target (a choice).** A pair whose target a current image did not
//! find (under a bridge) has its past images fitted all the same
//! ([`super::MatchOutcome::TargetUnseen`]), so the homography is there; its shift is
//! the target's residual on the last pair that had one (the roof-height parallax
//! changes as slowly as the UAVs' geometry; within a stream segment), none before.

use super::target_pair::apply;
use super::{MatchedSet, UnseenSet, VisionChain};
use crate::frame::FrameMeta;
use nalgebra::Matrix3;
use shared_types::assignment;

/// Another vehicle of the pair, in ideal pinhole pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct OtherPixels {
    /// In the current left and right images.
    pub current: [[f64; 2]; 2],
    /// In each past image of the set (`MatchedSet::past` order), when its transfer
    /// succeeded.
    pub past: Vec<Option<[f64; 2]>>,
    /// Its colour in the current left and right images (BGR).
    pub bgr: [[u8; 3]; 2],
}

/// What pairing and transfer made of the other objects of one pair.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OthersOutcome {
    pub targets: Vec<OtherPixels>,
    /// Objects seen by one current image and paired with none of the other's.
    pub unpaired: usize,
    /// There were objects on both sides but no homography between the current images
    /// (no keyframe fitted by both on this pair, or the target disagreed with it).
    pub no_geometry: bool,
}

/// A target residual beyond this (px) means the composed homography does not hold
/// for this pair: no pairing rather than a wrong one.
const MAX_TARGET_RESIDUAL_PX: f64 = 40.0;

/// An object in one current image: ideal pixel and colour.
type Seen = ([f64; 2], [u8; 3]);

/// The left and right objects that are the same vehicle, as (left, right) indices:
/// the optimal assignment on the distance from the left pixel carried by
/// `left_to_right` to the right one, within `gate` px, colours within `colour_gate`
/// per channel.
fn pair_across(
    sides: &[Vec<Seen>; 2],
    left_to_right: &Matrix3<f64>,
    gate: f64,
    colour_gate: f64,
) -> Vec<(usize, usize)> {
    let mapped: Vec<Option<[f64; 2]>> = sides[0]
        .iter()
        .map(|(p, _)| apply(left_to_right, *p))
        .collect();
    let distance = |i: usize, j: usize| -> Option<f64> {
        let m = mapped[i]?;
        let (pr, bgr_r) = sides[1][j];
        let bgr_l = sides[0][i].1;
        let colour_ok =
            (0..3).all(|c| (f64::from(bgr_l[c]) - f64::from(bgr_r[c])).abs() <= colour_gate);
        let d = (m[0] - pr[0]).hypot(m[1] - pr[1]);
        (colour_ok && d <= gate).then_some(d)
    };
    // Pairs outside the gates cost more than any set of pairs inside them: the
    // assignment first pairs as many as it can, then the closest.
    let forbidden = gate * (sides[0].len() + 1) as f64 + 1.0;
    let cost: Vec<Vec<f64>> = (0..sides[0].len())
        .map(|i| {
            (0..sides[1].len())
                .map(|j| distance(i, j).unwrap_or(forbidden))
                .collect()
        })
        .collect();
    assignment::min_cost(&cost)
        .into_iter()
        .enumerate()
        .filter_map(|(i, j)| j.filter(|&j| distance(i, j).is_some()).map(|j| (i, j)))
        .collect()
}

impl VisionChain {
    /// The other objects of `current` (as detection found them) paired across the
    /// views and carried into the past images of `matched` (the target's set on this
    /// pair, just matched by [`VisionChain::match_current`]).
    pub fn others(&mut self, current: [&FrameMeta; 2], matched: &MatchedSet) -> OthersOutcome {
        let left_to_right = self.left_to_right(current, matched);
        if let Some((_, shift)) = left_to_right {
            self.last_target_shift = Some(shift);
        }
        self.others_through(current, matched, left_to_right.map(|(h, _)| h))
    }

    /// The other objects of a pair whose target a current image did not find, paired
    /// through its past images' homography shifted by the last target residual, and
    /// carried into those past images (module docs).
    pub fn others_unseen(&self, current: [&FrameMeta; 2], unseen: &UnseenSet) -> OthersOutcome {
        let left_to_right = unseen.left_to_right.first().map(|h| {
            let [dx, dy] = self.last_target_shift.unwrap_or([0.0; 2]);
            Matrix3::new(1.0, 0.0, dx, 0.0, 1.0, dy, 0.0, 0.0, 1.0) * h
        });
        self.others_through(current, &unseen.set, left_to_right)
    }

    fn others_through(
        &self,
        current: [&FrameMeta; 2],
        matched: &MatchedSet,
        left_to_right: Option<Matrix3<f64>>,
    ) -> OthersOutcome {
        let mut out = OthersOutcome::default();
        let mut sides: [Vec<Seen>; 2] = current.map(|f| {
            f.others
                .as_slice()
                .iter()
                .filter_map(|c| {
                    let [u, v] = c.centre;
                    f.distortion
                        .undistort_pixel(&f.intrinsics, u, v)
                        .map(|p| (p, c.bgr))
                })
                .collect()
        });
        // A mended pair (`target_pair`): the candidate taken for the target is the
        // target; the vehicle the detector had taken is another.
        if let Some((side, before)) = matched.mended {
            let now = matched.current[side].pixel;
            if let Some(seen) = sides[side]
                .iter_mut()
                .find(|(p, _)| (p[0] - now.x).hypot(p[1] - now.y) < 1e-6)
            {
                seen.0 = before;
            }
        }
        if sides[0].is_empty() || sides[1].is_empty() {
            out.unpaired = sides[0].len() + sides[1].len();
            return out;
        }
        let Some(left_to_right) = left_to_right else {
            out.no_geometry = true;
            out.unpaired = sides[0].len() + sides[1].len();
            return out;
        };
        let pairs = pair_across(
            &sides,
            &left_to_right,
            self.config.others_gate_px,
            self.config.others_colour_gate,
        );
        out.unpaired = sides[0].len() + sides[1].len() - 2 * pairs.len();
        for (i, j) in pairs {
            let current_px = [sides[0][i].0, sides[1][j].0];
            let past = matched
                .past
                .iter()
                .map(|m| self.transfer_into(m, current_px))
                .collect();
            out.targets.push(OtherPixels {
                current: current_px,
                past,
                bgr: [sides[0][i].1, sides[1][j].1],
            });
        }
        out
    }

    /// The ground homography from the current left image to the current right one
    /// (the first of [`VisionChain::ground_homographies`]) shifted by the target's
    /// residual, and that shift; `None` without one or when the target lies more
    /// than [`MAX_TARGET_RESIDUAL_PX`] off it.
    fn left_to_right(
        &self,
        current: [&FrameMeta; 2],
        matched: &MatchedSet,
    ) -> Option<(Matrix3<f64>, [f64; 2])> {
        let h = *self.ground_homographies(current, matched).first()?;
        let target = [0, 1].map(|side| {
            let p = matched.current[side].pixel;
            [p.x, p.y]
        });
        let mapped = apply(&h, target[0])?;
        let shift = [target[1][0] - mapped[0], target[1][1] - mapped[1]];
        if shift[0].hypot(shift[1]) > MAX_TARGET_RESIDUAL_PX {
            return None;
        }
        let translate = Matrix3::new(1.0, 0.0, shift[0], 0.0, 1.0, shift[1], 0.0, 0.0, 1.0);
        Some((translate * h, shift))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RED: [u8; 3] = [36, 28, 214];
    const BLUE: [u8; 3] = [200, 120, 40];

    /// The right image is the left shifted 100 px left: each vehicle pairs with its
    /// own, a vehicle whose colour differs is not paired, one beyond the gate neither.
    #[test]
    fn vehicles_pair_by_mapped_position_and_colour() {
        let h = Matrix3::new(1.0, 0.0, -100.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        let left = vec![
            ([300.0, 200.0], RED),
            ([320.0, 200.0], RED),
            ([400.0, 300.0], BLUE),
            ([500.0, 100.0], RED),
        ];
        let right = vec![
            ([221.0, 201.0], RED), // the second left one, 1.4 px off
            ([199.0, 200.0], RED), // the first, 1 px off
            ([300.0, 300.0], RED), // where the blue one maps, but red
            ([430.0, 100.0], RED), // 30 px from where the last maps
        ];
        let mut pairs = pair_across(&[left, right], &h, 12.0, 60.0);
        pairs.sort_unstable();
        assert_eq!(pairs, vec![(0, 1), (1, 0)]);
    }

    #[test]
    fn a_homography_that_sends_points_to_infinity_pairs_nothing() {
        let h = Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -300.0);
        let sides = [vec![([300.0, 200.0], RED)], vec![([300.0, 200.0], RED)]];
        assert!(pair_across(&sides, &h, 12.0, 60.0).is_empty());
    }
}
