//! What every service process does the same way: its command-line arguments from the
//! supervisor, logging (`RUST_LOG`), its configuration section, the event-driven wait
//! loop, and counting lost samples from sequence gaps.

use crate::transport::Ipc;
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};

/// Arguments the supervisor passes to every service.
#[derive(Debug, Clone, clap::Args)]
pub struct ServiceArgs {
    /// The run's id: the iceoryx2 service prefix `dualgeo/<run-id>/`.
    #[arg(long)]
    pub run_id: String,
    /// Where to write `<stage>.<incarnation>.json` (histograms and counters): once a
    /// second while running and on exit.
    #[arg(long)]
    pub stats_dir: PathBuf,
    /// The run's configuration (TOML with sections per stage); defaults if absent.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Where the service keeps its checkpoint (`crate::checkpoint`), so a restarted
    /// service resumes; none: nothing is kept.
    #[arg(long)]
    pub state_dir: Option<PathBuf>,
    /// 0 for the first start, n for the n-th restart by the supervisor.
    #[arg(long, default_value_t = 0)]
    pub incarnation: u32,
    /// Where to append this process's per-frame spans (`dualgeo run --trace`); none:
    /// no spans are kept.
    #[arg(long)]
    pub trace_dir: Option<PathBuf>,
    /// The source waits for every pair to be acknowledged (`dualgeo run --rate max`):
    /// work handed between a service's threads then lands on fixed frames, so that a
    /// replay repeats exactly.
    #[arg(long)]
    pub flow_controlled: bool,
}

impl ServiceArgs {
    /// This process's span recorder (off unless `--trace-dir` was given).
    pub fn tracer(&self, process: &str) -> crate::trace::Tracer {
        crate::trace::Tracer::new(self.trace_dir.as_deref(), process, self.incarnation)
    }

    /// `<state-dir>/<name>` when the run keeps state.
    pub fn state_file(&self, name: &str) -> Option<PathBuf> {
        self.state_dir.as_ref().map(|d| d.join(name))
    }
}

/// How often a running service refreshes its statistics file.
pub const STATS_SAVE_INTERVAL: std::time::Duration = std::time::Duration::from_secs(1);

/// Saves a stage's statistics at most once per [`STATS_SAVE_INTERVAL`] while it runs,
/// so a killed service leaves all but its last second (called after the outputs of a
/// wake-up are published: the save never delays a frame's own result).
pub struct StatsSaver {
    dir: PathBuf,
    incarnation: u32,
    last: std::time::Instant,
}

impl StatsSaver {
    pub fn new(args: &ServiceArgs) -> Self {
        Self {
            dir: args.stats_dir.clone(),
            incarnation: args.incarnation,
            last: std::time::Instant::now(),
        }
    }

    /// Saves if the last save is older than the interval.
    pub fn tick(&mut self, stats: &crate::stats::StageStats) {
        if self.last.elapsed() >= STATS_SAVE_INTERVAL {
            self.last = std::time::Instant::now();
            if let Err(e) = stats.save(&self.dir, self.incarnation) {
                tracing::warn!("statistics not saved: {e}");
            }
        }
    }

    /// The final save, when the service stops.
    pub fn finish(
        &self,
        stats: &crate::stats::StageStats,
    ) -> Result<PathBuf, crate::stats::StatsError> {
        stats.save(&self.dir, self.incarnation)
    }
}

/// The exit status of a service that refused its input or its configuration
/// (sysexits' `EX_CONFIG`). The supervisor does not restart it: a new process would be
/// refused the same way (as systemd's `RestartPreventExitStatus`). Any other failure
/// (a crash, a lost shared-memory service) is restarted by the policy.
pub const EXIT_PERMANENT: u8 = 78;

/// An error that restarting the process cannot cure: a bad configuration, a source that
/// cannot be read. [`exit_code`] turns it into [`EXIT_PERMANENT`]; so does a
/// [`ShellError::Config`] anywhere in an error's chain.
#[derive(Debug, thiserror::Error)]
#[error("{what}")]
pub struct Permanent {
    what: String,
    #[source]
    source: Option<Box<dyn std::error::Error + Send + Sync + 'static>>,
}

impl Permanent {
    /// `what` was refused, because of `source`.
    pub fn new(
        what: impl Into<String>,
        source: impl Into<Box<dyn std::error::Error + Send + Sync + 'static>>,
    ) -> Self {
        Self {
            what: what.into(),
            source: Some(source.into()),
        }
    }

    /// `what` was refused; it says why itself.
    pub fn because(what: impl Into<String>) -> Self {
        Self {
            what: what.into(),
            source: None,
        }
    }
}

