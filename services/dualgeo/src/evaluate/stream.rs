//! A simulated scene streamed through the whole chain in one process, as the scene suite
//! and the Monte Carlo evaluation need it: the simulator renders each pair, the colour
//! detector (with its track, gated by the default estimator's prediction as in `run`:
//! [`SceneStream::observe_estimate`]) finds the target, and each [`Lane`] runs its own
//! vision chain and estimators on the same pixels. A scene whose vehicle is not the
//! colour detector's red is detected by its motion ([`detection::motion`]), and the
//! stream plays the operator once: when the motion detector first looks, it designates
//! the target at its true pixel (as `acquire_px` does in `run`). Apart from that
//! click, truth comes along for scoring only; nothing here gives it to the chain or the
//! estimators.

use super::video_link::VideoLink;
use acquisition::sim::{SimConfig, SimStep, Simulator};
use anyhow::Result;
use detection::camera_swing::CameraView;
use detection::motion::{MotionConfig, MotionDetector};
use detection::prediction_gate::{self, GateConfig, RecentPredictions, TargetPrediction};
use detection::{ColourBlobConfig, TrackCounts, TrackedDetector};
use geolocation::geolocator::Geolocator;
use geolocation::tracks::{TrackConfig, Tracks};
use geolocation::{
    geolocate_filtered_paper, Estimate, EstimatorConfig, EstimatorError, EstimatorMethod,
    FilteredEstimate, Quality, TemporalEstimator,
};
use matching::epipolar::MatchReject;
use matching::set_message::{matched_set, refused_set, SetHeader};
use matching::{ChainCounts, FrameInput, MatchOutcome, MatchingConfig, VisionChain};
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::clock::process_cpu_ns;
use shared_types::conventions::{Intrinsics, Uav};
use shared_types::lens::Distortion;
use shared_types::messages::{EstimateMsg, EstimateStatus};
use shared_types::stats::StageStats;

/// What every frame of a scene shares.
#[derive(Debug, Clone, Copy)]
pub struct FrameGeometry {
    pub intrinsics: Intrinsics,
    pub lens: Distortion,
    pub width: u32,
    pub height: u32,
}

/// One rendered pair with its detections.
pub struct Pair<'a> {
    pub step: SimStep,
    pub geometry: FrameGeometry,
    pub images: &'a [cv::Mat; 2],
    pub detections: [Option<[f64; 2]>; 2],
    /// Every other object each detector listed, as the detection service publishes
    /// them (matching mends a pair on two vehicles from them, `chain::target_pair`).
    pub others: [matching::frame::Others; 2],
    /// The target inside both images and not hidden (truth, for scoring).
    pub visible: bool,
}

/// The detector a scene needs: the colour detector for the red target, the motion
/// detector for any other, with the pair at which the operator designates the target.
enum SceneDetector {
    Colour(Box<TrackedDetector>),
    Motion(Box<MotionDetector>, u64),
}

impl SceneDetector {
    /// For a stream that sees every `every`-th pair: the motion detector's gaps are
    /// kept in seconds (its defaults' frames at the full rate, divided by `every`).
    fn for_scene(config: &SimConfig, every: u64) -> Result<Self> {
        if config.vehicle.colour_bgr.is_none() {
            return Ok(Self::Colour(Box::new(TrackedDetector::new(
                ColourBlobConfig::default(),
            )?)));
        }
        let d = MotionConfig::default();
        let scaled = |frames: u32| (frames as u64 / every).max(1) as u32;
        let short_gap_frames = scaled(d.short_gap_frames);
        let motion = MotionConfig {
            short_gap_frames,
            long_gap_frames: scaled(d.long_gap_frames).max(short_gap_frames),
            ..d
        };
        // It first looks at the pair 2 × short_gap_frames.
        let first_look = 2 * u64::from(short_gap_frames);
        Ok(Self::Motion(
            Box::new(MotionDetector::new(motion)?),
            first_look,
        ))
    }
}

