//! The geolocation service's other vehicles: each [`OtherTarget`] of an observation
//! set located with the yaw biases of the target's estimate on the same pair
//! ([`crate::shared_bias`]), then the tracks ([`crate::tracks`]) updated and the
//! confirmed ones put into the [`EstimateMsg`]. Every field of the set is untrusted, as
//! in [`crate::set_message`]: a bad pixel drops that vehicle (counted), never a panic,
//! never a NaN out.
//!
//! Before the target's estimate, [`detection_identity`] asks the other vehicles whether
//! the target's detections are another tracked vehicle (`target_identity.rs`).
//!
//! Counters: `others_located`, `others_unseen_located` (of those, located alone on a
//! pair without the target), `others_rejected.<kind>`, `others_no_biases` (a pair
//! with other vehicles but no valid target estimate to take the biases from),
//! `others_skipped` (vehicles of a pair whose target detections were another's),
//! `tracks_confirmed`, `tracks_deleted`, `tracks_tentative_dropped`,
//! `tracks_reacquired`, `tracks_reidentified`, `tracks_target_fixes`,
//! `tracks_unreported_static`.

use crate::observation::ImagePoseErrors;
use crate::shared_bias::{locate_with_biases, OtherFix, SharedBiases};
use crate::target_identity::{log_likelihood_ratios, IdentityCheck};
use crate::tracks::{TrackQuality, TrackReport, Tracks};
use crate::TemporalEstimator;
use crate::{EstimatorConfig, Observation};
use nalgebra::{Matrix2, Vector2};
use shared_types::messages::{
    EstimateMsg, EstimateStatus, ObservationSetMsg, OtherTarget, TrackEstimate, MAX_TRACKS,
};
use shared_types::stats::StageStats;

/// The shared biases of the target's estimate `msg`, when it is valid.
fn biases_of(msg: &EstimateMsg) -> Option<SharedBiases> {
    if msg.status != EstimateStatus::Ok as u32 {
        return None;
    }
    let c = &msg.covariance;
    Some(SharedBiases {
        mean: msg.yaw_bias_deg.map(f64::to_radians),
        covariance: Matrix2::new(c[10], c[11], c[14], c[15]),
    })
}

/// The observations of vehicle `other` (the set's images with its pixels, where its
/// transfer reached) and the target's through the same images, each image's pose
/// error as the target's filter estimated it removed (`pose_errors`, where it has
/// the image; the current images' only `with_current`: an earlier update's are
/// another pair's). `None` when an entry or pixel is bad.
fn observations_of(
    set: &ObservationSetMsg,
    other: &OtherTarget,
    pose_errors: Option<&ImagePoseErrors>,
    with_current: bool,
) -> Option<(Vec<Observation>, Vec<Observation>)> {
    let entries = set.entries();
    if entries.len() < 2 {
        return None;
    }
    let mut theirs = Vec::with_capacity(entries.len());
    let mut target = Vec::with_capacity(entries.len());
    for (i, e) in entries.iter().enumerate() {
        let pixel = match i {
            0 | 1 => Some(other.current[i]),
            _ => other.past_pixel(i - 2),
        };
        let Some(pixel) = pixel else { continue };
        if !pixel.iter().all(|v| v.is_finite()) {
            return None;
        }
        let o = Observation::from_entry(e, i).ok()?;
        let error = pose_errors.and_then(|p| match i {
            0 | 1 => p.of_current(o.uav).filter(|_| with_current),
            _ => p.of_past((o.uav, e.frame_seq)),
        });
        let o = error.map_or(o, |e| o.with_pose_error_removed(&e));
        target.push(o);
        theirs.push(Observation {
            pixel: Vector2::new(pixel[0], pixel[1]),
            ..o
        });
    }
    Some((theirs, target))
}

