//! The keyframe rings as plain data (issue #13), so a restarted matching service does
//! not wait for the UAVs to fly N − 1 baselines again before its first estimate
//! (3 × T_re = 24 m at the defaults, ~1.5–2.5 s of flight). The service writes one
//! file per admitted keyframe (its features, ~60 kB at 1 500 keypoints) and a small
//! index (which keyframes, oldest first, and the smoothed positions of the baseline
//! ruler); a restarted service reads them back. Guided-matching priors are not kept:
//! the first match of each keyframe after a restart is unguided.

use crate::chain::VisionChain;
use crate::features::Features;
use crate::hamming::Descriptor;
use crate::ring::Keyframe;
use nalgebra::Point3;
use opencv::core as cv;
use shared_types::conventions::{Intrinsics, Uav};
use shared_types::lens::Distortion;
use shared_types::messages::{MountSample, PoseSample};
use std::sync::Arc;

/// One keyframe: its measured state and its features.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct KeyframeSnapshot {
    pub uav: u8,
    pub seq: u64,
    pub t_s: f64,
    /// x, y, z (m), yaw, pitch, roll (°), as measured.
    pub pose: [f64; 6],
    /// The camera's mount, yaw, pitch, roll (°) ([`MountSample`]).
    pub mount: [f64; 3],
    pub baseline_position: [f64; 3],
    pub intrinsics: Intrinsics,
    pub distortion: [f64; 5],
    pub width: u32,
    pub height: u32,
    pub points: Vec<[f32; 2]>,
    pub descriptors: Vec<Descriptor>,
}

/// Which keyframes each ring holds (oldest first) and the baseline ruler's state.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RingIndex {
    pub keyframes: [Vec<u64>; 2],
    /// Per UAV: (t, smoothed position).
    pub smoothed: [Option<(f64, [f64; 3])>; 2],
    /// The stream segment they are of (`FrameHeader::segment`): a restarted service
    /// whose first frame is of a later segment starts over.
    pub segment: u32,
}

impl KeyframeSnapshot {
    pub fn of(uav: Uav, kf: &Keyframe) -> Self {
        let p = kf.pose;
        Self {
            uav: uav.index() as u8,
            seq: kf.seq,
            t_s: kf.t_s,
            pose: [p.x_m, p.y_m, p.z_m, p.yaw_deg, p.pitch_deg, p.roll_deg],
            mount: [p.mount.yaw_deg, p.mount.pitch_deg, p.mount.roll_deg],
            baseline_position: kf.baseline_position.coords.into(),
            intrinsics: kf.intrinsics,
            distortion: kf.distortion.0,
            width: kf.width,
            height: kf.height,
            points: kf.features.points.iter().map(|p| [p.x, p.y]).collect(),
            descriptors: kf.features.descriptors.clone(),
        }
    }

    /// The keyframe, or why this snapshot cannot be one.
    pub fn keyframe(&self) -> Result<Keyframe, String> {
        let finite = self.t_s.is_finite()
            && self.pose.iter().all(|v| v.is_finite())
            && self.mount.iter().all(|v| v.is_finite())
            && self.baseline_position.iter().all(|v| v.is_finite())
            && self.distortion.iter().all(|v| v.is_finite())
            && self.points.iter().flatten().all(|v| v.is_finite());
        if !finite {
            return Err(format!("keyframe {}: a value is not finite", self.seq));
        }
        if self.points.len() != self.descriptors.len() {
            return Err(format!(
                "keyframe {}: {} points but {} descriptors",
                self.seq,
                self.points.len(),
                self.descriptors.len()
            ));
        }
        if self.width == 0 || self.height == 0 || self.width > 16_384 || self.height > 16_384 {
            return Err(format!(
                "keyframe {}: image size {}×{}",
                self.seq, self.width, self.height
            ));
        }
        let k = self.intrinsics;
        if ![k.fx, k.fy, k.cx, k.cy].iter().all(|v| v.is_finite()) || k.fx <= 0.0 || k.fy <= 0.0 {
            return Err(format!("keyframe {}: bad intrinsics", self.seq));
        }
        let [x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg] = self.pose;
        let points = self
            .points
            .iter()
            .map(|&[x, y]| cv::Point2f::new(x, y))
            .collect();
        Ok(Keyframe {
            seq: self.seq,
            t_s: self.t_s,
            pose: PoseSample {
                x_m,
                y_m,
                z_m,
                yaw_deg,
                pitch_deg,
                roll_deg,
                mount: MountSample {
                    yaw_deg: self.mount[0],
                    pitch_deg: self.mount[1],
                    roll_deg: self.mount[2],
                },
            },
            baseline_position: Point3::from(self.baseline_position),
            intrinsics: self.intrinsics,
            distortion: Distortion(self.distortion),
            width: self.width,
            height: self.height,
            features: Arc::new(Features::new(
                points,
                self.descriptors.clone(),
                self.width,
                self.height,
            )),
        })
    }
}

impl VisionChain {
    /// The newest keyframe of `uav`'s ring (after an admitting [`VisionChain::admit`]).
    pub fn newest_keyframe(&self, uav: Uav) -> Option<KeyframeSnapshot> {
        self.rings[uav.index()]
            .newest()
            .map(|kf| KeyframeSnapshot::of(uav, kf))
    }

