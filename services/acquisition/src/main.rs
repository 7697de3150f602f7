//! `dualgeo-acquisition`: the acquisition service shell. Streams stereo pairs from the
//! live simulator, a recording or a flight ([`acquisition::source`]) into the frame
//! services: each frame is rendered or decoded *directly into a loaned shared-memory
//! sample* (the only write of its pixels; a flight's video frame is decoded by OpenCV
//! and copied once, docs/flight-io.md), stamped, sent, and the detection and matching
//! stages are woken.
//!
//! Acquisition never blocks: when no sample can be loaned (every buffer in use), the pair
//! is dropped and counted (`pairs_dropped`). A corrupt image in a recording is logged
//! with its path and counted (`bad_frames`); its pair is skipped and the stream goes on.
//! At the end of the stream the supervisor is woken with the end-of-stream event and
//! the process idles until it is told to stop (SIGTERM), so nothing it sent is lost.
//!
//! Pacing: `realtime` follows the recording's (or simulator's) clock and never waits
//! for anyone; `max` is flow-controlled instead: one pair ahead of matching at most,
//! which acknowledges every pair it finishes (or drops) on the `wake/acquisition` event
//! service. A missing acknowledgement is given up after 1 s (`flow_timeouts`); a late
//! one never counts beyond the pairs sent, so a timeout cannot open a second slot.
//! The end of the stream is announced once the last pair is acknowledged.
//!
//! Restart (issue #13): with `--state-dir`, the stream position is checkpointed before
//! each pair is sent ([`acquisition::resume`]). A restarted acquisition (incarnation > 0)
//! skips to it: the recording's next pair, or the simulator stepped (not rendered) to
//! it; the clock is re-anchored so the resumed pair is due at once, and the simulator's
//! stream log is appended to.
//!
//! Live input (issue #13): every pair passes [`LiveGate`] before it is sent; a pair with
//! a non-finite pose, time going backwards, a frame without a pose or a pose without a
//! frame, pixels of the wrong size, or left/right skew beyond the pairing window is
//! dropped and counted (`live_faults.<kind>`); a telemetry gap is counted. The first
//! fault of a kind is logged, the totals when the stream stops. `--inject-faults RATE`
//! makes the live simulator deliver such faults (`injected_faults`, and
//! `injected_lost` for the pairs a gap loses in transit).
//!
//! Histograms (µs): `produce` (render or decode of a pair), `pacing_lag` (how late a
//! pair left against its schedule), `resume` (skipping to the checkpointed position).
//! Counters: `pairs_in`, `frames_in`, `pairs_dropped`, `bad_frames`, `loops`,
//! `flow_timeouts`, `resumed`, `checkpoint_refused`, `checkpoint_failed`, and the
//! source's own as `source.<name>` (a flight's `no_pose_position`, `no_pose_attitude`,
//! `no_pose_gimbal`, `unpaired_frames`, `tlog_crc_errors`, `tlog_resyncs`,
//! `tlog_truncated`).

use acquisition::live_gate::{LiveGate, LiveSample};
use acquisition::recording::{StreamLog, TelemetryRow, TruthRow};
use acquisition::resume::StreamPosition;
use acquisition::sim::faults::FaultInjector;
use acquisition::sim::ScenarioArgs;
use acquisition::source::{FrameSource, SourceError};
use anyhow::{bail, Context, Result};
use clap::Parser;
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::EventId;
use shared_types::clock::{elapsed_us, monotonic_ns};
use shared_types::conventions::Uav;
use shared_types::messages::{FrameHeader, PixelFormat};
use shared_types::shell::{self, apply_realtime, init_tracing, Permanent, ServiceArgs, StatsSaver};
use shared_types::stats::StageStats;
use shared_types::transport::{Endpoint, FramePublisher, Ipc, Stage, END_OF_STREAM_EVENT};
use std::path::PathBuf;
use std::time::Duration;

#[derive(Parser)]
#[command(about = "dualgeo acquisition service (started by `dualgeo run`)")]
struct Args {
    #[command(flatten)]
    service: ServiceArgs,
    /// `sim` (the live simulator), a recording directory, or a flight's flight.toml.
    #[arg(long, default_value = "sim")]
    source: String,
    /// The simulated scenario (with `--source sim`).
    #[command(flatten)]
    scenario: ScenarioArgs,
    /// `realtime` (the recorded/simulated clock), `max` (as fast as possible) or a pair
    /// rate in Hz.
    #[arg(long, default_value = "realtime")]
    rate: String,
    /// Start again at the end (soak runs); stops on SIGINT/SIGTERM.
    #[arg(long = "loop")]
    looping: bool,
    /// Stream the source this many times, then end (a `--loop` that stops; each pass
    /// is a stream segment of its own).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    laps: Option<u64>,
    /// Simulator: write what was streamed (telemetry.csv, truth.csv) here.
    #[arg(long)]
    log_dir: Option<PathBuf>,
}

