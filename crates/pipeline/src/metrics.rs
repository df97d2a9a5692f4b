//! The Prometheus text endpoint: counters and the latency histogram of a
//! running pipeline at `http://<listen>/metrics`, served from the edge
//! runtime (many connections at once, bounded).

use crate::run::{Counters, LATENCY_BASE_US, LATENCY_BUCKETS};
use photopose_stream::{EdgeHandle, HttpLimits, StreamError, TextEndpoint};
use std::fmt::Write as _;
use std::net::SocketAddr;
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// The metrics in Prometheus' text exposition format.
pub fn render(c: &Counters) -> String {
    let mut s = String::with_capacity(4096);
    let counters = [
        (
            "photopose_frames_in_total",
            "Frames delivered by the source.",
            &c.frames_in,
        ),
        (
            "photopose_frames_dropped_total",
            "Frames dropped by the overflow policy.",
            &c.frames_dropped,
        ),
        (
            "photopose_frames_processed_total",
            "Frames processed by the detection workers.",
            &c.frames_processed,
        ),
        (
            "photopose_poses_ok_total",
            "Pose messages with a pose.",
            &c.poses_ok,
        ),
        (
            "photopose_poses_failed_total",
            "Pose messages without a pose.",
            &c.poses_failed,
        ),
        (
            "photopose_poses_stale_total",
            "Stale messages sent while no frame came.",
            &c.stale,
        ),
    ];
    for (name, help, v) in counters {
        let _ = writeln!(
            s,
            "# HELP {name} {help}\n# TYPE {name} counter\n{name} {}",
            v.load(Ordering::Relaxed)
        );
    }
    if let Some(src) = &c.source {
        let st = src.snapshot();
        for (name, help, v) in [
            (
                "photopose_source_missing_frames_total",
                "Frames the camera sent that never arrived (gaps in its frame ids).",
                st.missing,
            ),
            (
                "photopose_source_incomplete_frames_total",
                "Frames that arrived incomplete or damaged (not processed).",
                st.incomplete,
            ),
            (
                "photopose_source_losses_total",
                "Times the camera was lost.",
                st.losses,
            ),
            (
                "photopose_source_opens_total",
                "Times the camera was (re)opened.",
                st.opens,
            ),
        ] {
            let _ = writeln!(s, "# HELP {name} {help}\n# TYPE {name} counter\n{name} {v}");
        }
        let name = "photopose_source_connected";
        let _ = writeln!(
            s,
            "# HELP {name} Whether the camera is connected and streaming.\n# TYPE {name} gauge\n{name} {}",
            u8::from(st.connected)
        );
    }
    if let Some(tcp) = &c.tcp {
        for (name, help, kind, v) in [
            (
                "photopose_stream_clients",
                "TCP pose stream clients connected now.",
                "gauge",
                &tcp.connected,
            ),
            (
                "photopose_stream_clients_dropped_total",
                "TCP clients dropped because their queue was full (too slow).",
                "counter",
                &tcp.dropped,
            ),
            (
                "photopose_stream_clients_disconnected_total",
                "TCP clients that left (closed, reset, write failed).",
                "counter",
                &tcp.disconnected,
            ),
            (
                "photopose_stream_clients_refused_total",
                "TCP connections closed at once: the client limit was reached.",
                "counter",
                &tcp.refused,
            ),
            (
                "photopose_stream_lines_dropped_total",
                "Pose lines not streamed over TCP because the edge runtime was behind.",
                "counter",
                &tcp.lines_dropped,
            ),
        ] {
            let _ = writeln!(
                s,
                "# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {}",
                v.load(Ordering::Relaxed)
            );
        }
    }
    if let Some(rsi) = &c.rsi {
        for (name, value) in rsi.snapshot().metrics() {
            let kind = if name.ends_with("_total") {
                "counter"
            } else {
                "gauge"
            };
            let _ = writeln!(s, "# TYPE {name} {kind}\n{name} {value}");
        }
    }
    let name = "photopose_latency_seconds";
    let _ = writeln!(
        s,
        "# HELP {name} Frame hand-over to pose sent.\n# TYPE {name} histogram"
    );
    let mut cumulative = 0u64;
    for k in 0..LATENCY_BUCKETS {
        cumulative += c.latency_histogram[k].load(Ordering::Relaxed);
        // Every fourth edge keeps the exposition short (two per octave).
        if k % 4 == 3 {
            let le = LATENCY_BASE_US * 2f64.powf(k as f64 / 8.0) / 1e6;
            let _ = writeln!(s, "{name}_bucket{{le=\"{le:.6}\"}} {cumulative}");
        }
    }
    let _ = writeln!(s, "{name}_bucket{{le=\"+Inf\"}} {cumulative}");
    let _ = writeln!(
        s,
        "{name}_sum {:.6}",
        c.latency_us_sum.load(Ordering::Relaxed) as f64 / 1e6
    );
    let _ = writeln!(s, "{name}_count {cumulative}");
    s
}

