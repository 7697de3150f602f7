//! `dualgeo run`: the supervisor of the four service processes.
//!
//! 1. Starts detection, matching and geolocation, and waits until every one of them is
//!    connected (subscribers and listeners counted through iceoryx2).
//! 2. Starts acquisition, which streams the live simulator (default), a recording or a
//!    flight (videos + MAVLink logs, docs/flight-io.md).
//! 3. Collects the estimates (event-driven: a WaitSet on its wake listener, with a
//!    100 ms tick for the progress bar and to watch the children).
//! 4. Restarts a service that dies (`restart.rs`; `--restart never` ends the run
//!    instead). The services checkpoint their state under `<out>/state/`, so a
//!    restarted one resumes: acquisition's stream position, matching's keyframe rings,
//!    geolocation's filter.
//! 5. On end of stream (after the pipeline has drained), `--run-for-s`, SIGINT or
//!    SIGTERM: stops the services, gathers their latency histograms and counters, and
//!    writes the outputs (`outputs.rs`). A service that fails to start, or dies more
//!    often than the policy allows, ends the run with its name, its exit status and a
//!    non-zero exit.
//!
//! Valid estimates also go out live as they arrive: MAVLink and Cursor-on-Target
//! (`live_out/`, `--mavlink-out`, `--cot-out`); `--mcap` records the run for Foxglove
//! (`mcap_out/`).

mod accuracy;
mod children;
mod collect;
mod latency;
mod live_out;
mod mcap_out;
mod outputs;
pub(crate) mod plots;
mod restart;
mod soak;
mod trace_file;
mod track;

use anyhow::{bail, Context, Result};
use children::Service;
use shared_types::service_names::new_run_id;
use shared_types::transport::clean_dead_nodes;
use std::path::{Path, PathBuf};
use std::time::Duration;

#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// `sim` (the live simulator), a recording directory, or a flight's flight.toml.
    #[arg(long, default_value = "sim")]
    pub source: String,
    /// The simulated scenario (with `--source sim`).
    #[command(flatten)]
    pub scenario: acquisition::sim::ScenarioArgs,
    /// `realtime` (the recording's clock; the simulator's 30 FPS), `max`, or pairs/s.
    #[arg(long, default_value = "realtime")]
    pub rate: String,
    /// Stream the source again and again until SIGINT/SIGTERM (soak runs).
    #[arg(long = "loop")]
    pub looping: bool,
    /// Stream the source this many times, then end as at the end of a recording (a
    /// `--loop` that stops by itself: every pass is a segment of its own, and at
    /// `--rate max` each repeats the first exactly).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub laps: Option<u64>,
    /// Output directory (created; existing outputs in it are replaced).
    #[arg(long, default_value = "dualgeo-out")]
    pub out: PathBuf,
    /// Configuration: TOML with [matching], [estimator], [detection] and [realtime]
    /// sections.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Seconds to wait for the services to connect.
    #[arg(long, default_value_t = 30.0)]
    pub connect_timeout_s: f64,
    /// End the run after this many seconds of streaming (with `--loop`: a soak of
    /// fixed length). Not the simulated scenario's `--duration-s`.
    #[arg(long)]
    pub run_for_s: Option<f64>,
    #[command(flatten)]
    pub restart: restart::RestartArgs,
    #[command(flatten)]
    pub live_out: live_out::LiveOutArgs,
    #[command(flatten)]
    pub mcap: mcap_out::McapArgs,
    /// Write a per-frame trace of the run (Chrome trace-event JSON: open it in
    /// ui.perfetto.dev or chrome://tracing): a span per stage per frame, one track per
    /// process, on the shared monotonic clock. Off by default.
    #[arg(long, value_name = "FILE")]
    pub trace: Option<PathBuf>,
    /// Soak report: sample every process's memory and descriptors and the stages'
    /// latency this often (soak.csv, soak.png and a flatness verdict).
    #[arg(long, default_value_t = 60.0)]
    pub sample_every_s: f64,
    /// Samples before this are left out of the soak verdict (rings, caches and pools
    /// fill first).
    #[arg(long, default_value_t = 60.0)]
    pub soak_warm_up_s: f64,
}

