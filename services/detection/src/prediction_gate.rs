//! Gating detections by the geolocation filter's prediction (issue #23, item 4).
//!
//! The temporal filter knows where the target is (with its covariance), how it moves
//! and both yaw biases. Projected into a camera with that frame's measured pose, its
//! predicted position gives a pixel and a radius: a blob of the target's colour
//! outside that circle is not the target, however alone it is in the frame (a red
//! look-alike while the target hides under a bridge was taken for it before). The
//! radius covers the filter's horizontal uncertainty, the velocity's over the lag, one
//! frame's pose noise (the measured pose is not corrected), and half a vehicle.
//!
//! Pure geometry over plain data: the detection service feeds it the estimates it
//! receives, the evaluation its in-process filter's.

use serde::{Deserialize, Serialize};
use shared_types::conventions::{camera_to_world, Attitude, Intrinsics};
use shared_types::lens::Distortion;
use shared_types::messages::{EstimateMsg, EstimateStatus, PoseSample};

/// The filter's word on the target, as detection uses it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetPrediction {
    /// Time of the estimate (the recording's clock), s.
    pub t_s: f64,
    /// World ENU, m.
    pub position: [f64; 3],
    /// (v_x, v_y), m/s.
    pub velocity: [f64; 2],
    /// σ_x² + σ_y², m².
    pub horizontal_variance_m2: f64,
    /// 1σ of the horizontal velocity, √(σ_vx² + σ_vy²), m/s (taken for each
    /// component: a little wider than needed).
    pub velocity_std_mps: f64,
    /// (δψ_L, δψ_R), radians (measured yaw = true + bias).
    pub yaw_bias: [f64; 2],
    /// Their variances, rad²: a yaw error turns the target's pixel about the image
    /// centre, so a converging filter's gate is as wide as its bias σ makes it.
    pub yaw_bias_variance: [f64; 2],
    /// The filter was coasting: both cameras' last detections disagreed with its
    /// prediction, so the image tracks are suspect and the blob nearest the predicted
    /// pixel is taken, not the track's ([`Gate::prefer_centre`]).
    pub coasting: bool,
}

impl TargetPrediction {
    /// From an estimate with status `Ok`, quality `converging` (0), `tracking` (1) or
    /// `coasting` (2), every value finite. A converging filter gates too: its bias σ
    /// widens the gate, and a gate wider than `max_radius_frac` excludes nothing.
    /// (Gating only with `tracking` left the detector alone while the bias hypotheses
    /// were still open: `suite_traffic` seed 3 took a look-alike in one camera at
    /// 4.4 s.) A coasting one gates with its prediction and marks it `coasting`: on
    /// `suite_traffic` seed 5 both cameras' tracks followed a look-alike out from under
    /// a bridge while the filter coasted on the hidden target; taking the blob nearest
    /// the prediction brings them back to the target when it reappears.
    pub fn from_estimate(m: &EstimateMsg) -> Option<Self> {
        let p = Self {
            t_s: m.t_s,
            position: m.position,
            velocity: m.velocity_mps,
            horizontal_variance_m2: m.covariance[0] + m.covariance[5],
            velocity_std_mps: m.velocity_acc_mps,
            yaw_bias: m.yaw_bias_deg.map(f64::to_radians),
            yaw_bias_variance: [m.covariance[10], m.covariance[15]],
            coasting: m.quality == 2,
        };
        let ok = m.status == EstimateStatus::Ok as u32 && m.quality <= 2;
        (ok && p.is_finite()).then_some(p)
    }

    pub fn is_finite(&self) -> bool {
        self.t_s.is_finite()
            && self
                .position
                .iter()
                .chain(&self.velocity)
                .chain(&self.yaw_bias)
                .chain(&self.yaw_bias_variance)
                .chain([&self.horizontal_variance_m2, &self.velocity_std_mps])
                .all(|v| v.is_finite())
            && self.yaw_bias_variance.iter().all(|v| *v >= 0.0)
            && self.horizontal_variance_m2 >= 0.0
            && self.velocity_std_mps >= 0.0
    }
}

