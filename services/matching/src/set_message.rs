//! Matching's answer for one pair as the [`ObservationSetMsg`] geolocation receives:
//! the matching service publishes it, and `dualgeo evaluate`'s in-process chain builds
//! the same message so that its geolocation is the service's own
//! (`geolocation::geolocator`).

use crate::chain::OthersOutcome;
use crate::chain::{MatchedSet, UnseenSet};
use geolocation::Observation;
use shared_types::messages::{
    ObservationSetMsg, OtherTarget, PoseNoise, MAX_OBSERVATIONS, MAX_OTHER_TARGETS,
};

/// What every set of one pair carries besides its observations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetHeader {
    pub pair_seq: u64,
    /// The earlier of the two frames' capture times, ns.
    pub capture_ns: u64,
    /// The left frame's stream time, s.
    pub t_s: f64,
    /// Past images the chain rejected for this pair.
    pub rejected_past: u32,
    /// The frames' stream segment.
    pub segment: u32,
    /// The current (left, right) frames' (seq, stream time).
    pub frames: [(u64, f64); 2],
    /// Each UAV's pose-sample noise so far ([`crate::VisionChain::pose_noise`]).
    pub pose_noise: [PoseNoise; 2],
}

impl SetHeader {
    fn message(&self, refused: u32) -> ObservationSetMsg {
        ObservationSetMsg {
            pair_seq: self.pair_seq,
            capture_ns: self.capture_ns,
            t_s: self.t_s,
            rejected_past: self.rejected_past,
            segment: self.segment,
            refused,
            pose_noise: self.pose_noise,
            ..Default::default()
        }
    }
}

/// A pair refused as two vehicles (`chain::target_pair`): the current images only,
/// marked `refused` (geolocation publishes the filter's prediction for it).
pub fn refused_set(header: &SetHeader, current: &[Observation; 2]) -> ObservationSetMsg {
    let mut msg = header.message(ObservationSetMsg::REFUSED_TWO_VEHICLES);
    fill_entries(&mut msg, current.iter().zip(header.frames));
    msg
}

/// A pair without the target's detection in one of its images: no entries, marked
/// `TARGET_UNSEEN` (geolocation reports the other vehicles' tracks for it; without it
/// they went unreported for as long as the target was hidden).
pub fn unseen_set(header: &SetHeader) -> ObservationSetMsg {
    header.message(ObservationSetMsg::TARGET_UNSEEN)
}

/// A pair without the target's detection whose past images were fitted all the same
/// and whose other vehicles were paired (`others`, not empty): marked
/// `TARGET_UNSEEN`, with its images as entries (the target's pixels (0, 0), unknown:
/// geolocation reads only the vehicles') and the vehicles. Without vehicles,
/// [`unseen_set`].
pub fn unseen_set_with_others(
    header: &SetHeader,
    unseen: &UnseenSet,
    others: &OthersOutcome,
) -> ObservationSetMsg {
    if others.targets.is_empty() {
        return unseen_set(header);
    }
    ObservationSetMsg {
        refused: ObservationSetMsg::TARGET_UNSEEN,
        ..matched_set(header, &unseen.set, others)
    }
}

/// A matched pair: its current and past observations and the other vehicles paired
/// across it (`others`, as many as the message has room for: `others_dropped` counts
/// the rest).
pub fn matched_set(
    header: &SetHeader,
    matched: &MatchedSet,
    others: &OthersOutcome,
) -> ObservationSetMsg {
    let mut msg = header.message(0);
    put_others(others, &mut msg);
    let frames = header
        .frames
        .into_iter()
        .chain(matched.past.iter().map(|p| (p.seq, p.t_s)));
    fill_entries(
        &mut msg,
        matched
            .current
            .iter()
            .chain(&matched.past_observations)
            .zip(frames),
    );
    // Each past image's rotation from the current cameras, as the images measure it.
    let count = msg.count as usize;
    for (entry, p) in msg.entries[2..count.max(2)].iter_mut().zip(&matched.past) {
        for (side, r) in p.rotations.iter().enumerate() {
            if let Some(r) = r {
                let v = nalgebra::Rotation3::from_matrix(r).scaled_axis();
                if v.iter().all(|x| x.is_finite()) {
                    entry.rotation[side] = [v.x, v.y, v.z];
                    entry.rotation_valid |= 1 << side;
                }
            }
        }
    }
    msg
}

/// The other vehicles into `msg`, as many as fit (`others_dropped` the rest).
fn put_others(outcome: &OthersOutcome, msg: &mut ObservationSetMsg) {
    let kept = outcome.targets.len().min(MAX_OTHER_TARGETS);
    msg.others_dropped = (outcome.targets.len() - kept) as u32;
    for (slot, t) in msg.others.iter_mut().zip(&outcome.targets) {
        *slot = OtherTarget {
            current: t.current,
            bgr: t.bgr,
            ..OtherTarget::default()
        };
        for (k, p) in t.past.iter().enumerate().take(MAX_OBSERVATIONS - 2) {
            if let Some(p) = p {
                slot.past[k] = *p;
                slot.past_valid |= 1 << k;
            }
        }
    }
    msg.other_count = kept as u32;
}

