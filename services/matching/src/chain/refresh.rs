//! The refresh: keyframe work off the per-pair path (issue #24).
//!
//! Every pair is answered from what frame-to-frame tracking holds (`past.rs`). The
//! work that costs tens of milliseconds — ORB on a frame, matching it with every
//! selected past image (guided or brute force), the robust fits that give the
//! tracker its ground points, and the features of a frame the keyframe ring admits —
//! runs here instead, on one frame of one UAV at a time, on a thread of its own
//! (a [`RefreshJob`] in, a [`RefreshResult`] out: the hand-over type between the
//! threads). The chain lands the result at a frame boundary (`landing.rs`).
//!
//! Choices, where the issue is silent:
//! - **When a refresh lands.** In a replay at `--rate max` and in the evaluation, on
//!   the frame `refresh_landing_frames` after its own, waiting for the thread if it
//!   is late: the answers then do not depend on how fast the machine was, and a
//!   replay repeats exactly. Live, on the first frame after it finishes: never later
//!   than it must, and the pair never waits.
//! - **A frame after a gap** (more than `frame_tracking::MAX_GAP_S` since the UAV's
//!   previous one: a sparse stream, a long drop) has nothing tracked into it, so its
//!   refresh lands on it and its pair waits: without that, a 10 FPS stream would
//!   never be located. It is the only case where a pair waits live.
//! - **One refresh in flight per UAV**; a frame that wants one while it runs waits
//!   for the next frame after it lands (the bound of the queue: two jobs).
//! - **Live, the thread runs below the per-pair path**: normal scheduling at nice 15
//!   while the stages run SCHED_FIFO (`[realtime]`), so it takes only the CPU the
//!   critical path leaves (and yields to the live simulator's renderer, the stand-in
//!   for a camera). In a replay at `--rate max` it keeps matching's priority: pairs
//!   wait for it there, and at nice 5 it was starved (45 against 56 estimates/s).
//! - **Same answers on any thread**: OpenCV's RNG is seeded per fit from the frame
//!   and the keyframe, and each UAV has its own ORB extractor, used in frame order.

use super::anchors::{KeyframeId, SeedPairs};
use super::fresh_fit::{fit_side, FitSide};
use super::{ChainTiming, Step};
use crate::config::MatchingConfig;
use crate::epipolar::MatchReject;
use crate::features::{Features, OrbExtractor};
use crate::frame::{extract_undistorted, ChainCounts, ChainError, FrameInput, FrameMeta};
use crate::frame_tracking::MAX_LANDING_FRAMES;
use crate::hamming::Nearest2;
use crate::ring::Keyframe;
use crossbeam_channel::{Receiver, Sender, TryRecvError};
use nalgebra::{Matrix3, Point3, Vector3};
use opencv::core as cv;
use shared_types::clock::monotonic_ns;
use shared_types::conventions::{camera_to_world, Uav};
use std::sync::Arc;
use std::time::Instant;

/// One frame of one UAV to refresh.
pub struct RefreshJob {
    pub(super) uav: Uav,
    pub(super) frame: FrameMeta,
    pub(super) grey: Arc<cv::Mat>,
    /// The selected past images (with their ring's UAV), each with the ground
    /// homography current → past that guides matching (if one is young enough).
    pub(super) past: Vec<(Uav, Keyframe, Option<Matrix3<f64>>)>,
    /// The frame's baseline position, when the ring would admit it.
    pub(super) admit: Option<Point3<f64>>,
    pub(super) submitted_ns: u64,
}

/// One past image's fit on the refreshed frame.
pub(super) struct PastFit {
    pub(super) id: KeyframeId,
    /// The ground homography current → past (the next guide, and a link).
    pub(super) homography: Option<Matrix3<f64>>,
    /// Ground inliers for the tracker.
    pub(super) seeds: SeedPairs,
    pub(super) result: Result<(), MatchReject>,
}

/// What a refresh hands back: the hand-over type between the refresh thread and the
/// per-pair path.
pub struct RefreshResult {
    pub(super) uav: Uav,
    pub(super) frame: FrameMeta,
    pub(super) features: Arc<Features>,
    pub(super) fits: Vec<PastFit>,
    pub(super) admit: Option<Point3<f64>>,
    pub(super) counts: ChainCounts,
    /// Timed steps (`orb`, `match`, `F`) and the whole job (`refresh`), for the trace.
    pub(super) steps: Vec<Step>,
}

/// A finished job, whatever its outcome.
pub(super) struct Landing {
    pub(super) uav: Uav,
    pub(super) seq: u64,
    pub(super) outcome: Result<RefreshResult, ChainError>,
    pub(super) submitted_ns: u64,
    pub(super) finished_ns: u64,
}

