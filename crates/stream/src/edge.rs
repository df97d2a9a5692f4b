//! The edge runtime: one tokio runtime on a few named threads of its own
//! that serves the network edges people and other programs talk to (the TCP
//! pose stream, the metrics endpoint, later more), and the bounded hand-over
//! of lines from the pipeline's dedicated threads to it.
//!
//! The pipeline's threads (grabber, detection workers, output, RSI) never
//! await. They hand lines to the runtime through a line feed ([`line_feed`]): a fixed
//! pool of preallocated buffers passed through two lock-free bounded queues
//! plus a [`tokio::sync::Notify`] that wakes the edge task. Handing over a
//! line never blocks and, once the buffers have grown to the line length,
//! never allocates; when the edge is behind (no free buffer) the line is
//! dropped and counted.

use crate::StreamError;
use crossbeam_queue::ArrayQueue;
use std::future::Future;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

/// How long [`Edge::stop`] lets the tasks finish (clients flushing their
/// queues) before the runtime drops whatever still runs.
pub const STOP_GRACE: Duration = Duration::from_secs(2);

/// The tokio runtime of the network edges, on threads named `edge-N`.
///
/// Dropping it (or [`Edge::stop`]) asks every task to end, waits up to
/// [`STOP_GRACE`] for them and joins the runtime's threads. Stop it from a
/// plain thread, not from inside an async task.
pub struct Edge {
    runtime: Option<tokio::runtime::Runtime>,
    handle: EdgeHandle,
}

impl std::fmt::Debug for Edge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Edge")
            .field("running", &self.runtime.is_some())
            .finish()
    }
}

/// Where servers are started on the edge runtime; cheap to clone.
#[derive(Debug, Clone)]
pub struct EdgeHandle {
    runtime: tokio::runtime::Handle,
    stop: CancellationToken,
    tracker: TaskTracker,
}

impl Edge {
    /// Starts the runtime with `threads` worker threads (clamped to 1..=4).
    pub fn start(threads: usize) -> Result<Self, StreamError> {
        let counter = AtomicUsize::new(0);
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(threads.clamp(1, 4))
            .thread_name_fn(move || format!("edge-{}", counter.fetch_add(1, Ordering::Relaxed)))
            .enable_io()
            .enable_time()
            .build()
            .map_err(|source| StreamError::Runtime { source })?;
        let handle = EdgeHandle {
            runtime: runtime.handle().clone(),
            stop: CancellationToken::new(),
            tracker: TaskTracker::new(),
        };
        Ok(Edge {
            runtime: Some(runtime),
            handle,
        })
    }

    /// The handle servers are started with.
    pub fn handle(&self) -> &EdgeHandle {
        &self.handle
    }

    /// Ends every task (after at most [`STOP_GRACE`]) and joins the threads.
    pub fn stop(mut self) {
        self.shut_down();
    }

    fn shut_down(&mut self) {
        let Some(runtime) = self.runtime.take() else {
            return;
        };
        self.handle.stop.cancel();
        self.handle.tracker.close();
        if tokio::runtime::Handle::try_current().is_ok() {
            // Inside some other runtime we must not block: let it go.
            runtime.shutdown_background();
            return;
        }
        let tracker = self.handle.tracker.clone();
        runtime.block_on(async move {
            if tokio::time::timeout(STOP_GRACE, tracker.wait())
                .await
                .is_err()
            {
                tracing::info!(
                    tasks = tracker.len(),
                    "edge tasks still running after the grace period; ending them"
                );
            }
        });
        // Drops what is left and joins the worker threads.
        runtime.shutdown_timeout(Duration::from_millis(500));
    }
}

impl Drop for Edge {
    fn drop(&mut self) {
        self.shut_down();
    }
}

impl EdgeHandle {
    /// Runs `task` on the edge runtime; [`Edge::stop`] waits for it (within
    /// its grace period).
    pub fn spawn<F>(&self, task: F)
    where
        F: Future<Output = ()> + Send + 'static,
    {
        self.tracker.spawn_on(task, &self.runtime);
    }

    /// Cancelled when the edge stops; a child token for one server.
    pub fn stop_token(&self) -> CancellationToken {
        self.stop.child_token()
    }

    /// A tokio TCP listener on `listen`, registered with this runtime.
    pub(crate) fn listen(
        &self,
        listen: std::net::SocketAddr,
        what: &'static str,
    ) -> Result<(tokio::net::TcpListener, std::net::SocketAddr), StreamError> {
        let socket = |what: &'static str, addr: String| {
            move |source| StreamError::Socket { what, addr, source }
        };
        let std_listener =
            std::net::TcpListener::bind(listen).map_err(socket(what, listen.to_string()))?;
        let addr = std_listener
            .local_addr()
            .map_err(socket("cannot read the address of", listen.to_string()))?;
        std_listener.set_nonblocking(true).map_err(socket(
            "cannot make the listener non-blocking on",
            addr.to_string(),
        ))?;
        let _entered = self.runtime.enter();
        let listener = tokio::net::TcpListener::from_std(std_listener)
            .map_err(socket("cannot register the listener on", addr.to_string()))?;
        Ok((listener, addr))
    }
}