/// The scene's renderer, detector and the frame geometry every lane shares.
pub struct SceneStream {
    sim: Simulator,
    detector: SceneDetector,
    gate: GateConfig,
    predictions: RecentPredictions,
    /// What the detector counted (gated out, re-acquired, ...) over the stream.
    pub detector_counts: TrackCounts,
    images: [cv::Mat; 2],
    every: u64,
    k: u64,
    geometry: FrameGeometry,
    /// When set, the chain sees these decoded H.264 frames instead of the rendered ones.
    link: Option<VideoLink>,
}

impl SceneStream {
    /// Streams every `every`-th pair of `config`'s route.
    pub fn new(config: SimConfig, every: u64) -> Result<Self> {
        let (w, h) = (config.camera.width as i32, config.camera.height as i32);
        let detector = SceneDetector::for_scene(&config, every.max(1))?;
        let sim = Simulator::new(config)?;
        let blank = || cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0));
        Ok(Self {
            geometry: FrameGeometry {
                intrinsics: sim.intrinsics(),
                lens: sim.distortion(),
                width: w as u32,
                height: h as u32,
            },
            sim,
            detector,
            gate: ColourBlobConfig::default().gate,
            predictions: RecentPredictions::default(),
            detector_counts: TrackCounts::default(),
            images: [blank()?, blank()?],
            every: every.max(1),
            k: 0,
            link: None,
        })
    }

    /// Streams `config`'s route as [`SceneStream::new`] does, with every frame through
    /// H.264 at `crf` ([`VideoLink`]).
    pub fn through_video(config: SimConfig, every: u64, crf: u8) -> Result<Self> {
        let mut stream = Self::new(config.clone(), every)?;
        stream.link = Some(VideoLink::encode(&config, stream.sim.city().clone(), crf)?);
        Ok(stream)
    }

    /// What geolocation published for pair `pair_seq` (the frames' `seq`): later
    /// pairs' detections are gated by it as the detection service gates them
    /// ([`TargetPrediction::from_estimate`]), with the detection service's lag
    /// ([`prediction_gate::ESTIMATE_LAG_PAIRS`]).
    pub fn observe_estimate(&mut self, pair_seq: u64, estimate: Option<&EstimateMsg>) {
        let prediction = estimate.and_then(TargetPrediction::from_estimate);
        self.predictions.push(pair_seq, prediction);
    }

    /// Pairs this stream will give.
    pub fn pair_count(&self) -> u64 {
        self.sim.frame_count() / self.every
    }

    /// The next pair, rendered and detected, or `None` at the end of the route.
    pub fn next_pair(&mut self) -> Result<Option<Pair<'_>>> {
        let step = loop {
            let Some(step) = self.sim.step() else {
                return Ok(None);
            };
            self.k += 1;
            if self.k.is_multiple_of(self.every) {
                break step;
            }
            if let Some(link) = &mut self.link {
                link.skip_pair()?;
            }
        };
        {
            let [l, r] = &mut self.images;
            let stride = 3 * self.geometry.width as usize;
            // Rendered also through a link: visibility (truth) reads the renderer.
            self.sim
                .render_pair(&step, l.data_bytes_mut()?, r.data_bytes_mut()?, stride);
            if let Some(link) = &mut self.link {
                link.read_pair(l.data_bytes_mut()?, r.data_bytes_mut()?)?;
            }
        }
        let mut detections = [None, None];
        let mut others = [matching::frame::Others::default(); 2];
        for (i, d) in detections.iter_mut().enumerate() {
            let f = &step.frames[i];
            let gate = self.predictions.for_pair(f.seq).and_then(|p| {
                let frame = prediction_gate::FrameGeometry {
                    t_s: f.t_s,
                    uav: i,
                    pose: f.measured,
                    intrinsics: self.geometry.intrinsics,
                    distortion: self.geometry.lens,
                    width: self.geometry.width,
                };
                prediction_gate::gate_for(&p, &frame, &self.gate)
            });
            *d = match &mut self.detector {
                SceneDetector::Colour(detector) => detector
                    .detect_gated(
                        i,
                        f.t_s,
                        &self.images[i],
                        gate,
                        CameraView::new(&f.measured, self.geometry.intrinsics, self.geometry.lens),
                    )?
                    .map(|d| d.centre),
                SceneDetector::Motion(detector, first_look) => {
                    // The operator's click, once (the pairs this stream sees, from 1).
                    if self.k / self.every == *first_look + 1 {
                        if let Some(px) = f.target_px {
                            detector.designate(i, px);
                        }
                    }
                    detector.detect(i, &self.images[i], gate)?.map(|d| d.centre)
                }
            };
            // The candidates as the detection service lists them beside the target.
            let mut found = Vec::new();
            match &mut self.detector {
                SceneDetector::Colour(detector) => {
                    detector.candidates(&self.images[i], &mut found)?
                }
                SceneDetector::Motion(detector, _) => {
                    found.extend(detector.last_movers().iter().map(|m| m.as_detection()))
                }
            }
            let mut msg = shared_types::messages::DetectionMsg::default();
            if let Some(c) = *d {
                msg.found = 1;
                msg.centre = c;
            }
            detection::candidates::fill(&mut msg, &found, &self.images[i])?;
            others[i] = matching::frame::Others::of(&msg);
        }
        if let SceneDetector::Colour(detector) = &mut self.detector {
            let c = detector.take_counts();
            let total = &mut self.detector_counts;
            total.gated_out += c.gated_out;
            total.reacquired += c.reacquired;
            total.swings_followed += c.swings_followed;
            total.track_kept += c.track_kept;
            total.partial_view_dropped += c.partial_view_dropped;
        }
        let visible = [Uav::Left, Uav::Right]
            .iter()
            .all(|&uav| self.sim.target_visible(&step, uav));
        Ok(Some(Pair {
            step,
            geometry: self.geometry,
            images: &self.images,
            detections,
            others,
            visible,
        }))
    }
}

