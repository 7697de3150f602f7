//! What the chain knows of each past image between pairs, for each current side: the
//! last fitted ground homography (the guide of guided matching), the *anchor* of
//! frame-to-frame tracking (`frame_tracking.rs`: the past image's ground inliers
//! under the tracker's ids), a failed fit not to retry before the next ORB frame, and
//! the links that guide a newly selected keyframe through one matched before. From
//! these the chain decides which frames need ORB (`wants_features`).

use super::{FrameMeta, VisionChain};
use crate::epipolar::MatchReject;
use crate::frame_tracking::{Motion, TrackedPoints};
use nalgebra::Matrix3;
use opencv::core as cv;
use shared_types::conventions::Uav;
use std::collections::HashMap;
use std::sync::Arc;

/// What one current side knows of a past image before matching it.
#[derive(Debug, Clone, Default)]
pub(super) struct Guide {
    /// The last fitted ground homography, young enough to guide matching.
    pub(super) prior: Option<Matrix3<f64>>,
    /// Tracked correspondences with the past image (`frame_tracking.rs`): the
    /// current frame's followed ground points joined with the anchor's.
    pub(super) tracked: Option<(cv::Vector<cv::Point2f>, cv::Vector<cv::Point2f>)>,
    /// Why the fit failed on this side's last ORB frame, if it did and this frame is
    /// tracked from it.
    pub(super) failed: Option<MatchReject>,
}

/// (current side, keyframe's UAV, keyframe seq).
pub(super) type PriorKey = (usize, usize, u64);

/// (keyframe's UAV, keyframe seq).
pub(super) type KeyframeId = (usize, u64);

/// Ground inliers of a fit to track: (current, past) points.
pub(super) type SeedPairs = Vec<(cv::Point2f, cv::Point2f)>;

/// A ground homography, current → keyframe pixels, found with the current frame of
/// time `t_s`.
#[derive(Debug, Clone)]
pub(super) struct Prior {
    pub(super) t_s: f64,
    pub(super) homography: Matrix3<f64>,
    /// The ground inliers of the last fresh fit, as the tracker follows them.
    pub(super) anchor: Option<Anchor>,
}

/// A past image's ground inliers handed to the current side's tracker: the tracker's
/// ids (valid in `epoch` only) with their points in the past image, by increasing id.
#[derive(Debug, Clone)]
pub(super) struct Anchor {
    pub(super) epoch: u64,
    pub(super) pairs: Arc<Vec<(u32, cv::Point2f)>>,
}

impl VisionChain {
    /// Whether `frame` of `uav` should run ORB rather than only be tracked: the ring
    /// may admit it, or a past image it will be matched with has neither an anchor in
    /// the tracker's epoch nor a failure recorded there. A wrong guess costs time,
    /// never accuracy: a pair that needs features it lacks gets them late
    /// ([`super::ChainCounts::late_orb`]).
    pub fn wants_features(
        &self,
        uav: Uav,
        seq: u64,
        t_s: f64,
        position: nalgebra::Point3<f64>,
    ) -> bool {
        let here = self.predicted_baseline(uav, t_s, position);
        if self.rings[uav.index()].would_admit(&here) {
            return true;
        }
        let wanted = self.config.images_per_uav - 1;
        let mut selections = Vec::with_capacity(2);
        for ring_uav in [Uav::Left, Uav::Right] {
            let at = if ring_uav == uav {
                here
            } else {
                match self.smoothed[ring_uav.index()] {
                    Some((_, p)) => p,
                    None => return false,
                }
            };
            let selected = self.rings[ring_uav.index()].select(&at, seq, wanted);
            if selected.len() < wanted {
                // Warming up: no matching, so no features unless admitted.
                return false;
            }
            selections.push((ring_uav, selected));
        }
        let Some((epoch, _)) = self.trackers[uav.index()].next_step(seq) else {
            return true;
        };
        selections.iter().any(|(ring_uav, selected)| {
            selected.iter().any(|kf| {
                let key = (uav.index(), ring_uav.index(), kf.seq);
                let anchor = self.priors.get(&key).and_then(|p| p.anchor.as_ref());
                let known = anchor.is_some_and(|a| a.epoch == epoch)
                    || self.failed.get(&key).is_some_and(|(e, _)| *e == epoch);
                !known
            })
        })
    }

