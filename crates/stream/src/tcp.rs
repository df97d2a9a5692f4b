//! TCP: any number of clients receive every pose as a JSON line. Each client
//! has a writer thread and a bounded queue of preallocated line buffers; a
//! client whose queue is full (it reads too slowly) is dropped with a log,
//! so a slow client never stalls the pipeline. Publishing copies the line
//! into a free buffer of each client: no allocation once warm.

use crate::StreamError;
use crossbeam_channel::{bounded, Receiver, Sender, TrySendError};
use std::io::Write;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// Counters of the TCP server.
#[derive(Debug, Default)]
pub struct TcpStats {
    /// Clients accepted.
    pub accepted: AtomicU64,
    /// Clients dropped for a full queue or a write error.
    pub dropped: AtomicU64,
    /// Clients connected now.
    pub connected: AtomicU64,
}

struct Client {
    peer: SocketAddr,
    filled: Sender<Vec<u8>>,
    free: Receiver<Vec<u8>>,
    alive: Arc<AtomicBool>,
    writer: Option<JoinHandle<()>>,
}

/// A TCP server streaming pose lines to its clients.
pub struct TcpServer {
    addr: SocketAddr,
    pending: Receiver<Client>,
    clients: Vec<Client>,
    stats: Arc<TcpStats>,
    stop: Arc<AtomicBool>,
    acceptor: Option<JoinHandle<()>>,
    queue: usize,
    /// Clients being torn down, joined on shutdown.
    retired: Arc<Mutex<Vec<JoinHandle<()>>>>,
}

impl std::fmt::Debug for TcpServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TcpServer")
            .field("addr", &self.addr)
            .field("clients", &self.clients.len())
            .field("queue", &self.queue)
            .finish()
    }
}

impl TcpServer {
    /// Listens on `listen`; every client gets a queue of `queue` lines.
    pub fn bind(listen: SocketAddr, queue: usize) -> Result<Self, StreamError> {
        let listener = TcpListener::bind(listen).map_err(|source| StreamError::Socket {
            what: "cannot listen for TCP pose clients on",
            addr: listen.to_string(),
            source,
        })?;
        let addr = listener
            .local_addr()
            .map_err(|source| StreamError::Socket {
                what: "cannot read the address of",
                addr: listen.to_string(),
                source,
            })?;
        listener
            .set_nonblocking(true)
            .map_err(|source| StreamError::Socket {
                what: "cannot make the TCP listener non-blocking on",
                addr: addr.to_string(),
                source,
            })?;
        let queue = queue.max(1);
        let stop = Arc::new(AtomicBool::new(false));
        let stats = Arc::new(TcpStats::default());
        let (tx, pending) = bounded::<Client>(64);
        let acceptor = {
            let stop = stop.clone();
            let stats = stats.clone();
            std::thread::Builder::new()
                .name("pose-tcp-accept".into())
                .spawn(move || accept_loop(listener, tx, queue, stop, stats))
                .map_err(|source| StreamError::Socket {
                    what: "cannot start the TCP acceptor for",
                    addr: addr.to_string(),
                    source,
                })?
        };
        Ok(TcpServer {
            addr,
            pending,
            clients: Vec::new(),
            stats,
            stop,
            acceptor: Some(acceptor),
            queue,
            retired: Arc::new(Mutex::new(Vec::new())),
        })
    }

    /// The address the server listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The counters.
    pub fn stats(&self) -> &TcpStats {
        &self.stats
    }

    /// The counters, shareable with a metrics thread.
    pub fn shared_stats(&self) -> Arc<TcpStats> {
        Arc::clone(&self.stats)
    }

