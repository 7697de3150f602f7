//! Live MAVLink telemetry (`telemetry = "udpin:HOST:PORT"` in flight.toml): a thread
//! receives the autopilot's UDP datagrams, decodes them (CRC checked, several frames
//! per datagram allowed) and hands each navigation sample, stamped with its arrival on
//! CLOCK_MONOTONIC, to the source through a lock-free ring (`rtrb`): the source never
//! blocks on the socket and the socket is never left unread while the source works.
//!
//! Counted, never fatal: datagrams and messages received, CRC errors, bytes that were
//! not a frame, messages lost on the link (gaps in each sender's sequence number), and
//! samples dropped because the ring was full (the source fell behind by a second).

use super::tlog::{split_datagram, NavSample};
use shared_types::clock::monotonic_ns;
use std::collections::HashMap;
use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// Samples the ring holds: a second of two 50 Hz streams, twice over.
const RING: usize = 256;

/// One sample as it arrived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arrival {
    pub system: u8,
    pub sample: NavSample,
    /// CLOCK_MONOTONIC when its datagram was received.
    pub host_ns: u64,
}

/// The receiver's counters (shared with its thread).
#[derive(Debug, Default)]
struct Counters {
    datagrams: AtomicU64,
    messages: AtomicU64,
    crc_errors: AtomicU64,
    garbage: AtomicU64,
    lost: AtomicU64,
    ring_full: AtomicU64,
}

pub struct LiveTelemetry {
    ring: rtrb::Consumer<Arrival>,
    counters: Arc<Counters>,
    reported: [u64; 6],
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    local: std::net::SocketAddr,
}

/// `udpin:HOST:PORT` → `HOST:PORT`.
pub fn udpin_address(s: &str) -> Option<&str> {
    s.strip_prefix("udpin:").filter(|a| !a.is_empty())
}

/// Messages lost between two sequence numbers of one sender (MAVLink's 8-bit wrapping
/// counter). A jump back or of more than half the range is a restarted sender, not a
/// loss.
pub fn lost_between(last: u8, seq: u8) -> u64 {
    let gap = seq.wrapping_sub(last).wrapping_sub(1);
    if gap < 128 {
        u64::from(gap)
    } else {
        0
    }
}

impl LiveTelemetry {
    /// Binds the socket (an error names the address) and starts the receiver.
    pub fn bind(address: &str) -> Result<Self, String> {
        let addr = udpin_address(address)
            .ok_or_else(|| format!("telemetry {address:?}: live telemetry is udpin:HOST:PORT"))?;
        let socket =
            UdpSocket::bind(addr).map_err(|e| format!("telemetry {address}: cannot bind: {e}"))?;
        socket
            .set_read_timeout(Some(Duration::from_millis(100)))
            .map_err(|e| format!("telemetry {address}: {e}"))?;
        let local = socket
            .local_addr()
            .map_err(|e| format!("telemetry {address}: {e}"))?;
        let (producer, ring) = rtrb::RingBuffer::new(RING);
        let counters = Arc::new(Counters::default());
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (counters, stop) = (counters.clone(), stop.clone());
            std::thread::Builder::new()
                .name("mavlink-in".into())
                .spawn(move || receive(socket, producer, &counters, &stop))
                .map_err(|e| format!("telemetry {address}: {e}"))?
        };
        Ok(Self {
            ring,
            counters,
            reported: [0; 6],
            stop,
            thread: Some(thread),
            local,
        })
    }

    /// The address the socket is bound to (its port when `:0` was asked).
    pub fn local_addr(&self) -> std::net::SocketAddr {
        self.local
    }

    /// Every sample that arrived since the last call, in arrival order.
    pub fn drain(&mut self, mut f: impl FnMut(Arrival)) {
        while let Ok(a) = self.ring.pop() {
            f(a);
        }
    }

    /// Counters since the last call: `telemetry_datagrams`, `telemetry_messages`,
    /// `telemetry_crc_errors`, `telemetry_garbage`, `telemetry_lost`,
    /// `telemetry_ring_full`.
    pub fn take_counts(&mut self) -> Vec<(&'static str, u64)> {
        let c = &self.counters;
        let now = [
            &c.datagrams,
            &c.messages,
            &c.crc_errors,
            &c.garbage,
            &c.lost,
            &c.ring_full,
        ]
        .map(|a| a.load(Ordering::Relaxed));
        let names = [
            "telemetry_datagrams",
            "telemetry_messages",
            "telemetry_crc_errors",
            "telemetry_garbage",
            "telemetry_lost",
            "telemetry_ring_full",
        ];
        super::increments(names, now, &mut self.reported)
    }
}

