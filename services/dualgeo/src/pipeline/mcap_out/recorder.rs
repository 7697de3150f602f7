//! The recorder thread of `--mcap`: its own iceoryx2 node in the supervisor, one more
//! subscriber on each UAV's frames (the frame services keep a spare for it), on the
//! detections, the observation sets and the estimates. It is not on the estimate's path:
//! it polls its subscribers every [`POLL`] (the stages are woken by their producers; a
//! monitor is not, so that no stage waits on it), and a frame it cannot keep up with is
//! overwritten in its queue, never held back: counted in `mcap.frames_lost`.
//!
//! A failed write (disk full) ends the recording, not the run: counted in
//! `mcap.write_failed`, logged once, and the file is finished as far as it got.

use super::encode::{self, StageTimes};
use super::schemas::{self, Channel, CHANNELS};
use super::McapArgs;
use crate::pipeline::live_out::TargetFix;
use acquisition::recording::Origin;
use anyhow::{anyhow, Context, Result};
use serde_json::Value;
use shared_types::conventions::Uav;
use shared_types::messages::{DetectionMsg, EstimateMsg, FrameHeader, ObservationSetMsg};
use shared_types::service_names::Topic;
use shared_types::transport::{Endpoint, FrameSubscriber, MsgSubscriber};
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// How often the recorder looks at its subscribers when it found nothing: a frame
/// queue holds 2 frames (66 ms at 30 FPS), so 5 ms loses none unless encoding lags.
const POLL: Duration = Duration::from_millis(5);
/// Pairs whose stage times are kept waiting for their estimate.
const JOIN_WINDOW: u64 = 256;

/// What the recorder wrote.
#[derive(Debug, Default, Clone)]
pub struct RecorderReport {
    /// Messages per channel of [`CHANNELS`].
    pub messages: [u64; CHANNELS.len()],
    /// `mcap.*` counters for the supervisor's report.
    pub counters: BTreeMap<&'static str, u64>,
}

struct Subscribers {
    frames: [FrameSubscriber; 2],
    detections: MsgSubscriber<DetectionMsg>,
    observations: MsgSubscriber<ObservationSetMsg>,
    estimates: MsgSubscriber<EstimateMsg>,
}

/// The stage times of one pair, per UAV where there are two.
#[derive(Default)]
struct Join {
    frames: [Option<u64>; 2],
    detections: [Option<u64>; 2],
    observations: Option<u64>,
}

impl Join {
    fn times(&self) -> StageTimes {
        let both = |a: [Option<u64>; 2]| Some(a[0]?.max(a[1]?));
        StageTimes {
            frames_ns: both(self.frames),
            detections_ns: both(self.detections),
            observations_ns: self.observations,
        }
    }
}

struct Recorder {
    writer: Option<mcap::Writer<BufWriter<File>>>,
    channel_ids: [u16; CHANNELS.len()],
    report: RecorderReport,
    origin: Option<Origin>,
    image_every: u64,
    jpeg_quality: i32,
    last_frame_seq: [Option<u64>; 2],
    joins: HashMap<u64, Join>,
}