/// Vehicle `other` located relative to the target: both through the same images with
/// the same biases, and the difference added to the target's estimate `msg`. What
/// the two share (each image's GPS and attitude error, the altitude's) cancels in the
/// difference; the target's filter has averaged it out of the target's own estimate
/// over time, one window of a vehicle could not.
///
/// Not all of it cancels: an image's yaw, tilt or GPS error turns or scales its rays
/// about the camera, which moves two vehicles metres apart differently (~10 % of
/// their separation on `multi_crawl` seed 8, ≤ 0.07 m without navigation noise). A
/// past image keeps its error for every pair that reuses it (seconds), so the tracks
/// could not average that part: each image's pose error as the target's filter
/// estimated it (`pose_errors`, its keyframe states: `temporal.rs`) is removed
/// first. Over the 24 flights of `dualgeo evaluate --multi-target`, GOSPA 2.41 →
/// 1.82 m (`multi_town`), 2.21 → 1.80 (`suite_traffic`), 2.54 → 1.91 (`multi_crawl`).
///
/// Its covariance, as the tracks weigh a fix: the target's (x, y) block plus the
/// vehicle's own with the biases taken as known (the tracks' learnt noise scale fits
/// it to their innovations). What persists from pair to pair, and so outlives a
/// track's averaging (`OtherFix::persistent_xy`), is stated apart: the target's
/// (x, y) block, and the biases' error carried into the difference. The biases'
/// error does not cancel there: it turns each UAV's rays about the UAV, so the
/// difference moves by (J_vehicle − J_target) δψ, J the fixes' `bias_sensitivity`;
/// with the target's error, correlated with the biases' in the filter, its covariance
/// is M C Mᵀ, M = [I₂ | J_d] and C the filter's (x, y, δψ_L, δψ_R) covariance. The
/// same for z: the target's altitude variance and the biases' share of the
/// difference's z (the filter keeps no z–bias covariance). The target's (x, y) block
/// is in the fix's covariance too, which the tracks' learnt noise scale fits to the
/// innovations (it sits at its floor: the double count there is small).
fn locate_relative(
    set: &ObservationSetMsg,
    other: &OtherTarget,
    msg: &EstimateMsg,
    biases: &SharedBiases,
    pose_errors: Option<&ImagePoseErrors>,
    config: &EstimatorConfig,
) -> Result<OtherFix, &'static str> {
    let (theirs, target) = observations_of(set, other, pose_errors, true).ok_or("bad_input")?;
    let fix = locate_with_biases(&theirs, biases, config).map_err(|e| e.kind())?;
    let reference = locate_with_biases(&target, biases, config).map_err(|e| e.kind())?;
    let c = &msg.covariance;
    let target_xy = Matrix2::new(c[0], c[1], c[4], c[5]);
    // (x, y, δψ_L, δψ_R) of the target's filter, row-major.
    let target_and_biases = nalgebra::Matrix4::from_row_slice(c);
    let d = fix.position - reference.position;
    let position = nalgebra::Point3::new(
        msg.position[0] + d.x,
        msg.position[1] + d.y,
        msg.position[2] + d.z,
    );
    let j = fix.bias_sensitivity - reference.bias_sensitivity;
    // Its error e_target + J_d e_biases, the two correlated in the filter: with
    // M = [I₂ | J_d], M C Mᵀ over the filter's (x, y, δψ_L, δψ_R) covariance C.
    let mut m = nalgebra::Matrix2x4::zeros();
    m.fixed_view_mut::<2, 2>(0, 0).fill_with_identity();
    m.fixed_view_mut::<2, 2>(0, 2).copy_from(&j);
    let persistent_xy = m * target_and_biases * m.transpose();
    let jz: [f64; 2] = std::array::from_fn(|k| {
        fix.altitude_bias_sensitivity[k] - reference.altitude_bias_sensitivity[k]
    });
    let jz_v = Vector2::from(jz);
    let persistent_z_var = msg.altitude_std_error_m.powi(2) + jz_v.dot(&(biases.covariance * jz_v));
    if !persistent_xy.iter().all(|v| v.is_finite()) || !persistent_z_var.is_finite() {
        return Err("non_finite_result");
    }
    Ok(OtherFix {
        position,
        covariance_xy: target_xy + fix.covariance_xy_given_biases,
        covariance_xy_given_biases: target_xy + fix.covariance_xy_given_biases,
        bias_sensitivity: j,
        persistent_xy,
        altitude_bias_sensitivity: jz,
        persistent_z_var,
        // The difference's own scatter: both windows' (eq. 22). The target's altitude
        // error is in every fix alike and stated apart (`persistent_z_var`); counted
        // here too, a track averaged its fixes as if each were that noisy and kept
        // the target's early error for seconds.
        altitude_std_error_m: fix
            .altitude_std_error_m
            .hypot(reference.altitude_std_error_m),
        reference_z: Some(msg.position[2]),
        colour_bgr: Some(colour_of(other)),
        as_stated: false,
    })
}

