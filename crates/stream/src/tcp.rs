//! TCP: clients receive every pose as a JSON line, served on the edge
//! runtime ([`crate::edge`]). The output thread hands each line over through
//! a line feed ([`crate::edge::line_feed`]: no allocation, never blocks;
//! dropped and counted when the edge is behind). One hub task accepts clients and fans
//! the lines out; each client is a task with a bounded queue of lines. A
//! client whose queue is full (it reads too slowly) is dropped, connections
//! beyond the client limit are accepted and closed at once, and a client
//! that leaves leaves nothing behind.

use crate::edge::{line_feed, EdgeHandle, FeedReceiver, FeedSender};
use crate::StreamError;
use bytes::Bytes;
use photopose_telemetry::{Collect, Counter, Scrape};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, Notify};
use tokio_util::sync::CancellationToken;

/// Largest accepted `client_queue` (lines queued per client).
pub const MAX_CLIENT_QUEUE: usize = 4096;
/// Largest accepted `max_clients`.
pub const MAX_CLIENTS: usize = 1024;
/// Lines handed from the output thread to the hub at most at once (the
/// feed's buffer pool); one pool for all clients.
const FEED_LINES: usize = 1024;
/// Initial capacity of a feed buffer: a pose line is about 1.9 kB with its
/// 36 covariance numbers, 2.1 kB with the robot's state.
const LINE_CAPACITY: usize = 4096;
/// At most one log line per this interval about refused clients.
const REFUSAL_LOG_INTERVAL: Duration = Duration::from_secs(10);

/// The bounds of a TCP pose stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TcpLimits {
    /// Clients served at once (1..=[`MAX_CLIENTS`]); more are refused.
    pub max_clients: usize,
    /// Lines queued per client (1..=[`MAX_CLIENT_QUEUE`]) before it is dropped.
    pub client_queue: usize,
}

impl Default for TcpLimits {
    fn default() -> Self {
        TcpLimits {
            max_clients: 16,
            client_queue: 256,
        }
    }
}

/// Counters of the TCP server.
#[derive(Debug, Default)]
pub struct TcpStats {
    /// Clients accepted (and served).
    pub accepted: Counter,
    /// Clients dropped because their queue was full (they read too slowly).
    pub dropped: Counter,
    /// Clients that left (closed, reset, or a write failed).
    pub disconnected: Counter,
    /// Connections refused (closed at once) because the client limit was reached.
    pub refused: Counter,
    /// Lines not sent to anyone because the edge runtime was behind.
    pub lines_dropped: Counter,
    /// Clients connected now.
    pub connected: AtomicU64,
}

impl Collect for TcpStats {
    fn collect(&self, out: &mut Scrape<'_>) -> std::fmt::Result {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        out.gauge(
            "photopose_stream_clients",
            "TCP pose stream clients connected now.",
            g(&self.connected) as f64,
        )?;
        for (name, help, v) in [
            (
                "photopose_stream_clients_accepted_total",
                "TCP pose stream clients accepted (and served).",
                &self.accepted,
            ),
            (
                "photopose_stream_clients_dropped_total",
                "TCP clients dropped because their queue was full (too slow).",
                &self.dropped,
            ),
            (
                "photopose_stream_clients_disconnected_total",
                "TCP clients that left (closed, reset, write failed).",
                &self.disconnected,
            ),
            (
                "photopose_stream_clients_refused_total",
                "TCP connections closed at once: the client limit was reached.",
                &self.refused,
            ),
            (
                "photopose_stream_lines_dropped_total",
                "Pose lines not streamed over TCP because the edge runtime was behind.",
                &self.lines_dropped,
            ),
        ] {
            out.counter(name, help, v.get())?;
        }
        Ok(())
    }
}

/// A TCP server streaming pose lines to its clients from the edge runtime.
#[derive(Debug)]
pub struct TcpServer {
    addr: SocketAddr,
    feed: FeedSender,
    stats: Arc<TcpStats>,
    limits: TcpLimits,
}

