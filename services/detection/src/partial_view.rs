//! A detection of a partly hidden target (sliding under a bridge or trees, leaving the
//! frame) is a blob of the visible part, and its centroid is off the target point by up
//! to half the vehicle's length: a confident wrong position for everything downstream.
//! [`PartialViewGuard`] drops such detections, per camera, by their apparent size: the
//! long side of the box (about the vehicle's length whatever its heading: at 45° a
//! 4.5 × 2 m box's long side grows by only 2 %) against a slowly updated reference
//! from the detections it accepted. Dropped detections are counted by the caller.
//!
//! The reference follows slow changes (altitude, zoom) through its moving average, and
//! is re-seeded when nothing has been accepted for `reseed_after_s`, so a real lasting
//! change of scale costs that long at most.

use crate::Detection;

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PartialViewConfig {
    /// A detection whose box long side is under this share of the reference is
    /// dropped (0 turns the guard off). A blob at 0.75 puts the centroid at most
    /// 1/8 of the vehicle's length (~0.6 m for 4.5 m) off the target point.
    pub min_size_ratio: f64,
    /// Weight of each accepted detection in the reference (exponential average).
    pub smoothing: f64,
    /// Seconds without an accepted detection after which the next one re-seeds the
    /// reference.
    pub reseed_after_s: f64,
}

impl Default for PartialViewConfig {
    fn default() -> Self {
        Self {
            min_size_ratio: 0.75,
            smoothing: 0.1,
            reseed_after_s: 2.0,
        }
    }
}

impl PartialViewConfig {
    pub fn validate(&self) -> Result<(), String> {
        let ok = (0.0..1.0).contains(&self.min_size_ratio)
            && self.smoothing > 0.0
            && self.smoothing <= 1.0
            && self.reseed_after_s.is_finite()
            && self.reseed_after_s > 0.0;
        if ok {
            Ok(())
        } else {
            Err(format!(
                "partial-view guard needs 0 <= min_size_ratio < 1, 0 < smoothing <= 1 and \
                 reseed_after_s > 0, got {self:?}"
            ))
        }
    }
}

/// The guard of one camera.
#[derive(Debug, Clone, Copy, Default)]
pub struct PartialViewGuard {
    config: PartialViewConfig,
    /// Reference long side, pixels, and when a detection was last accepted.
    reference: Option<(f64, f64)>,
    /// Where the target was last seen (accepted or partly hidden), pixels, and when.
    last_seen: Option<([f64; 2], f64)>,
}

/// Where to look for the target (see [`PartialViewGuard::hint`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackHint {
    pub centre: [f64; 2],
    /// Seen within `reseed_after_s`: look only near `centre`. Otherwise the track is
    /// stale: take the blob nearest `centre`, however far (after an occlusion the
    /// target reappears near where it vanished; a car of its colour elsewhere is
    /// farther).
    pub fresh: bool,
    /// Seconds since the target was last seen.
    pub age_s: f64,
}

impl PartialViewGuard {
    pub fn new(config: PartialViewConfig) -> Self {
        Self {
            config,
            reference: None,
            last_seen: None,
        }
    }

    /// Where this camera last saw the target (whole or partly hidden): the hint for
    /// [`crate::ColourBlobDetector::detect_near`], so another vehicle of the target's
    /// colour is not taken for it. `None` before the first detection.
    pub fn hint(&self, t_s: f64) -> Option<TrackHint> {
        self.last_seen.map(|(centre, at)| TrackHint {
            centre,
            fresh: t_s - at <= self.config.reseed_after_s,
            age_s: (t_s - at).max(0.0),
        })
    }

    /// The camera turned since the target was last seen: the track's pixel is now
    /// `centre` (when it was last seen stays).
    pub fn moved_to(&mut self, centre: [f64; 2]) {
        if let Some((c, _)) = self.last_seen.as_mut() {
            *c = centre;
        }
    }

