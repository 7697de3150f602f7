//! Matching configuration (Section 2.3).

use serde::{Deserialize, Serialize};

/// How F_Ln and F_Rn are estimated from ORB matches.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FundamentalMethod {
    /// The paper's eight-point algorithm inside RANSAC (OpenCV `FM_RANSAC`).
    Ransac8Point,
    /// OpenCV's USAC MAGSAC++: faster and finds more inliers here.
    Magsac,
    /// The essential matrix from the calibrated intrinsics (5-point, MAGSAC++), then
    /// F = K_n⁻ᵀ E K⁻¹: the same F, estimated with 5 degrees of freedom instead of 7.
    Essential,
    /// The default: the dominant plane's homography, decomposed, keeping the level
    /// solution (the vertical from the measured roll and pitch); F = K_n⁻ᵀ [t]× R K⁻¹.
    /// Cross-UAV matches lie almost all on the ground, where F is degenerate and E
    /// two-fold ambiguous (`ground_plane` module docs, docs/matching.md).
    GroundPlane,
}

/// ORB's keypoint ranking (OpenCV `ORB::ScoreType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OrbScore {
    /// FAST's own score: the default. On the Table 1 route it kept more ground corners
    /// and cut every after-filter error 2–3× against Harris (docs/matching.md).
    Fast,
    /// The Harris corner response (OpenCV's default).
    Harris,
}

/// USAC's scoring of a hypothesis (OpenCV `ScoreMethod`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UsacScore {
    /// MAGSAC++: marginalises over the noise scale.
    Magsac,
    /// MSAC: truncated squared residuals; cheaper.
    Msac,
}

