//! The daemon's metrics: the pipeline's own counters ([`Counters`]: frames,
//! poses, the pose latency histogram, pose quality), which also hold the
//! other parts' (camera source, grabber, ring, TCP stream, RSI server), and
//! the Prometheus endpoint serving them all at `http://<listen>/metrics`
//! from the edge runtime (many connections at once, bounded). Everything
//! is recorded in `photopose-telemetry`'s lock-free types and encoded at
//! scrape time. The running pipeline (`run`) uses this module; this module
//! knows nothing of it.

use photopose_acquire::grabber::GrabberCounters;
use photopose_acquire::ring::RingCounters;
use photopose_stream::{EdgeHandle, HttpLimits, HttpStats, StreamError, TextEndpoint};
use photopose_telemetry::{Collect, Counter, Exposition, Gauge, Histogram, Scrape};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Counters of a running pipeline (read them any time).
#[derive(Debug)]
pub struct Counters {
    /// Frames delivered by the source.
    pub frames_in: Counter,
    /// Frames dropped by the overflow policy.
    pub frames_dropped: Counter,
    /// Frames processed by the workers.
    pub frames_processed: Counter,
    /// Frames located in tracking mode (from the latest pose).
    pub frames_tracked: Counter,
    /// Messages with a pose.
    pub poses_ok: Counter,
    /// Messages without a pose (too few targets, error).
    pub poses_failed: Counter,
    /// Stale messages sent while no frame came.
    pub stale: Counter,
    /// Results that carry no targets because the pool of target lists had
    /// none free.
    pub results_without_targets: Arc<Counter>,
    /// Pose latency: frame hand-over → message sent.
    pub latency: Histogram,
    /// σ0 of the last pose, px.
    pub sigma0_px: Gauge,
    /// Targets used by the last pose.
    pub targets: Gauge,
    /// Position standard deviation of the last pose (length of the
    /// centre's σ vector), metres.
    pub position_std_m: Gauge,
    /// When the last pose was sent: ns after `epoch`, plus one (0: none yet).
    pub(crate) last_pose: AtomicU64,
    /// When the last frame came from the source, the same way.
    pub(crate) last_frame: AtomicU64,
    pub(crate) epoch: Instant,
    /// The grabber's counters (the pipeline hands them to its grabber).
    pub grabber: Arc<GrabberCounters>,
    /// The ring's counters, once the pipeline built its ring.
    pub ring: Option<Arc<RingCounters>>,
    /// The source's own counters (GigE: missing and incomplete frames,
    /// losses, openings, connection), when it keeps them.
    pub source: Option<Arc<photopose_acquire::SourceCounters>>,
    /// The camera's exposure (GigE: the exposure in effect and the control
    /// loop's writes), when the source reports it.
    pub exposure: Option<Arc<photopose_acquire::ExposureLink>>,
    /// The TCP pose stream's counters (clients), when one is configured.
    pub tcp: Option<Arc<photopose_stream::TcpStats>>,
    /// The UDP destinations' counters, when there are any.
    pub udp: Option<Arc<photopose_stream::UdpStats>>,
    /// The RSI server's counters, when it runs.
    pub rsi: Option<Arc<photopose_rsi::monitor::Stats>>,
    /// The Zenoh publisher's counters, when `[zenoh]` is enabled.
    pub zenoh: Option<Arc<ZenohStats>>,
}

/// Counters of the Zenoh publisher (`[zenoh]`, `sink::zenoh`).
#[derive(Debug, Default)]
pub struct ZenohStats {
    /// Pose messages put on Zenoh.
    pub poses_published: Counter,
    /// Pose messages dropped on the output thread: the edge was behind.
    pub poses_dropped: Counter,
    /// ROS 2 messages put on Zenoh.
    pub ros2_published: Counter,
    /// ROS 2 messages dropped on the output thread: the edge was behind.
    pub ros2_dropped: Counter,
    /// Puts Zenoh refused (pose, ROS 2 and status).
    pub put_errors: Counter,
    /// Status messages put.
    pub statuses: Counter,
    /// Queries of the latest pose answered.
    pub queries: Counter,
}

