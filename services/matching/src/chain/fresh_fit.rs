//! One current side against one past image from ORB matches: guided by the last
//! ground homography, else brute force, once more with a looser ratio when starved,
//! then the robust fit of F (eq. 24–26). The refresh thread does this for every past
//! image of a refreshed frame (`refresh.rs`); the per-pair path does it only with
//! tracking off (`past.rs`).

use super::anchors::SeedPairs;
use super::Step;
use crate::config::MatchingConfig;
use crate::epipolar::{
    estimate_fundamental_masked, match_points, match_points_guided, MatchReject, PairGeometry,
};
use crate::features::Features;
use crate::ground_plane::PlaneModel;
use crate::hamming::Nearest2;
use crate::ring::Keyframe;
use crate::ChainTiming;
use nalgebra::{Matrix3, Vector3};
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::clock::monotonic_ns;
use shared_types::conventions::{Intrinsics, Uav};
use std::time::Instant;

/// What one side's fit works on.
pub(super) struct FitSide<'a> {
    /// The past image's UAV (for the trace).
    pub(super) uav: Uav,
    pub(super) kf: &'a Keyframe,
    /// The current frame's features.
    pub(super) features: &'a Features,
    /// The ground homography current → past to guide matching, if young enough.
    pub(super) prior: Option<&'a Matrix3<f64>>,
    /// (current, past) cameras.
    pub(super) intrinsics: (&'a Intrinsics, &'a Intrinsics),
    /// The vertical in the current camera's frame (roll and pitch only).
    pub(super) up: &'a Vector3<f64>,
}

/// One side's fit.
pub(super) struct SideFit {
    pub(super) result: Result<PairGeometry, MatchReject>,
    /// Ground inliers to track (current, past points); empty unless the level ground
    /// plane gave F and tracking is on.
    pub(super) seeds: SeedPairs,
    /// Matched guided by the prior (and that fit held).
    pub(super) guided: bool,
    /// Matched again with `retry_ratio_test`.
    pub(super) retried: bool,
}

/// Matches `side.features` with the past image's and fits F, adding the times to
/// `timing` and the steps to `steps`.
pub(super) fn fit_side(
    config: &MatchingConfig,
    side: FitSide,
    neighbours: &mut Vec<Option<Nearest2>>,
    timing: &mut ChainTiming,
    steps: &mut Vec<Step>,
) -> SideFit {
    let FitSide {
        uav,
        kf,
        features,
        prior,
        intrinsics,
        up,
    } = side;
    let mut fit = |guide: Option<&Matrix3<f64>>,
                   ratio: f32,
                   timing: &mut ChainTiming,
                   steps: &mut Vec<Step>| {
        let t = Instant::now();
        let t_ns = monotonic_ns();
        let (a, b) = match guide {
            Some(h) => match_points_guided(
                features,
                &kf.features,
                h,
                config.guided_radius_px as f32,
                ratio,
                neighbours,
            ),
            None => match_points(features, &kf.features, ratio, neighbours),
        };
        timing.matching_us += super::micros(t);
        steps.push(Step::since("match", uav, kf.seq, t_ns));
        let t = Instant::now();
        let t_ns = monotonic_ns();
        let mut mask = cv::Mat::default();
        let result = estimate_fundamental_masked(&a, &b, intrinsics, up, config, &mut mask);
        timing.fundamental_us += super::micros(t);
        steps.push(Step::since("F", uav, kf.seq, t_ns));
        let seeds = match &result {
            Ok(g) if config.track_between_orb && g.model == Some(PlaneModel::GroundPlane) => {
                ground_seeds(&a, &b, &mask, config.track_points_per_image)
            }
            _ => Vec::new(),
        };
        (result, seeds)
    };
    let mut out = SideFit {
        result: Err(MatchReject::FundamentalFailed),
        seeds: Vec::new(),
        guided: false,
        retried: false,
    };
    if let Some(h) = prior {
        (out.result, out.seeds) = fit(Some(h), config.ratio_test, timing, steps);
        out.guided = out.result.is_ok();
    }
    if out.result.is_err() {
        (out.result, out.seeds) = fit(None, config.ratio_test, timing, steps);
    }
    // Too little support under the strict ratio: a scene with repeated texture
    // (windows, lane marks) loses its good matches to the ratio test. Once more,
    // looser; the robust fit and `min_inliers` still judge the result.
    let starved = matches!(
        out.result,
        Err(MatchReject::TooFewMatches { .. } | MatchReject::TooFewInliers { .. })
    );
    if starved && config.retry_ratio_test > config.ratio_test {
        (out.result, out.seeds) = fit(None, config.retry_ratio_test, timing, steps);
        out.retried = true;
    }
    out
}

/// Up to `most` ground inliers of a fit (a stride through them, so they stay spread),
/// as (current, past) points: what the tracker follows until the next refresh.
fn ground_seeds(
    current: &cv::Vector<cv::Point2f>,
    past: &cv::Vector<cv::Point2f>,
    mask: &cv::Mat,
    most: usize,
) -> SeedPairs {
    let inliers: Vec<usize> = (0..current.len())
        .filter(|&i| mask.at::<u8>(i as i32).is_ok_and(|m| *m != 0))
        .collect();
    let stride = inliers.len().div_ceil(most.max(1)).max(1);
    inliers
        .iter()
        .step_by(stride)
        .filter_map(|&i| Some((current.get(i).ok()?, past.get(i).ok()?)))
        .collect()
}
