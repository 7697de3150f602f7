//! Eq. (24)–(28) for one past image on the per-pair path: F_Ln and F_Rn, each from
//! the correspondences frame-to-frame tracking followed (or, with tracking off, from
//! ORB matches: `fresh_fit.rs`), and the intersection of the two epipolar lines.

use super::anchors::Guide;
use super::fresh_fit::{fit_side, FitSide};
use super::{micros, FrameMeta, PastMatch, Step};
use crate::config::MatchingConfig;
use crate::epipolar::{
    estimate_fundamental, transfer_point, ImageBounds, MatchReject, PairGeometry,
};
use crate::features::Features;
use crate::ring::Keyframe;
use crate::ChainTiming;
use nalgebra::{Matrix3, Vector3};
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
    pub(super) timing: ChainTiming,
    pub(super) steps: Vec<Step>,
    /// Sides matched again with `retry_ratio_test`.
    pub(super) retried: [bool; 2],
}

/// Eq. (24)–(28) for one past image: F_Ln from the current left image, F_Rn from the
/// current right one, and the intersection of the two epipolar lines. A side with a
/// prior homography is matched guided first, and by brute force if that fit fails.
/// Without `detections` (the target unseen in a current image) the fits alone: the
/// match's `pixel` is NaN, for the other vehicles' transfers only (never in a
/// [`super::MatchedSet`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn match_past(
    config: &MatchingConfig,
    uav: Uav,
    kf: &Keyframe,
    current: &[FrameMeta; 2],
    detections: Option<[[f64; 2]; 2]>,
    features: &[Option<Arc<Features>>; 2],
    guides: &[Guide; 2],
    neighbours: &mut Vec<Option<crate::hamming::Nearest2>>,
) -> PastResult {
    let job_start = monotonic_ns();
    let mut out = PastResult {
        result: Err(MatchReject::FundamentalFailed),
        homographies: [None, None],
        timing: ChainTiming::default(),
        steps: Vec::new(),
        retried: [false, false],
    };
    let step = |name: &'static str, start_ns: u64| Step::since(name, uav, kf.seq, start_ns);
    let mut geometry: [Option<PairGeometry>; 2] = [None, None];
    let mut guided = [false, false];
    let mut chained = [false, false];
    for side in 0..2 {
        // The vertical in the current camera's frame: roll and pitch only (the yaw and
        // its unknown bias turn about it).
        let up = camera_to_world(current[side].pose.attitude()).transpose() * Vector3::z();
        let intrinsics = (&current[side].intrinsics, &kf.intrinsics);
        let Some(features) = &features[side] else {
            // No features (tracking on): the tracked correspondences, fitted like
            // matches.
            let t = Instant::now();
            let t_ns = monotonic_ns();
            let result = match (&guides[side].tracked, guides[side].failed) {
                (Some((a, b)), _) => estimate_fundamental(a, b, intrinsics, &up, config),
                // Failed on this side's last refresh: not retried until the next.
                (None, Some(reason)) => Err(reason),
                // Nothing tracked to this past image yet: answered without it.
                (None, None) => Err(MatchReject::AwaitingRefresh),
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
        let fit = fit_side(
            config,
            FitSide {
                uav,
                kf,
                features,
                prior: guides[side].prior.as_ref(),
                intrinsics,
                up: &up,
            },
            neighbours,
            &mut out.timing,
            &mut out.steps,
        );
        guided[side] = fit.guided;
        out.retried[side] = fit.retried;
        match fit.result {
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
    let pixel = match detections {
        Some(detections) => {
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
            pixel
        }
        None => Ok([f64::NAN; 2]),
    };
    out.steps.push(step("past", job_start));
    out.result = pixel.map(|pixel| PastMatch {
        uav,
        seq: kf.seq,
        t_s: kf.t_s,
        pixel,
        inliers: [gl.inliers, gr.inliers],
        fundamental: [gl.f, gr.f],
        models: [gl.model, gr.model],
        rotations: [gl.rotation, gr.rotation],
        guided,
        chained,
    });
    out
}