/// Checks every section of the configuration before any process starts.
fn check_config(path: &Path) -> Result<()> {
    use shared_types::shell::load_section;
    load_section::<matching::MatchingConfig>(Some(path), "matching")?
        .validate()
        .map_err(anyhow::Error::msg)
        .context("[matching]")?;
    load_section::<geolocation::EstimatorConfig>(Some(path), "estimator")?
        .validate()
        .context("[estimator]")?;
    let detection = load_section::<detection::config::DetectionConfig>(Some(path), "detection")?;
    // A learned detector's model is loaded here once: a missing file, a model OpenCV
    // cannot read, an output it cannot decode or a class the names file lacks is an
    // error before any process starts.
    if let (detection::config::DetectorKind::Yolo, Some(yolo)) = (detection.kind, detection.yolo) {
        detection::yolo::YoloDetector::new(yolo).context("[detection.yolo]")?;
    }
    load_section::<shared_types::realtime::RealtimeConfig>(Some(path), "realtime")?.validate()?;
    load_section::<geolocation::tracks::TrackConfig>(Some(path), "tracks")?
        .validate()
        .map_err(anyhow::Error::msg)?;
    let text = std::fs::read_to_string(path)?;
    let table: toml::Table = toml::from_str(&text)?;
    let known = ["matching", "estimator", "detection", "tracks", "realtime"];
    for key in table.keys() {
        if !known.contains(&key.as_str()) {
            bail!(
                "{}: unknown section [{key}] (expected {})",
                path.display(),
                known.join(", ")
            );
        }
    }
    Ok(())
}

