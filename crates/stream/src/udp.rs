//! UDP: one datagram per pose to each configured destination, through a
//! socket connected to it (so that the kernel reports an unreachable port
//! on the next send). A destination that cannot be reached is counted and
//! logged when its state changes, never on every datagram; sending never
//! blocks.

use crate::StreamError;
use std::net::{SocketAddr, UdpSocket};

/// Sends each pose line as one datagram to every destination.
#[derive(Debug)]
pub struct UdpSender {
    destinations: Vec<Destination>,
}

#[derive(Debug)]
struct Destination {
    socket: UdpSocket,
    addr: SocketAddr,
    failing: bool,
    sent: u64,
    errors: u64,
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
                failing: false,
                sent: 0,
                errors: 0,
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
                    if d.failing {
                        d.failing = false;
                        tracing::info!(destination = %d.addr, "UDP pose destination reachable again");
                    }
                }
                Err(e) => {
                    d.errors += 1;
                    if !d.failing {
                        d.failing = true;
                        tracing::warn!(destination = %d.addr, error = %e, "UDP pose destination unreachable; counting and going on");
                    }
                }
            }
        }
    }

    /// `(destination, datagrams sent, send errors)` per destination.
    pub fn stats(&self) -> impl Iterator<Item = (SocketAddr, u64, u64)> + '_ {
        self.destinations.iter().map(|d| (d.addr, d.sent, d.errors))
    }
}