/// A vehicle's colour: its two views' mean (BGR).
fn colour_of(other: &OtherTarget) -> [f64; 3] {
    std::array::from_fn(|c| (f64::from(other.bgr[0][c]) + f64::from(other.bgr[1][c])) / 2.0)
}

/// Each other vehicle of `set` relative to the target's detection, (x, y) m, both
/// located with `biases` through the same images (`target_identity.rs`); one that
/// cannot be located is left out.
pub fn relative_offsets(
    set: &ObservationSetMsg,
    biases: &SharedBiases,
    config: &EstimatorConfig,
) -> Vec<[f64; 2]> {
    set.others()
        .iter()
        .filter_map(|other| {
            let (theirs, target) = observations_of(set, other, None, true)?;
            let a = locate_with_biases(&theirs, biases, config).ok()?;
            let b = locate_with_biases(&target, biases, config).ok()?;
            let d = a.position - b.position;
            (d.x.is_finite() && d.y.is_finite()).then_some([d.x, d.y])
        })
        .collect()
}

/// Which vehicle the target's detections of `set` are, as the other vehicles of the
/// pair place them against the tracks (`target_identity.rs`): `Some(id)` when they
/// are track `id`'s. `None` before the filter has started.
pub fn detection_identity(
    set: &ObservationSetMsg,
    temporal: &TemporalEstimator,
    tracks: &Tracks,
    check: &mut IdentityCheck,
    config: &EstimatorConfig,
) -> Option<u32> {
    let prior = temporal.predict_target(set.t_s)?;
    // Only with both biases known (module docs of `target_identity`).
    let limit = config
        .temporal
        .converged_bias_sigma_deg
        .to_radians()
        .powi(2);
    let c = &prior.yaw_bias_covariance;
    if !(c[(0, 0)] <= limit && c[(1, 1)] <= limit) {
        check.clear();
        return None;
    }
    let biases = SharedBiases {
        mean: prior.yaw_bias,
        covariance: prior.yaw_bias_covariance,
    };
    let offsets = relative_offsets(set, &biases, config);
    let predictions = tracks.predictions(set.t_s);
    check.see_at(
        set.t_s,
        &log_likelihood_ratios(&prior, &predictions, &offsets),
    )
}

/// Locates the other vehicles of `set`, updates `tracks` and writes the confirmed
/// tracks into `msg` (the target's estimate of the same pair). When the set's target
/// detections are another vehicle's or two vehicles (`trusted` false:
/// `detection_identity`, a refused set), the others are not located (their positions
/// relative to that vehicle would be put about the target's): the tracks coast, a
/// pair without fixes (counted `others_skipped`). (Left untouched instead, no miss
/// counted against them, `multi_town` seed 5's target was located in 79 % of its
/// pairs instead of 96 %: the filter coasted 2 s and then took the look-alike; why
/// the untouched tracks did that was not traced.)
pub fn add_tracks(
    set: &ObservationSetMsg,
    msg: &mut EstimateMsg,
    tracks: &mut Tracks,
    config: &EstimatorConfig,
    stats: &mut StageStats,
    trusted: bool,
    pose_errors: Option<&ImagePoseErrors>,
) {
    let others = set.others();
    if !trusted && !others.is_empty() {
        stats.count("others_skipped", others.len() as u64);
    }
    let biases = if trusted { biases_of(msg) } else { None };
    let mut fixes: Vec<OtherFix> = Vec::with_capacity(others.len());
    match biases {
        // A skipped pair's vehicles are counted `others_skipped` above, not here.
        None if trusted && !others.is_empty() => stats.count("others_no_biases", 1),
        None => {}
        Some(b) => {
            for other in others {
                let located = locate_relative(set, other, msg, &b, pose_errors, config);
                keep_fix(located, set.pair_seq, false, &mut fixes, stats);
            }
        }
    }
    let target =
        (msg.status == EstimateStatus::Ok as u32).then_some([msg.position[0], msg.position[1]]);
    let reports = tracks.update(set.t_s, &fixes, target);
    put_reports(msg, &reports, tracks, stats);
}