    /// Keyframe `seq` of `uav`'s ring, if the ring holds it.
    pub fn keyframe_snapshot(&self, uav: Uav, seq: u64) -> Option<KeyframeSnapshot> {
        self.rings[uav.index()]
            .iter()
            .find(|kf| kf.seq == seq)
            .map(|kf| KeyframeSnapshot::of(uav, kf))
    }

    pub fn ring_index(&self) -> RingIndex {
        RingIndex {
            keyframes: [Uav::Left, Uav::Right]
                .map(|u| self.rings[u.index()].iter().map(|kf| kf.seq).collect()),
            smoothed: self.smoothed.map(|s| s.map(|(t, p)| (t, p.coords.into()))),
            segment: self.segment,
        }
    }

    /// Refills the rings from `index` and the keyframes it names (`load` reads one by
    /// UAV and sequence number). A keyframe that cannot be read or trusted ends its
    /// ring where it is (older ones stay). Returns the keyframes restored.
    pub fn restore_rings(
        &mut self,
        index: &RingIndex,
        mut load: impl FnMut(Uav, u64) -> Result<KeyframeSnapshot, String>,
    ) -> Result<usize, String> {
        let mut restored = 0;
        for uav in [Uav::Left, Uav::Right] {
            for &seq in &index.keyframes[uav.index()] {
                let snap = load(uav, seq)?;
                if snap.uav as usize != uav.index() || snap.seq != seq {
                    return Err(format!(
                        "keyframe file of {uav:?} {seq} holds another keyframe"
                    ));
                }
                self.rings[uav.index()].push_restored(snap.keyframe()?);
                restored += 1;
            }
            if let Some((t, p)) = index.smoothed[uav.index()] {
                if t.is_finite() && p.iter().all(|v| v.is_finite()) {
                    self.smoothed[uav.index()] = Some((t, Point3::from(p)));
                }
            }
        }
        self.segment = index.segment;
        Ok(restored)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn snapshot(seq: u64) -> KeyframeSnapshot {
        KeyframeSnapshot {
            uav: 1,
            seq,
            t_s: seq as f64 / 30.0,
            pose: [1.0, 2.0, 100.0, 10.0, 0.5, -0.5],
            mount: [5.0, -45.0, 0.5],
            baseline_position: [1.0, 2.0, 100.0],
            intrinsics: Intrinsics::new(500.0, 500.0, 320.0, 240.0),
            distortion: [0.0; 5],
            width: 640,
            height: 480,
            points: vec![[10.0, 20.0], [300.5, 200.25]],
            descriptors: vec![[1, 2, 3, 4], [5, 6, 7, 8]],
        }
    }

    #[test]
    fn a_keyframe_survives_the_round_trip() {
        let s = snapshot(7);
        let kf = s.keyframe().unwrap();
        assert_eq!(KeyframeSnapshot::of(Uav::Right, &kf), s);
        assert_eq!(kf.features.points.len(), 2);
    }

    #[test]
    fn untrustworthy_keyframes_are_refused() {
        let mut s = snapshot(1);
        s.points[0][0] = f32::NAN;
        assert!(s.keyframe().is_err());
        let mut s = snapshot(1);
        s.descriptors.pop();
        assert!(s.keyframe().unwrap_err().contains("descriptors"));
        let mut s = snapshot(1);
        s.mount[1] = f64::NAN;
        assert!(s.keyframe().is_err());
        let mut s = snapshot(1);
        s.width = 0;
        assert!(s.keyframe().is_err());
        let mut s = snapshot(1);
        s.intrinsics.fx = -1.0;
        assert!(s.keyframe().is_err());
    }

    #[test]
    fn rings_are_restored_in_order_with_their_ruler() {
        let config = crate::MatchingConfig::default();
        let mut chain = VisionChain::new(config, geolocation::EstimatorConfig::default()).unwrap();
        let index = RingIndex {
            keyframes: [vec![], vec![3, 9]],
            smoothed: [None, Some((0.3, [1.0, 2.0, 100.0]))],
            segment: 2,
        };
        let n = chain
            .restore_rings(&index, |_, seq| Ok(snapshot(seq)))
            .unwrap();
        assert_eq!(n, 2);
        assert_eq!(chain.ring_index(), index);
        assert_eq!(chain.newest_keyframe(Uav::Right).unwrap().seq, 9);
        let wrong = chain.restore_rings(&index, |_, _| Ok(snapshot(4)));
        assert!(wrong.unwrap_err().contains("another keyframe"));
    }

    /// A new stream segment empties the rings and the ruler; the index says which
    /// segment they are of, so a restart in the new one does not bring the old back.
    #[test]
    fn a_new_segment_empties_the_rings() {
        let config = crate::MatchingConfig::default();
        let mut chain = VisionChain::new(config, geolocation::EstimatorConfig::default()).unwrap();
        chain.refresh_on_thread(true).unwrap();
        let index = RingIndex {
            keyframes: [vec![], vec![3, 9]],
            smoothed: [None, Some((0.3, [1.0, 2.0, 100.0]))],
            segment: 0,
        };
        chain
            .restore_rings(&index, |_, seq| Ok(snapshot(seq)))
            .unwrap();
        chain.start_over(1).unwrap();
        assert_eq!(chain.segment(), 1);
        assert_eq!(
            chain.ring_index(),
            RingIndex {
                keyframes: [vec![], vec![]],
                smoothed: [None, None],
                segment: 1,
            }
        );
    }
}
