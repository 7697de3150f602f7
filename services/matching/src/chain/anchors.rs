//! What the chain knows of each past image between pairs, for each current side: the
//! last fitted ground homography (the guide of guided matching), the *anchor* of
//! frame-to-frame tracking (`frame_tracking.rs`: the past image's ground inliers
//! under the tracker's ids), a failed fit not to retry before the next refresh, and
//! the links that guide a newly selected keyframe through one matched before. From
//! these the chain decides which frames to refresh (`wants_refresh`).

use super::refresh::RefreshJob;
use super::{FrameMeta, VisionChain};
use crate::epipolar::MatchReject;
use crate::frame::ChainError;
use crate::frame_tracking::{Motion, Observed, TrackedPoints};
use nalgebra::Matrix3;
use opencv::core as cv;
use shared_types::clock::monotonic_ns;
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
    /// The anchor before it: live, a pair observed before the last refresh landed
    /// may still be waiting for its detections, in the epoch before.
    pub(super) previous: Option<Anchor>,
}

impl Prior {
    pub(super) fn new(t_s: f64, homography: Matrix3<f64>) -> Self {
        Self {
            t_s,
            homography,
            anchor: None,
            previous: None,
        }
    }

    /// The anchor of tracking epoch `epoch`, if it is one of the two kept.
    fn anchor_of(&self, epoch: u64) -> Option<&Anchor> {
        [&self.anchor, &self.previous]
            .into_iter()
            .flatten()
            .find(|a| a.epoch == epoch)
    }
}

/// A past image's ground inliers handed to the current side's tracker: the tracker's
/// ids (valid in `epoch` only) with their points in the past image, by increasing id.
#[derive(Debug, Clone)]
pub(super) struct Anchor {
    pub(super) epoch: u64,
    pub(super) pairs: Arc<Vec<(u32, cv::Point2f)>>,
}

impl VisionChain {
    /// The refresh frame `frame` of `uav` needs, if any (none while one is in flight):
    /// the ring may admit it, tracking has nothing (warm-up, a lost track), the
    /// cadence is due, or a past image its pair will be matched with has neither an
    /// anchor in the frame's epoch nor a failure recorded there.
    pub(super) fn wants_refresh(
        &self,
        uav: Uav,
        frame: &FrameMeta,
        observed: &Observed,
    ) -> Option<RefreshJob> {
        let grey = observed.grey()?;
        if self.refresher.busy(uav) || !self.trackers[uav.index()].enabled() {
            return None;
        }
        let here = self.predicted_baseline(uav, frame.t_s, frame.pose.position());
        let admit = self.rings[uav.index()].would_admit(&here).then_some(here);
        let wanted = self.config.images_per_uav - 1;
        let mut past = Vec::new();
        let mut unknown = false;
        let epoch = observed.motion.as_ref().map(|m| m.epoch);
        for ring_uav in [Uav::Left, Uav::Right] {
            let at = if ring_uav == uav {
                Some(here)
            } else {
                self.smoothed[ring_uav.index()].map(|(_, p)| p)
            };
            let selected = match at {
                Some(at) => self.rings[ring_uav.index()].select(&at, frame.seq, wanted),
                None => Vec::new(),
            };
            if selected.len() < self.config.past_images_needed() {
                // Warming up: no matching, so only the features of an admission.
                past.clear();
                unknown = false;
                break;
            }
            // The ring's newest keyframe, too close to be selected yet, is the next to
            // be: matched now, it has an anchor the moment it is selected, rather than
            // missing from its first pairs while a refresh runs.
            let newest = self.rings[ring_uav.index()]
                .newest()
                .filter(|n| n.seq < frame.seq && !selected.iter().any(|kf| kf.seq == n.seq));
            if let Some(n) = newest {
                let prior = self.guide(uav.index(), ring_uav, n.seq, frame, None).prior;
                past.push((ring_uav, n.clone(), prior));
            }
            for kf in selected {
                let key = (uav.index(), ring_uav.index(), kf.seq);
                let anchor = self.priors.get(&key).and_then(|p| p.anchor.as_ref());
                let known = epoch.is_some_and(|e| {
                    anchor.is_some_and(|a| a.epoch == e)
                        || self.failed.get(&key).is_some_and(|(f, _)| *f == e)
                });
                unknown |= !known;
                let prior = self.guide(uav.index(), ring_uav, kf.seq, frame, None).prior;
                past.push((ring_uav, kf.clone(), prior));
            }
        }
        let lost = observed.motion.is_none() && !past.is_empty();
        let due = self.refresher.cadence_due(uav, frame.seq) && !past.is_empty();
        (admit.is_some() || lost || due || unknown).then(|| RefreshJob {
            uav,
            frame: FrameMeta {
                detection: None,
                ..*frame
            },
            grey: Arc::clone(grey),
            past,
            admit,
            submitted_ns: monotonic_ns(),
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
        let tracked = motion.and_then(|m| Some(join(&prior.anchor_of(m.epoch)?.pairs, &m.tracked)));
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

    /// Hands side `side`'s ground inliers (each past image's, current ↔ past, found on
    /// the refreshed frame `frame`) to its tracker, which follows them to its newest
    /// frame; keeps each past image's share as its anchor, and records the past images
    /// whose fit failed so that tracked frames do not ask again before the next
    /// refresh. Returns the new epoch's motion on the tracker's newest frame, or
    /// `None` when nothing was handed over (the old epoch goes on).
    pub(super) fn seed(
        &mut self,
        side: usize,
        frame: &FrameMeta,
        seeds: Vec<(PriorKey, SeedPairs)>,
        failures: Vec<(PriorKey, MatchReject)>,
    ) -> Result<Option<Motion>, ChainError> {
        if seeds.is_empty() {
            return Ok(None);
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
        let Some((epoch, tracked)) = self.trackers[side].hand_over(
            frame.seq,
            &points,
            &frame.intrinsics,
            &frame.distortion,
        )?
        else {
            return Ok(None);
        };
        for (key, pairs) in anchors {
            if let Some(prior) = self.priors.get_mut(&key) {
                prior.previous = prior.anchor.replace(Anchor {
                    epoch,
                    pairs: Arc::new(pairs),
                });
            }
        }
        for (key, reason) in failures {
            self.failed.insert(key, (epoch, reason));
        }
        Ok(Some(Motion {
            epoch,
            step: 0,
            tracked: Arc::new(tracked),
        }))
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