/// `[detection.gate]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GateConfig {
    pub enabled: bool,
    /// Gate radius in σ's of the predicted pixel (3.7 = χ²(2) at 99.9 %).
    pub sigmas: f64,
    /// One frame's pose noise, as the estimator's noise model states it (the gate uses
    /// the measured pose as it is).
    pub sigma_position_m: f64,
    pub sigma_attitude_deg: f64,
    /// Added to the radius: half a vehicle, so a detection on its edge still fits.
    pub margin_m: f64,
    /// A gate wider than this share of the image width gates nothing.
    pub max_radius_frac: f64,
    /// A camera that found nothing inside its gate for this long looks everywhere
    /// again (re-acquisition, counted).
    pub reacquire_after_s: f64,
    /// Estimates older than this (the recording's clock) gate nothing.
    pub max_age_s: f64,
}

impl Default for GateConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            sigmas: 3.7,
            sigma_position_m: 3.0,
            sigma_attitude_deg: 2.0,
            margin_m: 2.5,
            max_radius_frac: 0.35,
            reacquire_after_s: 3.0,
            max_age_s: 1.0,
        }
    }
}

impl GateConfig {
    pub fn validate(&self) -> Result<(), String> {
        let non_negative = [
            self.sigma_position_m,
            self.sigma_attitude_deg,
            self.margin_m,
        ];
        let positive = [
            self.sigmas,
            self.max_radius_frac,
            self.reacquire_after_s,
            self.max_age_s,
        ];
        if non_negative.iter().all(|v| v.is_finite() && *v >= 0.0)
            && positive.iter().all(|v| v.is_finite() && *v > 0.0)
        {
            Ok(())
        } else {
            Err(format!(
                "gate settings must be finite and positive: {self:?}"
            ))
        }
    }
}

/// Where the target may be in one frame: a circle in (distorted) pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gate {
    pub centre: [f64; 2],
    pub radius_px: f64,
    /// 1σ of the predicted pixel (the radius is `sigmas` of it plus the margin).
    pub sigma_px: f64,
    /// From a coasting filter: the blob nearest `centre` is the target rather than the
    /// image track's, unless the prediction hardly tells them apart
    /// (`tracked::KEEP_TRACK`).
    pub prefer_centre: bool,
}

impl Gate {
    pub fn contains(&self, p: [f64; 2]) -> bool {
        (p[0] - self.centre[0]).hypot(p[1] - self.centre[1]) <= self.radius_px
    }
}

/// One frame: what the gate needs of its header.
#[derive(Debug, Clone, Copy)]
pub struct FrameGeometry {
    pub t_s: f64,
    /// 0 = left, 1 = right.
    pub uav: usize,
    pub pose: PoseSample,
    pub intrinsics: Intrinsics,
    pub distortion: Distortion,
    pub width: u32,
}