/// USAC's local optimisation of the best hypothesis so far (OpenCV `LocalOptimMethod`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UsacLocalOptimisation {
    None,
    /// Inner RANSAC on the inliers.
    Inner,
    /// Inner RANSAC plus iterated least squares.
    InnerAndIterative,
    /// Graph-cut RANSAC.
    GraphCut,
    /// MAGSAC++'s σ-consensus (OpenCV's default with `USAC_MAGSAC`).
    Sigma,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MatchingConfig {
    /// N: images per UAV in a geolocation (the current one and N − 1 past ones);
    /// 2N in all. The paper's "8 images" is N = 4.
    pub images_per_uav: usize,
    /// T_re of the baseline constraint, metres between consecutive selected images.
    pub keyframe_spacing_m: f64,
    /// Past images per UAV a pair needs to be matched while the ring is still short
    /// of the N − 1 the baseline constraint selects (clamped to N − 1; default 1; 3
    /// is the paper's full window, which its tables keep). UAVs following a slow car
    /// fly the (N − 1) × T_re it takes slowly (24 m: 12 s at 2 m/s); with 1, the
    /// first sets carry fewer rows and the estimator states the wider covariance that
    /// follows. Measured (docs/matching.md "The start"): with 1 the first estimate
    /// comes at 1.9–2.2 s instead of 3.6–4.2 s on four Monte Carlo scenes and at 6.0
    /// s instead of 14.4 s on `multi_crawl`, the target's calibration no worse. The
    /// other vehicles, located relative to the target, move with its converging
    /// first estimates: the tracks' travel test counts that drift (`tracks.rs`,
    /// `persistent_drop`), so a static object is not taken for a vehicle.
    pub min_past_images: usize,
    /// Time constant smoothing the measured positions the baseline constraint is
    /// measured with, seconds (0 = raw GPS).
    pub baseline_smoothing_s: f64,
    /// Keyframes kept per UAV.
    pub ring_capacity: usize,
    /// ORB features per frame of up to 640 × 480 pixels. 1 500 since the scene suite
    /// (issue #12): with 500, a third of the past images of the 640×480 suite scenes
    /// were rejected for too few inliers and the Table 2 error of the aerial-photo
    /// scene was 8.8 m (1.0 m with 1 500; docs/matching.md). With `orb_scale_with_area` a
    /// larger frame gets proportionally more (by pixel count, at most 2×): the same
    /// density of features, so a 1280 × 720 camera is not starved.
    pub orb_features: i32,
    pub orb_scale_with_area: bool,
    /// Cells the features are spread over (0 = ORB's own ranking only): each cell keeps
    /// its best keypoints up to an equal share of `orb_features` (`features.rs`).
    pub orb_spread_cells: usize,
    /// ORB detects this many times `orb_features` candidates for spreading to choose from.
    pub orb_candidate_factor: i32,
    /// FAST thresholds tried in turn while a frame has fewer candidates than
    /// `orb_features` (low-texture ground); the first is ORB's usual 20.
    pub orb_fast_thresholds: Vec<i32>,
    /// ORB pyramid levels (scale step 1.2). Few levels suit two UAVs at one altitude.
    pub orb_levels: i32,
    /// How ORB ranks its keypoints.
    pub orb_score: OrbScore,
    /// A frame whose optical axis is more than this many degrees off the vertical (by
    /// its measured pitch and roll: a tilted or gimballed camera) has its ORB features
    /// found on the view a camera looking straight down would have (`rectify.rs`): ORB
    /// does not survive the perspective between two oblique UAVs. 20° leaves every
    /// nadir frame of the suite as it is (their tilt from bank and AHRS noise stays
    /// under 15°); 90 or more: never.
    pub rectify_above_tilt_deg: f64,
    /// Refine keypoints to sub-pixel positions (`cornerSubPix`). Off by default: with
    /// the ground-plane F and FAST ranking it made every Table 1 figure worse and cost
    /// ~4 ms per pair (docs/matching.md).
    pub subpixel_keypoints: bool,
    /// Lowe's ratio test on the two nearest Hamming neighbours.
    pub ratio_test: f32,
    /// A past image whose brute-force matching gave too few matches or inliers is
    /// matched once more with this looser ratio (0 = no retry); counted as
    /// `retried_looser_ratio` in matching's counters. Off by default: on the suite it
    /// rescued 1–3 % of the past images it retried and cost a fifth of the CPU.
    pub retry_ratio_test: f32,
    /// Guided matching: a past image matched with an earlier current frame of the same
    /// UAV less than `guided_max_age_s` ago is matched again only within this many
    /// pixels of where that pair's ground homography predicts (0 = always brute
    /// force). Brute force runs when there is no prior or the guided fit fails.
    pub guided_radius_px: f64,
    /// Oldest prior guided matching uses, seconds.
    pub guided_max_age_s: f64,
    pub fundamental: FundamentalMethod,
    /// RANSAC inlier threshold (distance to the epipolar line), pixels.
    pub ransac_threshold_px: f64,
    pub ransac_confidence: f64,
    /// Hypotheses tried at most (USAC honours it through `UsacParams`).
    pub ransac_max_iterations: i32,
    /// Hypotheses tried at most for the `ground_plane` homography (4-point USAC).
    pub homography_max_iterations: i32,
    /// `ground_plane`: a dominant plane tilted more than this from the vertical is not
    /// the ground; the 5-point E is used instead. Degrees.
    pub max_ground_tilt_deg: f64,
    /// USAC scoring for `magsac` and `essential`.
    pub usac_score: UsacScore,
    /// USAC local optimisation for `magsac` and `essential`.
    pub usac_local_optimisation: UsacLocalOptimisation,
    /// Local-optimisation rounds.
    pub usac_lo_iterations: i32,
    /// Threads sharing the past images of one geolocation (1 = the calling thread only).
    pub match_threads: usize,
    /// Fewer inliers than this rejects the past image.
    pub min_inliers: usize,
    /// Epipolar lines of eq. (27) and (28) closer to parallel than this reject it.
    /// The intersection's error is a line's error over the sine of their angle: 30°
    /// caps that gain at 2×. On the Table 1 route, 30° rather than 5° cut the largest
    /// after-filter z error from 8.2 to 1.6 m for 2 % fewer geolocations
    /// (docs/matching.md).
    pub min_line_angle_deg: f64,
    /// A transferred point must lie at least this far inside the image.
    pub border_px: f64,
    /// Between ORB frames, follow each camera's ground matches frame to frame (KLT)
    /// instead of running ORB and Hamming matching on every frame
    /// (`frame_tracking.rs`, issue #15); F is still fitted afresh on every frame. Off =
    /// ORB and matching on every frame, as before.
    pub track_between_orb: bool,
    /// ORB and Hamming matching (a *refresh*, `chain/refresh.rs`) at least every this
    /// many frames of a UAV while tracking.
    pub track_refresh_frames: u32,
    /// A refresh runs beside the per-pair path and lands this many frames after the
    /// frame it was taken on, in a replay at `--rate max` and in the evaluation (so
    /// both repeat exactly); live, it lands on the first frame after it finishes.
    /// 0 = on the frame itself (the pair waits for it: the refresh is back on the
    /// critical path).
    pub refresh_landing_frames: u32,
    /// Ground inliers of each past image's fit handed to the tracker (a stride through
    /// them), at most.
    pub track_points_per_image: usize,
    /// Fewer followed points than this loses the track (ORB again).
    pub track_min_inliers: usize,
    /// Followed points must agree on one frame-to-frame homography within this many
    /// pixels.
    pub track_ransac_px: f64,
    /// Several targets (`chain/others.rs`): another object of the current left image
    /// and one of the right image are the same vehicle only if the left one, carried
    /// by the ground homography between the two images, lands within this many pixels
    /// of the right one ...
    pub others_gate_px: f64,
    /// ... and their colours differ by at most this much per channel (0–255; 255
    /// turns the colour test off).
    pub others_colour_gate: f64,
    /// A pair whose target a current image did not find (hidden under a bridge, say)
    /// still has its past images fitted when both images show other vehicles, and
    /// those are paired and carried into them as on any pair (`chain/others.rs`,
    /// `others_unseen`); false: such a pair carries no vehicle.
    pub others_when_unseen: bool,
    /// The target's two current detections are one vehicle only if the left one,
    /// carried by the ground homography between the two images, lands within this
    /// angle of the right one, milliradians (× the right camera's focal length in
    /// pixels / 1000: 16 px at 640 × 480 and 60°, 48 px at 1920 px and 60°;
    /// `chain::target_pair`: a car roof's parallax and the homography's error stay
    /// within it, two cars abreast a lane apart do not). A pair beyond it is mended
    /// from the detector's candidates or dropped. 0 turns the check off.
    pub target_pair_gate_mrad: f64,
}

