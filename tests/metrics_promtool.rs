//! The metrics endpoint passes `promtool check metrics` (Prometheus' own
//! linter: HELP on every metric, base units, counter suffixes, histogram
//! series) on a real scrape of the daemon (`photopose run`, synthetic
//! source) with the RSI server enabled and the simulated KUKA controller
//! (`photopose rsi-sim`) driving it, over HTTP on 127.0.0.1.
//!
//! Needs `promtool` (Debian package `prometheus`, installed by
//! `.ci/deps.sh`).

mod common;

use common::{bin, free_tcp_port, free_udp_port, metric, root, scrape, scratch, Killed};
use std::net::UdpSocket;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

#[test]
fn a_scrape_with_rsi_running_passes_promtool() {
    let promtool = Command::new("promtool").arg("--version").output();
    assert!(
        promtool.is_ok_and(|o| o.status.success()),
        "promtool is missing: install the Debian package `prometheus` (.ci/deps.sh)"
    );
    let dir = scratch("metrics-promtool");
    let (tcp_port, metrics_port, rsi_port) = (free_tcp_port(), free_tcp_port(), free_udp_port());
    let udp_sink = UdpSocket::bind("127.0.0.1:0").unwrap();
    let config = std::fs::read_to_string(root().join("config/photopose.toml"))
        .unwrap()
        .replace(
            "udp = [\"127.0.0.1:5005\"]",
            &format!("udp = [\"{}\"]", udp_sink.local_addr().unwrap()),
        )
        .replace(
            "tcp_listen = \"127.0.0.1:5006\"",
            &format!("tcp_listen = \"127.0.0.1:{tcp_port}\""),
        )
        .replace(
            "listen = \"127.0.0.1:9464\"",
            &format!("listen = \"127.0.0.1:{metrics_port}\""),
        )
        .replace("enabled = false", "enabled = true")
        .replace("bind = \"0.0.0.0\"", "bind = \"127.0.0.1\"")
        .replace("[\"192.168.1.10\"]", "[\"127.0.0.1\"]")
        .replace(
            "# hand_eye = \"/etc/photopose/hand-eye.toml\"",
            &format!(
                "hand_eye = \"{}\"",
                root().join("config/bench/hand-eye.toml").display()
            ),
        )
        .replace("port = 49152", &format!("port = {rsi_port}"));
    assert!(config.contains("enabled = true") && config.contains(&rsi_port.to_string()));
    let path = dir.join("photopose.toml");
    std::fs::write(&path, config).unwrap();
    let _daemon = Killed(
        bin()
            .args(["run", "--config"])
            .arg(&path)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let t0 = Instant::now();
    while scrape(metrics_port).is_none() {
        assert!(t0.elapsed() < Duration::from_secs(20), "daemon not serving");
        std::thread::sleep(Duration::from_millis(50));
    }
    // The simulated controller, 4 ms cycles for about 8 s (it outlives
    // the scrapes below; killed on drop).
    let _controller = Killed(
        bin()
            .args(["rsi-sim", "--server"])
            .arg(format!("127.0.0.1:{rsi_port}"))
            .args(["--cycles", "2000", "--timeout", "100000"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    // Wait until poses and RSI cycles are counted, so that every family
    // (histograms included) has values.
    let body = loop {
        let body = scrape(metrics_port).expect("the daemon answers");
        let cycles = metric(&body, "photopose_rsi_reply_latency_seconds_count").unwrap_or(0.0);
        let poses = metric(&body, "photopose_latency_seconds_count").unwrap_or(0.0);
        if cycles >= 50.0 && poses >= 2.0 {
            break body;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(40),
            "no RSI cycles or poses counted:\n{body}"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let scraped = dir.join("scrape.txt");
    std::fs::write(&scraped, &body).unwrap();
    let out = Command::new("promtool")
        .args(["check", "metrics"])
        .stdin(std::fs::File::open(&scraped).unwrap())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "promtool check metrics: {:?}\n{}{}\n{body}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    // What the operator asked for is there.
    for family in [
        "# TYPE photopose_latency_seconds histogram",
        "# TYPE photopose_rsi_reply_latency_seconds histogram",
        "photopose_build_info{version=\"",
        "# TYPE photopose_pose_sigma0_pixels gauge",
        "# TYPE photopose_pose_targets gauge",
        "# TYPE photopose_pose_position_std_meters gauge",
        "# TYPE photopose_last_pose_age_seconds gauge",
        "photopose_rsi_state{state=\"",
        "# TYPE photopose_grabber_frames_published_total counter",
        "# TYPE photopose_ring_frames_delivered_total counter",
        "# TYPE photopose_stream_clients gauge",
        "# TYPE photopose_metrics_requests_total counter",
        "# TYPE photopose_stream_udp_datagrams_sent_total counter",
        "photopose_source_connected 1",
        "# TYPE photopose_last_frame_age_seconds gauge",
    ] {
        assert!(body.contains(family), "{family} missing:\n{body}");
    }
    assert!(!body.contains("_us"), "no abbreviated units:\n{body}");
}