    /// Queues `line` for every client; never blocks. A client with a full
    /// queue, or whose writer has failed, is dropped.
    pub fn publish(&mut self, line: &[u8]) {
        while let Ok(c) = self.pending.try_recv() {
            self.clients.push(c);
        }
        let mut k = 0;
        while k < self.clients.len() {
            let c = &mut self.clients[k];
            let ok = c.alive.load(Ordering::Acquire)
                && match c.free.try_recv() {
                    Ok(mut buf) => {
                        buf.clear();
                        buf.extend_from_slice(line);
                        !matches!(
                            c.filled.try_send(buf),
                            Err(TrySendError::Full(_) | TrySendError::Disconnected(_))
                        )
                    }
                    Err(_) => false,
                };
            if ok {
                k += 1;
                continue;
            }
            let c = self.clients.swap_remove(k);
            let reason = if c.alive.load(Ordering::Acquire) {
                "its queue is full (it reads too slowly)"
            } else {
                "writing to it failed (disconnected)"
            };
            tracing::warn!(client = %c.peer, queue = self.queue, "dropping TCP pose client: {reason}");
            self.retire(c);
        }
    }

    fn retire(&mut self, mut c: Client) {
        c.alive.store(false, Ordering::Release);
        self.stats.dropped.fetch_add(1, Ordering::Relaxed);
        self.stats.connected.fetch_sub(1, Ordering::Relaxed);
        // Dropping the sender ends the writer thread.
        drop(c.filled);
        if let (Some(w), Ok(mut r)) = (c.writer.take(), self.retired.lock()) {
            r.push(w);
        }
    }

    /// Stops accepting, lets the writers flush what is queued and joins all threads.
    pub fn shutdown(mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(a) = self.acceptor.take() {
            let _ = a.join();
        }
        while let Ok(c) = self.pending.try_recv() {
            self.clients.push(c);
        }
        for mut c in self.clients.drain(..) {
            drop(c.filled);
            if let Some(w) = c.writer.take() {
                let _ = w.join();
            }
        }
        if let Ok(mut r) = self.retired.lock() {
            for w in r.drain(..) {
                let _ = w.join();
            }
        }
    }
}

fn accept_loop(
    listener: TcpListener,
    tx: Sender<Client>,
    queue: usize,
    stop: Arc<AtomicBool>,
    stats: Arc<TcpStats>,
) {
    while !stop.load(Ordering::Acquire) {
        match listener.accept() {
            Ok((stream, peer)) => {
                let _ = stream.set_nodelay(true);
                let _ = stream.set_nonblocking(false);
                // A stuck peer must not hold its writer forever.
                let _ = stream.set_write_timeout(Some(Duration::from_secs(2)));
                let (filled_tx, filled_rx) = bounded::<Vec<u8>>(queue);
                let (free_tx, free_rx) = bounded::<Vec<u8>>(queue);
                for _ in 0..queue {
                    let _ = free_tx.send(Vec::with_capacity(1024));
                }
                let alive = Arc::new(AtomicBool::new(true));
                let writer = {
                    let alive = alive.clone();
                    std::thread::Builder::new()
                        .name("pose-tcp-client".into())
                        .spawn(move || write_loop(stream, filled_rx, free_tx, alive))
                };
                match writer {
                    Ok(w) => {
                        stats.accepted.fetch_add(1, Ordering::Relaxed);
                        stats.connected.fetch_add(1, Ordering::Relaxed);
                        tracing::info!(client = %peer, "TCP pose client connected");
                        let c = Client {
                            peer,
                            filled: filled_tx,
                            free: free_rx,
                            alive,
                            writer: Some(w),
                        };
                        if tx.send(c).is_err() {
                            return;
                        }
                    }
                    Err(e) => {
                        tracing::error!(client = %peer, error = %e, "cannot start a writer for a TCP client")
                    }
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(10))
            }
            Err(e) => {
                tracing::warn!(error = %e, "accepting a TCP pose client failed");
                std::thread::sleep(Duration::from_millis(100));
            }
        }
    }
}

fn write_loop(
    mut stream: TcpStream,
    filled: Receiver<Vec<u8>>,
    free: Sender<Vec<u8>>,
    alive: Arc<AtomicBool>,
) {
    for buf in filled.iter() {
        if stream.write_all(&buf).is_err() {
            alive.store(false, Ordering::Release);
            return;
        }
        let _ = free.try_send(buf);
    }
    let _ = stream.flush();
}