/// `observations`, each with its frame's (seq, capture time), into `msg`'s entries:
/// as many as fit.
fn fill_entries<'a>(
    msg: &mut ObservationSetMsg,
    observations: impl Iterator<Item = (&'a Observation, (u64, f64))>,
) {
    for (slot, (o, (seq, t_s))) in msg
        .entries
        .iter_mut()
        .zip(observations)
        .take(MAX_OBSERVATIONS)
    {
        *slot = o.to_entry();
        slot.frame_seq = seq;
        slot.t_s = t_s;
        msg.count += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chain::{OtherPixels, PastMatch};
    use nalgebra::{Matrix3, Point3, Vector2};
    use shared_types::conventions::{Attitude, Intrinsics, Uav};

    fn observation(uav: Uav, u: f64) -> Observation {
        Observation {
            uav,
            position: Point3::new(u, 2.0, 100.0),
            attitude: Attitude {
                yaw: 0.1,
                pitch: 0.0,
                roll: 0.0,
            },
            mount: shared_types::conventions::Mount::NADIR,
            pixel: Vector2::new(u, 240.0),
            intrinsics: Intrinsics {
                fx: 500.0,
                fy: 500.0,
                cx: 320.0,
                cy: 240.0,
            },
        }
    }

    fn header() -> SetHeader {
        SetHeader {
            pair_seq: 9,
            capture_ns: 5,
            t_s: 1.5,
            rejected_past: 1,
            segment: 2,
            frames: [(9, 1.5), (9, 1.51)],
            pose_noise: [
                PoseNoise {
                    sigma: [3.1, 2.9, 3.0, 2.1, 1.9, 2.0],
                    mean_step_s: 1.0 / 30.0,
                    chords: 40,
                    _reserved: 0,
                },
                PoseNoise::default(),
            ],
        }
    }

    fn past(uav: Uav, seq: u64) -> PastMatch {
        PastMatch {
            uav,
            seq,
            t_s: seq as f64 / 10.0,
            pixel: [0.0; 2],
            inliers: [0; 2],
            fundamental: [Matrix3::identity(); 2],
            models: [None; 2],
            rotations: [None; 2],
            guided: [false; 2],
            chained: [false; 2],
        }
    }

    /// A set of the current pair and `past`, each past image with its observation.
    fn matched(past: Vec<(Observation, PastMatch)>) -> MatchedSet {
        let (past_observations, past) = past.into_iter().unzip();
        MatchedSet {
            current: [
                observation(Uav::Left, 300.0),
                observation(Uav::Right, 310.0),
            ],
            past_observations,
            past,
            mended: None,
        }
    }

    #[test]
    fn a_matched_set_carries_every_image_and_the_other_vehicles() {
        // The right UAV's past image carries its rotation from the current left camera
        // (the images' measure of it), and none from the right one.
        let turned = nalgebra::Rotation3::from_euler_angles(0.01, -0.02, 0.3);
        let mut right = past(Uav::Right, 4);
        right.rotations[0] = Some(turned.into_inner());
        let matched = matched(vec![
            (observation(Uav::Left, 200.0), past(Uav::Left, 3)),
            (observation(Uav::Right, 210.0), right),
        ]);
        let others = OthersOutcome {
            targets: vec![OtherPixels {
                current: [[1.0, 2.0], [3.0, 4.0]],
                past: vec![None, Some([5.0, 6.0])],
                bgr: [[1, 2, 3], [4, 5, 6]],
            }],
            ..Default::default()
        };
        let msg = matched_set(&header(), &matched, &others);
        assert_eq!((msg.pair_seq, msg.refused, msg.segment), (9, 0, 2));
        assert_eq!((msg.rejected_past, msg.capture_ns, msg.t_s), (1, 5, 1.5));
        assert_eq!(msg.pose_noise, header().pose_noise);
        assert_eq!(msg.count, 4);
        let e = msg.entries();
        assert_eq!(
            e.iter().map(|e| (e.frame_seq, e.t_s)).collect::<Vec<_>>(),
            vec![(9, 1.5), (9, 1.51), (3, 0.3), (4, 0.4)]
        );
        assert_eq!(e[2].pixel, [200.0, 240.0]);
        assert_eq!((e[2].rotation_from(0), e[2].rotation_from(1)), (None, None));
        let v = e[3]
            .rotation_from(0)
            .expect("the rotation from the left camera");
        assert!((nalgebra::Vector3::from(v) - turned.scaled_axis()).norm() < 1e-12);
        assert_eq!(e[3].rotation_from(1), None);
        assert_eq!((msg.other_count, msg.others_dropped), (1, 0));
        let o = msg.others()[0];
        assert_eq!(o.current, [[1.0, 2.0], [3.0, 4.0]]);
        assert_eq!((o.past_pixel(0), o.past_pixel(1)), (None, Some([5.0, 6.0])));
    }

    #[test]
    fn others_beyond_the_room_are_counted_dropped() {
        let matched = matched(Vec::new());
        let others = OthersOutcome {
            targets: vec![
                OtherPixels {
                    current: [[1.0, 2.0]; 2],
                    past: Vec::new(),
                    bgr: [[0; 3]; 2],
                };
                MAX_OTHER_TARGETS + 3
            ],
            ..Default::default()
        };
        let msg = matched_set(&header(), &matched, &others);
        assert_eq!(msg.other_count as usize, MAX_OTHER_TARGETS);
        assert_eq!(msg.others_dropped, 3);
    }

    #[test]
    fn a_refused_set_holds_the_current_images_marked_refused() {
        let current = [
            observation(Uav::Left, 300.0),
            observation(Uav::Right, 310.0),
        ];
        let msg = refused_set(&header(), &current);
        assert_eq!((msg.refused, msg.count, msg.other_count), (1, 2, 0));
        assert_eq!(msg.entries()[1].frame_seq, 9);
        assert_eq!(msg.entries()[1].uav, 1);
        // Geolocation raises its σ's from it on refused sets too.
        assert_eq!(msg.pose_noise, header().pose_noise);
    }
}