/// The gate of `frame` from `prediction`, or `None` when there is none to apply: gating
/// off, an estimate too old, a target behind the camera, or a circle so wide it would
/// not exclude anything.
pub fn gate_for(
    prediction: &TargetPrediction,
    frame: &FrameGeometry,
    config: &GateConfig,
) -> Option<Gate> {
    let dt = frame.t_s - prediction.t_s;
    if !config.enabled || !dt.is_finite() || dt.abs() > config.max_age_s || frame.uav > 1 {
        return None;
    }
    let p = nalgebra::Vector3::new(
        prediction.position[0] + prediction.velocity[0] * dt,
        prediction.position[1] + prediction.velocity[1] * dt,
        prediction.position[2],
    );
    let attitude: Attitude = frame
        .pose
        .attitude()
        .corrected_for_yaw_bias(prediction.yaw_bias[frame.uav]);
    let camera = camera_to_world(attitude).transpose() * (p - frame.pose.position().coords);
    let pixel = frame.intrinsics.project(camera)?;
    let depth = camera.z;
    let f = frame.intrinsics.fx;
    let centre = if frame.distortion.is_none() {
        [pixel.x, pixel.y]
    } else {
        frame
            .distortion
            .distort_pixel(&frame.intrinsics, pixel.x, pixel.y)
    };
    // Per-axis σ of the position the gate must cover, m: half the horizontal variance
    // per axis, the velocity's over the lag, and the frame's GPS error.
    let metres2 = prediction.horizontal_variance_m2 / 2.0
        + (prediction.velocity_std_mps * dt).powi(2)
        + config.sigma_position_m.powi(2);
    // The bias's uncertainty turns the pixel about the principal point.
    let off_centre = (pixel.x - frame.intrinsics.cx).hypot(pixel.y - frame.intrinsics.cy);
    let sigma_px = ((f / depth).powi(2) * metres2
        + (f * config.sigma_attitude_deg.to_radians()).powi(2)
        + off_centre.powi(2) * prediction.yaw_bias_variance[frame.uav])
        .sqrt();
    let radius_px = config.sigmas * sigma_px + f * config.margin_m / depth;
    let finite = centre.iter().all(|v| v.is_finite()) && radius_px.is_finite();
    (finite && radius_px <= config.max_radius_frac * frame.width as f64).then_some(Gate {
        centre,
        radius_px,
        sigma_px,
        prefer_centre: prediction.coasting,
    })
}

/// A frame is gated by the newest estimate of a pair at least this many pairs older.
/// With `--rate max` one pair is in flight and matching acknowledges a pair before
/// geolocation has estimated it, so the estimate of the pair just before may or may
/// not have arrived when a frame is detected; the one before that has (a whole pair's
/// decoding, detection and matching later). A fixed lag keeps replays repeatable.
pub const ESTIMATE_LAG_PAIRS: u64 = 2;

/// The last few estimates by pair, for [`ESTIMATE_LAG_PAIRS`].
///
/// A pair with no estimate to gate with (none made, or rejected) leaves the newest
/// one in force until it is older than `max_age_s` ([`gate_for`]): while the target
/// is hidden, a blob of its colour far from where it should be is not it. Measured
/// over 8 seeds of `suite_traffic` this was worse when the detector still took a lone
/// look-alike far from a fresh track (gross errors 24 → 48 %: a filter that had taken
/// the look-alike kept it); with the constellation and the lone-blob rule
/// (`constellation.rs`, `colour_blob.rs`) it is better (see CHANGELOG).
#[derive(Debug, Default)]
pub struct RecentPredictions {
    /// (pair_seq, prediction), oldest first; at most 8.
    items: std::collections::VecDeque<(u64, Option<TargetPrediction>)>,
    /// The newest trusted prediction that has left `items`.
    evicted: Option<(u64, TargetPrediction)>,
    /// The first pair of the stream's current segment: estimates of earlier pairs
    /// speak of a world that is gone.
    floor: u64,
}

impl RecentPredictions {
    /// Remembers what the estimate of `pair_seq` says (`None`: nothing to gate with,
    /// e.g. the filter was converging).
    pub fn push(&mut self, pair_seq: u64, prediction: Option<TargetPrediction>) {
        if pair_seq < self.floor {
            return;
        }
        if self.items.len() == 8 {
            if let Some((s, Some(p))) = self.items.pop_front() {
                self.evicted = Some((s, p));
            }
        }
        self.items.push_back((pair_seq, prediction));
    }

    /// The stream jumped at pair `first_seq` (a new segment, e.g. a looped recording
    /// starting over): every prediction so far, and every later estimate of an
    /// earlier pair, is forgotten. The filter starts over too, and gates again once it
    /// has an estimate of the new segment.
    /// True when this moved the start (the first camera to see the new segment).
    pub fn start_segment(&mut self, first_seq: u64) -> bool {
        self.items.clear();
        self.evicted = None;
        let moved = first_seq > self.floor;
        self.floor = self.floor.max(first_seq);
        moved
    }