impl Drop for LiveTelemetry {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn receive(socket: UdpSocket, mut ring: rtrb::Producer<Arrival>, c: &Counters, stop: &AtomicBool) {
    let mut buf = vec![0u8; 65_536];
    let mut last_seq: HashMap<(u8, u8), u8> = HashMap::new();
    while !stop.load(Ordering::Acquire) {
        let n = match socket.recv(&mut buf) {
            Ok(n) => n,
            // A timeout (look at `stop` again) or a transient error: go on.
            Err(_) => continue,
        };
        let host_ns = monotonic_ns();
        c.datagrams.fetch_add(1, Ordering::Relaxed);
        let (frames, garbage) = split_datagram(&buf[..n]);
        if garbage {
            c.garbage.fetch_add(1, Ordering::Relaxed);
        }
        for f in frames {
            c.messages.fetch_add(1, Ordering::Relaxed);
            if let Some(last) = last_seq.insert((f.system, f.component), f.seq) {
                c.lost
                    .fetch_add(lost_between(last, f.seq), Ordering::Relaxed);
            }
            if !f.crc_ok {
                c.crc_errors.fetch_add(1, Ordering::Relaxed);
            }
            let Some(sample) = f.sample else { continue };
            let arrival = Arrival {
                system: f.system,
                sample,
                host_ns,
            };
            if ring.push(arrival).is_err() {
                c.ring_full.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::common::{MavMessage, ATTITUDE_DATA};
    use mavlink::{MavHeader, MavlinkVersion};

    #[test]
    fn losses_are_the_gaps_of_the_wrapping_sequence() {
        assert_eq!(lost_between(4, 5), 0);
        assert_eq!(lost_between(4, 7), 2);
        assert_eq!(lost_between(254, 1), 2);
        assert_eq!(lost_between(9, 3), 0, "a restarted sender");
        assert_eq!(lost_between(9, 9), 0, "a duplicate");
    }

    #[test]
    fn only_udpin_addresses_are_live_telemetry() {
        assert_eq!(
            udpin_address("udpin:127.0.0.1:14550"),
            Some("127.0.0.1:14550")
        );
        assert!(udpin_address("udp:127.0.0.1:14550").is_none());
        assert!(udpin_address("udpin:").is_none());
        assert!(LiveTelemetry::bind("udpin:no-such-host.invalid:1").is_err());
    }

    fn frame(seq: u8, ms: u32) -> Vec<u8> {
        let msg = MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms: ms,
            ..Default::default()
        });
        let h = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: seq,
        };
        let mut out = Vec::new();
        mavlink::write_versioned_msg(&mut out, MavlinkVersion::V2, h, &msg).unwrap();
        out
    }

    #[test]
    fn a_sender_on_loopback_is_received_in_order() {
        let mut live = LiveTelemetry::bind("udpin:127.0.0.1:0").expect("bind");
        let port = live.local_addr().port();
        let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
        for (seq, ms) in [(0u8, 0u32), (1, 20), (4, 80)] {
            tx.send_to(&frame(seq, ms), ("127.0.0.1", port)).unwrap();
        }
        tx.send_to(b"not mavlink", ("127.0.0.1", port)).unwrap();
        let mut got = Vec::new();
        for _ in 0..400 {
            live.drain(|a| got.push(a.sample.t_s()));
            if got.len() == 3 {
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(got, vec![0.0, 0.02, 0.08]);
        // The garbage datagram came last: wait until it is counted too.
        let mut counts: HashMap<&str, u64> = HashMap::new();
        for _ in 0..400 {
            for (k, v) in live.take_counts() {
                *counts.entry(k).or_default() += v;
            }
            if counts.contains_key("telemetry_garbage") {
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(counts.get("telemetry_messages"), Some(&3));
        assert_eq!(counts.get("telemetry_lost"), Some(&2));
        assert_eq!(counts.get("telemetry_garbage"), Some(&1));
        assert!(live.take_counts().is_empty(), "counts are increments");
    }
}
