//! The supervisor's own iceoryx2 side: waiting until the services are connected, then
//! collecting estimates until the stream ends, `--run-for-s` passes or a signal
//! arrives, while the restart policy (`restart.rs`) watches the services every 25 ms.
//!
//! The last guard before the outputs: an estimate that is not newer than the one
//! before it (`out_of_order`) or a valid one with a non-finite value (`non_finite`) is
//! dropped and counted. The services already guarantee both; the chaos test checks
//! that these counters stay 0.

use super::children::{describe, Service};
use super::live_out::LiveOutputs;
use super::restart::Supervision;
use super::soak::Sampler;
use super::track::TrackWriter;
use anyhow::{bail, Context, Result};
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use indicatif::{ProgressBar, ProgressStyle};
use shared_types::clock::{elapsed_us, monotonic_ns};
use shared_types::conventions::Uav;
use shared_types::messages::{DetectionMsg, EstimateMsg, ObservationSetMsg};
use shared_types::service_names::Topic;
use shared_types::stats::StageStats;
use shared_types::transport::{Endpoint, Ipc, MsgSubscriber, Stage, END_OF_STREAM_EVENT};
use std::io::IsTerminal;
use std::time::{Duration, Instant};

/// After the end of the stream, the pipeline is drained when no estimate has arrived
/// for this long (a geolocation takes tens of milliseconds).
const DRAIN_QUIET: Duration = Duration::from_millis(1500);
/// ... or at the latest after this.
const DRAIN_MAX: Duration = Duration::from_secs(15);

/// Where valid estimates go as they arrive: track.csv, and the live outputs.
pub struct Sinks {
    pub track: TrackWriter,
    pub live: LiveOutputs,
}

pub struct Collector {
    endpoint: Endpoint,
    /// Subscribers of the supervisor's own on each data service (the `--mcap` recorder),
    /// over the services' own.
    monitors: usize,
    estimates: MsgSubscriber<EstimateMsg>,
    listener: Listener<Ipc>,
}

/// What a run produced.
pub struct Collected {
    /// Estimate messages received (valid or not).
    pub messages: u64,
    /// The supervisor's own histograms (`transport` of the estimates hop).
    pub stats: StageStats,
    /// CLOCK_MONOTONIC when acquisition was started and when the stream ended.
    pub start_ns: u64,
    pub end_ns: u64,
    /// Stopped by SIGINT/SIGTERM rather than the end of the stream.
    pub interrupted: bool,
    /// Deaths, restarts and recoveries of the services.
    pub supervision: Supervision,
    /// The soak report's samples.
    pub sampler: Sampler,
}

/// Whether an estimate may be written out after `last_t_s` (counted when not).
fn admissible(msg: &EstimateMsg, last_t_s: Option<f64>, stats: &mut StageStats) -> bool {
    match msg.refusal(last_t_s) {
        Some(reason) => {
            stats.count(reason, 1);
            false
        }
        None => true,
    }
}

impl Collector {
    pub fn new(run_id: &str, monitors: usize) -> Result<Self> {
        let endpoint = Endpoint::new(run_id, "supervisor")?;
        let estimates = endpoint.subscriber::<EstimateMsg>(Topic::Estimates)?;
        let listener = endpoint.listener(Stage::Supervisor)?;
        Ok(Self {
            endpoint,
            monitors,
            estimates,
            listener,
        })
    }

    fn connected(&self) -> Result<bool> {
        let e = &self.endpoint;
        let m = self.monitors;
        Ok(e.frame_subscriber_count(Uav::Left)? >= 2 + m
            && e.frame_subscriber_count(Uav::Right)? >= 2 + m
            && e.subscriber_count::<DetectionMsg>(Topic::Detections)? > m
            && e.subscriber_count::<ObservationSetMsg>(Topic::Observations)? > m
            && e.listener_count(Stage::Detection)? >= 1
            && e.listener_count(Stage::Matching)? >= 1
            && e.listener_count(Stage::Geolocation)? >= 1)
    }

    /// Blocks until every consumer is connected; fails if a service exits first.
    pub fn wait_connected(&self, services: &mut [Service], timeout: Duration) -> Result<()> {
        let deadline = Instant::now() + timeout;
        loop {
            check_alive(services)?;
            if self.connected()? {
                return Ok(());
            }
            if Instant::now() > deadline {
                bail!("the services did not connect within {timeout:?}");
            }
            if self.endpoint.node.wait(Duration::from_millis(20)).is_err() {
                bail!("interrupted while the services were starting");
            }
        }
    }