    /// Whether `detection` at `t_s` looks like the whole target (keep it) or like a part
    /// of it (drop it). Non-finite boxes are dropped.
    pub fn accept(&mut self, t_s: f64, detection: &Detection) -> bool {
        let size = detection.bbox[2].max(detection.bbox[3]);
        if !(size.is_finite() && size > 0.0 && t_s.is_finite()) {
            return false;
        }
        // The detector found it near the hint: the track follows, whole or not.
        self.last_seen = Some((detection.centre, t_s));
        if self.config.min_size_ratio <= 0.0 {
            self.reference = Some((size, t_s));
            return true;
        }
        let seeded = match self.reference {
            Some((reference, last)) if t_s - last <= self.config.reseed_after_s => {
                if size < self.config.min_size_ratio * reference {
                    return false;
                }
                let a = self.config.smoothing;
                a * size + (1.0 - a) * reference
            }
            _ => size,
        };
        self.reference = Some((seeded, t_s));
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn box_of(long: f64) -> Detection {
        Detection {
            bbox: [100.0, 100.0, long, long * 0.45],
            centre: [100.0 + long / 2.0, 100.0],
            confidence: 1.0,
        }
    }

    #[test]
    fn a_target_sliding_under_a_bridge_is_dropped_until_it_is_whole_again() {
        let mut guard = PartialViewGuard::new(PartialViewConfig::default());
        let mut t = 0.0;
        for _ in 0..30 {
            assert!(guard.accept(t, &box_of(20.0)));
            t += 1.0 / 30.0;
        }
        // Entering: 90 % still passes, 70 % and less does not.
        assert!(guard.accept(t, &box_of(18.0)));
        for long in [14.0, 10.0, 6.0, 3.0] {
            t += 0.1;
            assert!(!guard.accept(t, &box_of(long)), "{long} px accepted");
        }
        // Out again within the re-seed time: whole again, accepted.
        t += 1.0;
        assert!(!guard.accept(t, &box_of(12.0)));
        assert!(guard.accept(t + 0.1, &box_of(19.5)));
    }

    #[test]
    fn a_lasting_change_of_scale_is_followed() {
        let mut guard = PartialViewGuard::new(PartialViewConfig::default());
        assert!(guard.accept(0.0, &box_of(20.0)));
        // Climbing slowly: the reference follows.
        let mut long = 20.0;
        for k in 1..200 {
            long *= 0.995;
            assert!(
                guard.accept(k as f64 / 30.0, &box_of(long)),
                "{long} at {k}"
            );
        }
        // A sudden halving (zoom out) is refused, then re-seeded after the quiet time.
        assert!(!guard.accept(7.0, &box_of(long / 2.0)));
        assert!(guard.accept(7.0 + 2.5, &box_of(long / 2.0)));
        assert!(guard.accept(7.0 + 2.6, &box_of(long / 2.0)));
    }

    #[test]
    fn bad_boxes_are_dropped_and_the_guard_can_be_off() {
        let mut guard = PartialViewGuard::new(PartialViewConfig::default());
        assert!(!guard.accept(0.0, &box_of(f64::NAN)));
        assert!(!guard.accept(0.0, &box_of(0.0)));
        let mut off = PartialViewGuard::new(PartialViewConfig {
            min_size_ratio: 0.0,
            ..Default::default()
        });
        assert!(off.accept(0.0, &box_of(20.0)));
        assert!(off.accept(0.1, &box_of(2.0)));
        assert!(PartialViewConfig {
            smoothing: 0.0,
            ..Default::default()
        }
        .validate()
        .is_err());
    }

    #[test]
    fn the_hint_follows_the_target_whole_or_partial_and_goes_stale() {
        let mut guard = PartialViewGuard::new(PartialViewConfig::default());
        assert_eq!(guard.hint(0.0), None);
        assert!(guard.accept(0.0, &box_of(20.0)));
        let hint = |centre, fresh, age_s| {
            Some(TrackHint {
                centre,
                fresh,
                age_s,
            })
        };
        assert_eq!(guard.hint(0.5), hint([110.0, 100.0], true, 0.5));
        // A partial view is dropped, but the track follows it.
        assert!(!guard.accept(
            0.6,
            &Detection {
                centre: [120.0, 104.0],
                ..box_of(5.0)
            }
        ));
        assert_eq!(guard.hint(1.6), hint([120.0, 104.0], true, 1.0));
        assert_eq!(guard.hint(2.7), hint([120.0, 104.0], false, 2.1));
    }
}