/// Whether `error` or anything in its chain of sources is permanent ([`Permanent`], or a
/// configuration the shell could not read).
pub fn is_permanent(error: &(dyn std::error::Error + 'static)) -> bool {
    std::iter::successors(Some(error), |e| e.source()).any(|e| {
        e.is::<Permanent>()
            || matches!(
                e.downcast_ref::<ShellError>(),
                Some(ShellError::Config { .. })
            )
    })
}

/// A service's exit: 0 on success; on failure the error and its causes on stderr (as
/// `fn main() -> Result` prints them) and [`EXIT_PERMANENT`] when the error is
/// permanent ([`is_permanent`]), else 1.
pub fn exit_code<E>(result: Result<(), E>) -> std::process::ExitCode
where
    E: std::fmt::Debug + AsRef<dyn std::error::Error + Send + Sync + 'static>,
{
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("Error: {e:?}");
            if is_permanent(e.as_ref()) {
                std::process::ExitCode::from(EXIT_PERMANENT)
            } else {
                std::process::ExitCode::FAILURE
            }
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ShellError {
    #[error("{path}: {detail}")]
    Config { path: PathBuf, detail: String },
    #[error("iceoryx2 wait: {0}")]
    Wait(String),
    #[error(transparent)]
    Realtime(#[from] crate::realtime::RealtimeError),
}

/// Applies the service's `[realtime.<stage>]` table (`crate::realtime`: CPUs, SCHED_FIFO,
/// locked memory) to the whole process and logs what it has: under `mode = "auto"` (the
/// default) a setting the kernel refuses is a warning and the service runs without
/// it. Called once, right after the service reads its configuration.
pub fn apply_realtime(path: Option<&Path>, stage: &str) -> Result<(), ShellError> {
    let config: crate::realtime::RealtimeConfig = load_section(path, "realtime")?;
    let priority = config.for_stage(stage)?;
    if config.mode == crate::realtime::RealtimeMode::Off || priority.is_off() {
        return Ok(());
    }
    let applied = crate::realtime::apply(config.mode, stage, priority)?;
    for refusal in &applied.refused {
        tracing::warn!("{refusal}: running without it");
    }
    tracing::info!(
        cpus = ?applied.cpus,
        fifo_priority = applied.fifo_priority,
        locked_kb = applied.locked_kb,
        threads = applied.threads,
        "[realtime.{stage}] applied"
    );
    Ok(())
}

/// Logs to stderr, filtered by `RUST_LOG` (default `info`), each line tagged with the
/// service name.
pub fn init_tracing(service: &str) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init();
    tracing::debug!(service, "logging started");
    iceoryx2::prelude::set_log_level(LogLevel::Error);
}

/// Section `section` of the TOML file at `path`, or `T::default()` when there is no
/// file or no such section. Unknown keys are errors (the types deny them).
pub fn load_section<T: DeserializeOwned + Default>(
    path: Option<&Path>,
    section: &str,
) -> Result<T, ShellError> {
    let Some(path) = path else {
        return Ok(T::default());
    };
    let err = |detail: String| ShellError::Config {
        path: path.to_path_buf(),
        detail,
    };
    let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
    parse_section(&text, section).map_err(err)
}

/// Section `section` of a TOML document, `T::default()` when it has none.
pub fn parse_section<T: DeserializeOwned + Default>(
    text: &str,
    section: &str,
) -> Result<T, String> {
    let table: toml::Table = toml::from_str(text).map_err(|e| e.to_string())?;
    match table.get(section) {
        None => Ok(T::default()),
        Some(value) => value
            .clone()
            .try_into()
            .map_err(|e| format!("[{section}]: {e}")),
    }
}

/// Why [`serve`] returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    /// SIGINT / SIGTERM (the supervisor's shutdown).
    Signal,
    /// The handler asked to stop.
    Requested,
}

/// When a stage woke up and since when it had been idle: a message published after
/// `idle_since_ns` found the stage waiting, so `wake_ns − published_ns` is the pure
/// transport hop (publish → consumer running). Messages published while the stage was
/// busy measure queueing instead and are left out of the hop histogram.
#[derive(Debug, Clone, Copy)]
pub struct Wake {
    pub wake_ns: u64,
    pub idle_since_ns: u64,
}

impl Wake {
    /// The hop in µs of a message published at `published_ns`, if the stage was idle.
    pub fn hop_us(&self, published_ns: u64) -> Option<u64> {
        (published_ns >= self.idle_since_ns)
            .then(|| crate::clock::elapsed_us(published_ns, self.wake_ns))
    }
}

/// Waits on `listener` in a WaitSet and calls `on_wake` each time it fires (the
/// listener is drained first). Returns on SIGINT/SIGTERM, when `on_wake` returns
/// `Ok(false)`, or with its error.
pub fn serve<E: std::fmt::Display>(
    listener: &Listener<Ipc>,
    mut on_wake: impl FnMut(Wake) -> Result<bool, E>,
) -> Result<Stop, ShellError> {
    let waitset = WaitSetBuilder::new()
        .create::<Ipc>()
        .map_err(|e| ShellError::Wait(format!("{e:?}")))?;
    let guard = waitset
        .attach_notification(listener)
        .map_err(|e| ShellError::Wait(format!("{e:?}")))?;
    let mut failure: Option<String> = None;
    let mut requested = false;
    let mut idle_since_ns = crate::clock::monotonic_ns();
    let result = waitset.wait_and_process(|id| {
        if !id.has_event_from(&guard) {
            return CallbackProgression::Continue;
        }
        let wake_ns = crate::clock::monotonic_ns();
        if let Err(e) = listener.try_wait(|_| {}) {
            failure = Some(format!("listener: {e:?}"));
            return CallbackProgression::Stop;
        }
        let outcome = on_wake(Wake {
            wake_ns,
            idle_since_ns,
        });
        idle_since_ns = crate::clock::monotonic_ns();
        match outcome {
            Ok(true) => CallbackProgression::Continue,
            Ok(false) => {
                requested = true;
                CallbackProgression::Stop
            }
            Err(e) => {
                failure = Some(e.to_string());
                CallbackProgression::Stop
            }
        }
    });
    if let Some(f) = failure {
        return Err(ShellError::Wait(f));
    }
    match result {
        Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => Ok(Stop::Signal),
        Ok(_) if requested => Ok(Stop::Requested),
        Ok(_) => Ok(Stop::Signal),
        Err(e) => Err(ShellError::Wait(format!("{e:?}"))),
    }
}

/// Counts samples lost between consecutive sequence numbers of one stream.
#[derive(Debug, Clone, Copy, Default)]
pub struct SeqGaps {
    last: Option<u64>,
    pub lost: u64,
}

impl SeqGaps {
    /// Notes `seq`; returns how many were skipped since the previous one.
    pub fn see(&mut self, seq: u64) -> u64 {
        let gap = match self.last {
            Some(last) if seq > last + 1 => seq - last - 1,
            _ => 0,
        };
        if self.last.is_none_or(|last| seq > last) {
            self.last = Some(seq);
        }
        self.lost += gap;
        gap
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permanent_errors_are_found_anywhere_in_the_chain() {
        use anyhow::Context;
        let config = ShellError::Config {
            path: "x.toml".into(),
            detail: "[detection]: unknown field `hue`".into(),
        };
        let from_config: anyhow::Result<()> = Err(config).context("load the configuration");
        let e = from_config.unwrap_err();
        assert!(is_permanent(e.as_ref()));
        let marked: anyhow::Result<()> = Err(anyhow::Error::new(Permanent::new(
            "--source /nowhere",
            std::io::Error::from(std::io::ErrorKind::NotFound),
        )))
        .context("open the source");
        assert!(is_permanent(marked.unwrap_err().as_ref()));
        let transient = anyhow::anyhow!("iceoryx2 service lost").context("publish frame");
        assert!(!is_permanent(transient.as_ref()));
        assert!(!is_permanent(
            anyhow::Error::new(ShellError::Wait("interrupted".into())).as_ref()
        ));
        assert_eq!(
            exit_code::<anyhow::Error>(Ok(())),
            std::process::ExitCode::SUCCESS
        );
        assert_eq!(
            exit_code(Err(anyhow::Error::new(Permanent::because("bad model")))),
            std::process::ExitCode::from(EXIT_PERMANENT)
        );
        assert_eq!(exit_code(Err(transient)), std::process::ExitCode::FAILURE);
    }

    #[test]
    fn gaps_count_missing_sequence_numbers() {
        let mut g = SeqGaps::default();
        assert_eq!(g.see(5), 0);
        assert_eq!(g.see(6), 0);
        assert_eq!(g.see(9), 2);
        assert_eq!(g.see(3), 0); // a restart (loop) is not a loss
        assert_eq!(g.lost, 2);
    }

    #[derive(Debug, Default, serde::Deserialize, PartialEq)]
    #[serde(deny_unknown_fields, default)]
    struct Section {
        a: u32,
    }

    #[test]
    fn sections_default_and_reject_unknown_keys() {
        let dir = std::env::temp_dir().join(format!("dualgeo-shell-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("c.toml");
        std::fs::write(&path, "[x]\na = 3\n[y]\nb = 1\n").unwrap();
        assert_eq!(load_section::<Section>(Some(&path), "x").unwrap().a, 3);
        assert_eq!(load_section::<Section>(Some(&path), "z").unwrap().a, 0);
        assert_eq!(load_section::<Section>(None, "x").unwrap().a, 0);
        let e = load_section::<Section>(Some(&path), "y")
            .unwrap_err()
            .to_string();
        assert!(e.contains("c.toml") && e.contains("[y]"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