/// The estimate a published message holds, as the evaluation scores it, with its
/// quality; `None` unless its status is `Ok`.
pub fn published(msg: &EstimateMsg) -> Option<(Estimate, Quality)> {
    if msg.status != EstimateStatus::Ok as u32 {
        return None;
    }
    let estimate = Estimate {
        position: nalgebra::Point3::from(msg.position),
        yaw_bias: msg.yaw_bias_deg.map(f64::to_radians),
        covariance: nalgebra::Matrix4::from_row_slice(&msg.covariance),
        altitude_std_error_m: msg.altitude_std_error_m,
        iterations: msg.iterations as usize,
        converged: msg.converged != 0,
        images_used: msg.images_used as usize,
    };
    Some((estimate, Quality::from_index(msg.quality)?))
}

/// What one lane made of one pair.
pub struct LaneStep {
    /// What the geolocation service publishes for the pair's set (its status says
    /// whether it holds an estimate: [`published`]); `None` when matching gave no set
    /// (no detection, not enough history).
    pub default: Option<EstimateMsg>,
    /// The pair was refused as two vehicles: `default` is the filter's prediction (not
    /// timed, the paper's method not run).
    pub coasted: bool,
    /// The paper's method on the same set, when the lane scores it.
    pub paper: Option<Result<FilteredEstimate, EstimatorError>>,
    /// Process CPU time of the chain and the default estimate, µs.
    pub cpu_us: f64,
    pub counts: ChainCounts,
    pub rejections: Vec<(Uav, u64, MatchReject)>,
}

/// One chain and its estimators: the poses it is given decide the protocol.
pub struct Lane {
    chain: VisionChain,
    pub estimator: EstimatorConfig,
    /// The geolocation service's own logic on the set message matching would publish:
    /// the default estimator, the other vehicles' tracks and their word on the
    /// target's detections (`geolocation::target_identity`), `[tracks]` as `run`'s
    /// defaults.
    geolocator: Geolocator,
    /// The geolocation service's counters over the lane's pairs.
    pub stats: StageStats,
    /// Give the chain the true poses (Table 1) instead of the measured ones.
    true_poses: bool,
    /// Also run the paper's method on each matched set (not timed).
    score_paper: bool,
}

impl Lane {
    pub fn new(
        matching: &MatchingConfig,
        estimator: EstimatorConfig,
        true_poses: bool,
        score_paper: bool,
    ) -> Result<Self> {
        let config = Self::temporal_config(&estimator);
        let tracks = TrackConfig::default();
        Ok(Self {
            chain: VisionChain::new(matching.clone(), estimator)?,
            geolocator: Geolocator::new(
                config,
                tracks,
                Some(TemporalEstimator::new(config)?),
                Tracks::new(tracks).map_err(anyhow::Error::msg)?,
            ),
            stats: StageStats::new("geolocation"),
            estimator,
            true_poses,
            score_paper,
        })
    }