    /// What side `side`'s current frame knows of keyframe `seq` of `uav`: the last
    /// fitted homography if young enough to guide matching, and the tracked
    /// correspondences if this frame followed the points of that keyframe's anchor.
    pub(super) fn guide(
        &self,
        side: usize,
        uav: Uav,
        seq: u64,
        frame: &FrameMeta,
        motion: Option<&Motion>,
    ) -> Guide {
        let failed = match (self.failed.get(&(side, uav.index(), seq)), motion) {
            (Some((epoch, reason)), Some(m)) if *epoch == m.epoch => Some(*reason),
            _ => None,
        };
        let config = &self.config;
        let Some(prior) = self.priors.get(&(side, uav.index(), seq)) else {
            return Guide {
                failed,
                prior: self.linked_prior(side, uav, seq, frame),
                ..Guide::default()
            };
        };
        let age = frame.t_s - prior.t_s;
        let fresh = (0.0..=config.guided_max_age_s).contains(&age);
        let tracked = match (&prior.anchor, motion) {
            (Some(a), Some(m)) if a.epoch == m.epoch => Some(join(&a.pairs, &m.tracked)),
            _ => None,
        };
        Guide {
            prior: (fresh && config.guided_radius_px > 0.0).then_some(prior.homography),
            tracked,
            failed,
        }
    }

    /// A guide to keyframe `seq` of `uav` that this side has never matched: through
    /// a past image both were matched with, `H_cur→kf = H_kf→j⁻¹ · H_cur→j` (all ground
    /// homographies). Without it a newly selected keyframe is matched by brute force,
    /// the slowest step of the chain (docs/pipeline.md).
    fn linked_prior(
        &self,
        side: usize,
        uav: Uav,
        seq: u64,
        frame: &FrameMeta,
    ) -> Option<Matrix3<f64>> {
        let config = &self.config;
        if config.guided_radius_px <= 0.0 {
            return None;
        }
        self.links
            .get(&(uav.index(), seq))?
            .iter()
            .find_map(|((j_uav, j_seq), h_link)| {
                let p = self.priors.get(&(side, *j_uav, *j_seq))?;
                let fresh = (0.0..=config.guided_max_age_s).contains(&(frame.t_s - p.t_s));
                let h = h_link.try_inverse()? * p.homography;
                (fresh && h.iter().all(|v| v.is_finite())).then_some(h)
            })
    }

    /// Hands side `side`'s ground inliers (each past image's, current ↔ past) to its
    /// tracker, keeps each past image's share as its anchor, and records the past
    /// images whose fit failed so that tracked frames do not ask for ORB again.
    pub(super) fn seed(
        &mut self,
        side: usize,
        frame: &FrameMeta,
        seeds: Vec<(PriorKey, SeedPairs)>,
        failures: Vec<(PriorKey, MatchReject)>,
    ) {
        if seeds.is_empty() {
            return;
        }
        // One id per distinct current point (a keypoint can be an inlier with several
        // past images).
        let mut ids: HashMap<(u32, u32), u32> = HashMap::new();
        let mut points = Vec::new();
        let mut anchors = Vec::with_capacity(seeds.len());
        for (key, pairs) in seeds {
            let mut anchor: Vec<(u32, cv::Point2f)> = pairs
                .iter()
                .map(|(c, p)| {
                    let id = *ids
                        .entry((c.x.to_bits(), c.y.to_bits()))
                        .or_insert_with(|| {
                            points.push(*c);
                            points.len() as u32 - 1
                        });
                    (id, *p)
                })
                .collect();
            anchor.sort_by_key(|(id, _)| *id);
            anchor.dedup_by_key(|(id, _)| *id);
            anchors.push((key, anchor));
        }
        let epoch =
            self.trackers[side].seed(frame.seq, &points, &frame.intrinsics, &frame.distortion);
        for (key, pairs) in anchors {
            if let Some(prior) = self.priors.get_mut(&key) {
                prior.anchor = epoch.map(|epoch| Anchor {
                    epoch,
                    pairs: Arc::new(pairs),
                });
            }
        }
        if let Some(epoch) = epoch {
            for (key, reason) in failures {
                self.failed.insert(key, (epoch, reason));
            }
        }
    }
}

/// Tracked correspondences: the anchor's past points joined by id with the points the
/// current frame followed (both sorted by id).
fn join(
    anchor: &[(u32, cv::Point2f)],
    tracked: &TrackedPoints,
) -> (cv::Vector<cv::Point2f>, cv::Vector<cv::Point2f>) {
    let (mut current, mut past) = (cv::Vector::new(), cv::Vector::new());
    let mut a = anchor.iter().peekable();
    for (id, point) in tracked.ids.iter().zip(&tracked.points) {
        while a.next_if(|(i, _)| i < id).is_some() {}
        if let Some((_, p)) = a.next_if(|(i, _)| i == id) {
            current.push(*point);
            past.push(*p);
        }
    }
    (current, past)
}
