//! Plays a recorded flight (as `dualgeo simulate --flight-out` writes it) as if it were
//! flying: each UAV's video streamed over UDP by the `ffmpeg` CLI (re-encoded as a
//! low-latency H.264 in MPEG-TS, at its own rate, `-re`), and its MAVLink telemetry sent over UDP at 50 Hz per message type
//! (ATTITUDE and GLOBAL_POSITION_INT resampled from the log, and
//! GIMBAL_DEVICE_ATTITUDE_STATUS when the log has a gimbal), paced by the wall clock
//! from the same start. Shared by tests/e2e_live_flight.rs and the `live_flight` bench.

#![allow(dead_code)] // each includer uses part of it

use acquisition::flight::tlog::{parse_tlog, NavSample};
use acquisition::flight::FlightMeta;
use mavlink::dialects::common::{MavMessage, ATTITUDE_DATA, GLOBAL_POSITION_INT_DATA};
use mavlink::{MavHeader, MavlinkVersion};
use std::net::UdpSocket;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Telemetry rate per message type and UAV.
pub const TELEMETRY_HZ: f64 = 50.0;

/// Local UDP ports of a live run: video and telemetry per UAV.
#[derive(Debug, Clone, Copy)]
pub struct LivePorts {
    pub video: [u16; 2],
    pub telemetry: [u16; 2],
}

fn free_port() -> u16 {
    let s = UdpSocket::bind("127.0.0.1:0").expect("a free UDP port");
    s.local_addr().expect("local address").port()
}

impl LivePorts {
    pub fn pick() -> Self {
        Self {
            video: [free_port(), free_port()],
            telemetry: [free_port(), free_port()],
        }
    }

    /// Whether dualgeo has bound every telemetry port (so nothing sent is lost before).
    pub fn telemetry_bound(&self) -> bool {
        self.telemetry
            .iter()
            .all(|p| UdpSocket::bind(("127.0.0.1", *p)).is_err())
    }
}