    fn temporal_config(estimator: &EstimatorConfig) -> EstimatorConfig {
        EstimatorConfig {
            method: EstimatorMethod::Temporal,
            ..*estimator
        }
    }

    /// Runs the chain and the estimators on one pair.
    pub fn step(&mut self, pair: &Pair) -> Result<LaneStep> {
        let g = pair.geometry;
        let inputs: Vec<FrameInput> = pair
            .step
            .frames
            .iter()
            .zip(pair.images)
            .zip(pair.detections)
            .map(|((f, image), detection)| FrameInput {
                seq: f.seq,
                t_s: f.t_s,
                pose: if self.true_poses {
                    f.true_pose
                } else {
                    f.measured
                },
                image,
                detection,
                intrinsics: g.intrinsics,
                distortion: g.lens,
                width: g.width,
                height: g.height,
            })
            .collect();
        let started = process_cpu_ns();
        let [(l, _), (r, _)] = self.chain.observe_pair([&inputs[0], &inputs[1]])?;
        let mut observed = [l, r];
        let mut metas = [inputs[0].meta(), inputs[1].meta()];
        for (meta, others) in metas.iter_mut().zip(pair.others) {
            meta.others = others;
        }
        let mut timing = matching::ChainTiming::default();
        let mut rejections = Vec::new();
        let outcome = self.chain.match_current(
            [&metas[0], &metas[1]],
            &mut observed,
            &mut timing,
            &mut rejections,
        )?;
        let f = &pair.step.frames;
        let header = SetHeader {
            pair_seq: f[0].seq,
            capture_ns: 0,
            t_s: f[0].t_s,
            rejected_past: rejections.len() as u32,
            segment: 0,
            frames: [(f[0].seq, f[0].t_s), (f[1].seq, f[1].t_s)],
            pose_noise: self.chain.pose_noise(),
        };
        let mut cpu_us = 0.0;
        let (mut default, mut paper) = (None, None);
        if let MatchOutcome::Matched(set) = &outcome {
            let others = self.chain.others([&metas[0], &metas[1]], set);
            let msg = matched_set(&header, set, &others);
            default = Some(self.geolocator.estimate(&msg, &mut self.stats));
            // What the pipeline spends ends here; the paper's method is scored on the
            // same set but not timed.
            cpu_us = process_cpu_ns().saturating_sub(started) as f64 / 1e3;
            if self.score_paper {
                paper = Some(geolocate_filtered_paper(
                    &set.current[0],
                    &set.current[1],
                    &set.past_observations,
                    &self.estimator,
                ));
            }
        }
        // A pair refused as two vehicles: the geolocation service publishes the
        // filter's prediction for it, whose coasting gate brings the detectors back to
        // one vehicle.
        let coasted = matches!(outcome, MatchOutcome::TargetPairMismatch(_));
        if let MatchOutcome::TargetPairMismatch(current) = &outcome {
            let msg = refused_set(&header, current);
            default = Some(self.geolocator.estimate(&msg, &mut self.stats));
        }
        self.chain.admit([&metas[0], &metas[1]], &mut observed)?;
        Ok(LaneStep {
            default,
            coasted,
            paper,
            cpu_us,
            counts: self.chain.take_counts(),
            rejections,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use acquisition::sim::Presets;

    #[test]
    fn a_red_target_gets_the_colour_detector_any_other_the_motion_detector() {
        let red = Presets::builtin().get("suite_town").unwrap();
        assert!(matches!(
            SceneDetector::for_scene(&red, 2).unwrap(),
            SceneDetector::Colour(_)
        ));
        let silver = Presets::builtin().get("tilted45_silver").unwrap();
        // Every 2nd pair: the gaps halve (10 → 5 frames), so it first looks at pair 10.
        match SceneDetector::for_scene(&silver, 2).unwrap() {
            SceneDetector::Motion(_, first_look) => assert_eq!(first_look, 10),
            SceneDetector::Colour(_) => panic!("a silver car needs the motion detector"),
        }
    }
}
