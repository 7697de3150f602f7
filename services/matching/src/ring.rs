//! One UAV's keyframe ring: frames admitted by the paper's baseline constraint (the UAV
//! moved at least T_re since the last admitted frame), evicted oldest first at capacity.

use crate::features::Features;
use nalgebra::Point3;
use shared_types::conventions::Intrinsics;
use shared_types::lens::Distortion;
use shared_types::messages::PoseSample;
use std::collections::VecDeque;
use std::sync::Arc;

/// A past frame: its measured state and its ORB features (no pixels).
#[derive(Debug, Clone)]
pub struct Keyframe {
    pub seq: u64,
    pub t_s: f64,
    /// Measured pose (GPS + AHRS), as the estimator will use it.
    pub pose: PoseSample,
    /// Where the baseline constraint measures this frame from: the UAV's measured
    /// positions smoothed over time (`VisionChain`), so GPS noise does not decide which
    /// frames are T_re apart.
    pub baseline_position: Point3<f64>,
    pub intrinsics: Intrinsics,
    /// The lens: the transferred target pixel must fall inside the *distorted* frame.
    pub distortion: Distortion,
    pub width: u32,
    pub height: u32,
    pub features: Arc<Features>,
}

fn distance(a: &Point3<f64>, b: &Point3<f64>) -> f64 {
    (a - b).norm()
}

#[derive(Debug)]
pub struct KeyframeRing {
    capacity: usize,
    spacing_m: f64,
    frames: VecDeque<Keyframe>,
}

impl KeyframeRing {
    pub fn new(capacity: usize, spacing_m: f64) -> Self {
        Self {
            capacity: capacity.max(1),
            spacing_m,
            frames: VecDeque::with_capacity(capacity.max(1)),
        }
    }

    /// Admits `frame` if the ring is empty or the UAV moved at least T_re since the last
    /// admitted frame; evicts the oldest when full. Returns whether it was admitted.
    pub fn offer(&mut self, frame: Keyframe) -> bool {
        if !self.would_admit(&frame.baseline_position) {
            return false;
        }
        if self.frames.len() == self.capacity {
            self.frames.pop_front();
        }
        self.frames.push_back(frame);
        true
    }

    /// Whether [`KeyframeRing::offer`] would admit a frame measured from `position`.
    pub fn would_admit(&self, position: &Point3<f64>) -> bool {
        self.frames
            .back()
            .is_none_or(|last| distance(&last.baseline_position, position) >= self.spacing_m)
    }

    /// Up to `count` past keyframes for a geolocation at `current`, newest first, each at
    /// least T_re from the one chosen before it (the first from `current`): the baseline
    /// constraint between adjacent images of Section 2.2.
    pub fn select(&self, current: &Point3<f64>, current_seq: u64, count: usize) -> Vec<&Keyframe> {
        let mut chosen: Vec<&Keyframe> = Vec::with_capacity(count);
        let mut from = *current;
        for kf in self.frames.iter().rev() {
            if chosen.len() == count {
                break;
            }
            if kf.seq >= current_seq || distance(&from, &kf.baseline_position) < self.spacing_m {
                continue;
            }
            from = kf.baseline_position;
            chosen.push(kf);
        }
        chosen
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    pub fn iter(&self) -> impl Iterator<Item = &Keyframe> {
        self.frames.iter()
    }

    /// The newest keyframe (the one an admitting `offer` just added).
    pub fn newest(&self) -> Option<&Keyframe> {
        self.frames.back()
    }

    /// Puts back a keyframe of a checkpointed ring (oldest first), without the baseline
    /// check: the ring that saved it had already admitted it.
    pub fn push_restored(&mut self, frame: Keyframe) {
        if self.frames.len() == self.capacity {
            self.frames.pop_front();
        }
        self.frames.push_back(frame);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kf(seq: u64, x: f64) -> Keyframe {
        Keyframe {
            seq,
            t_s: seq as f64,
            pose: PoseSample {
                x_m: x,
                ..Default::default()
            },
            baseline_position: Point3::new(x, 0.0, 0.0),
            intrinsics: Intrinsics::new(500.0, 500.0, 320.0, 240.0),
            distortion: Distortion::NONE,
            width: 640,
            height: 480,
            features: Arc::new(Features::default()),
        }
    }

    #[test]
    fn admits_by_baseline_and_evicts_by_capacity() {
        let mut ring = KeyframeRing::new(3, 5.0);
        assert!(ring.offer(kf(0, 0.0)));
        assert!(!ring.offer(kf(1, 4.9)), "moved less than T_re");
        assert!(ring.offer(kf(2, 5.0)));
        assert!(ring.offer(kf(3, 11.0)));
        assert!(ring.offer(kf(4, 16.5)));
        assert_eq!(ring.len(), 3);
        assert_eq!(
            ring.iter().map(|k| k.seq).collect::<Vec<_>>(),
            vec![2, 3, 4],
            "oldest evicted"
        );
    }

    #[test]
    fn selection_keeps_the_baseline_between_neighbours() {
        let mut ring = KeyframeRing::new(10, 2.0);
        for (seq, x) in [(0, 0.0), (1, 2.0), (2, 4.5), (3, 7.0), (4, 9.0), (5, 11.0)] {
            assert!(ring.offer(kf(seq, x)));
        }
        let current = Point3::new(12.0, 0.0, 0.0);
        // From x = 12: 11 is too close; 9 (3 m) ok; 7 (2 m from 9) ok; 4.5 ok.
        let picked: Vec<u64> = ring.select(&current, 6, 3).iter().map(|k| k.seq).collect();
        assert_eq!(picked, vec![4, 3, 2]);
        // The current frame itself (same seq) is never its own past image.
        assert!(ring
            .select(&Point3::new(20.0, 0.0, 0.0), 5, 1)
            .iter()
            .all(|k| k.seq < 5));
    }
}
