//! A non-blocking UDP sender: the supervisor must never wait on a slow or absent peer.

use anyhow::{bail, Context, Result};
use shared_types::stats::StageStats;
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};

pub struct UdpSender {
    socket: UdpSocket,
    to: SocketAddr,
    /// Counter prefix: `mavlink` or `cot`.
    name: &'static str,
    warned: bool,
}

impl UdpSender {
    /// `host_port` is `HOST:PORT`; `option` names the flag in errors.
    pub fn open(host_port: &str, option: &str, name: &'static str) -> Result<Self> {
        let to = host_port
            .to_socket_addrs()
            .with_context(|| format!("{option}: cannot resolve {host_port:?}"))?
            .next()
            .with_context(|| format!("{option}: {host_port:?} has no address"))?;
        if to.port() == 0 {
            bail!("{option}: port 0 is not a destination");
        }
        let bind: SocketAddr = if to.is_ipv4() {
            "0.0.0.0:0".parse()?
        } else {
            "[::]:0".parse()?
        };
        let socket = UdpSocket::bind(bind).with_context(|| format!("{option}: bind"))?;
        socket.set_nonblocking(true)?;
        if to.ip().is_multicast() {
            // TAK's SA multicast: keep it on the local network.
            let _ = socket.set_multicast_ttl_v4(1);
        }
        Ok(Self {
            socket,
            to,
            name,
            warned: false,
        })
    }

    /// Sends one datagram; a failure (no route, buffer full) is counted and logged once.
    pub fn send(&mut self, bytes: &[u8], stats: &mut StageStats) -> bool {
        match self.socket.send_to(bytes, self.to) {
            Ok(_) => true,
            Err(e) => {
                stats.count(&format!("{}.send_failed", self.name), 1);
                if !self.warned {
                    self.warned = true;
                    tracing::warn!(to = %self.to, "{} send failed (counted from now on): {e}", self.name);
                }
                false
            }
        }
    }
}
