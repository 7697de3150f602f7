//! The learned detector in a stream (`[detection] kind = "yolo"`): the model on its
//! own thread, a template tracker per camera carrying the target between its results.
//!
//! A YOLO model costs tens of milliseconds a frame (YOLOv2-tiny at 416 × 416: ~66 ms on
//! this machine), more than a frame period, so it cannot sit on the per-frame path of
//! two 30 FPS cameras. Per camera, a frame goes to the model at most every
//! `every_frames` frames (sooner when the track is lost), one frame in flight at a
//! time; the per-frame thread makes the model's input (the letterboxed blob, the one
//! copy of the pixels the network needs) and keeps that frame's grey image. When the
//! model answers, the box it found is cut from that grey frame and found again in the
//! camera's newest frame ([`TemplateTrack::anchor`]); every frame after is tracked
//! ([`TemplateTrack::follow`]). A camera whose model run found nothing has no target
//! until a later run finds it.
//!
//! With flow control (`dualgeo run --rate max`) each model run is waited for on the
//! frame that started it, so a replay repeats exactly; live, it lands on whichever
//! frame is newest when it is done.

use crate::template_track::TemplateTrack;
use crate::yolo::{model_input, Letterbox, YoloConfig, YoloDetector};
use crate::{DetectError, Detection};
use crossbeam_channel::{bounded, Receiver, Sender};
use opencv::core as cv;
use opencv::prelude::*;
use std::thread::JoinHandle;

/// Search radius of the tracker beyond the box, pixels (a 640-px image: a vehicle at a
/// turn crosses ~50 px in 0.1 s, and frames come every 33 ms).
const SEARCH_PX: i32 = 32;

/// What the learned detector did since the last [`LearnedDetector::take_counts`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LearnedCounts {
    /// Model runs finished, and those that found a box of a kept class.
    pub model_runs: u64,
    pub model_found: u64,
    /// Model run time, microseconds, summed (for the mean).
    pub model_us: u64,
    /// Frames answered by the tracker, and tracks lost (the patch not found).
    pub tracked: u64,
    pub track_lost: u64,
}

struct Job {
    camera: usize,
    blob: cv::Mat,
    letterbox: Letterbox,
    grey: cv::Mat,
}

struct Answer {
    camera: usize,
    found: Result<Option<Detection>, DetectError>,
    grey: cv::Mat,
    micros: u64,
}

pub struct LearnedDetector {
    /// The model's square input size, and the pre-processing's buffers.
    input_size: i32,
    resized: cv::Mat,
    padded: cv::Mat,
    jobs: Option<Sender<Job>>,
    answers: Receiver<Answer>,
    worker: Option<JoinHandle<()>>,
    in_flight: bool,
    synchronous: bool,
    every_frames: u32,
    since_run: [u32; 2],
    /// An answer for a camera waits for that camera's next frame.
    pending: [Option<Answer>; 2],
    tracks: [TemplateTrack; 2],
    grey: cv::Mat,
    counts: LearnedCounts,
}

impl LearnedDetector {
    /// Forgets `camera`'s template track and any model answer waiting for it: its
    /// stream jumped (a new segment). The next frame runs the model.
    pub fn start_over(&mut self, camera: usize) {
        if camera > 1 {
            return;
        }
        self.tracks[camera].drop_track();
        self.pending[camera] = None;
        self.since_run[camera] = u32::MAX;
    }

    /// Loads the model (for the worker thread); `synchronous`: wait for each model
    /// run on the frame that started it.
    pub fn new(config: YoloConfig, synchronous: bool) -> Result<Self, DetectError> {
        let mut model = YoloDetector::new(config)?;
        let (every_frames, input_size) = (model.config().every_frames, model.config().input_size);
        let (jobs, job_rx) = bounded::<Job>(1);
        let (answer_tx, answers) = bounded::<Answer>(2);
        let worker = std::thread::Builder::new()
            .name("yolo".into())
            .spawn(move || {
                for job in job_rx {
                    let start = std::time::Instant::now();
                    let found = model.detect_blob(&job.blob, &job.letterbox);
                    let answer = Answer {
                        camera: job.camera,
                        found,
                        grey: job.grey,
                        micros: start.elapsed().as_micros() as u64,
                    };
                    if answer_tx.send(answer).is_err() {
                        break;
                    }
                }
            })
            .map_err(|e| DetectError::Config(format!("start the model thread: {e}")))?;
        Ok(Self {
            input_size,
            resized: cv::Mat::default(),
            padded: cv::Mat::default(),
            jobs: Some(jobs),
            answers,
            worker: Some(worker),
            in_flight: false,
            synchronous,
            every_frames,
            since_run: [u32::MAX; 2],
            pending: [None, None],
            tracks: [TemplateTrack::new(SEARCH_PX), TemplateTrack::new(SEARCH_PX)],
            grey: cv::Mat::default(),
            counts: LearnedCounts::default(),
        })
    }