/// Keeps a vehicle's fix (counted `others_located`, and `others_unseen_located` when
/// located `alone`), or counts why it has none (`others_rejected.<kind>`).
fn keep_fix(
    located: Result<OtherFix, &'static str>,
    pair: u64,
    alone: bool,
    fixes: &mut Vec<OtherFix>,
    stats: &mut StageStats,
) {
    match located {
        Ok(fix) => {
            stats.count("others_located", 1);
            if alone {
                stats.count("others_unseen_located", 1);
            }
            tracing::debug!(
                pair,
                x = fix.position.x,
                y = fix.position.y,
                z = fix.position.z,
                h_acc = fix.covariance_xy.trace().sqrt(),
                alone,
                "other vehicle located"
            );
            fixes.push(fix);
        }
        Err(kind) => stats.count(&format!("others_rejected.{kind}"), 1),
    }
}

/// Vehicle `other` located alone through the images of `set` (a pair without the
/// target), with the filter's predicted `biases` and each past image's pose error
/// as the filter's last update estimated it removed (`pose_errors`, the keyframes'
/// only: the current images' are not known without an update). One window,
/// nothing to cancel the images' GPS and attitude errors against: on `multi_crawl`
/// held-out seed 9 (the target hidden 7 s) such fixes scattered 3–5 m about the
/// truth, as one window of the paper's method does under its Table 2 noise. Its
/// covariance says so (h_acc 3–4 m there) and the tracks take it as stated
/// (`OtherFix::as_stated`). (Through the past images whose errors the filter knew
/// alone, leaving out the current pair's unknown ones: no better on seeds 7–9.)
fn locate_alone(
    set: &ObservationSetMsg,
    other: &OtherTarget,
    biases: &SharedBiases,
    pose_errors: Option<&ImagePoseErrors>,
    config: &EstimatorConfig,
) -> Result<OtherFix, &'static str> {
    let (theirs, _) = observations_of(set, other, pose_errors, false).ok_or("bad_input")?;
    let fix = locate_with_biases(&theirs, biases, config).map_err(|e| e.kind())?;
    Ok(OtherFix {
        colour_bgr: Some(colour_of(other)),
        ..fix
    })
}

/// The tracks of a pair whose target a camera's detector did not find
/// (`ObservationSetMsg::TARGET_UNSEEN`: under a bridge, say). The other vehicles
/// matching paired on it (through its past images, fitted without the target) are
/// located alone ([`locate_alone`]) with the biases the filter predicts, once they are
/// known (1σ within `converged_bias_sigma_deg`, as the identity check asks), and the
/// tracks take them; without any, each reported track is its prediction
/// (`Tracks::coasted`, which changes nothing). The target's filter is not touched and
/// its estimate stays rejected. Counted as on any pair (`others_located`,
/// `others_rejected.<kind>`), and `others_unseen_located`.
pub fn add_unseen_tracks(
    set: &ObservationSetMsg,
    msg: &mut EstimateMsg,
    tracks: &mut Tracks,
    temporal: Option<&TemporalEstimator>,
    config: &EstimatorConfig,
    stats: &mut StageStats,
) {
    let limit = config
        .temporal
        .converged_bias_sigma_deg
        .to_radians()
        .powi(2);
    let biases = temporal
        .and_then(|t| t.predict_target(set.t_s))
        .filter(|p| {
            let c = &p.yaw_bias_covariance;
            c[(0, 0)] <= limit && c[(1, 1)] <= limit
        })
        .map(|p| SharedBiases {
            mean: p.yaw_bias,
            covariance: p.yaw_bias_covariance,
        });
    let (Some(biases), false) = (biases, set.others().is_empty()) else {
        add_coasted_tracks(set.t_s, msg, tracks, stats);
        return;
    };
    let pose_errors = temporal.and_then(TemporalEstimator::last_pose_errors);
    let mut fixes = Vec::with_capacity(set.others().len());
    for other in set.others() {
        let located = locate_alone(set, other, &biases, pose_errors, config);
        keep_fix(located, set.pair_seq, true, &mut fixes, stats);
    }
    // No fix: the tracks coast, as on a pair without vehicles (an update without
    // fixes would count a miss against each).
    if fixes.is_empty() {
        add_coasted_tracks(set.t_s, msg, tracks, stats);
        return;
    }
    let reports = tracks.update(set.t_s, &fixes, None);
    put_reports(msg, &reports, tracks, stats);
}

