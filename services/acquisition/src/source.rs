//! Where pairs come from: the live simulator, a recording (format v1) or a flight
//! (video + MAVLink, [`crate::flight`]), behind one trait. The acquisition service
//! streams whatever [`open`] gives it; each source writes a pair's pixels straight into
//! the two loaned shared-memory frames it is handed.

use crate::flight::{FlightSource, LiveFlightSource};
use crate::recording::{decode_image_into, Recording, RecordingError, StereoPair, TruthRow};
use crate::sim::{ScenarioArgs, SimConfig, SimError, Simulator};
use shared_types::conventions::{Intrinsics, Uav};
use shared_types::messages::PoseSample;
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error(transparent)]
    Recording(#[from] RecordingError),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("{0}")]
    Flight(String),
    #[error("{0}")]
    Invalid(String),
    /// A pair the source dropped and counted itself (a flight's telemetry gap): not an
    /// error to log, a reason to go on.
    #[error("pair dropped by the source")]
    Dropped,
    /// A live source has no pair yet (asked again after a look for a stop request).
    #[error("no pair yet")]
    Waiting,
}

/// One pair's description, filled by the source.
pub struct PairInfo {
    /// Stream time of the pair (the left frame's), seconds.
    pub t_s: f64,
    /// Each UAV's navigation state at its frame's moment, as measured.
    pub poses: [PoseSample; 2],
    /// Truth, when the source knows it (the simulator): logged for evaluation only.
    pub truth: Option<[TruthRow; 2]>,
    /// CLOCK_MONOTONIC when the pair was handed over, for a live source (the later of
    /// its two decoded frames); `None`: when the source returned it.
    pub captured_ns: Option<u64>,
}

pub trait FrameSource {
    /// Width and height of both UAVs' frames.
    fn size(&self) -> (u32, u32);
    fn intrinsics(&self, uav: Uav) -> Intrinsics;
    /// Lens distortion of the pixels this source delivers (OpenCV's five coefficients).
    fn distortion(&self, uav: Uav) -> [f64; 5];
    /// Time between pairs, seconds.
    fn period_s(&self) -> f64;
    /// The live simulator's seed (it alone can inject live-input faults and log its
    /// stream); `None` for recorded sources.
    fn simulator_seed(&self) -> Option<u64> {
        None
    }
    /// Pairs taken from the source since the start or the last rewind, including the
    /// ones it dropped itself: the position a restart resumes at with [`Self::skip`].
    fn consumed(&self) -> u64;
    /// Skips the next `n` pairs (a restart resuming its predecessor's position; a
    /// paced replay that fell behind the clock).
    fn skip(&mut self, n: u64);
    /// Starts again from the first pair.
    fn rewind(&mut self) -> Result<(), SourceError>;
    /// Writes the next pair into `left` and `right` (packed BGR rows of `stride`
    /// bytes); `None` at the end of the stream; `Err` for a pair that could not be
    /// produced (the stream goes on).
    fn next_pair(
        &mut self,
        left: &mut [u8],
        right: &mut [u8],
        stride: usize,
    ) -> Option<Result<PairInfo, SourceError>>;
    /// The stream time of the pair [`Self::next_pair`] will produce, when the source
    /// knows it before producing it (a recording's telemetry rows, a video's frame
    /// index): paced replay then waits for the pair's moment first and decodes after
    /// it, as a live stream must (the honest clock of issue #15). `None` for a source
    /// that produces ahead (the simulator renders ahead: it stands in for the sensor)
    /// or stamps its own capture (a live flight).
    fn next_time_s(&self) -> Option<f64> {
        None
    }
    /// Counters the source kept since the last call (name, increment).
    fn take_counts(&mut self) -> Vec<(&'static str, u64)> {
        Vec::new()
    }
}