    /// The target in `camera`'s (0 = left, 1 = right) BGR `frame`, if the model has
    /// found it and the tracker still holds it.
    pub fn detect(
        &mut self,
        camera: usize,
        frame: &cv::Mat,
    ) -> Result<Option<Detection>, DetectError> {
        if camera > 1 {
            return Err(DetectError::Config(format!(
                "camera {camera} is not 0 or 1"
            )));
        }
        crate::check_bgr(frame)?;
        opencv::imgproc::cvt_color_def(frame, &mut self.grey, opencv::imgproc::COLOR_BGR2GRAY)?;
        self.collect(false)?;
        let mut found = match self.pending[camera].take() {
            Some(answer) => self.land(answer)?,
            None => {
                let followed = self.tracks[camera].follow(&self.grey)?;
                if followed.is_some() {
                    self.counts.tracked += 1;
                } else if self.tracks[camera].is_tracking() {
                    self.counts.track_lost += 1;
                }
                followed.map(|(c, score)| (c, score as f32))
            }
        };
        // Lost: the model sees the next frame it can.
        let due = !self.tracks[camera].is_tracking()
            || self.since_run[camera].saturating_add(1) >= self.every_frames;
        self.since_run[camera] = self.since_run[camera].saturating_add(1);
        if due && !self.in_flight {
            let (blob, letterbox) =
                model_input(frame, self.input_size, &mut self.resized, &mut self.padded)?;
            let job = Job {
                camera,
                blob,
                letterbox,
                grey: self.grey.try_clone()?,
            };
            if let Some(jobs) = &self.jobs {
                jobs.send(job)
                    .map_err(|_| DetectError::Config("the model thread has stopped".into()))?;
                self.in_flight = true;
                self.since_run[camera] = 0;
            }
            if self.synchronous {
                self.collect(true)?;
                if let Some(answer) = self.pending[camera].take() {
                    found = self.land(answer)?;
                }
            }
        }
        Ok(found.map(|(centre, confidence)| {
            let bbox = self.tracks[camera]
                .bbox()
                .unwrap_or([centre[0], centre[1], 0.0, 0.0]);
            Detection {
                bbox,
                centre,
                confidence,
            }
        }))
    }

    /// Takes the model's answers (waiting for one when `wait`) into `pending`.
    fn collect(&mut self, wait: bool) -> Result<(), DetectError> {
        let mut next = if wait && self.in_flight {
            Some(
                self.answers
                    .recv()
                    .map_err(|_| DetectError::Config("the model thread has stopped".into()))?,
            )
        } else {
            self.answers.try_recv().ok()
        };
        while let Some(answer) = next {
            self.in_flight = false;
            self.counts.model_runs += 1;
            self.counts.model_us += answer.micros;
            let camera = answer.camera;
            self.pending[camera] = Some(answer);
            next = self.answers.try_recv().ok();
        }
        Ok(())
    }

    /// A model answer on the camera's newest frame (`self.grey`): the box found again
    /// there, with the model's confidence.
    fn land(&mut self, answer: Answer) -> Result<Option<([f64; 2], f32)>, DetectError> {
        let track = &mut self.tracks[answer.camera];
        match answer.found? {
            Some(d) => {
                self.counts.model_found += 1;
                Ok(track
                    .anchor(&answer.grey, d.bbox, d.centre, &self.grey)?
                    .map(|(c, _)| (c, d.confidence)))
            }
            None => {
                track.drop_track();
                Ok(None)
            }
        }
    }

    /// The counts since the last call, and starts again from zero.
    pub fn take_counts(&mut self) -> LearnedCounts {
        std::mem::take(&mut self.counts)
    }
}

impl Drop for LearnedDetector {
    fn drop(&mut self) {
        // Closing the job channel ends the worker's loop.
        self.jobs = None;
        while self.answers.try_recv().is_ok() {}
        if let Some(worker) = self.worker.take() {
            let _ = worker.join();
        }
    }
}