impl Default for MatchingConfig {
    fn default() -> Self {
        Self {
            images_per_uav: 4,
            keyframe_spacing_m: 8.0,
            min_past_images: 1,
            baseline_smoothing_s: 0.5,
            ring_capacity: 16,
            orb_features: 1500,
            orb_spread_cells: 48,
            orb_candidate_factor: 4,
            orb_scale_with_area: true,
            orb_fast_thresholds: vec![20, 10, 5],
            orb_levels: 3,
            orb_score: OrbScore::Fast,
            rectify_above_tilt_deg: 20.0,
            subpixel_keypoints: false,
            ratio_test: 0.8,
            retry_ratio_test: 0.0,
            guided_radius_px: 32.0,
            guided_max_age_s: 0.5,
            fundamental: FundamentalMethod::GroundPlane,
            ransac_threshold_px: 1.0,
            ransac_confidence: 0.999,
            // 50 hypotheses, MSAC + graph-cut: 22 ms for the 12 E of a geolocation
            // against 181 ms with MAGSAC++'s defaults, at the same Table 1 accuracy
            // (docs/matching.md, "Speed").
            ransac_max_iterations: 50,
            homography_max_iterations: 500,
            max_ground_tilt_deg: 20.0,
            usac_score: UsacScore::Msac,
            usac_local_optimisation: UsacLocalOptimisation::GraphCut,
            usac_lo_iterations: 10,
            match_threads: 2,
            min_inliers: 30,
            min_line_angle_deg: 30.0,
            border_px: 2.0,
            track_between_orb: true,
            track_refresh_frames: 6,
            refresh_landing_frames: 2,
            track_points_per_image: 150,
            track_min_inliers: 30,
            track_ransac_px: 1.0,
            others_gate_px: 12.0,
            others_colour_gate: 60.0,
            others_when_unseen: true,
            target_pair_gate_mrad: 29.0,
        }
    }
}