    /// The prediction that gates the frames of pair `seq`: the newest trusted one at
    /// least [`ESTIMATE_LAG_PAIRS`] pairs older (how old it may be is [`gate_for`]'s
    /// call).
    pub fn for_pair(&self, seq: u64) -> Option<TargetPrediction> {
        let lagged = |s: &u64| s.saturating_add(ESTIMATE_LAG_PAIRS) <= seq;
        self.items
            .iter()
            .rev()
            .filter(|(s, _)| lagged(s))
            .find_map(|(_, p)| *p)
            .or_else(|| self.evicted.filter(|(s, _)| lagged(s)).map(|(_, p)| p))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nadir_frame(t_s: f64) -> FrameGeometry {
        FrameGeometry {
            t_s,
            uav: 0,
            pose: PoseSample {
                x_m: 0.0,
                y_m: 0.0,
                z_m: 100.0,
                yaw_deg: 0.0,
                pitch_deg: 0.0,
                roll_deg: 0.0,
                mount: Default::default(),
            },
            intrinsics: Intrinsics::new(554.26, 554.26, 319.5, 239.5),
            distortion: Distortion::default(),
            width: 640,
        }
    }

    fn prediction(x: f64, y: f64) -> TargetPrediction {
        TargetPrediction {
            t_s: 10.0,
            position: [x, y, 0.0],
            velocity: [0.0, 8.0],
            horizontal_variance_m2: 0.5,
            velocity_std_mps: 0.3,
            yaw_bias: [0.0, 0.0],
            yaw_bias_variance: [0.0, 0.0],
            coasting: false,
        }
    }

    #[test]
    fn a_target_below_the_camera_is_at_the_image_centre_and_moves_with_time() {
        let c = GateConfig::default();
        let g = gate_for(&prediction(0.0, 0.0), &nadir_frame(10.0), &c).unwrap();
        assert!((g.centre[0] - 319.5).abs() < 1e-6 && (g.centre[1] - 239.5).abs() < 1e-6);
        // 3 m and 2° of pose noise at 100 m: σ ≈ 25 px; 3.7 σ plus half a vehicle.
        assert!((85.0..120.0).contains(&g.radius_px), "{}", g.radius_px);
        // 0.25 s later it has driven 2 m north: the gate follows it in the image.
        let later = gate_for(&prediction(0.0, 0.0), &nadir_frame(10.25), &c).unwrap();
        assert!((later.centre[0] - g.centre[0]).hypot(later.centre[1] - g.centre[1]) > 10.0);
        // A look-alike 25 m away is outside the gate, the target inside.
        let lookalike = gate_for(&prediction(25.0, 0.0), &nadir_frame(10.0), &c).unwrap();
        assert!(g.contains(g.centre) && !g.contains(lookalike.centre));
    }

    /// A yaw error turns the target's pixel about the image centre: the biases' σ
    /// widens the gate of an off-centre target, not of one at the centre, and a
    /// converging filter's (15°) makes it too wide to gate.
    #[test]
    fn the_bias_sigma_widens_the_gate_off_centre() {
        let c = GateConfig::default();
        let radius = |x: f64, bias_deg: f64| {
            let mut p = prediction(x, 0.0);
            p.yaw_bias_variance = [bias_deg.to_radians().powi(2); 2];
            gate_for(&p, &nadir_frame(10.0), &c).map(|g| g.radius_px)
        };
        let centre = radius(0.0, 0.0).expect("gate");
        assert!((radius(0.0, 3.0).expect("gate") - centre).abs() < 1e-6);
        let off = radius(40.0, 0.0).expect("gate");
        let off_widened = radius(40.0, 3.0).expect("gate");
        assert!(off_widened > off + 5.0, "{off} → {off_widened}");
        assert!(radius(40.0, 15.0).is_none());
    }

    #[test]
    fn no_gate_when_it_cannot_be_trusted() {
        let c = GateConfig::default();
        // Too old, behind the camera, too uncertain, switched off, not finite.
        assert!(gate_for(&prediction(0.0, 0.0), &nadir_frame(12.0), &c).is_none());
        let mut above = prediction(0.0, 0.0);
        above.position[2] = 150.0;
        assert!(gate_for(&above, &nadir_frame(10.0), &c).is_none());
        let mut vague = prediction(0.0, 0.0);
        vague.horizontal_variance_m2 = 400.0;
        assert!(gate_for(&vague, &nadir_frame(10.0), &c).is_none());
        let off = GateConfig {
            enabled: false,
            ..c
        };
        assert!(gate_for(&prediction(0.0, 0.0), &nadir_frame(10.0), &off).is_none());
        let mut nan = nadir_frame(10.0);
        nan.pose.x_m = f64::NAN;
        assert!(gate_for(&prediction(0.0, 0.0), &nan, &c).is_none());
    }

    #[test]
    fn a_frame_is_gated_by_the_estimate_two_pairs_back() {
        let mut r = RecentPredictions::default();
        assert!(r.for_pair(5).is_none());
        for seq in 0..20 {
            let mut p = prediction(seq as f64, 0.0);
            p.t_s = seq as f64;
            r.push(seq, (seq != 16).then_some(p));
        }
        assert_eq!(r.for_pair(19).map(|p| p.t_s), Some(17.0));
        // The estimate two back said nothing (coasting): the newest trusted one before
        // it stands (gate_for decides whether it is too old).
        assert_eq!(r.for_pair(18).map(|p| p.t_s), Some(15.0));
        // Kept: the last 8, and the newest trusted one before them.
        assert_eq!(r.for_pair(13).map(|p| p.t_s), Some(11.0));
        assert_eq!(r.for_pair(12).map(|p| p.t_s), None);
        let mut quiet = RecentPredictions::default();
        quiet.push(0, Some(prediction(0.0, 0.0)));
        for seq in 1..30 {
            quiet.push(seq, None);
        }
        assert_eq!(quiet.for_pair(30).map(|p| p.t_s), Some(10.0));
    }

    #[test]
    fn a_new_segment_forgets_every_prediction_and_late_estimates_of_the_old_one() {
        let mut r = RecentPredictions::default();
        for seq in 0..10 {
            r.push(seq, Some(prediction(seq as f64, 0.0)));
        }
        assert!(r.for_pair(12).is_some());
        assert!(r.start_segment(12));
        assert!(r.for_pair(12).is_none(), "the old world gates nothing");
        // An estimate of an old pair arriving after the jump is dropped...
        r.push(11, Some(prediction(11.0, 0.0)));
        assert!(r.for_pair(20).is_none());
        // ... one of the new segment gates again.
        r.push(14, Some(prediction(14.0, 0.0)));
        assert_eq!(r.for_pair(16).map(|p| p.position[0]), Some(14.0));
        // A segment's start never moves the floor back.
        assert!(!r.start_segment(3));
        r.push(5, Some(prediction(5.0, 0.0)));
        assert!(r.for_pair(20).is_none());
    }

    #[test]
    fn every_ok_estimate_gates_a_coasting_one_prefers_its_centre() {
        let mut m = EstimateMsg {
            t_s: 1.0,
            quality: 1,
            ..Default::default()
        };
        assert!(TargetPrediction::from_estimate(&m).is_some_and(|p| !p.coasting));
        m.quality = 0;
        assert!(TargetPrediction::from_estimate(&m).is_some_and(|p| !p.coasting));
        m.quality = 2;
        let coasting = TargetPrediction::from_estimate(&m).expect("a coasting filter gates");
        assert!(coasting.coasting);
        m.quality = 3;
        assert!(
            TargetPrediction::from_estimate(&m).is_none(),
            "no such quality"
        );
        m.quality = 0;
        m.covariance[15] = -1.0;
        assert!(TargetPrediction::from_estimate(&m).is_none());
        m.covariance[15] = 0.0;
        m.quality = 1;
        m.status = EstimateStatus::Rejected as u32;
        assert!(TargetPrediction::from_estimate(&m).is_none());
    }
}
