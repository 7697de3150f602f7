//! Where a refresh meets the per-pair path: at a frame boundary of its UAV, before
//! the tracker observes the frame (or, with `refresh_landing_frames = 0`, right after
//! it observed the refreshed frame itself). Landing installs the refresh's ground
//! homographies as guides, hands its ground points to the tracker (a new epoch, with
//! an anchor per past image), records the fits that failed, and offers the frame to
//! the keyframe ring with its features and links.

use super::anchors::{KeyframeId, Prior};
use super::refresh::{Landing, Moment, RefreshResult};
use super::{FrameMeta, Step, VisionChain};
use crate::epipolar::MatchReject;
use crate::frame::{ChainError, FrameInput};
use crate::frame_tracking::{Motion, Observed, TrackReport};
use crate::ring::Keyframe;
use nalgebra::Matrix3;
use shared_types::conventions::Uav;

/// What one landed refresh did (matching's histograms and trace).
#[derive(Debug, Clone)]
pub struct LandingReport {
    pub uav: Uav,
    /// The frame the refresh was taken on, and the one it landed on.
    pub taken_seq: u64,
    pub landed_seq: u64,
    /// When it was asked for and when the thread finished it (CLOCK_MONOTONIC, ns).
    pub submitted_ns: u64,
    pub finished_ns: u64,
    /// How long the pair waited for it (µs): 0 live; at `--rate max`, a refresh still
    /// running on its landing frame.
    pub waited_us: u64,
    /// The thread's timed steps (`orb`, `match`, `F`, and `refresh` for the whole job).
    pub steps: Vec<Step>,
}

/// Landing reports kept for the caller at most (the service takes them every pair;
/// the evaluation never does).
const KEPT_REPORTS: usize = 8;

impl VisionChain {
    /// Before the tracker observes frame `seq` of `uav`: lands a refresh due there.
    /// A refresh of a frame no earlier than `seq` (the stream went back) is dropped.
    pub fn before_frame(&mut self, uav: Uav, seq: u64) -> Result<(), ChainError> {
        if self.refresher.in_flight(uav).is_some_and(|k| k >= seq) {
            if self.refresher.drain(uav)?.is_some() {
                self.counts.refresh_failed += 1;
            }
        } else if let Some((landing, waited)) =
            self.refresher.landing(uav, seq, Moment::Before, false)?
        {
            self.land(landing, seq, waited)?;
        }
        self.counts.refresh_failed += self.refresher.take_died();
        Ok(())
    }

    /// After the tracker observed `frame`: asks for its refresh if it needs one, and
    /// lands it at once when refreshes land on their own frame or the frame comes
    /// after a gap (a refresh still in flight then lands first: it cannot be followed
    /// across the gap, but it must not hold up this frame's).
    pub fn after_observe(
        &mut self,
        uav: Uav,
        frame: &FrameMeta,
        observed: &mut Observed,
    ) -> Result<(), ChainError> {
        let now = observed.after_gap;
        if now {
            if let Some((landing, waited)) = self.refresher.drain(uav)? {
                self.land(landing, frame.seq, waited)?;
            }
        }
        if let Some(job) = self.wants_refresh(uav, frame, observed) {
            self.refresher.submit(job)?;
        }
        if let Some((landing, waited)) =
            self.refresher.landing(uav, frame.seq, Moment::After, now)?
        {
            if let Some(motion) = self.land(landing, frame.seq, waited)? {
                observed.motion = Some(motion);
            }
        }
        self.counts.refresh_failed += self.refresher.take_died();
        Ok(())
    }

    /// Both frames of a pair, in the order the service observes them (both landings,
    /// both trackers, both requests), so that the evaluation answers as a replay at
    /// `--rate max` does.
    pub fn observe_pair(
        &mut self,
        frames: [&FrameInput; 2],
    ) -> Result<[(Observed, TrackReport); 2], ChainError> {
        for uav in [Uav::Left, Uav::Right] {
            self.before_frame(uav, frames[uav.index()].seq)?;
        }
        let mut seen = Vec::with_capacity(2);
        for uav in [Uav::Left, Uav::Right] {
            let (observed, counts, report) =
                self.trackers[uav.index()].observe(frames[uav.index()])?;
            self.counts += counts;
            seen.push((observed, report));
        }
        let [mut left, mut right]: [(Observed, TrackReport); 2] = seen
            .try_into()
            .map_err(|_| ChainError::Tracking("a pair without two frames"))?;
        self.after_observe(Uav::Left, &frames[0].meta(), &mut left.0)?;
        self.after_observe(Uav::Right, &frames[1].meta(), &mut right.0)?;
        Ok([left, right])
    }