/// `sim`, a recording folder, or a flight.toml.
pub fn open(source: &str, scenario: &ScenarioArgs) -> Result<Box<dyn FrameSource>, SourceError> {
    if source == "sim" {
        let config = scenario
            .config()
            .map_err(|e| SourceError::Invalid(e.to_string()))?;
        return Ok(Box::new(SimSource::new(config)?));
    }
    let path = Path::new(source);
    if path.is_file() && path.extension().is_some_and(|e| e == "toml") {
        let meta = crate::flight::FlightMeta::read(path).map_err(SourceError::Flight)?;
        if meta.is_live() {
            return Ok(Box::new(
                LiveFlightSource::open(meta).map_err(SourceError::Flight)?,
            ));
        }
        return Ok(Box::new(
            FlightSource::open(path).map_err(SourceError::Flight)?,
        ));
    }
    Ok(Box::new(RecordingSource::open(path)?))
}

pub struct SimSource {
    config: SimConfig,
    sim: Simulator,
    steps: u64,
    /// Where the renderer runs: threads of lower priority (see [`RENDER_NICE`]).
    render_pool: Option<rayon::ThreadPool>,
}

/// The live simulator stands in for a camera, and a camera costs the ground station
/// nothing: its renderer (~40 ms of CPU a pair, more than the pipeline's own work)
/// runs at this nice value, so that detection, matching and geolocation take a core
/// from it whenever they need one (issue #15). It renders a pair ahead, so it has the
/// CPU the pipeline leaves; a pair it renders late is counted (`pairs_behind`).
pub const RENDER_NICE: i32 = 10;

/// One thread at [`RENDER_NICE`] under the normal scheduler (a `[realtime.acquisition]`
/// SCHED_FIFO priority is the service's, not the camera's: under it nice would mean
/// nothing and the renderer would take a core from the pipeline). Nice is per thread
/// on Linux, and the thread the simulator starts for its second view inherits it.
/// One, not two: every pair then renders and degrades on the same thread, so its allocations stay in one malloc
/// arena (with two, the second thread's arena grew mid-run and the soak test saw
/// acquisition's memory step by two frames). `None` when the pool cannot be built:
/// the renderer then runs at the service's own priority.
fn render_pool() -> Option<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .thread_name(|i| format!("render-{i}"))
        .start_handler(|_| {
            // SAFETY: sched_setscheduler(0, SCHED_OTHER) and setpriority on the
            // calling thread's id (gettid) only change this thread's policy and nice
            // value; a failure (no permission) leaves it as it was.
            unsafe {
                let normal = libc::sched_param { sched_priority: 0 };
                if libc::sched_setscheduler(0, libc::SCHED_OTHER, &normal) != 0 {
                    tracing::debug!("the renderer keeps the service's scheduling policy");
                }
                let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
                if libc::setpriority(libc::PRIO_PROCESS, tid, RENDER_NICE) != 0 {
                    tracing::debug!("the renderer keeps the service's priority");
                }
            }
        })
        .build()
        .ok()
}

impl SimSource {
    pub fn new(config: SimConfig) -> Result<Self, SourceError> {
        let sim = Simulator::new(config.clone())?;
        Ok(Self {
            config,
            sim,
            steps: 0,
            render_pool: render_pool(),
        })
    }
}

impl FrameSource for SimSource {
    fn size(&self) -> (u32, u32) {
        (self.config.camera.width, self.config.camera.height)
    }

    fn intrinsics(&self, _uav: Uav) -> Intrinsics {
        self.sim.intrinsics()
    }

    fn distortion(&self, _uav: Uav) -> [f64; 5] {
        self.sim.distortion().0
    }

    fn period_s(&self) -> f64 {
        1.0 / self.config.frame_rate_hz
    }

    fn simulator_seed(&self) -> Option<u64> {
        Some(self.config.seed)
    }

    fn consumed(&self) -> u64 {
        self.steps
    }

    /// The simulator steps without rendering.
    fn skip(&mut self, n: u64) {
        for _ in 0..n {
            if self.sim.step().is_none() {
                break;
            }
            self.steps += 1;
        }
    }

    fn rewind(&mut self) -> Result<(), SourceError> {
        self.sim = Simulator::new(self.config.clone())?;
        self.steps = 0;
        Ok(())
    }

