//! A small, bounded HTTP/1.1 text endpoint on the edge runtime (the daemon's
//! Prometheus metrics): one path answers `GET` with the text a render
//! callback produces, everything else gets 404/405. Every connection is its
//! own task (hyper's HTTP/1 server), so a slow or idle client never delays
//! another. Bounded by a connection limit (more are closed at once and
//! counted), a request-head size limit (431 above it), a header read timeout
//! and a cap on a connection's lifetime.

use crate::edge::EdgeHandle;
use crate::StreamError;
use bytes::Bytes;
use http_body_util::Full;
use hyper::body::Incoming;
use hyper::header::{HeaderValue, ALLOW, CONTENT_TYPE};
use hyper::{Method, Request, Response, StatusCode};
use hyper_util::rt::{TokioIo, TokioTimer};
use photopose_telemetry::{Collect, Counter, Scrape};
use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::Semaphore;
use tokio_util::sync::CancellationToken;

/// Produces the body of a `GET` of the endpoint's path.
pub type Render = Arc<dyn Fn() -> String + Send + Sync>;

/// The bounds of a text endpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HttpLimits {
    /// Connections served at once; more are closed at once.
    pub max_connections: usize,
    /// Largest request head (request line and headers), bytes.
    pub max_head_bytes: usize,
    /// Time a client has to send a complete request head.
    pub header_timeout: Duration,
    /// Longest life of one connection (keep-alive included).
    pub max_connection_life: Duration,
}

impl Default for HttpLimits {
    fn default() -> Self {
        HttpLimits {
            max_connections: 64,
            max_head_bytes: 8192,
            header_timeout: Duration::from_secs(2),
            max_connection_life: Duration::from_secs(60),
        }
    }
}

/// Counters of a text endpoint.
#[derive(Debug, Default)]
pub struct HttpStats {
    /// Connections served.
    pub accepted: Counter,
    /// Connections closed at once because the limit was reached.
    pub refused: Counter,
    /// Requests answered.
    pub requests: Counter,
}

impl Collect for HttpStats {
    fn collect(&self, out: &mut Scrape<'_>) -> std::fmt::Result {
        out.counter(
            "photopose_metrics_connections_accepted_total",
            "Connections the metrics endpoint served.",
            self.accepted.get(),
        )?;
        out.counter(
            "photopose_metrics_connections_refused_total",
            "Connections to the metrics endpoint closed at once: its connection limit was reached.",
            self.refused.get(),
        )?;
        out.counter(
            "photopose_metrics_requests_total",
            "Requests the metrics endpoint answered.",
            self.requests.get(),
        )
    }
}

/// A running text endpoint; [`TextEndpoint::stop`] or the edge's stop ends it.
#[derive(Debug)]
pub struct TextEndpoint {
    addr: SocketAddr,
    stats: Arc<HttpStats>,
    stop: CancellationToken,
}

/// At most one log line per this interval about refused connections.
const REFUSAL_LOG_INTERVAL: Duration = Duration::from_secs(10);
/// Time a connection has to finish its answer when it is closed.
const GRACEFUL_CLOSE: Duration = Duration::from_secs(1);
/// The smallest request-head buffer hyper accepts.
const MIN_HEAD_BUFFER: usize = 8192;

impl TextEndpoint {
    /// Serves `render()` at `path` on `listen` from the edge runtime.
    pub fn start(
        edge: &EdgeHandle,
        listen: SocketAddr,
        path: &'static str,
        render: Render,
        limits: HttpLimits,
    ) -> Result<Self, StreamError> {
        Self::start_counted(edge, listen, path, render, limits, Arc::default())
    }