impl Collect for ZenohStats {
    fn collect(&self, out: &mut Scrape<'_>) -> std::fmt::Result {
        for (name, help, c) in [
            (
                "photopose_zenoh_poses_published_total",
                "Pose messages put on Zenoh.",
                &self.poses_published,
            ),
            (
                "photopose_zenoh_poses_dropped_total",
                "Pose messages not put on Zenoh because the edge runtime was behind.",
                &self.poses_dropped,
            ),
            (
                "photopose_zenoh_ros2_published_total",
                "ROS 2 PoseWithCovarianceStamped messages put on Zenoh.",
                &self.ros2_published,
            ),
            (
                "photopose_zenoh_ros2_dropped_total",
                "ROS 2 messages not put on Zenoh because the edge runtime was behind.",
                &self.ros2_dropped,
            ),
            (
                "photopose_zenoh_put_errors_total",
                "Puts refused by the Zenoh session.",
                &self.put_errors,
            ),
            (
                "photopose_zenoh_statuses_total",
                "Status messages put on Zenoh.",
                &self.statuses,
            ),
            (
                "photopose_zenoh_queries_total",
                "Queries of the latest pose answered.",
                &self.queries,
            ),
        ] {
            out.counter(name, help, c.get())?;
        }
        Ok(())
    }
}

impl Default for Counters {
    fn default() -> Self {
        Counters {
            frames_in: Counter::new(),
            frames_dropped: Counter::new(),
            frames_processed: Counter::new(),
            frames_tracked: Counter::new(),
            poses_ok: Counter::new(),
            poses_failed: Counter::new(),
            stale: Counter::new(),
            results_without_targets: Arc::default(),
            latency: Histogram::default(),
            sigma0_px: Gauge::new(f64::NAN),
            targets: Gauge::new(0.0),
            position_std_m: Gauge::new(f64::NAN),
            last_pose: AtomicU64::new(0),
            last_frame: AtomicU64::new(0),
            epoch: Instant::now(),
            grabber: Arc::default(),
            ring: None,
            source: None,
            exposure: None,
            tcp: None,
            udp: None,
            rsi: None,
            zenoh: None,
        }
    }
}

impl Counters {
    /// The latency below which a share `q` (0..=1) of the messages were
    /// sent, µs (the upper edge of the bucket; within 9.05 %).
    pub fn latency_quantile_us(&self, q: f64) -> Option<f64> {
        self.latency.quantile_seconds(q).map(|s| s * 1e6)
    }

    /// Notes a pose sent now with its quality (`sigma0_px`, targets used,
    /// position σ in mm). Lock-free, allocation-free.
    pub fn record_pose(
        &self,
        sigma0_px: Option<f64>,
        targets: u32,
        std_center_mm: Option<[f64; 3]>,
    ) {
        if let Some(s) = sigma0_px {
            self.sigma0_px.set(s);
        }
        self.targets.set(f64::from(targets));
        if let Some([x, y, z]) = std_center_mm {
            self.position_std_m
                .set((x * x + y * y + z * z).sqrt() / 1000.0);
        }
        self.stamp(&self.last_pose);
    }

    /// Counts a frame delivered by the source now.
    pub fn record_frame_in(&self) {
        self.frames_in.inc();
        self.stamp(&self.last_frame);
    }

    fn stamp(&self, at: &AtomicU64) {
        let ns = u64::try_from(self.epoch.elapsed().as_nanos()).unwrap_or(u64::MAX - 1);
        at.store(ns + 1, Ordering::Relaxed);
    }

    fn age_seconds(&self, at: &AtomicU64) -> Option<f64> {
        match at.load(Ordering::Relaxed) {
            0 => None,
            t => Some((self.epoch.elapsed().as_secs_f64() - (t - 1) as f64 / 1e9).max(0.0)),
        }
    }