/// The refresh's own state: one ORB extractor per UAV and matching's scratch.
pub(super) struct RefreshWorker {
    config: MatchingConfig,
    orbs: [OrbExtractor; 2],
    neighbours: Vec<Option<Nearest2>>,
}

impl RefreshWorker {
    pub(super) fn new(config: &MatchingConfig) -> Result<Self, ChainError> {
        Ok(Self {
            orbs: [OrbExtractor::new(config)?, OrbExtractor::new(config)?],
            neighbours: Vec::with_capacity(config.orb_features as usize),
            config: config.clone(),
        })
    }

    /// ORB on the frame, then each past image matched and fitted.
    pub(super) fn run(&mut self, job: RefreshJob) -> Landing {
        let (uav, seq, submitted_ns) = (job.uav, job.frame.seq, job.submitted_ns);
        let outcome = self.refresh(job);
        Landing {
            uav,
            seq,
            outcome,
            submitted_ns,
            finished_ns: monotonic_ns(),
        }
    }

    fn refresh(&mut self, job: RefreshJob) -> Result<RefreshResult, ChainError> {
        let start_ns = monotonic_ns();
        // The times go to the trace as steps; fit_side also sums them here.
        let mut timing = ChainTiming::default();
        let mut steps = Vec::new();
        let input = FrameInput::from_meta(&job.frame, &job.grey);
        let (features, mut counts) = extract_undistorted(&mut self.orbs[job.uav.index()], &input)?;
        steps.push(Step::since("orb", job.uav, job.frame.seq, start_ns));
        let features = Arc::new(features);
        let up = camera_to_world(job.frame.pose.attitude()).transpose() * Vector3::z();
        let mut fits = Vec::with_capacity(job.past.len());
        for (kf_uav, kf, prior) in &job.past {
            let kf_uav = *kf_uav;
            crate::robust_fit::seed_cv_rng(&[
                0x7e_f7e5,
                job.uav.index() as u64,
                kf_uav.index() as u64,
                kf.seq,
                job.frame.seq,
            ])?;
            let fit = fit_side(
                &self.config,
                FitSide {
                    uav: kf_uav,
                    kf,
                    features: &features,
                    prior: prior.as_ref(),
                    intrinsics: (&job.frame.intrinsics, &kf.intrinsics),
                    up: &up,
                },
                &mut self.neighbours,
                &mut timing,
                &mut steps,
            );
            counts.retried_looser_ratio += fit.retried as u64;
            counts.retry_rescued += (fit.retried && fit.result.is_ok()) as u64;
            let (homography, result) = match fit.result {
                Ok(g) => (g.homography, Ok(())),
                Err(reason) => (None, Err(reason)),
            };
            fits.push(PastFit {
                id: (kf_uav.index(), kf.seq),
                homography,
                seeds: fit.seeds,
                result,
            });
        }
        let mut whole = Step::since("refresh", job.uav, job.frame.seq, start_ns);
        whole.keyframe = job.frame.seq;
        steps.push(whole);
        Ok(RefreshResult {
            uav: job.uav,
            frame: job.frame,
            features,
            fits,
            admit: job.admit,
            counts,
            steps,
        })
    }
}

/// Where refreshes run: on the calling thread when asked for (the evaluation, tests),
/// or on a thread of their own (the service).
enum Runner {
    Inline(Box<RefreshWorker>),
    Thread {
        jobs: Sender<RefreshJob>,
        results: Receiver<Landing>,
        handle: Option<std::thread::JoinHandle<()>>,
        /// Land on the fixed frame (`--rate max`), else as soon as finished.
        fixed: bool,
    },
}

/// Before or after the tracker observed the frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Moment {
    Before,
    After,
}

/// The refreshes of both UAVs: when one is due, the one in flight per UAV, and
/// where they run.
pub(super) struct Refresher {
    runner: Runner,
    landing_frames: u64,
    refresh_frames: u64,
    /// The frame each UAV's refresh in flight was taken on.
    in_flight: [Option<u64>; 2],
    /// Finished jobs not landed yet.
    done: [Option<Landing>; 2],
    /// The last frame each UAV refreshed (for the cadence).
    last: [Option<u64>; 2],
    /// Wall time of the refreshes run on the calling thread since the last
    /// [`Refresher::take_inline_us`], µs.
    inline_us: f64,
    config: MatchingConfig,
    /// Times the refresh thread died since the last [`Refresher::take_died`].
    died: u64,
}