/// `--rate max`: pairs sent but not yet finished by matching, at most. One, so that a
/// replay repeats exactly (issue #23): with two in flight, the second pair's frames
/// reached matching before the first was matched, and whether the first was matched
/// (or abandoned for the newer one) and which frames ran ORB depended on which process
/// was scheduled first: three replays of one recording gave three track.csv files.
/// One in flight costs the overlap of detection with matching (figures in
/// docs/pipeline.md).
const MAX_IN_FLIGHT: u64 = 1;

#[derive(Debug, Clone, Copy)]
enum Rate {
    Realtime,
    Max,
    Hz(f64),
}

fn parse_rate(s: &str) -> Result<Rate> {
    match s {
        "realtime" => Ok(Rate::Realtime),
        "max" => Ok(Rate::Max),
        other => match other.parse::<f64>() {
            Ok(hz) if hz.is_finite() && hz > 0.0 => Ok(Rate::Hz(hz)),
            _ => bail!("--rate must be realtime, max or a positive number of Hz, got {other:?}"),
        },
    }
}

/// When a pair is due on the replay clock, seconds after the start: its stream time
/// (`realtime`), its place in a fixed rate, or never (`max`).
fn due_s(rate: Rate, t_stream: f64, seq: u64) -> Option<f64> {
    match rate {
        Rate::Realtime => Some(t_stream),
        Rate::Hz(hz) => Some(seq as f64 / hz),
        Rate::Max => None,
    }
}

/// Waits until CLOCK_MONOTONIC reaches `due_ns` (never returning before it);
/// `false` on a stop request.
fn wait_until(endpoint: &Endpoint, due_ns: u64) -> bool {
    loop {
        let now = monotonic_ns();
        if now >= due_ns {
            return true;
        }
        if endpoint
            .node
            .wait(Duration::from_nanos(due_ns - now))
            .is_err()
        {
            return false;
        }
    }
}

