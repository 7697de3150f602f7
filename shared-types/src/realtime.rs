//! Priorities for an embedded ground station (issue #24, item 3): per service, the CPUs
//! it may run on, a SCHED_FIFO priority and locked memory, from the run's `[realtime]`
//! section:
//!
//! ```toml
//! [realtime]
//! mode = "auto"         # auto (default) | required | off
//! [realtime.matching]   # a table given replaces that service's default; keys left out are off
//! cpus = [1]            # sched_setaffinity; empty: any CPU
//! fifo_priority = 20    # SCHED_FIFO 1–99; 0: the normal scheduler
//! lock_memory = true    # mlockall(MCL_CURRENT | MCL_FUTURE)
//! ```
//!
//! with one table each for `acquisition`, `detection`, `matching` and `geolocation`.
//! The default is SCHED_FIFO for the four services (acquisition 10, detection and
//! matching 20, geolocation 30: the later a stage, the sooner its frame is done), no
//! pinning, no locked memory: measured on this project's 2-core machine and its stock
//! kernel it halves the end-to-end median and cuts the live p99 by a quarter
//! (docs/pipeline.md, "Priorities"). The services block on their wait sets between
//! frames, so they leave the CPU whenever they have nothing to do, and the kernel's
//! `sched_rt_runtime_us` keeps 5 % for everything else even if one spun.
//!
//! The service applies its table to every thread it has when it starts (the threads
//! it starts later inherit it) and reads the result back. A setting the kernel refuses
//! (no CAP_SYS_NICE / RLIMIT_RTPRIO for SCHED_FIFO, RLIMIT_MEMLOCK for locked memory):
//! under `auto` the service logs a warning naming it and what it needs and runs
//! without it; under `required` it stops before its first frame.

use serde::{Deserialize, Serialize};

/// What a service does with its table.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RealtimeMode {
    /// Apply what the kernel allows; warn about the rest.
    #[default]
    Auto,
    /// Apply everything or stop the service before its first frame.
    Required,
    /// Change nothing.
    Off,
}

/// The `[realtime]` section: the mode and one table per service.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RealtimeConfig {
    pub mode: RealtimeMode,
    pub acquisition: StagePriority,
    pub detection: StagePriority,
    pub matching: StagePriority,
    pub geolocation: StagePriority,
}

impl Default for RealtimeConfig {
    /// SCHED_FIFO by stage (measured: docs/pipeline.md, "Priorities").
    fn default() -> Self {
        let fifo = |fifo_priority| StagePriority {
            fifo_priority,
            ..StagePriority::default()
        };
        Self {
            mode: RealtimeMode::Auto,
            acquisition: fifo(10),
            detection: fifo(20),
            matching: fifo(20),
            geolocation: fifo(30),
        }
    }
}

/// One service's `[realtime.<service>]` table (all off when written without keys).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StagePriority {
    /// CPUs the service's threads may run on; empty: any.
    pub cpus: Vec<usize>,
    /// SCHED_FIFO priority, 1–99; 0: the normal scheduler (SCHED_OTHER).
    pub fifo_priority: u8,
    /// Lock every page the process has and will map (mlockall): no page fault on a
    /// frame buffer or a heap page swapped out in the middle of a frame.
    pub lock_memory: bool,
}

/// The highest SCHED_FIFO priority Linux has.
pub const MAX_FIFO_PRIORITY: u8 = 99;

#[derive(Debug, thiserror::Error)]
pub enum RealtimeError {
    #[error("[realtime] has no service `{0}` (acquisition, detection, matching, geolocation)")]
    NoSuchStage(String),
    #[error("[realtime.{stage}] cpus: CPU {cpu} is not one of this machine's {available} (0–{})", available - 1)]
    NoSuchCpu {
        stage: String,
        cpu: usize,
        available: usize,
    },
    #[error(
        "[realtime.{stage}] fifo_priority {priority} is outside 1–{MAX_FIFO_PRIORITY} (0: off)"
    )]
    Priority { stage: String, priority: u8 },
    #[error("[realtime.{stage}] {what}: the kernel refused ({source}); {hint}")]
    Refused {
        stage: String,
        what: &'static str,
        source: std::io::Error,
        hint: &'static str,
    },
    #[error("[realtime.{stage}] {what} did not hold: asked {asked}, the thread has {found}")]
    NotApplied {
        stage: String,
        what: &'static str,
        asked: String,
        found: String,
    },
}

