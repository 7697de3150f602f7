//! The restart policy (issue #13): a service that dies (crash, panic, SIGKILL, OOM) is
//! started again while the others keep running, instead of ending the run.
//!
//! - `--restart on-failure` (default): a service that had run for at least
//!   [`STABLE_AFTER`] is restarted at once (a ground station wants its track back);
//!   one that dies sooner is crash-looping, and its restarts back off: 250 ms, 500 ms,
//!   … at most 4 s, doubling with each quick death in a row. More than
//!   `--max-restarts` deaths of one service within `--restart-window-s` end the run as
//!   before, naming the service and its last exit status.
//! - `--restart never`: the first death ends the run.
//! - Either way, a service that exits with `shell::EXIT_PERMANENT` (78) refused its
//!   input or configuration and is not restarted: the run ends, naming it.
//!
//! Before a restart, what the dead process left in iceoryx2 (its node, ports and
//! loaned samples) is removed (`clean_dead_nodes`: the child has been reaped by
//! `waitpid`, so iceoryx2 sees the node as dead); the new process then opens the same
//! services under the same run id and resumes from its checkpoint (`--state-dir`).
//!
//! Each death is one [`Restart`]: when it was seen, when the new process started, and
//! when estimates resumed: the first valid estimate of a pair captured after the death
//! was seen (an estimate of an older pair still in the pipeline proves nothing). Pairs
//! lost to a restart: sequence numbers between the last estimate message before the
//! death and that first estimate after it that produced no estimate message at all.

use super::children::{describe, Service};
use anyhow::{bail, Result};
use serde::Serialize;
use shared_types::clock::monotonic_ns;
use shared_types::messages::{EstimateMsg, EstimateStatus};
use shared_types::shell::EXIT_PERMANENT;
use shared_types::transport::clean_dead_nodes;
use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RestartMode {
    /// Restart a service that dies, within the limits.
    OnFailure,
    /// End the run when a service dies.
    Never,
}

#[derive(Debug, Clone, Copy, clap::Args)]
pub struct RestartArgs {
    /// What to do when a service dies.
    #[arg(long, value_enum, default_value = "on-failure")]
    pub restart: RestartMode,
    /// Deaths of one service within the window that end the run.
    #[arg(long, default_value_t = 10)]
    pub max_restarts: usize,
    /// The window of `--max-restarts`, seconds.
    #[arg(long, default_value_t = 60.0)]
    pub restart_window_s: f64,
}

/// A service that exits with [`EXIT_PERMANENT`] refused its input or configuration:
/// it is never restarted, whatever the mode.
pub fn is_permanent(status: std::process::ExitStatus) -> bool {
    status.code() == Some(i32::from(EXIT_PERMANENT))
}

const BACKOFF_FIRST: Duration = Duration::from_millis(250);
const BACKOFF_MAX: Duration = Duration::from_secs(4);
/// A service that ran this long before dying was healthy: no backoff.
pub const STABLE_AFTER: Duration = Duration::from_secs(1);

/// The wait before restarting a service after `quick` deaths in a row, each less than
/// [`STABLE_AFTER`] after its start (this one included).
pub fn backoff(quick: usize) -> Duration {
    match quick {
        0 => Duration::ZERO,
        n => BACKOFF_FIRST
            .saturating_mul(1 << (n - 1).min(16))
            .min(BACKOFF_MAX),
    }
}

/// One death and its recovery; CLOCK_MONOTONIC nanoseconds.
#[derive(Debug, Clone, Serialize)]
pub struct Restart {
    pub service: &'static str,
    /// The incarnation that died.
    pub incarnation: u32,
    pub status: String,
    pub died_ns: u64,
    pub restarted_ns: Option<u64>,
    pub resumed_ns: Option<u64>,
    /// The last estimate message's pair before the death, the first valid one after.
    pub last_pair_before: Option<u64>,
    pub first_pair_after: Option<u64>,
    /// Estimate messages received between the two.
    between: u64,
}