/// A bounded, allocation-free hand-over of lines from a plain thread to one
/// task on the edge runtime. Build it with [`line_feed`].
#[derive(Debug)]
struct LineFeed {
    /// Buffers ready to be filled by the publisher.
    free: ArrayQueue<Vec<u8>>,
    /// Filled buffers in publishing order, for the edge task.
    filled: ArrayQueue<Vec<u8>>,
    /// Wakes the edge task after a push (or the close).
    ready: Notify,
    /// The publisher is gone: the task forwards what is left and ends.
    closed: AtomicBool,
    /// Lines dropped because the edge was behind (no free buffer).
    dropped: AtomicU64,
}

/// The publishing end of a line feed (owned by one pipeline thread).
#[derive(Debug)]
pub struct FeedSender {
    feed: Arc<LineFeed>,
}

/// The edge end of a line feed (owned by one task).
#[derive(Debug)]
pub struct FeedReceiver {
    feed: Arc<LineFeed>,
}

/// A feed of `buffers` preallocated line buffers of `line_capacity` bytes.
pub fn line_feed(buffers: usize, line_capacity: usize) -> (FeedSender, FeedReceiver) {
    let buffers = buffers.max(1);
    let feed = Arc::new(LineFeed {
        free: ArrayQueue::new(buffers),
        filled: ArrayQueue::new(buffers),
        ready: Notify::new(),
        closed: AtomicBool::new(false),
        dropped: AtomicU64::new(0),
    });
    for _ in 0..buffers {
        let _ = feed.free.push(Vec::with_capacity(line_capacity));
    }
    (
        FeedSender {
            feed: Arc::clone(&feed),
        },
        FeedReceiver { feed },
    )
}

impl FeedSender {
    /// Hands `line` to the edge task; never blocks. Returns `false` (and
    /// counts it) when the edge is behind and the line was dropped.
    pub fn send(&self, line: &[u8]) -> bool {
        let Some(mut buf) = self.feed.free.pop() else {
            self.feed.dropped.fetch_add(1, Ordering::Relaxed);
            return false;
        };
        buf.clear();
        buf.extend_from_slice(line);
        // Every buffer is in exactly one queue, so `filled` has room.
        if self.feed.filled.push(buf).is_err() {
            self.feed.dropped.fetch_add(1, Ordering::Relaxed);
            return false;
        }
        self.feed.ready.notify_one();
        true
    }

    /// Lines dropped so far because the edge was behind.
    pub fn dropped(&self) -> u64 {
        self.feed.dropped.load(Ordering::Relaxed)
    }
}

impl Drop for FeedSender {
    fn drop(&mut self) {
        self.feed.closed.store(true, Ordering::Release);
        self.feed.ready.notify_one();
    }
}

impl FeedReceiver {
    /// Waits until a line was handed over or the sender is gone.
    pub async fn ready(&self) {
        if self.feed.filled.is_empty() && !self.is_closed() {
            self.feed.ready.notified().await;
        }
    }

    /// The next line in publishing order, if any; give the buffer back
    /// with [`FeedReceiver::give_back`].
    pub fn take(&self) -> Option<Vec<u8>> {
        self.feed.filled.pop()
    }

    /// Returns a buffer to the pool.
    pub fn give_back(&self, buf: Vec<u8>) {
        let _ = self.feed.free.push(buf);
    }

    /// Whether the sender is gone (lines may still be waiting).
    pub fn is_closed(&self) -> bool {
        self.feed.closed.load(Ordering::Acquire)
    }

    /// Lines dropped so far because the edge was behind.
    pub fn dropped(&self) -> u64 {
        self.feed.dropped.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_feed_keeps_order_and_drops_when_no_buffer_is_free() {
        let (tx, rx) = line_feed(3, 16);
        for k in 0..5u8 {
            tx.send(&[k; 4]);
        }
        assert_eq!(tx.dropped(), 2);
        let mut got = Vec::new();
        while let Some(b) = rx.take() {
            got.push(b[0]);
            rx.give_back(b);
        }
        assert_eq!(got, [0, 1, 2]);
        assert!(tx.send(b"again"));
        assert!(!rx.is_closed());
        drop(tx);
        assert!(rx.is_closed());
        assert_eq!(rx.take().as_deref(), Some(&b"again"[..]));
    }

    #[test]
    fn the_runtime_names_its_threads_and_joins_them_on_stop() {
        let edge = Edge::start(2).unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        for _ in 0..2 {
            let tx = tx.clone();
            edge.handle().spawn(async move {
                let name = std::thread::current().name().map(str::to_string);
                let _ = tx.send(name);
            });
        }
        for _ in 0..2 {
            let name = rx.recv_timeout(Duration::from_secs(5)).unwrap().unwrap();
            assert!(name.starts_with("edge-"), "{name}");
        }
        // A task that waits for the stop ends with it.
        let token = edge.handle().stop_token();
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        edge.handle().spawn(async move {
            token.cancelled().await;
            let _ = done_tx.send(());
        });
        let t0 = std::time::Instant::now();
        edge.stop();
        assert!(t0.elapsed() < STOP_GRACE, "stopped at once");
        done_rx.try_recv().unwrap();
    }
}