    fn next_pair(
        &mut self,
        left: &mut [u8],
        right: &mut [u8],
        stride: usize,
    ) -> Option<Result<PairInfo, SourceError>> {
        let step = self.sim.step()?;
        self.steps += 1;
        let sim = &mut self.sim;
        match &self.render_pool {
            Some(pool) => pool.install(|| sim.render_pair(&step, left, right, stride)),
            None => sim.render_pair(&step, left, right, stride),
        }
        let truth = step.frames.each_ref().map(|f| TruthRow {
            uav: f.uav,
            frame: f.seq,
            t_s: f.t_s,
            pose: f.true_pose,
            target: f.target,
            target_px: f.target_px,
            gimbal: None,
        });
        Some(Ok(PairInfo {
            t_s: step.frames[0].t_s,
            poses: [step.frames[0].measured, step.frames[1].measured],
            truth: Some(truth),
            captured_ns: None,
        }))
    }
}

pub struct RecordingSource {
    rec: Recording,
    pairs: Vec<StereoPair>,
    next: usize,
}

impl RecordingSource {
    pub fn open(root: &Path) -> Result<Self, SourceError> {
        let rec = Recording::open(root)?;
        let pairs = rec.pairs();
        if pairs.is_empty() {
            return Err(SourceError::Invalid(format!(
                "{}: no stereo pairs (left and right images within half a frame period)",
                root.display()
            )));
        }
        let cameras = [Uav::Left, Uav::Right].map(|u| rec.meta.uav(u).camera);
        if (cameras[0].width, cameras[0].height) != (cameras[1].width, cameras[1].height) {
            return Err(SourceError::Invalid(format!(
                "{}: left and right cameras must have the same image size",
                root.display()
            )));
        }
        Ok(Self {
            rec,
            pairs,
            next: 0,
        })
    }
}

impl FrameSource for RecordingSource {
    fn size(&self) -> (u32, u32) {
        let c = self.rec.meta.uav(Uav::Left).camera;
        (c.width, c.height)
    }

    fn intrinsics(&self, uav: Uav) -> Intrinsics {
        self.rec.meta.uav(uav).camera.intrinsics()
    }

    fn distortion(&self, uav: Uav) -> [f64; 5] {
        self.rec.meta.uav(uav).camera.distortion
    }

    fn period_s(&self) -> f64 {
        1.0 / self.rec.meta.frame_rate_hz
    }

    fn consumed(&self) -> u64 {
        self.next as u64
    }

    fn next_time_s(&self) -> Option<f64> {
        let pair = self.pairs.get(self.next)?;
        Some(self.rec.telemetry[pair.left].t_s)
    }

    fn skip(&mut self, n: u64) {
        self.next = usize::try_from(n)
            .ok()
            .and_then(|n| self.next.checked_add(n))
            .unwrap_or(usize::MAX)
            .min(self.pairs.len());
    }

    fn rewind(&mut self) -> Result<(), SourceError> {
        self.next = 0;
        Ok(())
    }

    fn next_pair(
        &mut self,
        left: &mut [u8],
        right: &mut [u8],
        _stride: usize,
    ) -> Option<Result<PairInfo, SourceError>> {
        let pair = *self.pairs.get(self.next)?;
        self.next += 1;
        let rec = &self.rec;
        let result = (|| -> Result<PairInfo, SourceError> {
            let decode = |index: usize, dst: &mut [u8]| {
                let row = &rec.telemetry[index];
                let camera = rec.meta.uav(row.uav).camera;
                decode_image_into(&rec.root.join(&row.file), camera.width, camera.height, dst)
            };
            // Left and right decode at once (issue #15: the pair's decoding is on the
            // end-to-end clock): the left on rayon's persistent pool, never a thread
            // per pair (OpenCV keeps per-thread data of every thread that called it).
            let (l, r) = rayon::join(|| decode(pair.left, left), || decode(pair.right, right));
            l?;
            r?;
            Ok(PairInfo {
                t_s: rec.telemetry[pair.left].t_s,
                // The cameras' poses: for a tilted or gimballed camera, the body's
                // attitude turned into the equivalent nadir one (recording format v2).
                poses: [rec.camera_pose(pair.left), rec.camera_pose(pair.right)],
                truth: None,
                captured_ns: None,
            })
        })();
        Some(result)
    }
}