impl TcpServer {
    /// Listens on `listen` and serves clients on `edge` within `limits`
    /// (clamped to their ranges).
    pub fn bind(
        edge: &EdgeHandle,
        listen: SocketAddr,
        limits: TcpLimits,
    ) -> Result<Self, StreamError> {
        let limits = TcpLimits {
            max_clients: limits.max_clients.clamp(1, MAX_CLIENTS),
            client_queue: limits.client_queue.clamp(1, MAX_CLIENT_QUEUE),
        };
        let (listener, addr) = edge.listen(listen, "cannot listen for TCP pose clients on")?;
        let (feed, lines) = line_feed(FEED_LINES, LINE_CAPACITY);
        let stats = Arc::new(TcpStats::default());
        let hub = Hub {
            listener,
            lines,
            limits,
            stats: Arc::clone(&stats),
            stop: edge.stop_token(),
            edge: edge.clone(),
            clients: Vec::with_capacity(limits.max_clients),
            refusals: Refusals::default(),
            left: Arc::new(Notify::new()),
        };
        edge.spawn(hub.run());
        Ok(TcpServer {
            addr,
            feed,
            stats,
            limits,
        })
    }

    /// The address the server listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The bounds in force.
    pub fn limits(&self) -> TcpLimits {
        self.limits
    }

    /// The counters.
    pub fn stats(&self) -> &TcpStats {
        &self.stats
    }

    /// The counters, shareable with a metrics endpoint.
    pub fn shared_stats(&self) -> Arc<TcpStats> {
        Arc::clone(&self.stats)
    }

    /// Hands `line` to every client; never blocks, never allocates once
    /// warm. When the edge is behind the line is dropped and counted.
    pub fn publish(&mut self, line: &[u8]) {
        if !self.feed.send(line) {
            self.stats.lines_dropped.inc();
        }
    }

    /// Stops accepting; the clients get what is queued, then their
    /// connections are closed. Returns at once: the edge runtime finishes
    /// the work (and [`crate::edge::Edge::stop`] waits for it).
    pub fn shutdown(self) {
        // Dropping the feed's sender closes it: the hub forwards the lines
        // still waiting and ends.
        drop(self.feed);
    }
}

/// Rate-limited logging of refused connections.
#[derive(Default)]
struct Refusals {
    last_log: Option<Instant>,
    since_log: u64,
}

/// What the hub keeps of a served client.
struct ClientLink {
    lines: mpsc::Sender<Bytes>,
    kick: CancellationToken,
    peer: SocketAddr,
}

/// Accepts clients and fans the lines out (one task per server).
struct Hub {
    listener: TcpListener,
    lines: FeedReceiver,
    limits: TcpLimits,
    stats: Arc<TcpStats>,
    stop: CancellationToken,
    edge: EdgeHandle,
    clients: Vec<ClientLink>,
    refusals: Refusals,
    /// Woken by a client task that ends, so its link is forgotten at once.
    left: Arc<Notify>,
}

impl Hub {
    async fn run(mut self) {
        loop {
            tokio::select! {
                biased;
                _ = self.stop.cancelled() => break,
                _ = self.left.notified() => self.clients.retain(|c| !c.lines.is_closed()),
                _ = self.lines.ready() => {
                    self.fan_out();
                    if self.lines.is_closed() {
                        self.fan_out();
                        break;
                    }
                }
                accepted = self.listener.accept() => match accepted {
                    Ok((stream, peer)) => self.admit(stream, peer),
                    Err(e) => {
                        // Out of descriptors and the like: wait, do not spin.
                        tracing::warn!(error = %e, "accepting a TCP pose client failed");
                        tokio::time::sleep(Duration::from_millis(100)).await;
                    }
                },
            }
        }
        // Dropping the senders lets every client flush its queue and close.
        self.clients.clear();
    }