pub fn run(args: &RunArgs) -> Result<()> {
    if let Some(c) = &args.config {
        check_config(c)?;
    }
    let source = Path::new(&args.source);
    let is_flight = source.is_file() && source.extension().is_some_and(|e| e == "toml");
    if args.source != "sim" && !source.is_dir() && !is_flight {
        bail!(
            "--source {}: not a directory or a flight.toml (use `sim`, a recording \
             directory, or a flight's flight.toml)",
            args.source
        );
    }
    for name in children::SERVICES {
        children::service_binary(name)?;
    }
    // Before any process starts: a bad address or a missing origin is refused here.
    let (_, _, origin) = outputs::source_facts(args, Path::new(""))?;
    // A recorded flight is opened by the reader acquisition uses (both logs parsed,
    // both videos opened), as a recording is by `source_facts`: one it refuses is an
    // error here, not a service that exits. A live flight's sockets are acquisition's.
    if is_flight {
        let meta = acquisition::flight::FlightMeta::read(source).map_err(anyhow::Error::msg)?;
        if !meta.is_live() {
            acquisition::flight::FlightSource::open(source)
                .map_err(anyhow::Error::msg)
                .with_context(|| format!("--source {}", source.display()))?;
        }
    }
    let live =
        live_out::LiveOutputs::open(&args.live_out, origin, outputs::source_geoid_height(args)?)?;
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("create {}", out.display()))?;
    if !(args.sample_every_s.is_finite() && args.sample_every_s >= 0.1) {
        bail!(
            "--sample-every-s must be at least 0.1 s, got {}",
            args.sample_every_s
        );
    }
    if let Some(d) = args.run_for_s {
        if !(d.is_finite() && d > 0.0) {
            bail!("--run-for-s must be a positive number of seconds, got {d}");
        }
    }
    let stats_dir = out.join("stats");
    let stream_dir = out.join("stream");
    let state_dir = out.join("state");
    let trace_dir = out.join("trace");
    if let Some(dir) = args
        .trace
        .as_ref()
        .and_then(|f| f.parent())
        .filter(|d| !d.as_os_str().is_empty())
    {
        if !dir.is_dir() {
            bail!("--trace: no directory {}", dir.display());
        }
    }
    if trace_dir.exists() {
        std::fs::remove_dir_all(&trace_dir)
            .with_context(|| format!("clear {}", trace_dir.display()))?;
    }
    if args.trace.is_some() {
        std::fs::create_dir_all(&trace_dir)
            .with_context(|| format!("create {}", trace_dir.display()))?;
    }
    for dir in [&stats_dir, &stream_dir, &state_dir] {
        if dir.exists() {
            std::fs::remove_dir_all(dir).with_context(|| format!("clear {}", dir.display()))?;
        }
        std::fs::create_dir_all(dir).with_context(|| format!("create {}", dir.display()))?;
    }
    shared_types::checkpoint::create_dir(&state_dir)?;
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&state_dir, std::fs::Permissions::from_mode(0o700))
            .with_context(|| format!("make {} owner-only", state_dir.display()))?;
    }
    let cleaned = clean_dead_nodes();
    if cleaned > 0 {
        tracing::info!(cleaned, "removed resources of dead iceoryx2 nodes");
    }
    let run_id = new_run_id();
    let mut common = vec![
        "--run-id".to_string(),
        run_id.clone(),
        "--stats-dir".into(),
        stats_dir.display().to_string(),
        "--state-dir".into(),
        state_dir.display().to_string(),
    ];
    if let Some(c) = &args.config {
        common.extend(["--config".into(), c.display().to_string()]);
    }
    if args.trace.is_some() {
        common.extend(["--trace-dir".into(), trace_dir.display().to_string()]);
    }
    if args.rate == "max" {
        common.push("--flow-controlled".into());
    }
    eprintln!(
        "dualgeo run {run_id}: source {}, rate {}, output {}",
        args.source,
        args.rate,
        out.display()
    );

    // The recorder subscribes first, so that it sees the stream from its first frame.
    let recording = mcap_out::McapRecording::start(&args.mcap, &run_id, origin)?;
    let collector =
        collect::Collector::new(&run_id, mcap_out::McapRecording::subscribers(&recording))?;
    let mut services: Vec<Service> = Vec::new();
    let started = (|| -> Result<()> {
        for name in ["geolocation", "matching", "detection"] {
            services.push(Service::spawn(name, &common)?);
        }
        collector.wait_connected(
            &mut services,
            Duration::from_secs_f64(args.connect_timeout_s),
        )?;
        let mut acq = common.clone();
        acq.extend([
            "--source".into(),
            args.source.clone(),
            "--rate".into(),
            args.rate.clone(),
        ]);
        acq.extend(args.scenario.to_args());
        if args.looping {
            acq.push("--loop".into());
        }
        if let Some(n) = args.laps {
            acq.extend(["--laps".into(), n.to_string()]);
        }
        acq.extend(["--log-dir".into(), stream_dir.display().to_string()]);
        services.push(Service::spawn("acquisition", &acq)?);
        Ok(())
    })();
    if let Err(e) = started {
        if let Some(r) = recording {
            let _ = r.finish(&mut shared_types::stats::StageStats::new("supervisor"));
        }
        let failures = children::stop_all(&mut services, Duration::from_secs(5));
        for f in failures {
            eprintln!("  {f}");
        }
        return Err(e);
    }

    let track = track::TrackWriter::create(&out.join("track.csv"), origin)?;
    let supervision = restart::Supervision::new(args.restart);
    let duration = args.run_for_s.map(Duration::from_secs_f64);
    let sampler = soak::Sampler::new(
        out,
        &stats_dir,
        Duration::from_secs_f64(args.sample_every_s),
    )?;
    let outcome = collector.stream(
        &mut services,
        supervision,
        duration,
        collect::Sinks { track, live },
        sampler,
    );
    // Before the services stop: the recorder takes what is still queued.
    let mut mcap_stats = shared_types::stats::StageStats::new("supervisor");
    let recorded = recording.map(|r| r.finish(&mut mcap_stats));
    let failures = children::stop_all(&mut services, Duration::from_secs(10));
    let mut collected = match outcome {
        Ok(c) => c,
        Err(e) => {
            for f in &failures {
                eprintln!("  {f}");
            }
            return Err(e);
        }
    };
    if !failures.is_empty() {
        bail!("services did not stop cleanly: {}", failures.join("; "));
    }
    if let Some(r) = recorded {
        r?;
        collected.stats.merge(&mcap_stats);
    }
    if let Some(file) = &args.trace {
        let t = trace_file::write(&trace_dir, file)?;
        eprintln!(
            "trace: {} ({} spans; open it in ui.perfetto.dev){}",
            file.display(),
            t.spans,
            if t.unreadable_lines > 0 {
                format!(", {} unreadable lines skipped", t.unreadable_lines)
            } else {
                String::new()
            }
        );
    }
    outputs::write_all(args, out, &stats_dir, &stream_dir, &collected)
}