impl RealtimeConfig {
    /// The table of `stage` (a service name).
    pub fn for_stage(&self, stage: &str) -> Result<&StagePriority, RealtimeError> {
        match stage {
            "acquisition" => Ok(&self.acquisition),
            "detection" => Ok(&self.detection),
            "matching" => Ok(&self.matching),
            "geolocation" => Ok(&self.geolocation),
            other => Err(RealtimeError::NoSuchStage(other.to_string())),
        }
    }

    /// Checks every table against this machine's CPUs (before any process starts).
    pub fn validate(&self) -> Result<(), RealtimeError> {
        let available = configured_cpus();
        for (stage, p) in [
            ("acquisition", &self.acquisition),
            ("detection", &self.detection),
            ("matching", &self.matching),
            ("geolocation", &self.geolocation),
        ] {
            p.validate(stage, available)?;
        }
        Ok(())
    }
}

impl StagePriority {
    pub fn is_off(&self) -> bool {
        self.cpus.is_empty() && self.fifo_priority == 0 && !self.lock_memory
    }

    fn validate(&self, stage: &str, available: usize) -> Result<(), RealtimeError> {
        if let Some(&cpu) = self.cpus.iter().find(|&&c| c >= available) {
            return Err(RealtimeError::NoSuchCpu {
                stage: stage.to_string(),
                cpu,
                available,
            });
        }
        if self.fifo_priority > MAX_FIFO_PRIORITY {
            return Err(RealtimeError::Priority {
                stage: stage.to_string(),
                priority: self.fifo_priority,
            });
        }
        Ok(())
    }
}

/// What a service has after [`apply`], read back from the kernel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Applied {
    /// Settings the kernel refused (under `auto` only; `required` stops instead).
    pub refused: Vec<String>,
    /// Threads the settings were applied to.
    pub threads: usize,
    /// The calling thread's allowed CPUs.
    pub cpus: Vec<usize>,
    /// Its SCHED_FIFO priority, 0 under the normal scheduler.
    pub fifo_priority: u8,
    /// Kilobytes the process has locked (`VmLck` of /proc/self/status).
    pub locked_kb: u64,
}

/// CPUs the kernel was configured with (CPU numbers run 0..this).
pub fn configured_cpus() -> usize {
    // SAFETY: sysconf only reads a system value.
    let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_CONF) };
    usize::try_from(n)
        .ok()
        .filter(|n| *n > 0)
        .unwrap_or(1)
        .min(libc::CPU_SETSIZE as usize)
}