    fn admit(&mut self, stream: TcpStream, peer: SocketAddr) {
        // Forget clients that have left.
        self.clients.retain(|c| !c.lines.is_closed());
        if self.clients.len() >= self.limits.max_clients {
            self.stats.refused.inc();
            drop(stream);
            let r = &mut self.refusals;
            r.since_log += 1;
            if r.last_log
                .is_none_or(|t| t.elapsed() >= REFUSAL_LOG_INTERVAL)
            {
                tracing::warn!(
                    client = %peer,
                    refused = r.since_log,
                    max_clients = self.limits.max_clients,
                    "refusing TCP pose clients: the client limit is reached (output.tcp_max_clients)"
                );
                r.last_log = Some(Instant::now());
                r.since_log = 0;
            }
            return;
        }
        let _ = stream.set_nodelay(true);
        let (tx, rx) = mpsc::channel(self.limits.client_queue);
        let kick = CancellationToken::new();
        self.stats.accepted.inc();
        self.stats.connected.fetch_add(1, Ordering::Relaxed);
        tracing::info!(client = %peer, "TCP pose client connected");
        let ended = Ended {
            stats: Arc::clone(&self.stats),
            hub: Arc::clone(&self.left),
        };
        self.edge
            .spawn(serve_client(stream, peer, rx, kick.clone(), ended));
        self.clients.push(ClientLink {
            lines: tx,
            kick,
            peer,
        });
    }

    /// Forwards every waiting line to every client; drops full clients.
    fn fan_out(&mut self) {
        while let Some(buf) = self.lines.take() {
            if self.clients.is_empty() {
                self.lines.give_back(buf);
                continue;
            }
            let line = Bytes::copy_from_slice(&buf);
            self.lines.give_back(buf);
            let (stats, queue) = (&self.stats, self.limits.client_queue);
            self.clients
                .retain(|c| match c.lines.try_send(line.clone()) {
                    Ok(()) => true,
                    Err(mpsc::error::TrySendError::Closed(_)) => false,
                    Err(mpsc::error::TrySendError::Full(_)) => {
                        c.kick.cancel();
                        stats.dropped.inc();
                        tracing::info!(
                            client = %c.peer,
                            queue,
                            "dropping TCP pose client: its queue is full (it reads too slowly)"
                        );
                        false
                    }
                });
        }
    }
}

/// However a client task ends: the connected gauge goes down and the hub
/// is told to forget the client.
struct Ended {
    stats: Arc<TcpStats>,
    hub: Arc<Notify>,
}

impl Drop for Ended {
    fn drop(&mut self) {
        self.stats.connected.fetch_sub(1, Ordering::Relaxed);
        self.hub.notify_one();
    }
}

/// Serves one client; when it ends, the socket and the queue are gone
/// before the hub is told.
async fn serve_client(
    stream: TcpStream,
    peer: SocketAddr,
    lines: mpsc::Receiver<Bytes>,
    kick: CancellationToken,
    ended: Ended,
) {
    if let Some(reason) = write_lines(stream, lines, kick).await {
        ended.stats.disconnected.inc();
        tracing::info!(client = %peer, %reason, "TCP pose client disconnected");
    }
    drop(ended);
}

/// Writes the queued lines to one client until it leaves (the reason is
/// returned), is kicked, or the server closes (the queue is flushed first).
async fn write_lines(
    stream: TcpStream,
    mut lines: mpsc::Receiver<Bytes>,
    kick: CancellationToken,
) -> Option<String> {
    let (mut reader, mut writer) = stream.into_split();
    // Clients send nothing; reading notices when they leave.
    let mut scratch = [0u8; 256];
    loop {
        tokio::select! {
            biased;
            _ = kick.cancelled() => return None,
            line = lines.recv() => match line {
                Some(line) => {
                    tokio::select! {
                        biased;
                        _ = kick.cancelled() => return None,
                        written = writer.write_all(&line) => {
                            if let Err(e) = written {
                                return Some(format!("writing failed: {e}"));
                            }
                        }
                    }
                }
                None => {
                    // The server closes: everything queued was written.
                    let _ = writer.shutdown().await;
                    return None;
                }
            },
            read = reader.read(&mut scratch) => match read {
                Ok(0) => return Some("closed by the client".to_string()),
                Ok(_) => {}
                Err(e) => return Some(format!("reading failed: {e}")),
            },
        }
    }
}