/// Serves [`render`] at `/metrics` on the edge runtime
/// ([`photopose_stream::http`]): every connection its own task, so an idle
/// or slow client never delays a scrape; bounded by
/// [`photopose_stream::HttpLimits`].
#[derive(Debug)]
pub struct MetricsServer {
    endpoint: TextEndpoint,
}

impl MetricsServer {
    /// Listens on `listen` and serves from `edge` until [`MetricsServer::stop`]
    /// or the edge stops.
    pub fn start(
        edge: &EdgeHandle,
        listen: SocketAddr,
        counters: Arc<Counters>,
    ) -> Result<Self, StreamError> {
        let endpoint = TextEndpoint::start(
            edge,
            listen,
            "/metrics",
            Arc::new(move || render(&counters)),
            HttpLimits::default(),
        )?;
        Ok(MetricsServer { endpoint })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.endpoint.local_addr()
    }

    /// Stops accepting and closes the connections.
    pub fn stop(self) {
        self.endpoint.stop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use std::io::{Read, Write};

    #[test]
    fn serves_the_counters_over_http() {
        let c = Arc::new(Counters::default());
        c.frames_in.store(42, Ordering::Relaxed);
        let edge = photopose_stream::Edge::start(1).unwrap();
        let server =
            MetricsServer::start(edge.handle(), "127.0.0.1:0".parse().unwrap(), c).unwrap();
        let mut s = std::net::TcpStream::connect(server.local_addr()).unwrap();
        s.write_all(b"GET /metrics HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
            .unwrap();
        let mut body = String::new();
        s.read_to_string(&mut body).unwrap();
        assert!(body.starts_with("HTTP/1.1 200 OK"), "{body}");
        assert!(body.contains("photopose_frames_in_total 42"), "{body}");
        assert!(body.contains("photopose_latency_seconds_count 0"), "{body}");
        assert!(
            !body.contains("photopose_source_"),
            "no source counters: {body}"
        );
        let mut s = std::net::TcpStream::connect(server.local_addr()).unwrap();
        s.write_all(b"GET /other HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
            .unwrap();
        let mut other = String::new();
        s.read_to_string(&mut other).unwrap();
        assert!(other.starts_with("HTTP/1.1 404"), "{other}");
        server.stop();
        edge.stop();
    }

    #[test]
    fn source_and_stream_counters_appear_when_present() {
        let src = Arc::new(photopose_acquire::SourceCounters::default());
        src.missing.store(3, Ordering::Relaxed);
        src.losses.store(1, Ordering::Relaxed);
        src.connected.store(true, Ordering::Relaxed);
        let tcp = Arc::new(photopose_stream::TcpStats::default());
        tcp.connected.store(2, Ordering::Relaxed);
        let c = Counters {
            source: Some(src),
            tcp: Some(tcp),
            ..Counters::default()
        };
        let body = render(&c);
        for line in [
            "photopose_source_missing_frames_total 3",
            "photopose_source_losses_total 1",
            "photopose_source_connected 1",
            "photopose_stream_clients 2",
            "photopose_stream_clients_dropped_total 0",
            "photopose_stream_clients_refused_total 0",
            "photopose_stream_lines_dropped_total 0",
        ] {
            assert!(body.lines().any(|l| l == line), "{line} missing:\n{body}");
        }
    }
}