impl Refresher {
    pub(super) fn inline(config: &MatchingConfig) -> Result<Self, ChainError> {
        Ok(Self {
            runner: Runner::Inline(Box::new(RefreshWorker::new(config)?)),
            landing_frames: config.refresh_landing_frames as u64,
            refresh_frames: config.track_refresh_frames.max(1) as u64,
            in_flight: [None, None],
            done: [None, None],
            last: [None, None],
            inline_us: 0.0,
            config: config.clone(),
            died: 0,
        })
    }

    /// Moves the refreshes to a thread of their own; `fixed`: land on the fixed frame
    /// (a replay at `--rate max`), else as soon as finished (live).
    pub(super) fn start_thread(
        &mut self,
        config: &MatchingConfig,
        fixed: bool,
    ) -> Result<(), ChainError> {
        let mut worker = RefreshWorker::new(config)?;
        let (jobs, job_rx) = crossbeam_channel::bounded::<RefreshJob>(2);
        let (result_tx, results) = crossbeam_channel::bounded::<Landing>(2);
        let handle = std::thread::Builder::new()
            .name("refresh".into())
            .spawn(move || {
                // A replay at `--rate max` waits for its refreshes at fixed frames:
                // there the thread keeps matching's priority (it is on the path of
                // throughput); live it goes below everything.
                if !fixed {
                    below_the_critical_path();
                }
                for job in job_rx {
                    if result_tx.send(worker.run(job)).is_err() {
                        break;
                    }
                }
            })
            .map_err(|e| ChainError::Config(format!("cannot start the refresh thread: {e}")))?;
        self.runner = Runner::Thread {
            jobs,
            results,
            handle: Some(handle),
            fixed,
        };
        Ok(())
    }

    /// The wall time of the refreshes run on the calling thread since the last call.
    pub(super) fn take_inline_us(&mut self) -> f64 {
        std::mem::take(&mut self.inline_us)
    }

    /// Whether `uav` has a refresh in flight.
    pub(super) fn busy(&self, uav: Uav) -> bool {
        self.in_flight[uav.index()].is_some()
    }

    /// The cadence: frame `seq` crosses a multiple of `track_refresh_frames` since the
    /// UAV's last refresh. The right UAV's phase is half a period, so the two UAVs
    /// refresh on different pairs and the thread takes one frame at a time.
    pub(super) fn cadence_due(&self, uav: Uav, seq: u64) -> bool {
        let k = self.refresh_frames;
        let phase = uav.index() as u64 * k / 2;
        self.last[uav.index()]
            .is_none_or(|last| seq.saturating_add(phase) / k != last.saturating_add(phase) / k)
    }

    pub(super) fn submit(&mut self, mut job: RefreshJob) -> Result<(), ChainError> {
        let (i, seq) = (job.uav.index(), job.frame.seq);
        if self.in_flight[i].is_some() {
            return Err(ChainError::Tracking("a second refresh for one UAV"));
        }
        if let Runner::Thread { jobs, .. } = &self.runner {
            match jobs.send(job) {
                Ok(()) => {
                    self.in_flight[i] = Some(seq);
                    self.last[i] = Some(seq);
                    return Ok(());
                }
                Err(e) => {
                    job = e.into_inner();
                    self.thread_died()?;
                }
            }
        }
        if let Runner::Inline(worker) = &mut self.runner {
            let t = Instant::now();
            self.done[i] = Some(worker.run(job));
            self.inline_us += super::micros(t);
        }
        self.in_flight[i] = Some(seq);
        self.last[i] = Some(seq);
        Ok(())
    }

    /// The refresh of `uav` that lands at `moment` of its frame `seq`, if one does,
    /// with the time the pair waited for it (µs). `now`: a refresh of `seq` itself
    /// lands on it whatever `refresh_landing_frames` says (a frame after a gap).
    pub(super) fn landing(
        &mut self,
        uav: Uav,
        seq: u64,
        moment: Moment,
        now: bool,
    ) -> Result<Option<(Landing, u64)>, ChainError> {
        let i = uav.index();
        let Some(k) = self.in_flight[i] else {
            return Ok(None);
        };
        // Before the tracker observes `seq`, a refresh of an earlier frame lands; after
        // it, only one of `seq` itself (landing_frames = 0, or a frame after a gap).
        let placed = match moment {
            Moment::Before => k < seq,
            Moment::After => k == seq,
        };
        let due = placed && (k.saturating_add(self.landing_frames) <= seq || now);
        // Live, a refresh lands when finished, but never later than the tracker keeps
        // its frame.
        let overdue = placed && k.saturating_add(MAX_LANDING_FRAMES as u64) <= seq;
        let (fixed, live) = match &self.runner {
            Runner::Inline(_) => (true, false),
            Runner::Thread { fixed, .. } => (*fixed, !*fixed),
        };
        let start = monotonic_ns();
        let landing = if due && (fixed || self.landing_frames == 0 || now) || overdue {
            self.wait(i)?
        } else if live && placed && moment == Moment::Before {
            self.poll()?;
            self.done[i].take()
        } else {
            None
        };
        let waited = shared_types::clock::elapsed_us(start, monotonic_ns());
        Ok(landing.map(|l| {
            self.in_flight[i] = None;
            (l, waited)
        }))
    }

