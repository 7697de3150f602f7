//! The service processes: spawn, watch, stop, reap.
//!
//! Each child gets its own process group (so a terminal's Ctrl-C reaches only the
//! supervisor, which then stops the children in order) and `PR_SET_PDEATHSIG` (so a
//! killed supervisor does not leave orphans streaming). Every child is reaped with
//! `waitpid` (through `std::process::Child`), which is what lets iceoryx2 see a dead
//! node as dead.

use anyhow::{anyhow, Context, Result};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant};

pub const SERVICES: [&str; 4] = ["acquisition", "detection", "matching", "geolocation"];

/// Where the service binaries are: next to the running `dualgeo`.
pub fn service_binary(name: &str) -> Result<PathBuf> {
    let exe = std::env::current_exe().context("locate the dualgeo binary")?;
    let dir = exe
        .parent()
        .ok_or_else(|| anyhow!("{} has no parent directory", exe.display()))?;
    let path = dir.join(format!("dualgeo-{name}"));
    if !path.is_file() {
        return Err(anyhow!(
            "service binary {} not found. The four services are built with the workspace: \
             run `cargo build --release --workspace` (README's first command does).",
            path.display()
        ));
    }
    Ok(path)
}

pub struct Service {
    pub name: &'static str,
    child: Child,
    exited: Option<ExitStatus>,
    /// Arguments of the first start (a restart adds `--incarnation n`).
    args: Vec<String>,
    /// 0 for the first process, n after the n-th restart.
    pub incarnation: u32,
    /// When this incarnation was started.
    pub started: Instant,
    /// Its death was seen and handled by the restart policy (`restart.rs`): it is no
    /// longer a failure to report when the run stops.
    pub accounted: bool,
}

pub fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exit code {code}"),
        (None, Some(sig)) => format!("signal {sig}"),
        _ => status.to_string(),
    }
}

fn start(name: &'static str, args: &[String]) -> Result<Child> {
    let binary = service_binary(name)?;
    let mut cmd = Command::new(&binary);
    cmd.args(args);
    // Own process group; die with the supervisor.
    // SAFETY: only async-signal-safe calls (setpgid, prctl) between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            if libc::setpgid(0, 0) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    cmd.spawn()
        .with_context(|| format!("start the {name} service ({})", binary.display()))
}

impl Service {
    pub fn spawn(name: &'static str, args: &[String]) -> Result<Self> {
        Ok(Self {
            name,
            child: start(name, args)?,
            exited: None,
            args: args.to_vec(),
            incarnation: 0,
            started: Instant::now(),
            accounted: false,
        })
    }

    /// Starts the next incarnation of a service that has exited (and been reaped).
    pub fn respawn(&mut self) -> Result<()> {
        let incarnation = self.incarnation + 1;
        let mut args = self.args.clone();
        args.extend(["--incarnation".into(), incarnation.to_string()]);
        self.child = start(self.name, &args)?;
        self.exited = None;
        self.incarnation = incarnation;
        self.started = Instant::now();
        self.accounted = false;
        Ok(())
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Reaps the child if it has exited (non-blocking).
    pub fn poll(&mut self) -> Result<Option<ExitStatus>> {
        if self.exited.is_none() {
            self.exited = self
                .child
                .try_wait()
                .with_context(|| format!("wait for {}", self.name))?;
        }
        Ok(self.exited)
    }

    /// SIGTERM, then SIGKILL after `grace`; always reaps.
    pub fn stop(&mut self, grace: Duration) -> Result<ExitStatus> {
        if let Some(s) = self.poll()? {
            return Ok(s);
        }
        let pid = self.child.id() as libc::pid_t;
        // SAFETY: plain kill(2) on our own child's pid, which is not yet reaped.
        unsafe { libc::kill(pid, libc::SIGTERM) };
        let deadline = Instant::now() + grace;
        while Instant::now() < deadline {
            if let Some(s) = self.poll()? {
                return Ok(s);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        tracing::warn!(
            service = self.name,
            "did not stop within {grace:?}; killing it"
        );
        let _ = self.child.kill();
        let status = self
            .child
            .wait()
            .with_context(|| format!("reap {}", self.name))?;
        self.exited = Some(status);
        Ok(status)
    }
}

/// Stops every service (last started first) and reports the ones that did not exit 0
/// (a service already dead and handled by the restart policy is not reported again).
pub fn stop_all(services: &mut [Service], grace: Duration) -> Vec<String> {
    let mut failures = Vec::new();
    for s in services.iter_mut().rev() {
        let accounted = s.accounted;
        match s.stop(grace) {
            Ok(_) if accounted => {}
            Ok(status) if status.success() => {}
            Ok(status) => failures.push(format!("{} ended with {}", s.name, describe(status))),
            Err(e) => failures.push(format!("{}: {e:#}", s.name)),
        }
    }
    failures
}