impl Restart {
    /// Death seen → estimates resumed, milliseconds.
    pub fn recovery_ms(&self) -> Option<f64> {
        self.resumed_ns
            .map(|r| r.saturating_sub(self.died_ns) as f64 * 1e-6)
    }

    /// Pair sequence numbers that produced no estimate message across this restart.
    pub fn pairs_lost(&self) -> u64 {
        match (self.last_pair_before, self.first_pair_after) {
            (Some(a), Some(b)) if b > a => (b - a - 1).saturating_sub(self.between),
            _ => 0,
        }
    }
}

pub struct Supervision {
    args: RestartArgs,
    /// Per service: when it died recently, and when its pending restart is due.
    deaths: BTreeMap<&'static str, VecDeque<Instant>>,
    /// Per service: deaths in a row that came soon after a start.
    quick: BTreeMap<&'static str, usize>,
    pending: BTreeMap<&'static str, Instant>,
    pub restarts: Vec<Restart>,
    last_pair: Option<u64>,
}

impl Supervision {
    pub fn new(args: RestartArgs) -> Self {
        Self {
            args,
            deaths: BTreeMap::new(),
            quick: BTreeMap::new(),
            pending: BTreeMap::new(),
            restarts: Vec::new(),
            last_pair: None,
        }
    }

    /// Notes deaths, ends the run when the policy says so, and starts the services
    /// whose backoff has passed.
    pub fn watch(&mut self, services: &mut [Service]) -> Result<()> {
        let now = Instant::now();
        let window = Duration::from_secs_f64(self.args.restart_window_s.max(0.0));
        for s in services.iter_mut() {
            if s.accounted {
                continue;
            }
            let Some(status) = s.poll()? else {
                continue;
            };
            if is_permanent(status) {
                bail!(
                    "the {} service refused its input or configuration ({}); a restart \
                     would be refused the same way, so the run ends. Its log is above",
                    s.name,
                    describe(status)
                );
            }
            if self.args.restart == RestartMode::Never {
                bail!(
                    "the {} service ended unexpectedly ({}); its log is above",
                    s.name,
                    describe(status)
                );
            }
            let deaths = self.deaths.entry(s.name).or_default();
            while deaths
                .front()
                .is_some_and(|t| now.duration_since(*t) > window)
            {
                deaths.pop_front();
            }
            deaths.push_back(now);
            if deaths.len() > self.args.max_restarts {
                bail!(
                    "the {} service died {} times within {:.0} s (last: {}); giving up. Its log is above",
                    s.name,
                    deaths.len(),
                    window.as_secs_f64(),
                    describe(status)
                );
            }
            let quick = self.quick.entry(s.name).or_default();
            *quick = if now.duration_since(s.started) < STABLE_AFTER {
                *quick + 1
            } else {
                0
            };
            let wait = backoff(*quick);
            tracing::warn!(
                service = s.name,
                incarnation = s.incarnation,
                status = %describe(status),
                "service died; restarting it in {wait:?}"
            );
            s.accounted = true;
            self.pending.insert(s.name, now + wait);
            self.restarts.push(Restart {
                service: s.name,
                incarnation: s.incarnation,
                status: describe(status),
                died_ns: monotonic_ns(),
                restarted_ns: None,
                resumed_ns: None,
                last_pair_before: self.last_pair,
                first_pair_after: None,
                between: 0,
            });
        }
        let due: Vec<&'static str> = self
            .pending
            .iter()
            .filter(|(_, t)| **t <= now)
            .map(|(n, _)| *n)
            .collect();
        if due.is_empty() {
            return Ok(());
        }
        let cleaned = clean_dead_nodes();
        for name in due {
            self.pending.remove(name);
            let Some(s) = services.iter_mut().find(|s| s.name == name) else {
                continue;
            };
            s.respawn()?;
            tracing::info!(
                service = name,
                incarnation = s.incarnation,
                cleaned,
                "service restarted"
            );
            let started = monotonic_ns();
            if let Some(r) = self
                .restarts
                .iter_mut()
                .rev()
                .find(|r| r.service == name && r.restarted_ns.is_none())
            {
                r.restarted_ns = Some(started);
            }
        }
        Ok(())
    }