    /// `uav`'s refresh in flight, waited for whatever its frame: for a frame after a
    /// gap, whose own refresh must land on it, and for a stream that went back (a
    /// frame no later than the refresh's: it is dropped by the caller).
    pub(super) fn drain(&mut self, uav: Uav) -> Result<Option<(Landing, u64)>, ChainError> {
        let i = uav.index();
        if self.in_flight[i].is_none() {
            return Ok(None);
        }
        let start = monotonic_ns();
        let landing = self.wait(i)?;
        let waited = shared_types::clock::elapsed_us(start, monotonic_ns());
        self.in_flight[i] = None;
        Ok(landing.map(|l| (l, waited)))
    }

    /// The stream jumped (a new segment): the refreshes in flight are waited for and
    /// dropped, the cadence starts again. The thread stays (OpenCV keeps data per
    /// thread that ever called it: a thread per segment would grow the service).
    pub(super) fn start_over(&mut self) -> Result<(), ChainError> {
        for uav in [Uav::Left, Uav::Right] {
            self.drain(uav)?;
        }
        self.done = [None, None];
        self.last = [None, None];
        Ok(())
    }

    /// The frame `uav`'s refresh in flight was taken on.
    pub(super) fn in_flight(&self, uav: Uav) -> Option<u64> {
        self.in_flight[uav.index()]
    }

    /// Every finished job, kept until it lands.
    fn poll(&mut self) -> Result<(), ChainError> {
        let mut died = false;
        if let Runner::Thread { results, .. } = &self.runner {
            loop {
                match results.try_recv() {
                    Ok(l) => {
                        let u = l.uav.index();
                        self.done[u] = Some(l);
                    }
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => {
                        died = true;
                        break;
                    }
                }
            }
        }
        if died {
            self.thread_died()?;
        }
        Ok(())
    }

    /// Waits for `uav`'s job; `None` if the thread died with it.
    fn wait(&mut self, i: usize) -> Result<Option<Landing>, ChainError> {
        loop {
            if let Some(l) = self.done[i].take() {
                return Ok(Some(l));
            }
            let Runner::Thread { results, .. } = &self.runner else {
                return Err(ChainError::Tracking("an inline refresh did not run"));
            };
            match results.recv() {
                Ok(l) => {
                    let u = l.uav.index();
                    self.done[u] = Some(l);
                }
                Err(_) => {
                    self.thread_died()?;
                    return Ok(None);
                }
            }
        }
    }

    /// The refresh thread is gone (it panicked): its jobs are lost, and refreshes run
    /// on the calling thread from now on, so the chain goes on (slower, and said so).
    fn thread_died(&mut self) -> Result<(), ChainError> {
        tracing::error!("the refresh thread has stopped: refreshes run on the pair's path now");
        self.runner = Runner::Inline(Box::new(RefreshWorker::new(&self.config)?));
        self.in_flight = [None, None];
        self.died += 1;
        Ok(())
    }

    /// How many times the refresh thread died (counted once each).
    pub(super) fn take_died(&mut self) -> u64 {
        std::mem::take(&mut self.died)
    }
}

impl Drop for Refresher {
    fn drop(&mut self) {
        if let Runner::Thread { jobs, handle, .. } = &mut self.runner {
            // Closing the queue ends the thread's loop.
            let (closed, _) = crossbeam_channel::bounded(0);
            drop(std::mem::replace(jobs, closed));
            if let Some(h) = handle.take() {
                let _ = h.join();
            }
        }
    }
}

/// Puts the calling thread on normal scheduling at nice 15: below every stage's
/// real-time priority, below a normal thread of the stages when `[realtime]` is off,
/// and below the live simulator's renderer (nice 10), which stands in for a camera
/// that costs a ground station nothing. A refusal is harmless (the thread then runs
/// as it was started).
fn below_the_critical_path() {
    // SAFETY: plain system calls on the calling thread with valid arguments.
    unsafe {
        let param = libc::sched_param { sched_priority: 0 };
        let _ = libc::sched_setscheduler(0, libc::SCHED_OTHER, &param);
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        let _ = libc::setpriority(libc::PRIO_PROCESS, tid, 15);
    }
}
