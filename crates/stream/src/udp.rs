//! UDP: one datagram per pose to each configured destination, through a
//! socket connected to it (so that the kernel reports an unreachable port
//! on the next send). A destination that cannot be reached is counted and
//! logged when its state changes, never on every datagram; sending never
//! blocks.

use crate::StreamError;
use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

/// A failing destination counts as reachable again after this long
/// without an error. (An unreachable port fails every other send: the
/// kernel reports the ICMP error on the send after the one that caused it.)
pub const RECOVERY: Duration = Duration::from_secs(1);

/// Sends each pose line as one datagram to every destination.
#[derive(Debug)]
pub struct UdpSender {
    destinations: Vec<Destination>,
}

#[derive(Debug)]
struct Destination {
    socket: UdpSocket,
    addr: SocketAddr,
    /// Time of the last error while the destination counts as failing.
    failing: Option<Instant>,
    sent: u64,
    errors: u64,
    /// Times the destination went from reachable to failing (logged once each).
    outages: u64,
}

impl UdpSender {
    /// A sender with one socket per destination, each bound to an
    /// ephemeral port of `bind` (e.g. `0.0.0.0:0`) and connected.
    pub fn new(bind: SocketAddr, destinations: &[SocketAddr]) -> Result<Self, StreamError> {
        let mut out = Vec::with_capacity(destinations.len());
        for &addr in destinations {
            let err = |what, source| StreamError::Socket {
                what,
                addr: addr.to_string(),
                source,
            };
            let socket =
                UdpSocket::bind(bind).map_err(|e| err("cannot bind a UDP socket for", e))?;
            socket
                .connect(addr)
                .map_err(|e| err("cannot address UDP datagrams to", e))?;
            socket
                .set_nonblocking(true)
                .map_err(|e| err("cannot make the UDP socket non-blocking for", e))?;
            out.push(Destination {
                socket,
                addr,
                failing: None,
                sent: 0,
                errors: 0,
                outages: 0,
            });
        }
        Ok(UdpSender { destinations: out })
    }

    /// Sends `line` to every destination.
    pub fn send(&mut self, line: &[u8]) {
        for d in &mut self.destinations {
            match d.socket.send(line) {
                Ok(_) => {
                    d.sent += 1;
                    if d.failing.is_some_and(|t| t.elapsed() >= RECOVERY) {
                        d.failing = None;
                        tracing::info!(destination = %d.addr, errors = d.errors, "UDP pose destination reachable again");
                    }
                }
                Err(e) => {
                    d.errors += 1;
                    if d.failing.is_none() {
                        d.outages += 1;
                        tracing::warn!(destination = %d.addr, error = %e, "UDP pose destination unreachable; counting and going on");
                    }
                    d.failing = Some(Instant::now());
                }
            }
        }
    }

    /// `(destination, datagrams sent, send errors)` per destination.
    pub fn stats(&self) -> impl Iterator<Item = (SocketAddr, u64, u64)> + '_ {
        self.destinations.iter().map(|d| (d.addr, d.sent, d.errors))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unreachable_port_is_one_outage_not_one_per_datagram() {
        // A port nobody listens on: every other send reports the ICMP error.
        let port = UdpSocket::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap();
        let mut tx = UdpSender::new("127.0.0.1:0".parse().unwrap(), &[port]).unwrap();
        for _ in 0..40 {
            tx.send(b"{}\n");
            std::thread::sleep(Duration::from_millis(2));
        }
        let d = &tx.destinations[0];
        assert!(d.errors >= 10, "the refusals are counted: {}", d.errors);
        assert_eq!(d.outages, 1, "one outage, logged once");
        assert!(d.failing.is_some());
    }
}