    /// Drops a pending restart of `service` (the run is ending without it).
    pub fn cancel(&mut self, service: &str) {
        self.pending.remove(service);
    }

    /// Follows the estimate stream: closes the recoveries this estimate proves.
    pub fn on_estimate(&mut self, msg: &EstimateMsg, received_ns: u64) {
        let valid = msg.status == EstimateStatus::Ok as u32;
        for r in self.restarts.iter_mut().filter(|r| r.resumed_ns.is_none()) {
            if valid && msg.capture_ns > r.died_ns {
                r.resumed_ns = Some(received_ns);
                r.first_pair_after = Some(msg.pair_seq);
            } else if r.last_pair_before.is_none_or(|p| msg.pair_seq > p) {
                r.between += 1;
            }
        }
        self.last_pair = Some(msg.pair_seq);
    }

    /// Restarts per service (every service listed).
    pub fn counts(&self) -> BTreeMap<String, u64> {
        let mut out: BTreeMap<String, u64> = super::children::SERVICES
            .iter()
            .map(|s| (s.to_string(), 0))
            .collect();
        for r in &self.restarts {
            *out.entry(r.service.to_string()).or_default() += 1;
        }
        out
    }

    pub fn pairs_lost(&self) -> u64 {
        self.restarts.iter().map(Restart::pairs_lost).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_from_nothing_to_a_cap() {
        assert_eq!(backoff(0), Duration::ZERO);
        assert_eq!(backoff(1), Duration::from_millis(250));
        assert_eq!(backoff(2), Duration::from_millis(500));
        assert_eq!(backoff(5), Duration::from_secs(4));
        assert_eq!(backoff(60), Duration::from_secs(4));
    }

    fn estimate(pair: u64, capture_ns: u64, ok: bool) -> EstimateMsg {
        EstimateMsg {
            pair_seq: pair,
            capture_ns,
            status: if ok {
                EstimateStatus::Ok as u32
            } else {
                EstimateStatus::Rejected as u32
            },
            ..Default::default()
        }
    }

    #[test]
    fn only_the_permanent_exit_status_prevents_a_restart() {
        use std::os::unix::process::ExitStatusExt;
        use std::process::ExitStatus;
        // wait(2) statuses: the exit code in the second byte, a signal in the first.
        assert!(is_permanent(ExitStatus::from_raw(78 << 8)));
        assert!(!is_permanent(ExitStatus::from_raw(1 << 8)));
        assert!(!is_permanent(ExitStatus::from_raw(0)));
        assert!(!is_permanent(ExitStatus::from_raw(libc::SIGKILL)));
    }

    #[test]
    fn recovery_waits_for_a_valid_estimate_of_a_pair_captured_after_the_death() {
        let mut s = Supervision::new(RestartArgs {
            restart: RestartMode::OnFailure,
            max_restarts: 3,
            restart_window_s: 60.0,
        });
        s.on_estimate(&estimate(10, 100, true), 110);
        s.restarts.push(Restart {
            service: "matching",
            incarnation: 0,
            status: "signal 9".into(),
            died_ns: 1_000,
            restarted_ns: Some(1_100),
            resumed_ns: None,
            last_pair_before: s.last_pair,
            first_pair_after: None,
            between: 0,
        });
        s.on_estimate(&estimate(11, 900, true), 1_200); // captured before the death
        s.on_estimate(&estimate(13, 1_500, false), 1_600); // not valid
        s.on_estimate(&estimate(16, 1_700, true), 2_000);
        let r = &s.restarts[0];
        assert_eq!(r.resumed_ns, Some(2_000));
        assert_eq!(r.first_pair_after, Some(16));
        // 11..=15 between 10 and 16: 11 and 13 arrived; 12, 14, 15 lost.
        assert_eq!(r.pairs_lost(), 3);
        assert_eq!(s.pairs_lost(), 3);
        assert!((r.recovery_ms().unwrap() - 0.001).abs() < 1e-9);
        assert_eq!(s.counts()["matching"], 1);
        assert_eq!(s.counts()["acquisition"], 0);
    }
}