    /// Collects estimates until end of stream (drained), `duration` or a signal.
    pub fn stream(
        self,
        services: &mut [Service],
        supervision: Supervision,
        duration: Option<Duration>,
        sinks: Sinks,
        sampler: Sampler,
    ) -> Result<Collected> {
        let waitset = WaitSetBuilder::new()
            .create::<Ipc>()
            .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
        let wake = waitset
            .attach_notification(&self.listener)
            .map_err(|e| anyhow::anyhow!("WaitSet attach: {e:?}"))?;
        let tick = waitset
            .attach_interval(Duration::from_millis(25))
            .map_err(|e| anyhow::anyhow!("WaitSet interval: {e:?}"))?;
        let Sinks {
            mut track,
            mut live,
        } = sinks;
        let progress = Progress::new();
        let mut c = Collected {
            messages: 0,
            stats: StageStats::new("supervisor"),
            start_ns: monotonic_ns(),
            end_ns: 0,
            interrupted: false,
            supervision,
            sampler,
        };
        let started = Instant::now();
        let mut last_t_s: Option<f64> = None;
        let mut eos_at: Option<Instant> = None;
        let mut last_estimate = Instant::now();
        let mut failure: Option<anyhow::Error> = None;
        let result = waitset.wait_and_process(|id| {
            let step = (|| -> Result<bool> {
                if id.has_event_from(&wake) {
                    let wake_ns = monotonic_ns();
                    let mut ended = false;
                    self.listener
                        .try_wait(|e| ended |= e.id.as_value() == END_OF_STREAM_EVENT)
                        .map_err(|e| anyhow::anyhow!("listener: {e:?}"))?;
                    if ended && eos_at.is_none() {
                        eos_at = Some(Instant::now());
                        c.end_ns = wake_ns;
                    }
                    let mut first = true;
                    while let Some(s) = self.estimates.receive().context("receive estimate")? {
                        let msg = *s.payload();
                        if first {
                            c.stats
                                .record("transport", elapsed_us(msg.published_ns, wake_ns));
                            first = false;
                        }
                        c.supervision.on_estimate(&msg, wake_ns);
                        last_estimate = Instant::now();
                        c.messages += 1;
                        if admissible(&msg, last_t_s, &mut c.stats) {
                            last_t_s = Some(msg.t_s);
                            track.push(&msg)?;
                            live.push(&msg, &mut c.stats);
                        }
                    }
                }
                c.supervision.watch(services)?;
                if id.has_event_from(&tick) {
                    live.tick(&mut c.stats);
                    progress.update(track.rows, c.messages, c.start_ns);
                    let restarts = c.supervision.restarts.len() as u64;
                    c.sampler.tick(services, restarts)?;
                }
                if eos_at.is_none() && duration.is_some_and(|d| started.elapsed() >= d) {
                    // `--run-for-s`: acquisition stops first, then the pipeline drains
                    // like at the end of a stream.
                    c.end_ns = monotonic_ns();
                    eos_at = Some(Instant::now());
                    c.supervision.cancel("acquisition");
                    let acquisition = services.iter_mut().find(|s| s.name == "acquisition");
                    if let Some(a) = acquisition.filter(|a| !a.accounted) {
                        a.accounted = true;
                        let status = a.stop(Duration::from_secs(5))?;
                        if !status.success() {
                            bail!("acquisition ended with {} when stopped", describe(status));
                        }
                    }
                }
                Ok(match eos_at {
                    Some(t) => last_estimate.elapsed() < DRAIN_QUIET && t.elapsed() < DRAIN_MAX,
                    None => true,
                })
            })();
            match step {
                Ok(true) => CallbackProgression::Continue,
                Ok(false) => CallbackProgression::Stop,
                Err(e) => {
                    failure = Some(e);
                    CallbackProgression::Stop
                }
            }
        });
        progress.finish(track.rows, c.start_ns);
        track.flush()?;
        if let Some(e) = failure {
            return Err(e);
        }
        match result {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                eprintln!("signal received: stopping the services");
                c.interrupted = true;
            }
            Ok(_) => {}
            Err(e) => bail!("WaitSet: {e:?}"),
        }
        if c.end_ns == 0 {
            c.end_ns = monotonic_ns();
        }
        Ok(c)
    }
}

/// Fails with the service's name and status if any has exited.
fn check_alive(services: &mut [Service]) -> Result<()> {
    for s in services.iter_mut() {
        if let Some(status) = s.poll()? {
            bail!(
                "the {} service ended unexpectedly ({}); its log is above",
                s.name,
                describe(status)
            );
        }
    }
    Ok(())
}

/// A live progress bar on a terminal, a plain line every 5 s otherwise.
struct Progress {
    bar: Option<ProgressBar>,
    last_line: std::cell::Cell<Instant>,
    last_tick: std::cell::Cell<Instant>,
}

fn rate(ok: u64, start_ns: u64) -> f64 {
    let secs = (monotonic_ns().saturating_sub(start_ns)) as f64 * 1e-9;
    if secs > 0.0 {
        ok as f64 / secs
    } else {
        0.0
    }
}

impl Progress {
    fn new() -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = ProgressBar::new_spinner();
            bar.set_style(
                ProgressStyle::with_template("{spinner} {elapsed_precise} {msg}")
                    .unwrap_or_else(|_| ProgressStyle::default_spinner()),
            );
            bar
        });
        Self {
            bar,
            last_line: std::cell::Cell::new(Instant::now()),
            last_tick: std::cell::Cell::new(Instant::now()),
        }
    }

    fn update(&self, ok: u64, messages: u64, start_ns: u64) {
        if self.last_tick.get().elapsed() < Duration::from_millis(100) {
            return;
        }
        self.last_tick.set(Instant::now());
        let hz = rate(ok, start_ns);
        let msg = format!("{ok} estimates, {hz:.1} per second ({messages} messages)");
        match &self.bar {
            Some(bar) => {
                bar.set_message(msg);
                bar.tick();
            }
            None if self.last_line.get().elapsed() >= Duration::from_secs(5) => {
                eprintln!("streaming: {msg}");
                self.last_line.set(Instant::now());
            }
            None => {}
        }
    }

    fn finish(&self, ok: u64, start_ns: u64) {
        if let Some(bar) = &self.bar {
            let hz = rate(ok, start_ns);
            bar.finish_with_message(format!("{ok} estimates, {hz:.1} per second"));
        }
    }
}