/// Applies `priority` (service `stage`'s table) to every thread of this process and
/// reads the calling thread's result back. Nothing is changed when the table is off or
/// `mode` is `off`. A setting the kernel refuses is an error under `required`; under
/// `auto` it is skipped and listed in [`Applied::refused`]. A table that does not fit
/// this machine is an error either way.
pub fn apply(
    mode: RealtimeMode,
    stage: &str,
    priority: &StagePriority,
) -> Result<Applied, RealtimeError> {
    priority.validate(stage, configured_cpus())?;
    let mut refusals = Vec::new();
    let mut settle = |result: Result<(), RealtimeError>| match (result, mode) {
        (Ok(()), _) => Ok(true),
        (Err(e @ RealtimeError::Refused { .. }), RealtimeMode::Auto) => {
            refusals.push(e.to_string());
            Ok(false)
        }
        (Err(e), _) => Err(e),
    };
    if mode == RealtimeMode::Off {
        return Ok(Applied {
            refused: Vec::new(),
            threads: 0,
            cpus: current_cpus(),
            fifo_priority: current_fifo_priority(),
            locked_kb: locked_kb(),
        });
    }
    let refused = |what, hint| {
        let source = std::io::Error::last_os_error();
        RealtimeError::Refused {
            stage: stage.to_string(),
            what,
            source,
            hint,
        }
    };
    let threads = thread_ids();
    // `call` on every thread, or the first refusal (a thread that ended meanwhile is not one).
    let on_every_thread = |call: &dyn Fn(libc::pid_t) -> libc::c_int, what, hint| {
        threads.iter().try_for_each(|&tid| {
            if call(tid) != 0 && !gone(tid) {
                Err(refused(what, hint))
            } else {
                Ok(())
            }
        })
    };
    let mut cpus_set = false;
    if !priority.cpus.is_empty() {
        // SAFETY: a zeroed cpu_set_t is the empty set; CPU_SET stays inside it (every
        // CPU number was checked against CPU_SETSIZE by `validate`).
        let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
        for &cpu in &priority.cpus {
            unsafe { libc::CPU_SET(cpu, &mut set) };
        }
        // SAFETY: `set` lives across the call and its size is passed with it.
        let result = on_every_thread(
            &|tid| unsafe { libc::sched_setaffinity(tid, std::mem::size_of_val(&set), &set) },
            "cpus",
            "is each CPU online and allowed to this process (its cgroup's cpuset)?",
        );
        cpus_set = settle(result)?;
    }
    let mut fifo_set = false;
    if priority.fifo_priority > 0 {
        let param = libc::sched_param {
            sched_priority: i32::from(priority.fifo_priority),
        };
        // SAFETY: `param` is a valid sched_param for SCHED_FIFO.
        let result = on_every_thread(
            &|tid| unsafe { libc::sched_setscheduler(tid, libc::SCHED_FIFO, &param) },
            "fifo_priority",
            "SCHED_FIFO needs CAP_SYS_NICE, an RLIMIT_RTPRIO (ulimit -r) at least this high, and real-time time in the cgroup",
        );
        fifo_set = settle(result)?;
    }
    if priority.lock_memory {
        // SAFETY: mlockall takes flags only.
        let result = if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } != 0 {
            Err(refused(
                "lock_memory",
                "mlockall needs CAP_IPC_LOCK or an RLIMIT_MEMLOCK (ulimit -l) above the process's size, shared memory included",
            ))
        } else {
            Ok(())
        };
        settle(result)?;
    }
    let applied = Applied {
        refused: refusals,
        threads: threads.len(),
        cpus: current_cpus(),
        fifo_priority: current_fifo_priority(),
        locked_kb: locked_kb(),
    };
    let not_applied = |what, asked: String, found: String| RealtimeError::NotApplied {
        stage: stage.to_string(),
        what,
        asked,
        found,
    };
    let mut asked_cpus = priority.cpus.clone();
    asked_cpus.sort_unstable();
    asked_cpus.dedup();
    if cpus_set && applied.cpus != asked_cpus {
        return Err(not_applied(
            "cpus",
            format!("{asked_cpus:?}"),
            format!("{:?}", applied.cpus),
        ));
    }
    if fifo_set && applied.fifo_priority != priority.fifo_priority {
        return Err(not_applied(
            "fifo_priority",
            priority.fifo_priority.to_string(),
            applied.fifo_priority.to_string(),
        ));
    }
    Ok(applied)
}

/// Every thread of this process (`/proc/self/task`); the calling one alone when that
/// cannot be read.
fn thread_ids() -> Vec<libc::pid_t> {
    let listed: Vec<libc::pid_t> = std::fs::read_dir("/proc/self/task")
        .map(|dir| {
            dir.filter_map(|e| e.ok()?.file_name().to_str()?.parse().ok())
                .collect()
        })
        .unwrap_or_default();
    if listed.is_empty() {
        vec![0]
    } else {
        listed
    }
}

