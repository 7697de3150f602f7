//! Killing services of a running `dualgeo run` at random moments and measuring how
//! fast estimates resume (issue #13). Shared by the CI test (`tests/e2e_chaos.rs`) and
//! the 100-kill bench (`bench/src/bin/chaos.rs`), which include this file.

#![allow(dead_code)] // each includer uses part of it

use std::path::Path;
use std::time::{Duration, Instant};

pub const SERVICES: [&str; 4] = ["acquisition", "detection", "matching", "geolocation"];

/// CLOCK_MONOTONIC in ns: the clock of `restarts.csv`.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec we own.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// A small fixed-seed generator (xorshift64*): the kill schedule is reproducible.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed.max(1))
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The pid of the child of `parent` running `dualgeo-<service>` (the kernel's command
/// name is cut at 15 characters).
pub fn service_pid(parent: u32, service: &str) -> Option<u32> {
    let name = format!("dualgeo-{service}");
    let comm_name = &name[..name.len().min(15)];
    for entry in std::fs::read_dir("/proc").ok()?.flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
            continue;
        };
        let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else {
            continue;
        };
        let comm = &stat[open + 1..close];
        let mut rest = stat[close + 2..].split_whitespace();
        let state = rest.next();
        let ppid = rest.next();
        if comm == comm_name && ppid == Some(&parent.to_string()) && state != Some("Z") {
            return Some(pid);
        }
    }
    None
}

/// Waits until every service runs under `parent` (a restarted one under a new pid).
pub fn wait_all_running(parent: u32, timeout: Duration) -> bool {
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        if SERVICES.iter().all(|s| service_pid(parent, s).is_some()) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}

/// `dualgeo simulate --preset default --duration-s SECONDS --out OUT`: the recording a
/// looped run replays.
pub fn simulate_default(dualgeo: &Path, seconds: u32, out: &Path) -> Result<(), String> {
    let o = std::process::Command::new(dualgeo)
        .args(["simulate", "--preset", "default", "--duration-s"])
        .arg(seconds.to_string())
        .arg("--out")
        .arg(out)
        .output()
        .map_err(|e| format!("spawn {}: {e}", dualgeo.display()))?;
    if o.status.success() {
        Ok(())
    } else {
        Err(format!(
            "dualgeo simulate failed ({}): {}",
            o.status,
            String::from_utf8_lossy(&o.stderr)
        ))
    }
}

/// Where a looped run stands in its recording, from what its `track.csv` has on disk
/// (flushed every 0.5 s). Each pass of a looped recording is a stream segment that
/// starts over, with the warm-up of a run's start (seconds without estimates): a kill
/// landing in it, or just before the end of a pass, would measure that warm-up and not
/// the restart. Kills are sent only while the current pass's estimates have flowed for
/// [`LapGuard::SETTLED`] pairs and its end is [`LapGuard::BEFORE_END`] pairs away. The
/// warm-up is read from the run itself (the first estimate's place in its pass).
pub struct LapGuard {
    track: std::path::PathBuf,
    /// Pairs in one pass of the recording, and its frame rate (infinite and 30 for a
    /// source that does not loop: only the warm-up is waited for).
    pairs_per_lap: f64,
    rate_hz: f64,
}

impl LapGuard {
    pub const SETTLED: f64 = 15.0;
    pub const BEFORE_END: f64 = 60.0;

    /// For a run writing to `out` from the recording `rec` (its `left/` images and
    /// `frame_rate_hz`; its clock starts at 0).
    pub fn new(out: &Path, rec: &Path) -> std::io::Result<Self> {
        let toml = std::fs::read_to_string(rec.join("recording.toml"))?;
        let rate_hz = toml
            .lines()
            .find_map(|l| {
                l.strip_prefix("frame_rate_hz")?
                    .trim_start()
                    .strip_prefix('=')
            })
            .and_then(|v| v.trim().parse::<f64>().ok())
            .ok_or_else(|| std::io::Error::other("recording.toml has no frame_rate_hz"))?;
        Ok(Self {
            track: out.join("track.csv"),
            pairs_per_lap: std::fs::read_dir(rec.join("left"))?.count().max(1) as f64,
            rate_hz,
        })
    }