    /// Seconds since the last pose was sent (`None` before the first).
    pub fn last_pose_age_seconds(&self) -> Option<f64> {
        self.age_seconds(&self.last_pose)
    }

    /// Seconds since the source delivered its last frame (`None` before
    /// the first).
    pub fn last_frame_age_seconds(&self) -> Option<f64> {
        self.age_seconds(&self.last_frame)
    }
}

impl Collect for Counters {
    fn collect(&self, out: &mut Scrape<'_>) -> std::fmt::Result {
        out.info(
            "photopose_build_info",
            "The running photopose build: its version in the label, value 1.",
            &[("version", env!("CARGO_PKG_VERSION"))],
        )?;
        for (name, help, c) in [
            (
                "photopose_frames_in_total",
                "Frames delivered by the source.",
                &self.frames_in,
            ),
            (
                "photopose_frames_dropped_total",
                "Frames dropped by the overflow policy.",
                &self.frames_dropped,
            ),
            (
                "photopose_frames_processed_total",
                "Frames processed by the detection workers.",
                &self.frames_processed,
            ),
            (
                "photopose_frames_tracked_total",
                "Frames located in tracking mode, from the latest pose instead of the whole frame.",
                &self.frames_tracked,
            ),
            (
                "photopose_poses_ok_total",
                "Pose messages with a pose.",
                &self.poses_ok,
            ),
            (
                "photopose_poses_failed_total",
                "Pose messages without a pose.",
                &self.poses_failed,
            ),
            (
                "photopose_poses_stale_total",
                "Stale messages sent while no frame came.",
                &self.stale,
            ),
            (
                "photopose_results_without_targets_total",
                "Results sent without their targets: no target list was free.",
                &self.results_without_targets,
            ),
        ] {
            out.counter(name, help, c.get())?;
        }
        out.histogram(
            "photopose_latency_seconds",
            "Pose latency: frame hand-over to pose sent.",
            &self.latency,
        )?;
        out.gauge(
            "photopose_pose_sigma0_pixels",
            "Sigma0 (a-posteriori standard deviation of unit weight) of the last pose, pixels (NaN before the first).",
            self.sigma0_px.get(),
        )?;
        out.gauge(
            "photopose_pose_targets",
            "Targets used by the last pose.",
            self.targets.get(),
        )?;
        out.gauge(
            "photopose_pose_position_std_meters",
            "Position standard deviation of the last pose (length of the centre's sigma vector), metres (NaN before the first).",
            self.position_std_m.get(),
        )?;
        out.gauge(
            "photopose_last_pose_age_seconds",
            "Time since the last pose message was sent (NaN before the first).",
            self.last_pose_age_seconds().unwrap_or(f64::NAN),
        )?;
        let frame_age = self.last_frame_age_seconds();
        out.gauge(
            "photopose_last_frame_age_seconds",
            "Time since the source delivered its last frame (NaN before the first).",
            frame_age.unwrap_or(f64::NAN),
        )?;
        self.grabber.collect(out)?;
        if let Some(ring) = &self.ring {
            ring.collect(out)?;
        }
        match &self.source {
            // A camera that knows its connection (GigE) says it.
            Some(src) => src.collect(out)?,
            // Other sources: connected while frames arrive.
            None => out.gauge(
                "photopose_source_connected",
                "Camera state: 1 while the camera is connected and streaming (sources without a connection: a frame within the last second), else 0.",
                f64::from(u8::from(frame_age.is_some_and(|a| a < 1.0))),
            )?,
        }
        if let Some(exposure) = &self.exposure {
            exposure.collect(out)?;
        }
        if let Some(tcp) = &self.tcp {
            tcp.collect(out)?;
        }
        if let Some(udp) = &self.udp {
            udp.collect(out)?;
        }
        if let Some(zenoh) = &self.zenoh {
            zenoh.collect(out)?;
        }
        if let Some(rsi) = &self.rsi {
            rsi.collect(out)?;
        }
        Ok(())
    }
}