    /// The landing reports since the last call.
    pub fn take_landings(&mut self) -> Vec<LandingReport> {
        self.landings.drain(..).collect()
    }

    /// Lands one finished refresh on frame `seq`; returns the new epoch's motion on
    /// the tracker's newest frame if the tracker took its points. A refresh that
    /// failed (OpenCV refusing the frame) is counted and the chain goes on.
    fn land(
        &mut self,
        landing: Landing,
        seq: u64,
        waited_us: u64,
    ) -> Result<Option<Motion>, ChainError> {
        let Landing {
            uav,
            seq: taken_seq,
            outcome,
            submitted_ns,
            finished_ns,
        } = landing;
        let r = match outcome {
            Ok(r) => r,
            Err(e) => {
                self.counts.refresh_failed += 1;
                tracing::warn!(?uav, frame = taken_seq, "refresh failed: {e}");
                return Ok(None);
            }
        };
        self.counts.refreshes += 1;
        self.counts += r.counts;
        let steps = r.steps.clone();
        let had_seeds = r.fits.iter().any(|f| !f.seeds.is_empty());
        let motion = self.land_result(r)?;
        if had_seeds && motion.is_none() {
            self.counts.refresh_not_followed += 1;
        }
        if self.landings.len() >= KEPT_REPORTS {
            self.landings.pop_front();
        }
        self.landings.push_back(LandingReport {
            uav,
            taken_seq,
            landed_seq: seq,
            submitted_ns,
            finished_ns,
            waited_us,
            steps,
        });
        Ok(motion)
    }

    fn land_result(&mut self, r: RefreshResult) -> Result<Option<Motion>, ChainError> {
        let side = r.uav.index();
        // The refresh's homographies guide the next matchings, unless the per-pair
        // path has fitted a newer one since.
        for fit in &r.fits {
            let Some(homography) = fit.homography else {
                continue;
            };
            let key = (side, fit.id.0, fit.id.1);
            match self.priors.get_mut(&key) {
                Some(p) if p.t_s > r.frame.t_s => {}
                Some(p) => {
                    p.t_s = r.frame.t_s;
                    p.homography = homography;
                }
                None => {
                    self.priors.insert(key, Prior::new(r.frame.t_s, homography));
                }
            }
        }
        let seeds = r
            .fits
            .iter()
            .filter(|f| !f.seeds.is_empty())
            .map(|f| ((side, f.id.0, f.id.1), f.seeds.clone()))
            .collect();
        // A fit that held without ground points to follow is recorded like a failure:
        // nothing can be tracked to that past image before the next refresh.
        let failures = r
            .fits
            .iter()
            .filter_map(|f| {
                let reason = match f.result {
                    Err(e) => e,
                    Ok(()) if f.seeds.is_empty() => MatchReject::NoGroundSeeds,
                    Ok(()) => return None,
                };
                Some(((side, f.id.0, f.id.1), reason))
            })
            .collect();
        let motion = self.seed(side, &r.frame, seeds, failures)?;
        if let Some(baseline_position) = r.admit {
            let f = r.frame;
            let admitted = self.rings[side].offer(Keyframe {
                seq: f.seq,
                t_s: f.t_s,
                pose: f.pose,
                baseline_position,
                intrinsics: f.intrinsics,
                distortion: f.distortion,
                width: f.width,
                height: f.height,
                features: r.features,
            });
            if admitted {
                // The ground homographies fitted on this very frame: its links.
                let links: Vec<(KeyframeId, Matrix3<f64>)> = r
                    .fits
                    .iter()
                    .filter_map(|fit| Some((fit.id, fit.homography?)))
                    .collect();
                if !links.is_empty() {
                    self.links.insert((side, f.seq), links);
                }
                self.landed_admissions[side] = true;
            }
        }
        Ok(motion)
    }
}