impl MatchingConfig {
    /// Past images per UAV a pair is matched with at least: `min_past_images`, at
    /// most the N − 1 the window wants.
    pub fn past_images_needed(&self) -> usize {
        self.min_past_images
            .min(self.images_per_uav.saturating_sub(1))
    }

    pub fn validate(&self) -> Result<(), String> {
        if self.images_per_uav < 1 || self.ring_capacity < self.images_per_uav {
            return Err("need images_per_uav >= 1 and ring_capacity >= images_per_uav".into());
        }
        if self.min_past_images < 1 {
            return Err("need min_past_images >= 1".into());
        }
        // Each keyframe holds its features (~100 KB): a typo must not reserve gigabytes.
        if self.ring_capacity > 1024 {
            return Err(format!(
                "ring_capacity {} is above 1024",
                self.ring_capacity
            ));
        }
        let ok = self.keyframe_spacing_m.is_finite()
            && self.keyframe_spacing_m >= 0.0
            && self.baseline_smoothing_s.is_finite()
            && self.baseline_smoothing_s >= 0.0
            && self.orb_features >= 8
            && (1..=16).contains(&self.orb_levels)
            && self.ratio_test > 0.0
            && self.ratio_test <= 1.0
            && (0.0..=1.0).contains(&self.retry_ratio_test)
            && self.orb_spread_cells <= 4096
            && self.rectify_above_tilt_deg.is_finite()
            && self.rectify_above_tilt_deg >= 0.0
            && (1..=16).contains(&self.orb_candidate_factor)
            && self.orb_fast_thresholds.len() <= 8
            && self
                .orb_fast_thresholds
                .iter()
                .all(|t| (1..=255).contains(t))
            && (0.0..=1000.0).contains(&self.guided_radius_px)
            && (0.0..=60.0).contains(&self.guided_max_age_s)
            && self.ransac_threshold_px > 0.0
            && self.ransac_confidence > 0.0
            && self.ransac_confidence < 1.0
            && self.ransac_max_iterations > 0
            && self.homography_max_iterations > 0
            && (0.0..=90.0).contains(&self.max_ground_tilt_deg)
            && self.usac_lo_iterations >= 0
            && (1..=64).contains(&self.match_threads)
            && self.min_inliers >= 8
            && self.min_line_angle_deg >= 0.0
            && self.border_px >= 0.0
            && (1..=1000).contains(&self.track_refresh_frames)
            && self.refresh_landing_frames <= crate::frame_tracking::MAX_LANDING_FRAMES
            && (8..=10_000).contains(&self.track_points_per_image)
            && self.track_min_inliers >= 8
            && self.track_ransac_px > 0.0
            && self.track_ransac_px.is_finite()
            && self.others_gate_px > 0.0
            && self.others_gate_px.is_finite()
            && (0.0..=255.0).contains(&self.others_colour_gate)
            && self.target_pair_gate_mrad >= 0.0
            && self.target_pair_gate_mrad.is_finite();
        if ok {
            Ok(())
        } else {
            Err(format!("invalid matching configuration: {self:?}"))
        }
    }
}