impl Recorder {
    fn create(path: &Path, origin: Option<Origin>, args: &McapArgs) -> Result<Self> {
        let file = File::create(path).with_context(|| format!("create {}", path.display()))?;
        let mut writer = mcap::WriteOptions::new()
            .compression(None)
            .library(format!("dualgeo {}", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(|e| anyhow!("start {}: {e}", path.display()))?;
        let mut channel_ids = [0u16; CHANNELS.len()];
        let mut schema_ids: HashMap<&str, u16> = HashMap::new();
        for (i, c) in CHANNELS.iter().enumerate() {
            let schema_id = match schema_ids.get(c.schema) {
                Some(&id) => id,
                None => {
                    let text = schemas::schema_text(c.schema)
                        .ok_or_else(|| anyhow!("no schema text for {}", c.schema))?;
                    let id =
                        writer.add_schema(c.schema, schemas::SCHEMA_ENCODING, text.as_bytes())?;
                    schema_ids.insert(c.schema, id);
                    id
                }
            };
            channel_ids[i] = writer.add_channel(
                schema_id,
                c.topic,
                schemas::MESSAGE_ENCODING,
                &BTreeMap::new(),
            )?;
        }
        Ok(Self {
            writer: Some(writer),
            channel_ids,
            report: RecorderReport::default(),
            origin,
            image_every: args.mcap_image_every.max(1),
            jpeg_quality: i32::from(args.mcap_jpeg_quality),
            last_frame_seq: [None; 2],
            joins: HashMap::new(),
        })
    }

    fn count(&mut self, name: &'static str) {
        *self.report.counters.entry(name).or_insert(0) += 1;
    }

    fn write(&mut self, channel: Channel, log_ns: u64, publish_ns: u64, msg: &Value) {
        let Some(w) = self.writer.as_mut() else {
            return;
        };
        let i = channel.index();
        let header = mcap::records::MessageHeader {
            channel_id: self.channel_ids[i],
            sequence: self.report.messages[i] as u32,
            log_time: log_ns,
            publish_time: publish_ns,
        };
        let data = msg.to_string();
        match w.write_to_known_channel(&header, data.as_bytes()) {
            Ok(()) => self.report.messages[i] += 1,
            Err(e) => {
                tracing::warn!(error = %e, "MCAP write failed: the recording stops here");
                self.count("mcap.write_failed");
                if let Some(mut w) = self.writer.take() {
                    let _ = w.finish();
                }
            }
        }
    }

    fn join(&mut self, pair_seq: u64) -> &mut Join {
        if self.joins.len() > 4 * JOIN_WINDOW as usize {
            self.joins.retain(|&k, _| k + JOIN_WINDOW >= pair_seq);
        }
        self.joins.entry(pair_seq).or_default()
    }

    fn on_frame(&mut self, h: &FrameHeader, payload: &[u8]) {
        let uav = usize::from(h.uav.min(1));
        if let Some(last) = self.last_frame_seq[uav] {
            if h.seq > last + 1 {
                *self.report.counters.entry("mcap.frames_lost").or_insert(0) += h.seq - last - 1;
            }
        }
        self.last_frame_seq[uav] = Some(h.seq);
        self.join(h.seq).frames[uav] = Some(h.published_ns);
        let Some((log_ns, time)) = encode::stamp(h.t_s) else {
            return self.count("mcap.bad_time");
        };
        if h.seq.is_multiple_of(self.image_every) {
            match encode::jpeg(h, payload, self.jpeg_quality) {
                Ok(j) => {
                    let m = encode::image_message(&time, uav, &j);
                    self.write(Channel::Image(uav), log_ns, h.published_ns, &m);
                }
                Err(e) => {
                    tracing::debug!(error = %e, "frame not encoded");
                    self.count("mcap.encode_failed");
                }
            }
        }
        match encode::camera_pose_message(&time, h) {
            Some(m) => self.write(Channel::Pose(uav), log_ns, h.published_ns, &m),
            None => self.count("mcap.bad_pose"),
        }
    }

    fn on_detection(&mut self, d: &DetectionMsg) {
        let uav = usize::from(d.uav.min(1));
        self.join(d.seq).detections[uav] = Some(d.published_ns);
        let Some((log_ns, time)) = encode::stamp(d.t_s) else {
            return self.count("mcap.bad_time");
        };
        let m = encode::detection_message(&time, d);
        self.write(Channel::Detection(uav), log_ns, d.published_ns, &m);
    }

    fn on_estimate(&mut self, e: &EstimateMsg) {
        let times = self
            .joins
            .remove(&e.pair_seq)
            .map(|j| j.times())
            .unwrap_or_default();
        let Some((log_ns, time)) = encode::stamp(e.t_s) else {
            return self.count("mcap.bad_time");
        };
        if encode::is_valid(e) {
            if let Some(fix) = self.origin.as_ref().and_then(|o| TargetFix::of(e, o)) {
                let m = encode::fix_message(&time, &fix, e);
                self.write(Channel::TargetFix, log_ns, e.published_ns, &m);
            }
            let m = encode::target_pose_message(&time, e);
            self.write(Channel::TargetPose, log_ns, e.published_ns, &m);
            let m = encode::quality_message(&time, e);
            self.write(Channel::TargetQuality, log_ns, e.published_ns, &m);
        }
        let m = encode::latency_message(&time, e, &times);
        self.write(Channel::Latency, log_ns, e.published_ns, &m);
        if let Some(origin) = &self.origin {
            if encode::is_valid(e) || !e.tracks().is_empty() {
                let m = encode::targets_message(&time, e, origin);
                self.write(Channel::Targets, log_ns, e.published_ns, &m);
            }
        }
    }

    /// Takes everything queued; `true` if there was anything.
    fn drain(&mut self, s: &Subscribers) -> Result<bool> {
        let mut any = false;
        for sub in &s.frames {
            while let Some(sample) = sub.receive().map_err(|e| anyhow!("receive frame: {e:?}"))? {
                any = true;
                let h = *sample.user_header();
                self.on_frame(&h, sample.payload());
            }
        }
        while let Some(s) = s.detections.receive().context("receive detection")? {
            any = true;
            self.on_detection(&{ *s.payload() });
        }
        while let Some(s) = s.observations.receive().context("receive observations")? {
            any = true;
            let (pair, published) = (s.payload().pair_seq, s.payload().published_ns);
            self.join(pair).observations = Some(published);
        }
        while let Some(s) = s.estimates.receive().context("receive estimate")? {
            any = true;
            self.on_estimate(&{ *s.payload() });
        }
        Ok(any)
    }

    fn finish(mut self) -> Result<RecorderReport> {
        if let Some(mut w) = self.writer.take() {
            w.finish()
                .map_err(|e| anyhow!("finish the MCAP file: {e}"))?;
            w.into_inner()
                .into_inner()
                .map_err(|e| anyhow!("flush the MCAP file: {e}"))?;
        }
        Ok(self.report)
    }
}

/// The thread's body: subscribe, say ready (or why not), record until `stop`, drain,
/// finish the file.
pub fn run(
    run_id: &str,
    path: &Path,
    origin: Option<Origin>,
    args: &McapArgs,
    stop: &AtomicBool,
    ready: std::sync::mpsc::Sender<Result<(), String>>,
) -> Result<RecorderReport> {
    let setup = (|| -> Result<(Endpoint, Subscribers, Recorder)> {
        let endpoint = Endpoint::new(run_id, "recorder")?;
        let subs = Subscribers {
            frames: [
                endpoint.frame_subscriber(Uav::Left)?,
                endpoint.frame_subscriber(Uav::Right)?,
            ],
            detections: endpoint.subscriber(Topic::Detections)?,
            observations: endpoint.subscriber(Topic::Observations)?,
            estimates: endpoint.subscriber(Topic::Estimates)?,
        };
        let recorder = Recorder::create(path, origin, args)?;
        Ok((endpoint, subs, recorder))
    })();
    let (_endpoint, subs, mut recorder) = match setup {
        Ok(s) => {
            let _ = ready.send(Ok(()));
            s
        }
        Err(e) => {
            let _ = ready.send(Err(format!("{e:#}")));
            return Err(e);
        }
    };
    while !stop.load(Ordering::Acquire) {
        if !recorder.drain(&subs)? {
            std::thread::sleep(POLL);
        }
    }
    recorder.drain(&subs)?;
    recorder.finish()
}