/// `--rate max` flow control: waits until fewer than `limit` pairs of the `seq` sent
/// are unacknowledged. A second without any acknowledgement gives the pair up
/// (`flow_timeouts`: matching lost it); acknowledgements never count beyond the pairs
/// sent, so a late one after a timeout cannot open an extra slot. `false` on a stop
/// request.
fn await_acks(
    listener: &Listener<Ipc>,
    endpoint: &Endpoint,
    stats: &mut StageStats,
    acknowledged: &mut u64,
    seq: u64,
    limit: u64,
) -> Result<bool> {
    let mut waited = false;
    while seq.saturating_sub(*acknowledged) >= limit {
        if waited {
            stats.count("flow_timeouts", 1);
            *acknowledged = seq;
            break;
        }
        listener
            .timed_wait(
                |e| *acknowledged = (*acknowledged + e.count).min(seq),
                Duration::from_secs(1),
            )
            .map_err(|e| anyhow::anyhow!("acknowledgement listener: {e:?}"))?;
        waited = seq.saturating_sub(*acknowledged) >= limit;
        if endpoint.node.wait(Duration::ZERO).is_err() {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Adds what the source counted since the last call to `stats`, as `source.<name>`.
fn count_source(source: &mut dyn FrameSource, stats: &mut StageStats) {
    for (name, n) in source.take_counts() {
        if n > 0 {
            stats.count(&format!("source.{name}"), n);
        }
    }
}

/// Exits with [`shell::EXIT_PERMANENT`] when the input or configuration was refused
/// (the supervisor does not restart that), 1 on any other failure.
fn main() -> std::process::ExitCode {
    shell::exit_code(run())
}

fn run() -> Result<()> {
    let args = Args::parse();
    init_tracing("acquisition");
    // Before the source starts its threads: they inherit it (the simulator's renderer
    // goes back to the normal scheduler, `source::render_pool`).
    apply_realtime(args.service.config.as_deref(), "acquisition")
        .map_err(|e| Permanent::new("[realtime]", e))?;
    let rate = parse_rate(&args.rate).map_err(|e| Permanent::because(e.to_string()))?;
    let mut source = acquisition::source::open(&args.source, &args.scenario)
        .map_err(|e| Permanent::new(format!("--source {}", args.source), e))?;
    let (width, height) = source.size();
    let stride = width as usize * 3;
    let frame_bytes = stride * height as usize;
    let endpoint = Endpoint::new(&args.service.run_id, "acquisition")?;
    let publishers: [FramePublisher; 2] = [
        endpoint.frame_publisher(Uav::Left, frame_bytes)?,
        endpoint.frame_publisher(Uav::Right, frame_bytes)?,
    ];
    let wake = [
        endpoint.notifier(Stage::Detection)?,
        endpoint.notifier(Stage::Matching)?,
    ];
    let wake_supervisor = endpoint.notifier(Stage::Supervisor)?;
    // `--rate max` replays as fast as matching finishes pairs (never more than
    // MAX_IN_FLIGHT ahead), so no frame is produced only to be dropped.
    let acks = match rate {
        Rate::Max => Some(endpoint.listener(Stage::Acquisition)?),
        _ => None,
    };
    let mut stats = StageStats::new("acquisition");
    let state_path = args.service.state_file("acquisition.ckpt");
    let resumed = match (&state_path, args.service.incarnation) {
        (Some(path), n) if n > 0 => match StreamPosition::load(path) {
            Ok(p) => p,
            Err(e) => {
                stats.count("checkpoint_refused", 1);
                tracing::warn!("stream position ignored, starting from the first pair: {e}");
                None
            }
        },
        _ => None,
    };
    let mut position = resumed.unwrap_or_default();
    // `--rate max`: a resumed stream has nothing in flight.
    let mut acknowledged = position.next_seq;
    if let Some(p) = resumed {
        let t0 = monotonic_ns();
        source.skip(p.consumed);
        // What the source counted on opening (a flight's damaged log records) was
        // counted by the first incarnation already; the merged statistics keep it once.
        drop(source.take_counts());
        stats.record("resume", elapsed_us(t0, monotonic_ns()));
        stats.count("resumed", 1);
        tracing::info!(
            next_pair = p.next_seq,
            loops = p.loops,
            "resuming the stream"
        );
    }
    let live_sim = source.simulator_seed();
    let mut log = match (live_sim, &args.log_dir) {
        (Some(_), Some(dir)) if resumed.is_some() => Some(StreamLog::reopen(dir)?),
        (Some(_), Some(dir)) => Some(StreamLog::create(dir)?),
        _ => None,
    };
    let intrinsics = [Uav::Left, Uav::Right].map(|u| {
        let k = source.intrinsics(u);
        [k.fx, k.fy, k.cx, k.cy]
    });
    let distortion = [Uav::Left, Uav::Right].map(|u| source.distortion(u));
    let mut saver = StatsSaver::new(&args.service);
    let mut trace = args.service.tracer("acquisition");
    let produce_name = if source.simulator_seed().is_some() {
        "render"
    } else {
        "decode"
    };
    let mut gate = LiveGate::new((width, height), source.period_s());
    let mut injector = match (live_sim, args.scenario.inject_faults) {
        (Some(seed), Some(rate)) => Some(FaultInjector::new(seed, rate).ok_or_else(|| {
            Permanent::because(format!("--inject-faults must be in [0, 1], got {rate}"))
        })?),
        (_, Some(_)) => {
            return Err(
                Permanent::because("--inject-faults works with the live simulator only").into(),
            )
        }
        _ => None,
    };
    tracing::info!(run = endpoint.run_id(), source = %args.source, width, height, ?rate, "acquisition streaming");

    let mut start_ns = monotonic_ns();
    // A resumed stream's clock is re-anchored at its first pair.
    let mut reanchor = resumed.is_some();
    let StreamPosition {
        next_seq: mut seq,
        mut t_offset,
        mut t_first,
        mut last_t,
        ..
    } = position;
    let mut signalled = false;
    'stream: loop {
        // Paced pairs usually wait (and see a stop request there), but a source slower
        // than its clock, or one whose pairs are all dropped, never does: look once per
        // pair.
        if endpoint.node.wait(Duration::ZERO).is_err() {
            signalled = true;
            break 'stream;
        }
        if let Some(listener) = &acks {
            if !await_acks(
                listener,
                &endpoint,
                &mut stats,
                &mut acknowledged,
                seq,
                MAX_IN_FLIGHT,
            )? {
                signalled = true;
                break 'stream;
            }
        }
        // Loan both samples first: a pair is only produced when both fit.
        let loans = (
            publishers[0].loan_slice(frame_bytes),
            publishers[1].loan_slice(frame_bytes),
        );
        let (Ok(mut left), Ok(mut right)) = loans else {
            stats.count("pairs_dropped", 1);
            // Every sample is in use downstream; try again at the next frame time.
            if endpoint
                .node
                .wait(Duration::from_secs_f64(source.period_s()))
                .is_err()
            {
                signalled = true;
                break 'stream;
            }
            continue;
        };
        // The honest clock (issue #15): a paced replay whose source knows the next
        // pair's time (a recording, a video file) waits for the pair's moment first and
        // only then decodes, as a live stream must; the moment is its capture time.
        let mut moment_ns: Option<u64> = None;
        let period_ns = (source.period_s() * 1e9) as u64;
        while let (Some(t_next), false) = (source.next_time_s(), matches!(rate, Rate::Max)) {
            let t_stream = t_next - *t_first.get_or_insert(t_next) + t_offset;
            let due = due_s(rate, t_stream, seq).unwrap_or(t_stream);
            if reanchor {
                start_ns = monotonic_ns().saturating_sub((due * 1e9) as u64);
                reanchor = false;
            }
            let due_ns = start_ns + (due * 1e9) as u64;
            // Behind the clock by more than a frame (the machine was busy): a live
            // stream would have replaced this pair by now. Skip it, counted, and
            // take the next; latency does not pile up.
            if matches!(rate, Rate::Realtime) && monotonic_ns() > due_ns + period_ns {
                gate.skipped(t_next + t_offset);
                source.skip(1);
                position.consumed = source.consumed();
                stats.count("pairs_behind", 1);
                continue;
            }
            if !wait_until(&endpoint, due_ns) {
                signalled = true;
                break 'stream;
            }
            stats.record("pacing_lag", elapsed_us(due_ns, monotonic_ns()));
            moment_ns = Some(due_ns);
            break;
        }
        let produce_start = monotonic_ns();
        let info = match source.next_pair(left.payload_mut(), right.payload_mut(), stride) {
            None => {
                let again = args.looping || args.laps.is_some();
                if again && args.laps.is_none_or(|n| position.loops + 1 < n) {
                    source.rewind()?;
                    t_offset += last_t + source.period_s() - t_first.unwrap_or(0.0);
                    t_first = None;
                    position.consumed = 0;
                    position.loops += 1;
                    stats.count("loops", 1);
                    continue;
                }
                break 'stream;
            }
            Some(Err(SourceError::Waiting)) => {
                count_source(source.as_mut(), &mut stats);
                continue;
            }
            Some(Err(SourceError::Dropped)) => {
                position.consumed = source.consumed();
                count_source(source.as_mut(), &mut stats);
                continue;
            }
            Some(Err(e)) => {
                position.consumed = source.consumed();
                tracing::warn!("pair skipped: {e:#}");
                stats.count("bad_frames", 1);
                continue;
            }
            Some(Ok(info)) => info,
        };
        position.consumed = source.consumed();
        count_source(source.as_mut(), &mut stats);
        // The gate sees the stream's clock (a loop goes on forward), as a live source's.
        let mut delivered = info.poses.map(|pose| LiveSample {
            t_s: info.t_s + t_offset,
            pose: Some(pose),
            size: Some((width, height)),
        });
        if let Some(inj) = injector.as_mut() {
            let before = inj.injected;
            let arrived = inj.apply(&mut delivered, source.period_s());
            stats.count("injected_faults", inj.injected - before);
            if !arrived {
                stats.count("injected_lost", 1);
                continue;
            }
        }
        let faults_before = gate.total();
        let checked = gate.check(&delivered);
        if gate.total() != faults_before {
            for (fault, n) in gate.counts() {
                stats
                    .counters
                    .insert(format!("live_faults.{}", fault.name()), *n);
            }
        }
        if checked.is_err() {
            continue;
        }
        let produced = monotonic_ns();
        // The source's own time: from the call, or from the frames' moment when they
        // arrived during it (a live source waits for its streams).
        let source_start = info
            .captured_ns
            .map_or(produce_start, |c| c.max(produce_start));
        stats.record("produce", elapsed_us(source_start, produced));
        let t_first_pair = *t_first.get_or_insert(info.t_s);
        last_t = info.t_s;
        let t_stream = info.t_s - t_first_pair + t_offset;
        // A source that produces ahead (the simulator, standing in for the sensor) is
        // paced after producing: the pair leaves at its moment, never earlier, and
        // that moment is its capture time.
        // (A live source is paced by its streams and stamps its own capture.)
        let paced_here = moment_ns.is_none() && info.captured_ns.is_none();
        if let (true, Some(due)) = (paced_here, due_s(rate, t_stream, seq)) {
            if reanchor {
                start_ns = monotonic_ns().saturating_sub((due * 1e9) as u64);
            }
            let due_ns = start_ns + (due * 1e9) as u64;
            if !wait_until(&endpoint, due_ns) {
                signalled = true;
                break 'stream;
            }
            stats.record("pacing_lag", elapsed_us(due_ns, monotonic_ns()));
            moment_ns = Some(due_ns);
            // Rendered more than a frame late: the sensor it stands in for has moved
            // on; skip the pairs it would have delivered meanwhile (counted).
            let late = produced.saturating_sub(due_ns) / period_ns.max(1);
            if matches!(rate, Rate::Realtime) && late > 0 {
                gate.skipped(info.t_s + t_offset + late as f64 * source.period_s());
                source.skip(late);
                stats.count("pairs_behind", late);
            }
        }
        reanchor = false;
        // Capture: a live source's own stamp (when its frames arrived), else the
        // pair's moment on the replay clock; with `--rate max`, when the source handed
        // the pair over (the end-to-end is then the pipeline's alone, decode excluded).
        let captured = info.captured_ns.or(moment_ns).unwrap_or(produced);
        trace.span(produce_name, seq, None, source_start, produced);
        let publish_start = monotonic_ns();
        for (uav, sample) in [(Uav::Left, &mut left), (Uav::Right, &mut right)] {
            *sample.user_header_mut() = FrameHeader {
                seq,
                capture_ns: captured,
                t_s: info.t_s + t_offset,
                uav: uav.index() as u8,
                pixel_format: PixelFormat::Bgr8 as u32,
                width,
                height,
                stride: stride as u32,
                pose: info.poses[uav.index()],
                intrinsics: intrinsics[uav.index()],
                distortion: distortion[uav.index()],
                // Each lap of a looped recording is a segment of its own: the world
                // jumps back to the recording's start.
                segment: u32::try_from(position.loops).unwrap_or(u32::MAX),
                ..Default::default()
            };
        }
        // The position after this pair, saved before it is sent (never sent twice).
        position = StreamPosition {
            next_seq: seq + 1,
            t_offset,
            t_first,
            last_t,
            ..position
        };
        if let Some(path) = &state_path {
            if let Err(e) = position.save(path) {
                stats.count("checkpoint_failed", 1);
                tracing::warn!("stream position not saved: {e}");
            }
        }
        if let (Some(log), Some(truth)) = (log.as_mut(), &info.truth) {
            for (uav, t) in truth.iter().enumerate() {
                let telemetry = TelemetryRow {
                    uav: t.uav,
                    frame: seq,
                    file: "live".into(),
                    t_s: info.t_s + t_offset,
                    pose: info.poses[uav],
                    gimbal: None,
                };
                let truth = TruthRow {
                    frame: seq,
                    t_s: info.t_s + t_offset,
                    ..t.clone()
                };
                log.append(&telemetry, &truth)?;
            }
            log.flush()?;
        }
        let mut sent_ns = publish_start;
        for mut sample in [left, right] {
            sent_ns = monotonic_ns();
            sample.user_header_mut().published_ns = sent_ns;
            sample.send().context("send frame")?;
        }
        // Ends when the last frame was stamped: what follows cannot precede it.
        trace.span("publish", seq, None, publish_start, sent_ns);
        for w in &wake {
            w.notify().context("wake a stage")?;
        }
        stats.count("pairs_in", 1);
        stats.count("frames_in", 2);
        seq += 1;
        saver.tick(&stats);
        trace.maybe_flush();
    }
    trace.flush();
    count_source(source.as_mut(), &mut stats);
    if let Some(log) = log {
        log.finish()?;
    }
    if !gate.counts().is_empty() {
        let totals: Vec<String> = gate
            .counts()
            .iter()
            .map(|(f, n)| format!("{} {n}", f.name()))
            .collect();
        tracing::warn!("live input faults: {}", totals.join(", "));
    }
    // `--rate max`: the last pair is answered before the end is announced, so the
    // supervisor's drain never races the last estimate.
    if let (false, Some(listener)) = (signalled, &acks) {
        signalled = !await_acks(listener, &endpoint, &mut stats, &mut acknowledged, seq, 1)?;
    }
    if !signalled {
        tracing::info!(pairs = seq, "end of stream");
        wake_supervisor
            .notify_with_custom_event_id(EventId::new(END_OF_STREAM_EVENT))
            .context("tell the supervisor the stream ended")?;
        // Stay until the supervisor stops us: what was sent stays readable.
        while endpoint.node.wait(Duration::from_millis(200)).is_ok() {}
    }
    let path = saver.finish(&stats)?;
    tracing::info!(stats = %path.display(), "acquisition stopped");
    Ok(())
}