/// The metrics of `counters` in Prometheus' text exposition format.
pub fn render(counters: Arc<Counters>) -> String {
    let mut e = Exposition::new();
    e.register(counters);
    e.render()
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
        let stats = Arc::new(HttpStats::default());
        let mut exposition = Exposition::new();
        exposition.register(counters);
        exposition.register(stats.clone());
        let endpoint = TextEndpoint::start_counted(
            edge,
            listen,
            "/metrics",
            Arc::new(move || exposition.render()),
            HttpLimits::default(),
            stats,
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
        c.frames_in.add(42);
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
            !body.contains("photopose_source_missing"),
            "no source counters: {body}"
        );
        assert!(
            body.contains("photopose_source_connected 0"),
            "no frame yet: {body}"
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
        src.missing.add(3);
        src.losses.add(1);
        src.connected.store(true, Ordering::Relaxed);
        let tcp = Arc::new(photopose_stream::TcpStats::default());
        tcp.connected.store(2, Ordering::Relaxed);
        let c = Counters {
            source: Some(src),
            tcp: Some(tcp),
            ..Counters::default()
        };
        let body = render(Arc::new(c));
        for line in [
            "photopose_source_missing_frames_total 3",
            "photopose_source_losses_total 1",
            "photopose_source_connected 1.0",
            "photopose_stream_clients 2.0",
            "photopose_stream_clients_dropped_total 0",
            "photopose_stream_clients_refused_total 0",
            "photopose_stream_lines_dropped_total 0",
        ] {
            assert!(body.lines().any(|l| l == line), "{line} missing:\n{body}");
        }
    }

    #[test]
    fn every_metric_has_help_and_follows_the_naming_scheme() {
        let (_producer, consumer) =
            photopose_acquire::Ring::build(2, photopose_acquire::Overflow::DropNewest, || {
                photopose_frame::Image::new_mono8(4, 4)
            });
        let c = Counters {
            source: Some(Arc::default()),
            tcp: Some(Arc::default()),
            rsi: Some(Arc::new(photopose_rsi::monitor::Stats::new())),
            ring: Some(consumer.shared_counters()),
            ..Counters::default()
        };
        c.latency.record_ns(2_000_000);
        c.record_pose(Some(0.1), 12, Some([0.01, 0.02, 0.02]));
        let body = render(Arc::new(c));
        let mut helped = std::collections::HashSet::new();
        let mut typed = std::collections::HashMap::new();
        for l in body.lines() {
            if let Some(h) = l.strip_prefix("# HELP ") {
                let (name, help) = h.split_once(' ').unwrap();
                assert!(!help.trim().is_empty(), "{l}");
                assert!(helped.insert(name.to_string()), "twice: {l}");
            } else if let Some(t) = l.strip_prefix("# TYPE ") {
                let (name, kind) = t.split_once(' ').unwrap();
                typed.insert(name.to_string(), kind.to_string());
            } else {
                let name = l.split(['{', ' ']).next().unwrap();
                let family = ["_bucket", "_sum", "_count"]
                    .iter()
                    .find_map(|x| name.strip_suffix(x))
                    .filter(|f| typed.get(*f).is_some_and(|k| k == "histogram"))
                    .unwrap_or(name);
                assert!(helped.contains(family), "no HELP: {l}");
                assert!(family.starts_with("photopose_"), "{l}");
                assert_eq!(
                    typed[family] == "counter",
                    family.ends_with("_total"),
                    "counters and only counters end in _total: {l}"
                );
                for abbreviated in ["_us", "_ms", "_ns", "_mm", "_px", "_secs"] {
                    assert!(!family.contains(abbreviated), "{l}");
                }
            }
        }
        for family in [
            "photopose_latency_seconds",
            "photopose_rsi_reply_latency_seconds",
        ] {
            assert_eq!(typed[family], "histogram", "{body}");
        }
        assert!(body.contains("photopose_pose_targets 12"), "{body}");
        assert!(
            body.contains("photopose_latency_seconds_count 1\n"),
            "{body}"
        );
    }
}