/// The tracks of a pair whose target a camera's detector did not find and on which
/// no vehicle can be located: each reported track is its prediction
/// (`Tracks::coasted`, which changes nothing), and the target's estimate stays
/// rejected.
pub fn add_coasted_tracks(
    t_s: f64,
    msg: &mut EstimateMsg,
    tracks: &mut Tracks,
    stats: &mut StageStats,
) {
    let reports = tracks.coasted(t_s);
    put_reports(msg, &reports, tracks, stats);
}

/// `reports` into `msg` (at most its room), with the tracks' counts since the last
/// call.
fn put_reports(
    msg: &mut EstimateMsg,
    reports: &[TrackReport],
    tracks: &mut Tracks,
    stats: &mut StageStats,
) {
    let c = tracks.take_counts();
    for (name, n) in [
        ("tracks_confirmed", c.confirmed),
        ("tracks_deleted", c.deleted),
        ("tracks_tentative_dropped", c.tentative_dropped),
        ("tracks_reacquired", c.reacquired),
        ("tracks_reidentified", c.reidentified),
        ("tracks_unreported_static", c.unreported_static),
        ("tracks_target_fixes", c.target_fixes),
    ] {
        if n > 0 {
            stats.count(name, n);
        }
    }
    msg.track_count = 0;
    for (slot, r) in msg.tracks.iter_mut().zip(reports.iter().take(MAX_TRACKS)) {
        let cov = r.covariance_xy;
        *slot = TrackEstimate {
            id: r.id,
            quality: match r.quality {
                TrackQuality::Tracking => 1,
                TrackQuality::Coasting => 2,
            },
            position: r.position,
            covariance_xy: [cov[(0, 0)], cov[(0, 1)], cov[(1, 0)], cov[(1, 1)]],
            altitude_std_error_m: r.altitude_std_m,
            velocity_mps: r.velocity_mps,
        };
    }
    // A track with a non-finite value is left out (counted), the rest close up.
    let mut kept = 0;
    for i in 0..reports.len().min(MAX_TRACKS) {
        let slot = msg.tracks[i];
        let finite = slot
            .position
            .iter()
            .chain(&slot.covariance_xy)
            .chain(&slot.velocity_mps)
            .all(|v| v.is_finite())
            && slot.altitude_std_error_m.is_finite();
        if finite {
            msg.tracks[kept] = slot;
            kept += 1;
        } else {
            stats.count("tracks_non_finite", 1);
        }
    }
    for slot in &mut msg.tracks[kept..] {
        *slot = TrackEstimate::default();
    }
    msg.track_count = kept as u64;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{NavNoise, SyntheticScenario};
    use crate::tracks::TrackConfig;
    use rand::SeedableRng;

    /// A set whose target and one other vehicle are the same synthetic trial moved by
    /// `offset` metres east: the other vehicle's pixels are its projections.
    fn set_and_truth(
        t_s: f64,
    ) -> (
        ObservationSetMsg,
        nalgebra::Point3<f64>,
        nalgebra::Point3<f64>,
    ) {
        let s = SyntheticScenario {
            noise: NavNoise::NONE,
            ..SyntheticScenario::default()
        };
        let trial = s
            .trial(t_s, 4, &mut rand::rngs::StdRng::seed_from_u64(3))
            .unwrap();
        let mut set = ObservationSetMsg {
            t_s,
            ..Default::default()
        };
        let offset = nalgebra::Vector3::new(6.0, 0.0, 0.0);
        let other_point = trial.target + offset;
        let mut other = OtherTarget::default();
        for (i, (slot, o)) in set.entries.iter_mut().zip(&trial.observations).enumerate() {
            *slot = o.to_entry();
            slot.frame_seq = i as u64;
            slot.t_s = t_s;
            set.count += 1;
            // The true camera (the measured attitude minus its bias) sees the point.
            let mut attitude = o.attitude;
            attitude.yaw -= trial.yaw_bias[o.uav.index()];
            let cam = shared_types::conventions::camera_to_world(attitude).transpose()
                * (other_point - o.position);
            let px = o.intrinsics.project(cam).unwrap();
            if i < 2 {
                other.current[i] = [px.x, px.y];
            } else {
                other.past[i - 2] = [px.x, px.y];
                other.past_valid |= 1 << (i - 2);
            }
        }
        set.others[0] = other;
        set.other_count = 1;
        (set, other_point, trial.target)
    }

    #[test]
    fn another_vehicle_is_located_with_the_targets_biases_and_tracked() {
        let (set, truth, target) = set_and_truth(6.0);
        let trial_bias = {
            let s = SyntheticScenario::default();
            s.bias.at(6.0).map(f64::to_degrees)
        };
        // The synthetic vehicle stands still: every confirmed track is reported.
        let every = TrackConfig {
            min_speed_mps: 0.0,
            ..TrackConfig::default()
        };
        let mut tracks = Tracks::new(every).unwrap();
        let mut stats = StageStats::new("t");
        let config = EstimatorConfig::default();
        let mut last = EstimateMsg::default();
        for k in 0..4 {
            // The target's estimate 0.5 m east of the target: the vehicle, located
            // relative to it, is 0.5 m east of where it is too.
            let mut msg = EstimateMsg {
                t_s: 6.0 + k as f64 / 30.0,
                yaw_bias_deg: trial_bias,
                position: [target.x + 0.5, target.y, target.z],
                ..Default::default()
            };
            msg.covariance[10] = 0.01_f64.to_radians().powi(2);
            msg.covariance[15] = 0.01_f64.to_radians().powi(2);
            let mut set = set;
            set.t_s = msg.t_s;
            add_tracks(&set, &mut msg, &mut tracks, &config, &mut stats, true, None);
            last = msg;
        }
        assert_eq!(stats.counter("others_located"), 4);
        assert_eq!(last.tracks().len(), 1);
        let t = last.tracks()[0];
        assert_eq!((t.id, t.quality), (1, 1));
        assert!(
            (t.position[0] - 0.5 - truth.x).abs() < 0.3,
            "{t:?} vs {truth}"
        );
        assert!((t.position[1] - truth.y).abs() < 0.3, "{t:?} vs {truth}");
    }

    /// Past images whose measured poses erred (3° of yaw, 2° of pitch, 2 m east)
    /// move another vehicle's fix relative to the target (the two do not see the
    /// error alike); with that error as the target's filter estimated it removed
    /// (`ImagePoseErrors`), the fix is where it is without the error.
    #[test]
    fn a_past_images_pose_error_known_to_the_filter_is_removed_from_the_fix() {
        let (mut set, truth, target) = set_and_truth(6.0);
        let trial_bias = SyntheticScenario::default().bias.at(6.0);
        let biases = SharedBiases {
            mean: trial_bias,
            covariance: Matrix2::identity() * 0.01_f64.to_radians().powi(2),
        };
        let msg = EstimateMsg {
            t_s: 6.0,
            yaw_bias_deg: trial_bias.map(f64::to_degrees),
            position: [target.x, target.y, target.z],
            ..Default::default()
        };
        let config = EstimatorConfig::default();
        let exact = locate_relative(&set, &set.others[0], &msg, &biases, None, &config).unwrap();
        assert!((exact.position - truth).xy().norm() < 0.3, "{exact:?}");
        let off = |fix: &OtherFix| (fix.position - exact.position).xy().norm();
        let e = [
            2.0,
            0.0,
            0.0,
            3.0_f64.to_radians(),
            2.0_f64.to_radians(),
            0.0,
        ];
        let mut past = Vec::new();
        for k in 2..set.entries().len() {
            let pose = &mut set.entries[k].pose;
            pose.x_m += e[0];
            pose.yaw_deg += e[3].to_degrees();
            pose.pitch_deg += e[4].to_degrees();
            let uav = Observation::from_entry(&set.entries[k], k).unwrap().uav;
            past.push(((uav, set.entries[k].frame_seq), e));
        }
        let erred = locate_relative(&set, &set.others[0], &msg, &biases, None, &config).unwrap();
        let known = ImagePoseErrors {
            t_s: 6.0,
            current: [None; 2],
            past,
        };
        let corrected =
            locate_relative(&set, &set.others[0], &msg, &biases, Some(&known), &config).unwrap();
        assert!(off(&erred) > 0.1, "{}", off(&erred));
        assert!(off(&corrected) < 0.01, "{}", off(&corrected));
    }

    /// A pair without the target (`TARGET_UNSEEN`, the entries' target pixels (0, 0),
    /// never read): the other vehicle located alone through the same images with the
    /// true biases is where it is; past images whose poses erred move it, and with
    /// their errors as the filter estimated them removed it is back. Without a filter
    /// (biases unknown) nothing is located and the tracks coast.
    #[test]
    fn a_vehicle_is_located_alone_when_the_target_is_unseen() {
        let (mut set, truth, _) = set_and_truth(6.0);
        set.refused = ObservationSetMsg::TARGET_UNSEEN;
        for e in set.entries.iter_mut() {
            e.pixel = [0.0; 2];
        }
        let biases = SharedBiases {
            mean: SyntheticScenario::default().bias.at(6.0),
            covariance: Matrix2::identity() * 0.01_f64.to_radians().powi(2),
        };
        let config = EstimatorConfig::default();
        let exact = locate_alone(&set, &set.others[0], &biases, None, &config).unwrap();
        assert!((exact.position - truth).xy().norm() < 0.3, "{exact:?}");
        assert!(exact.as_stated && exact.reference_z.is_none());
        let e = [
            1.5,
            -1.0,
            0.0,
            2.0_f64.to_radians(),
            0.0,
            1.0_f64.to_radians(),
        ];
        let mut past = Vec::new();
        for k in 2..set.entries().len() {
            let pose = &mut set.entries[k].pose;
            pose.x_m += e[0];
            pose.y_m += e[1];
            pose.yaw_deg += e[3].to_degrees();
            pose.roll_deg += e[5].to_degrees();
            let uav = Observation::from_entry(&set.entries[k], k).unwrap().uav;
            past.push(((uav, set.entries[k].frame_seq), e));
        }
        let off = |fix: &OtherFix| (fix.position - exact.position).xy().norm();
        let erred = locate_alone(&set, &set.others[0], &biases, None, &config).unwrap();
        // The current images' errors are not known without an update: only the past
        // images' are taken (these `current` would move it if they were).
        let known = ImagePoseErrors {
            t_s: 5.0,
            current: [Some([5.0, 0.0, 0.0, 0.0, 0.0, 0.0]); 2],
            past,
        };
        let corrected = locate_alone(&set, &set.others[0], &biases, Some(&known), &config).unwrap();
        assert!(off(&erred) > 0.3, "{}", off(&erred));
        assert!(off(&corrected) < 0.01, "{}", off(&corrected));

        let mut tracks = Tracks::new(TrackConfig::default()).unwrap();
        let mut stats = StageStats::new("t");
        let mut msg = EstimateMsg::default();
        add_unseen_tracks(&set, &mut msg, &mut tracks, None, &config, &mut stats);
        assert_eq!(stats.counter("others_located"), 0);
        assert_eq!(msg.track_count, 0);
    }

    #[test]
    fn without_a_target_estimate_or_with_a_bad_pixel_nothing_is_located() {
        let (mut set, _, _) = set_and_truth(6.0);
        let mut tracks = Tracks::new(TrackConfig::default()).unwrap();
        let mut stats = StageStats::new("t");
        let config = EstimatorConfig::default();
        let mut msg = EstimateMsg {
            status: EstimateStatus::Rejected as u32,
            ..Default::default()
        };
        add_tracks(&set, &mut msg, &mut tracks, &config, &mut stats, true, None);
        assert_eq!(stats.counter("others_no_biases"), 1);
        let mut msg = EstimateMsg::default();
        set.others[0].current[1][0] = f64::NAN;
        add_tracks(&set, &mut msg, &mut tracks, &config, &mut stats, true, None);
        assert_eq!(stats.counter("others_rejected.bad_input"), 1);
        assert_eq!(msg.track_count, 0);
    }
}