    /// For a run from a source that never starts over (the live simulator).
    pub fn unlooped(out: &Path) -> Self {
        Self {
            track: out.join("track.csv"),
            pairs_per_lap: f64::INFINITY,
            rate_hz: 30.0,
        }
    }

    /// The place in its pass (pairs) of the first and of the newest target estimate
    /// on disk. The stream's clock goes on across passes; pair numbers would drift
    /// with pairs skipped under load.
    fn places(&self) -> Option<(f64, f64)> {
        let text = std::fs::read_to_string(&self.track).ok()?;
        let lap_s = self.pairs_per_lap / self.rate_hz;
        let mut places = text.lines().skip(1).filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let t = f.first()?.parse::<f64>().ok()?;
            f.get(15).is_none_or(|id| *id == "0").then(|| {
                if lap_s.is_finite() {
                    t.rem_euclid(lap_s) * self.rate_hz
                } else {
                    t * self.rate_hz
                }
            })
        });
        let first = places.next()?;
        Some((first, places.last().unwrap_or(first)))
    }

    /// Whether a kill now lands in the middle of a pass, estimates flowing.
    pub fn mid_lap(&self) -> bool {
        self.places().is_some_and(|(first, newest)| {
            newest >= first + Self::SETTLED && newest + Self::BEFORE_END <= self.pairs_per_lap
        })
    }

    /// Waits until [`Self::mid_lap`]; false after `timeout`.
    pub fn wait(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if self.mid_lap() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        false
    }
}

/// One SIGKILL sent.
#[derive(Debug, Clone)]
pub struct Kill {
    pub service: &'static str,
    pub at_ns: u64,
}

/// Kills `count` services of the run `parent`, chosen by `rng` (`schedule` gives the
/// service for kill i when set), each `gap` seconds (uniform in the range) after every
/// service runs again. Returns the kills; stops early if the run ends.
pub fn kill_services(
    parent: u32,
    count: usize,
    rng: &mut Rng,
    gap_s: (f64, f64),
    guard: &LapGuard,
    schedule: impl Fn(usize, &mut Rng) -> &'static str,
    mut progress: impl FnMut(usize),
) -> Vec<Kill> {
    let mut kills = Vec::new();
    for i in 0..count {
        if !wait_all_running(parent, Duration::from_secs(20)) {
            break;
        }
        std::thread::sleep(Duration::from_secs_f64(rng.uniform(gap_s.0, gap_s.1)));
        if !guard.wait(Duration::from_secs(40)) {
            break;
        }
        let service = schedule(i, rng);
        let Some(pid) = service_pid(parent, service) else {
            break;
        };
        let at_ns = monotonic_ns();
        // SAFETY: kill(2) on the pid of a child of the run, read from /proc just now.
        unsafe { libc::kill(pid as i32, libc::SIGKILL) };
        kills.push(Kill { service, at_ns });
        progress(i + 1);
    }
    kills
}

/// One row of `restarts.csv`.
#[derive(Debug, Clone)]
pub struct RestartRow {
    pub service: String,
    pub died_ns: u64,
    pub resumed_ns: Option<u64>,
}

pub fn read_restarts(out: &Path) -> Vec<RestartRow> {
    let text = std::fs::read_to_string(out.join("restarts.csv")).unwrap_or_default();
    text.lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            Some(RestartRow {
                service: f.first()?.to_string(),
                died_ns: f.get(3)?.parse().ok()?,
                resumed_ns: f.get(5).and_then(|v| v.parse().ok()),
            })
        })
        .collect()
}

/// Kill → estimates resumed, ms, per kill (`None`: no estimate before the run ended, or
/// the supervisor never saw that death).
pub fn recoveries(kills: &[Kill], rows: &[RestartRow]) -> Vec<(&'static str, Option<f64>)> {
    kills
        .iter()
        .map(|k| {
            let row = rows
                .iter()
                .find(|r| r.service == k.service && r.died_ns >= k.at_ns);
            let ms = row
                .and_then(|r| r.resumed_ns)
                .map(|r| r.saturating_sub(k.at_ns) as f64 * 1e-6);
            (k.service, ms)
        })
        .collect()
}

/// The value at quantile `q` of sorted `v` (nearest rank).
pub fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v[((v.len() as f64 * q).ceil() as usize).clamp(1, v.len()) - 1]
}
