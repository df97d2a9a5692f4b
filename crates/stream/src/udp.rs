//! UDP: one datagram per pose to each configured destination, through a
//! socket connected to it (so that the kernel reports an unreachable port
//! on the next send). A destination that cannot be reached is counted and
//! logged when its state changes, never on every datagram; sending never
//! blocks.

use crate::StreamError;
use photopose_telemetry::{Collect, Counter, Scrape};
use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A failing destination counts as reachable again after this long
/// without an error. (An unreachable port fails every other send: the
/// kernel reports the ICMP error on the send after the one that caused it.)
pub const RECOVERY: Duration = Duration::from_secs(1);

/// Sends each pose line as one datagram to every destination.
#[derive(Debug)]
pub struct UdpSender {
    destinations: Vec<Destination>,
    stats: Arc<UdpStats>,
}

#[derive(Debug)]
struct Destination {
    socket: UdpSocket,
    addr: SocketAddr,
    /// Time of the last error while the destination counts as failing.
    failing: Option<Instant>,
}

/// Counters of a [`UdpSender`], one set per destination (in the order
/// given), shared with other threads (metrics).
#[derive(Debug, Default)]
pub struct UdpStats {
    destinations: Vec<DestinationStats>,
}

/// The counters of one UDP destination.
#[derive(Debug)]
pub struct DestinationStats {
    /// The destination.
    pub addr: SocketAddr,
    label: String,
    /// Datagrams sent.
    pub sent: Counter,
    /// Sends that failed.
    pub errors: Counter,
    /// Times the destination went from reachable to failing (logged once each).
    pub outages: Counter,
}

impl UdpStats {
    /// The destinations' counters.
    pub fn destinations(&self) -> &[DestinationStats] {
        &self.destinations
    }
}

impl Collect for UdpStats {
    fn collect(&self, out: &mut Scrape<'_>) -> std::fmt::Result {
        type Read = fn(&DestinationStats) -> u64;
        let families: [(&str, &str, Read); 3] = [
            (
                "photopose_stream_udp_datagrams_sent_total",
                "Pose datagrams sent, per UDP destination.",
                |d| d.sent.get(),
            ),
            (
                "photopose_stream_udp_send_errors_total",
                "Pose datagrams the socket refused to send (destination unreachable), per UDP destination.",
                |d| d.errors.get(),
            ),
            (
                "photopose_stream_udp_outages_total",
                "Times a UDP destination went from reachable to failing.",
                |d| d.outages.get(),
            ),
        ];
        for (name, help, read) in families {
            let series: Vec<(&str, u64)> = self
                .destinations
                .iter()
                .map(|d| (d.label.as_str(), read(d)))
                .collect();
            out.counter_family(name, help, "destination", &series)?;
        }
        Ok(())
    }
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
            });
        }
        let stats = Arc::new(UdpStats {
            destinations: out
                .iter()
                .map(|d| DestinationStats {
                    addr: d.addr,
                    label: d.addr.to_string(),
                    sent: Counter::new(),
                    errors: Counter::new(),
                    outages: Counter::new(),
                })
                .collect(),
        });
        Ok(UdpSender {
            destinations: out,
            stats,
        })
    }

    /// Sends `line` to every destination.
    pub fn send(&mut self, line: &[u8]) {
        for (d, c) in self.destinations.iter_mut().zip(&self.stats.destinations) {
            match d.socket.send(line) {
                Ok(_) => {
                    c.sent.inc();
                    if d.failing.is_some_and(|t| t.elapsed() >= RECOVERY) {
                        d.failing = None;
                        tracing::info!(destination = %d.addr, errors = c.errors.get(), "UDP pose destination reachable again");
                    }
                }
                Err(e) => {
                    c.errors.inc();
                    if d.failing.is_none() {
                        c.outages.inc();
                        tracing::warn!(destination = %d.addr, error = %e, "UDP pose destination unreachable; counting and going on");
                    }
                    d.failing = Some(Instant::now());
                }
            }
        }
    }

    /// `(destination, datagrams sent, send errors)` per destination.
    pub fn stats(&self) -> impl Iterator<Item = (SocketAddr, u64, u64)> + '_ {
        self.stats
            .destinations
            .iter()
            .map(|d| (d.addr, d.sent.get(), d.errors.get()))
    }

    /// The counters, to keep (metrics).
    pub fn shared_stats(&self) -> Arc<UdpStats> {
        Arc::clone(&self.stats)
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
        let c = &tx.stats.destinations[0];
        assert!(
            c.errors.get() >= 10,
            "the refusals are counted: {:?}",
            c.errors
        );
        assert_eq!(c.outages.get(), 1, "one outage, logged once");
        assert!(tx.destinations[0].failing.is_some());
        let mut e = photopose_telemetry::Exposition::new();
        e.register(tx.shared_stats());
        let text = e.render();
        let line = format!("photopose_stream_udp_outages_total{{destination=\"{port}\"}} 1");
        assert!(text.lines().any(|l| l == line), "{line} missing:\n{text}");
    }
}