/// A thread that ended between listing and setting is not a refusal.
fn gone(tid: libc::pid_t) -> bool {
    std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH) && tid != 0
}

/// The calling thread's allowed CPUs, ascending.
pub fn current_cpus() -> Vec<usize> {
    // SAFETY: a zeroed cpu_set_t filled by the kernel; CPU_ISSET stays inside it.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    if unsafe { libc::sched_getaffinity(0, std::mem::size_of_val(&set), &mut set) } != 0 {
        return Vec::new();
    }
    (0..libc::CPU_SETSIZE as usize)
        .filter(|&c| unsafe { libc::CPU_ISSET(c, &set) })
        .collect()
}

/// The calling thread's SCHED_FIFO priority, 0 under any other policy.
pub fn current_fifo_priority() -> u8 {
    // SAFETY: both calls only read the calling thread's scheduling.
    unsafe {
        if libc::sched_getscheduler(0) != libc::SCHED_FIFO {
            return 0;
        }
        let mut param = libc::sched_param { sched_priority: 0 };
        if libc::sched_getparam(0, &mut param) != 0 {
            return 0;
        }
        u8::try_from(param.sched_priority).unwrap_or(0)
    }
}

/// `VmLck` of /proc/self/status, kB (0 when it cannot be read).
pub fn locked_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmLck:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        })
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<RealtimeConfig, String> {
        crate::shell::parse_section(text, "realtime")
    }

    #[test]
    fn the_default_is_fifo_by_stage_where_the_kernel_allows() {
        let none = parse("[matching]\n").unwrap();
        assert_eq!(none, RealtimeConfig::default());
        assert_eq!(none.mode, RealtimeMode::Auto);
        let fifo = ["acquisition", "detection", "matching", "geolocation"]
            .map(|stage| none.for_stage(stage).unwrap().fifo_priority);
        assert_eq!(fifo, [10, 20, 20, 30]);
        for stage in ["acquisition", "detection", "matching", "geolocation"] {
            let p = none.for_stage(stage).unwrap();
            assert!(p.cpus.is_empty() && !p.lock_memory);
        }
        assert!(matches!(
            none.for_stage("renderer"),
            Err(RealtimeError::NoSuchStage(_))
        ));
        let off = parse("[realtime]\nmode = \"off\"\n").unwrap();
        assert_eq!(off.mode, RealtimeMode::Off);
        // Off changes nothing, whatever the tables say.
        let before = (current_cpus(), current_fifo_priority());
        let applied = apply(RealtimeMode::Off, "matching", &off.matching).unwrap();
        assert_eq!((applied.cpus, applied.fifo_priority), before);
        assert_eq!(applied.threads, 0);
    }

    #[test]
    fn each_service_has_its_own_table() {
        let c = parse(
            "[realtime.matching]\ncpus = [0]\nfifo_priority = 20\nlock_memory = true\n\
             [realtime.geolocation]\nfifo_priority = 30\n",
        )
        .unwrap();
        assert_eq!(
            c.matching,
            StagePriority {
                cpus: vec![0],
                fifo_priority: 20,
                lock_memory: true
            }
        );
        assert_eq!(c.geolocation.fifo_priority, 30);
        // A table not written keeps its default; one written replaces it.
        assert_eq!(c.detection.fifo_priority, 20);
        assert!(parse("[realtime.acquisition]\n")
            .unwrap()
            .acquisition
            .is_off());
        c.validate().unwrap();
    }

    #[test]
    fn bad_tables_are_refused_with_the_reason() {
        assert!(parse("[realtime.matching]\nnice = 3\n")
            .unwrap_err()
            .contains("nice"));
        assert!(parse("[realtime.renderer]\n")
            .unwrap_err()
            .contains("renderer"));
        assert!(parse("[realtime]\nmode = \"always\"\n")
            .unwrap_err()
            .contains("always"));
        let high = parse("[realtime.detection]\nfifo_priority = 120\n").unwrap();
        let e = high.validate().unwrap_err();
        assert!(
            matches!(e, RealtimeError::Priority { priority: 120, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("[realtime.detection]"));
        let far = parse("[realtime.detection]\ncpus = [0, 100000]\n").unwrap();
        let e = far.validate().unwrap_err();
        assert!(
            matches!(e, RealtimeError::NoSuchCpu { cpu: 100000, .. }),
            "{e}"
        );
        // Applying checks too, under `auto` as well: a table that does not fit this
        // machine is the user's mistake, not the kernel's refusal.
        let before = current_cpus();
        for mode in [RealtimeMode::Auto, RealtimeMode::Required] {
            assert!(matches!(
                apply(mode, "detection", &far.detection),
                Err(RealtimeError::NoSuchCpu { .. })
            ));
        }
        assert_eq!(current_cpus(), before);
    }

    #[test]
    fn an_off_table_changes_nothing() {
        let before = (current_cpus(), current_fifo_priority());
        let applied = apply(
            RealtimeMode::Required,
            "matching",
            &StagePriority::default(),
        )
        .unwrap();
        assert_eq!((applied.cpus.clone(), applied.fifo_priority), before);
        assert!(applied.threads >= 1);
    }

    /// Applying changes the whole process, so it runs in a child: this test binary
    /// started again for [`applied_in_a_child`] alone.
    #[test]
    fn a_service_is_pinned_raised_and_locked() {
        let exe = std::env::current_exe().unwrap();
        let out = std::process::Command::new(exe)
            .args([
                "--exact",
                "realtime::tests::applied_in_a_child",
                "--ignored",
                "--nocapture",
                "--test-threads",
                "1",
            ])
            .env("DUALGEO_REALTIME_CHILD", "1")
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{text}");
        assert!(text.contains("1 passed"), "{text}");
        println!("{text}");
    }

    /// Run by [`a_service_is_pinned_raised_and_locked`] in its own process.
    #[test]
    #[ignore = "changes the whole process: run in a child by a_service_is_pinned_raised_and_locked"]
    fn applied_in_a_child() {
        assert_eq!(
            std::env::var("DUALGEO_REALTIME_CHILD").as_deref(),
            Ok("1"),
            "run only by a_service_is_pinned_raised_and_locked"
        );
        // A thread started before: it is changed too.
        let (tx, rx) = std::sync::mpsc::channel::<()>();
        let (back_tx, back_rx) = std::sync::mpsc::channel();
        let early = std::thread::spawn(move || {
            rx.recv().unwrap();
            back_tx
                .send((current_cpus(), current_fifo_priority()))
                .unwrap();
        });
        let asked = StagePriority {
            cpus: vec![0],
            fifo_priority: 5,
            lock_memory: true,
        };
        match apply(RealtimeMode::Required, "matching", &asked) {
            Ok(applied) => {
                assert!(applied.refused.is_empty(), "{applied:?}");
                assert_eq!(applied.cpus, vec![0]);
                assert_eq!(applied.fifo_priority, 5);
                assert!(applied.threads >= 2, "{applied:?}");
                assert!(applied.locked_kb > 0, "{applied:?}");
                tx.send(()).unwrap();
                assert_eq!(back_rx.recv().unwrap(), (vec![0], 5));
                println!("applied: {applied:?}");
            }
            // A machine without CAP_SYS_NICE / CAP_IPC_LOCK: the refusal names the
            // setting and what it needs.
            Err(e @ RealtimeError::Refused { .. }) => {
                let text = e.to_string();
                assert!(text.starts_with("[realtime.matching]"), "{text}");
                assert!(text.contains("CAP_"), "{text}");
                println!("refused here: {text}");
                tx.send(()).unwrap();
            }
            Err(e) => panic!("{e}"),
        }
        early.join().unwrap();
    }
}
