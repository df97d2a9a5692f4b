//! The Prometheus text endpoint: counters and the latency histogram of a
//! running pipeline at `http://<listen>/metrics`, one thread, no framework.

use crate::run::{Counters, LATENCY_BASE_US, LATENCY_BUCKETS};
use std::fmt::Write as _;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

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
                "TCP clients dropped for a full queue or a write error.",
                "counter",
                &tcp.dropped,
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

/// Serves [`render`] over HTTP until stopped.
#[derive(Debug)]
pub struct MetricsServer {
    addr: SocketAddr,
    thread: Option<JoinHandle<()>>,
}

impl MetricsServer {
    /// Listens on `listen`; `stop` ends the thread.
    pub fn start(
        listen: SocketAddr,
        counters: Arc<Counters>,
        stop: Arc<AtomicBool>,
    ) -> std::io::Result<Self> {
        let listener = TcpListener::bind(listen)?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let thread = std::thread::Builder::new().name("metrics".into()).spawn(move || {
            while !stop.load(Ordering::Acquire) {
                match listener.accept() {
                    Ok((mut stream, _)) => {
                        let _ = stream.set_nonblocking(false);
                        let _ = stream.set_read_timeout(Some(Duration::from_millis(500)));
                        let _ = stream.set_write_timeout(Some(Duration::from_millis(500)));
                        let mut req = [0u8; 1024];
                        let n = stream.read(&mut req).unwrap_or(0);
                        let ok = req[..n].starts_with(b"GET /metrics");
                        let (status, body) = if ok {
                            ("200 OK", render(&counters))
                        } else {
                            ("404 Not Found", "try /metrics\n".to_string())
                        };
                        let _ = write!(
                            stream,
                            "HTTP/1.1 {status}\r\nContent-Type: text/plain; version=0.0.4\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                            body.len()
                        );
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => std::thread::sleep(Duration::from_millis(20)),
                    Err(e) => {
                        tracing::warn!(error = %e, "metrics endpoint: accept failed");
                        std::thread::sleep(Duration::from_millis(200));
                    }
                }
            }
        })?;
        Ok(MetricsServer {
            addr,
            thread: Some(thread),
        })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Waits for the thread (after the stop flag was set).
    pub fn join(mut self) {
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serves_the_counters_over_http() {
        let c = Arc::new(Counters::default());
        c.frames_in.store(42, Ordering::Relaxed);
        let stop = Arc::new(AtomicBool::new(false));
        let server = MetricsServer::start("127.0.0.1:0".parse().unwrap(), c, stop.clone()).unwrap();
        let mut s = std::net::TcpStream::connect(server.local_addr()).unwrap();
        s.write_all(b"GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n")
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
        stop.store(true, Ordering::Release);
        server.join();
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
        ] {
            assert!(body.lines().any(|l| l == line), "{line} missing:\n{body}");
        }
    }
}
