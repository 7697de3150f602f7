//! Eq. (24)–(28) for one past image: F_Ln and F_Rn, each from ORB matches (guided by
//! the last ground homography, else brute force) or from the correspondences
//! frame-to-frame tracking followed, and the intersection of the two epipolar lines.

use super::anchors::{Guide, SeedPairs};
use super::{micros, FrameMeta, PastMatch, Step};
use crate::config::MatchingConfig;
use crate::epipolar::{
    estimate_fundamental, estimate_fundamental_masked, match_points, match_points_guided,
    transfer_point, ImageBounds, MatchReject, PairGeometry,
};
use crate::features::Features;
use crate::ground_plane::PlaneModel;
use crate::ring::Keyframe;
use crate::ChainTiming;
use nalgebra::{Matrix3, Vector3};
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::clock::monotonic_ns;
use shared_types::conventions::{camera_to_world, Uav};
use std::sync::Arc;
use std::time::Instant;

/// One past image to match, with what guides each current side.
pub(super) type Job<'a> = ((Uav, &'a Keyframe), [Guide; 2]);

/// One past image's matching: the point (or why none), the homographies to keep as
/// priors, and which sides were matched guided.
pub(super) struct PastResult {
    pub(super) result: Result<PastMatch, MatchReject>,
    /// Ground homographies fitted on this frame.
    pub(super) homographies: [Option<Matrix3<f64>>; 2],
    /// Of sides matched by ORB: ground inliers to track (current, past points).
    pub(super) seeds: [SeedPairs; 2],
    pub(super) timing: ChainTiming,
    pub(super) steps: Vec<Step>,
    /// Sides matched again with `retry_ratio_test`.
    pub(super) retried: [bool; 2],
}

/// Eq. (24)–(28) for one past image: F_Ln from the current left image, F_Rn from the
/// current right one, and the intersection of the two epipolar lines. A side with a
/// prior homography is matched guided first, and by brute force if that fit fails.
#[allow(clippy::too_many_arguments)]
pub(super) fn match_past(
    config: &MatchingConfig,
    uav: Uav,
    kf: &Keyframe,
    current: &[FrameMeta; 2],
    detections: [[f64; 2]; 2],
    features: &[Option<Arc<Features>>; 2],
    guides: &[Guide; 2],
    neighbours: &mut Vec<Option<crate::hamming::Nearest2>>,
) -> PastResult {
    let job_start = monotonic_ns();
    let mut out = PastResult {
        result: Err(MatchReject::FundamentalFailed),
        homographies: [None, None],
        seeds: [Vec::new(), Vec::new()],
        timing: ChainTiming::default(),
        steps: Vec::new(),
        retried: [false, false],
    };
    let step = |name: &'static str, start_ns: u64| Step {
        name,
        uav: uav.index() as u8,
        keyframe: kf.seq,
        start_ns,
        end_ns: monotonic_ns(),
    };
    let mut geometry: [Option<PairGeometry>; 2] = [None, None];
    let mut guided = [false, false];
    let mut chained = [false, false];
    for side in 0..2 {
        // The vertical in the current camera's frame: roll and pitch only (the yaw and
        // its unknown bias turn about it).
        let up = camera_to_world(current[side].pose.attitude()).transpose() * Vector3::z();
        let intrinsics = (&current[side].intrinsics, &kf.intrinsics);
        let Some(features) = &features[side] else {
            // No features: `match_current` made sure this side has tracked
            // correspondences, fitted like matches.
            let t = Instant::now();
            let t_ns = monotonic_ns();
            let result = match (&guides[side].tracked, guides[side].failed) {
                (Some((a, b)), _) => estimate_fundamental(a, b, intrinsics, &up, config),
                // Failed on this side's last ORB frame: not retried until the next.
                (None, Some(reason)) => Err(reason),
                (None, None) => Err(MatchReject::FundamentalFailed),
            };
            out.timing.fundamental_us += micros(t);
            out.steps.push(step("F", t_ns));
            match result {
                Ok(g) => {
                    chained[side] = true;
                    out.homographies[side] = g.homography;
                    geometry[side] = Some(g);
                    continue;
                }
                Err(reason) => {
                    out.result = Err(reason);
                    out.steps.push(step("past", job_start));
                    return out;
                }
            }
        };
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
            timing.matching_us += micros(t);
            steps.push(step("match", t_ns));
            let t = Instant::now();
            let t_ns = monotonic_ns();
            let mut mask = cv::Mat::default();
            let result = estimate_fundamental_masked(&a, &b, intrinsics, &up, config, &mut mask);
            timing.fundamental_us += micros(t);
            steps.push(step("F", t_ns));
            let seeds = match &result {
                Ok(g) if config.track_between_orb && g.model == Some(PlaneModel::GroundPlane) => {
                    ground_seeds(&a, &b, &mask, config.track_points_per_image)
                }
                _ => Vec::new(),
            };
            (result, seeds)
        };
        let mut result = (Err(MatchReject::FundamentalFailed), Vec::new());
        if let Some(h) = &guides[side].prior {
            result = fit(Some(h), config.ratio_test, &mut out.timing, &mut out.steps);
            guided[side] = result.0.is_ok();
        }
        if result.0.is_err() {
            result = fit(None, config.ratio_test, &mut out.timing, &mut out.steps);
        }
        // Too little support under the strict ratio: a scene with repeated texture
        // (windows, lane marks) loses its good matches to the ratio test. Once more,
        // looser; the robust fit and `min_inliers` still judge the result.
        let starved = matches!(
            result.0,
            Err(MatchReject::TooFewMatches { .. } | MatchReject::TooFewInliers { .. })
        );
        if starved && config.retry_ratio_test > config.ratio_test {
            result = fit(
                None,
                config.retry_ratio_test,
                &mut out.timing,
                &mut out.steps,
            );
            out.retried[side] = true;
        }
        let (result, seeds) = result;
        out.seeds[side] = seeds;
        match result {
            Ok(g) => {
                out.homographies[side] = g.homography;
                geometry[side] = Some(g);
            }
            Err(reason) => {
                out.result = Err(reason);
                out.steps.push(step("past", job_start));
                return out;
            }
        }
    }
    let [Some(gl), Some(gr)] = geometry else {
        out.steps.push(step("past", job_start));
        return out;
    };
    let t = Instant::now();
    let t_ns = monotonic_ns();
    let pixel = transfer_point(
        &gl.f,
        detections[0],
        &gr.f,
        detections[1],
        &ImageBounds {
            intrinsics: &kf.intrinsics,
            distortion: &kf.distortion,
            width: kf.width,
            height: kf.height,
        },
        config,
    );
    out.timing.transfer_us += micros(t);
    out.steps.push(step("transfer", t_ns));
    out.steps.push(step("past", job_start));
    out.result = pixel.map(|pixel| PastMatch {
        uav,
        seq: kf.seq,
        t_s: kf.t_s,
        pixel,
        inliers: [gl.inliers, gr.inliers],
        fundamental: [gl.f, gr.f],
        models: [gl.model, gr.model],
        guided,
        chained,
    });
    out
}

/// Up to `most` ground inliers of a fit (a stride through them, so they stay spread),
/// as (current, past) points: what the tracker follows until the next ORB frame.
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