/// Is the `ffmpeg` CLI there?
pub fn have_ffmpeg() -> bool {
    Command::new("ffmpeg")
        .arg("-version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// flight.toml of the live flight: the recorded one's cameras and origin, with streams
/// and sockets instead of files.
pub fn write_live_toml(recorded: &Path, out: &Path, ports: LivePorts) {
    let mut meta = FlightMeta::read(&recorded.join("flight.toml")).expect("flight.toml");
    meta.truth = None;
    for (i, u) in [&mut meta.uav.left, &mut meta.uav.right]
        .into_iter()
        .enumerate()
    {
        u.video = format!(
            "udp://127.0.0.1:{}?overrun_nonfatal=1&fifo_size=1000000",
            ports.video[i]
        );
        u.telemetry = format!("udpin:127.0.0.1:{}", ports.telemetry[i]);
        u.time_offset_s = 0.0;
    }
    std::fs::write(out, toml::to_string(&meta).expect("TOML")).expect("write live flight.toml");
}

/// Records `seconds` of `preset` as a flight (`dualgeo simulate --flight-out OUT`), at
/// `frame_rate_hz` instead of the preset's when given (a preset of that rate on top of
/// it, in a presets file beside OUT).
pub fn record_flight(
    dualgeo: &Path,
    preset: &str,
    frame_rate_hz: Option<f64>,
    seconds: u32,
    out: &Path,
) {
    let mut simulate = Command::new(dualgeo);
    simulate.arg("simulate");
    match frame_rate_hz {
        None => simulate.args(["--preset", preset]),
        Some(hz) => {
            let presets = out.with_extension("presets.toml");
            if let Some(dir) = presets.parent() {
                std::fs::create_dir_all(dir).expect("create the flight's folder");
            }
            let built_in = include_str!("../../services/acquisition/presets/scenarios.toml");
            std::fs::write(
                &presets,
                format!(
                    "{built_in}\n[{preset}_at_rate]\nbase = \"{preset}\"\nframe_rate_hz = {hz:?}\n"
                ),
            )
            .expect("write the presets file");
            simulate
                .arg("--presets")
                .arg(&presets)
                .args(["--preset", &format!("{preset}_at_rate")])
        }
    };
    let o = simulate
        .arg("--duration-s")
        .arg(seconds.to_string())
        .arg("--flight-out")
        .arg(out)
        .output()
        .expect("simulate");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Starts `dualgeo run --source LIVE --out OUT` (the `dualgeo` binary) and waits,
/// at most 60 s, until it has bound every telemetry port, so that nothing sent is lost
/// before it listens.
pub fn start_run(dualgeo: &Path, live: &Path, out: &Path, ports: LivePorts) -> Child {
    let run = Command::new(dualgeo)
        .args(["run", "--source"])
        .arg(live)
        .arg("--out")
        .arg(out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("dualgeo run");
    let deadline = Instant::now() + Duration::from_secs(60);
    while !ports.telemetry_bound() {
        assert!(
            Instant::now() < deadline,
            "the telemetry sockets were never bound"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    run
}

/// Stops a run as its operator does (SIGINT) once the last datagrams have landed;
/// whether it exited cleanly, and its log (stdout and stderr).
pub fn stop_run(run: Child) -> (bool, String) {
    std::thread::sleep(Duration::from_millis(500));
    // SAFETY: signalling our own child.
    unsafe { libc::kill(run.id() as libc::pid_t, libc::SIGINT) };
    let o = run.wait_with_output().expect("dualgeo run output");
    let log = format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    (o.status.success(), log)
}

/// One UAV's telemetry as (autopilot time, value) series.
struct Series {
    attitude: Vec<(f64, [f64; 3])>,
    position: Vec<(f64, [f64; 3])>,
    /// The gimbal's roll, pitch, yaw relative to the body (vehicle frame), if any.
    gimbal: Vec<(f64, [f64; 3])>,
}

fn series(log: &Path, system: Option<u8>) -> Series {
    let (samples, _) = parse_tlog(&std::fs::read(log).expect("tlog"));
    let mut s = Series {
        attitude: Vec::new(),
        position: Vec::new(),
        gimbal: Vec::new(),
    };
    for (sys, sample) in samples {
        if system.is_some_and(|w| w != sys) {
            continue;
        }
        match sample {
            NavSample::Attitude { t_s, rpy_rad } => s.attitude.push((t_s, rpy_rad)),
            NavSample::Position {
                t_s,
                lat_deg,
                lon_deg,
                alt_m,
                ..
            } => s.position.push((t_s, [lat_deg, lon_deg, alt_m])),
            NavSample::Gimbal {
                t_s,
                rpy_rad,
                earth_frame,
            } => {
                // The simulator writes the vehicle frame; an earth-frame log is not
                // played here.
                assert!(!earth_frame, "earth-frame gimbal logs are not played");
                s.gimbal.push((t_s, rpy_rad));
            }
        }
    }
    s
}

/// Linear interpolation at `t` (angles the short way when `angles`).
fn at(series: &[(f64, [f64; 3])], t: f64, angles: bool) -> Option<[f64; 3]> {
    let i = series.partition_point(|(ts, _)| *ts < t);
    let (ta, a) = series.get(i.checked_sub(1)?)?;
    let (tb, b) = series.get(i)?;
    let f = (t - ta) / (tb - ta);
    Some([0, 1, 2].map(|k| {
        let d = if angles {
            (b[k] - a[k] + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI
        } else {
            b[k] - a[k]
        };
        a[k] + d * f
    }))
}

/// A live flight being played.
pub struct LiveSender {
    ffmpeg: Vec<Child>,
    stop: Arc<AtomicBool>,
    /// Telemetry is not sent before this (ns after the start): a link outage.
    quiet_until: Arc<AtomicU64>,
    t0: Instant,
    telemetry: Vec<JoinHandle<u64>>,
}

impl LiveSender {
    /// Starts both videos and both telemetry streams now.
    pub fn start(recorded: &Path, ports: LivePorts) -> Self {
        let meta = FlightMeta::read(&recorded.join("flight.toml")).expect("flight.toml");
        let stop = Arc::new(AtomicBool::new(false));
        let quiet_until = Arc::new(AtomicU64::new(0));
        let t0 = Instant::now();
        let mut ffmpeg = Vec::new();
        let mut telemetry = Vec::new();
        for (i, u) in [&meta.uav.left, &meta.uav.right].into_iter().enumerate() {
            ffmpeg.push(
                Command::new("ffmpeg")
                    .args(["-hide_banner", "-loglevel", "error", "-re", "-i"])
                    .arg(recorded.join(&u.video))
                    // As an airborne encoder streams: low-latency H.264 with a
                    // keyframe (and its parameter sets) every half second, so a
                    // receiver that joins or reopens decodes within it.
                    .args([
                        "-c:v",
                        "libx264",
                        "-preset",
                        "ultrafast",
                        "-tune",
                        "zerolatency",
                    ])
                    .args(["-g", "15", "-bf", "0", "-f", "mpegts"])
                    .arg(format!("udp://127.0.0.1:{}?pkt_size=1316", ports.video[i]))
                    .stdin(Stdio::null())
                    .spawn()
                    .expect("start ffmpeg"),
            );
            let s = series(&recorded.join(&u.telemetry), u.system_id);
            let (offset, system, port) = (
                u.time_offset_s,
                u.system_id.unwrap_or(1),
                ports.telemetry[i],
            );
            let (stop, quiet) = (stop.clone(), quiet_until.clone());
            telemetry.push(std::thread::spawn(move || {
                send(&s, offset, system, port, t0, &stop, &quiet)
            }));
        }
        Self {
            ffmpeg,
            stop,
            quiet_until,
            t0,
            telemetry,
        }
    }

    /// Both telemetry links go silent for `d` from now (nothing is sent, so nothing is
    /// lost either: the sequence numbers go on from the last sent).
    pub fn silence_telemetry(&self, d: Duration) {
        let until = (self.t0.elapsed() + d).as_nanos() as u64;
        self.quiet_until.store(until, Ordering::Release);
    }

    /// One UAV's video stalls for `d` (its ffmpeg stopped, then continued: it then
    /// sends the backlog at once).
    pub fn stall_video(&self, uav: usize, d: Duration) {
        let pid = self.ffmpeg[uav].id() as libc::pid_t;
        // SAFETY: signalling our own child, which we have not reaped.
        unsafe { libc::kill(pid, libc::SIGSTOP) };
        std::thread::sleep(d);
        unsafe { libc::kill(pid, libc::SIGCONT) };
    }

    /// Stops everything; the messages sent per UAV.
    pub fn stop(mut self) -> Vec<u64> {
        self.stop.store(true, Ordering::Release);
        for c in &mut self.ffmpeg {
            let _ = c.kill();
            let _ = c.wait();
        }
        self.telemetry
            .drain(..)
            .map(|t| t.join().expect("telemetry thread"))
            .collect()
    }
}

impl Drop for LiveSender {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        for c in &mut self.ffmpeg {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Sends ATTITUDE and GLOBAL_POSITION_INT (and GIMBAL_DEVICE_ATTITUDE_STATUS when the
/// log has a gimbal) at [`TELEMETRY_HZ`] from video time 0 (autopilot time `offset`),
/// each in its own datagram, at `t0 + (t − offset)`.
fn send(
    s: &Series,
    offset: f64,
    system: u8,
    port: u16,
    t0: Instant,
    stop: &AtomicBool,
    quiet_until: &AtomicU64,
) -> u64 {
    let socket = UdpSocket::bind("127.0.0.1:0").expect("sender socket");
    let mut header = MavHeader {
        system_id: system.into(),
        component_id: 1,
        sequence: 0,
    };
    let mut sent = 0;
    let mut buf = Vec::with_capacity(64);
    for k in 0.. {
        let t = offset + k as f64 / TELEMETRY_HZ;
        let (Some(rpy), Some(pos)) = (at(&s.attitude, t, true), at(&s.position, t, false)) else {
            if t > s.attitude.last().map_or(0.0, |a| a.0) {
                break;
            }
            continue;
        };
        let due = t0 + Duration::from_secs_f64(k as f64 / TELEMETRY_HZ);
        while Instant::now() < due {
            if stop.load(Ordering::Acquire) {
                return sent;
            }
            std::thread::sleep(
                due.saturating_duration_since(Instant::now())
                    .min(Duration::from_millis(5)),
            );
        }
        if t0.elapsed().as_nanos() < u128::from(quiet_until.load(Ordering::Acquire)) {
            continue;
        }
        let ms = (t * 1e3).round() as u32;
        let gimbal =
            at(&s.gimbal, t, true).map(|rpy| acquisition::flight::tlog::gimbal_message(ms, rpy));
        let messages = [
            MavMessage::ATTITUDE(ATTITUDE_DATA {
                time_boot_ms: ms,
                roll: rpy[0] as f32,
                pitch: rpy[1] as f32,
                yaw: rpy[2] as f32,
                ..Default::default()
            }),
            MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                time_boot_ms: ms,
                lat: (pos[0] * 1e7).round() as i32,
                lon: (pos[1] * 1e7).round() as i32,
                // The log's altitude is AMSL already (the reader adds N back).
                alt: (pos[2] * 1e3).round() as i32,
                ..Default::default()
            }),
        ];
        for m in messages.iter().chain(gimbal.as_ref()) {
            buf.clear();
            mavlink::write_versioned_msg(&mut buf, MavlinkVersion::V2, header, m)
                .expect("encode MAVLink");
            header.sequence = header.sequence.wrapping_add(1);
            if socket.send_to(&buf, ("127.0.0.1", port)).is_ok() {
                sent += 1;
            }
        }
    }
    sent
}