    /// [`TextEndpoint::start`] counting into `stats` (made first, e.g. so
    /// that the metrics it serves include its own).
    pub fn start_counted(
        edge: &EdgeHandle,
        listen: SocketAddr,
        path: &'static str,
        render: Render,
        limits: HttpLimits,
        stats: Arc<HttpStats>,
    ) -> Result<Self, StreamError> {
        let (listener, addr) = edge.listen(listen, "cannot listen for HTTP on")?;
        let stop = edge.stop_token();
        let mut http = hyper::server::conn::http1::Builder::new();
        http.timer(TokioTimer::new())
            .header_read_timeout(limits.header_timeout)
            .max_header_size(limits.max_head_bytes)
            .max_buf_size(limits.max_head_bytes.max(MIN_HEAD_BUFFER));
        let accept = {
            let (stats, stop, edge) = (Arc::clone(&stats), stop.clone(), edge.clone());
            let slots = Arc::new(Semaphore::new(limits.max_connections.max(1)));
            async move {
                let mut last_refusal_log: Option<Instant> = None;
                loop {
                    let (stream, peer) = tokio::select! {
                        biased;
                        _ = stop.cancelled() => return,
                        accepted = listener.accept() => match accepted {
                            Ok(a) => a,
                            Err(e) => {
                                tracing::warn!(error = %e, %addr, "HTTP endpoint: accept failed");
                                tokio::time::sleep(Duration::from_millis(100)).await;
                                continue;
                            }
                        },
                    };
                    let Ok(slot) = Arc::clone(&slots).try_acquire_owned() else {
                        stats.refused.inc();
                        let n = stats.refused.get();
                        drop(stream);
                        if last_refusal_log.is_none_or(|t| t.elapsed() >= REFUSAL_LOG_INTERVAL) {
                            tracing::warn!(client = %peer, %addr, refused_total = n,
                                "HTTP endpoint: connection limit reached, closing new connections");
                            last_refusal_log = Some(Instant::now());
                        }
                        continue;
                    };
                    stats.accepted.inc();
                    let service = {
                        let (render, stats) = (Arc::clone(&render), Arc::clone(&stats));
                        hyper::service::service_fn(move |req: Request<Incoming>| {
                            stats.requests.inc();
                            let response = respond(&req, path, &render);
                            async move { Ok::<_, Infallible>(response) }
                        })
                    };
                    let connection = http.serve_connection(TokioIo::new(stream), service);
                    let stop = stop.clone();
                    edge.spawn(async move {
                        let _slot = slot;
                        tokio::pin!(connection);
                        tokio::select! {
                            _ = connection.as_mut() => return,
                            _ = stop.cancelled() => {}
                            _ = tokio::time::sleep(limits.max_connection_life) => {}
                        }
                        // Finish the request in progress, then close.
                        connection.as_mut().graceful_shutdown();
                        let _ = tokio::time::timeout(GRACEFUL_CLOSE, connection).await;
                    });
                }
            }
        };
        edge.spawn(accept);
        Ok(TextEndpoint { addr, stats, stop })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The counters.
    pub fn stats(&self) -> &HttpStats {
        &self.stats
    }

    /// Stops accepting and closes the connections.
    pub fn stop(self) {
        self.stop.cancel();
    }
}

fn respond(req: &Request<Incoming>, path: &str, render: &Render) -> Response<Full<Bytes>> {
    let text = |status: StatusCode, body: String| {
        let mut r = Response::new(Full::new(Bytes::from(body)));
        *r.status_mut() = status;
        r.headers_mut().insert(
            CONTENT_TYPE,
            HeaderValue::from_static("text/plain; version=0.0.4; charset=utf-8"),
        );
        r
    };
    if req.uri().path() != path {
        return text(StatusCode::NOT_FOUND, format!("try {path}\n"));
    }
    match *req.method() {
        // hyper leaves the body out of a HEAD answer.
        Method::GET | Method::HEAD => text(StatusCode::OK, render()),
        _ => {
            let mut r = text(StatusCode::METHOD_NOT_ALLOWED, "GET only\n".into());
            r.headers_mut()
                .insert(ALLOW, HeaderValue::from_static("GET, HEAD"));
            r
        }
    }
}
