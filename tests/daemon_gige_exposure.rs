//! The daemon's exposure control loop on a real GigE Vision peer:
//! `photopose run` with `[source.gige.exposure_control] enabled = true`
//! against `arv-fake-gv-camera-0.8 -i 127.0.0.1` (a child of this test).
//! The fake camera starts at 10 000 µs and names its feature
//! `ExposureTimeAbs`: the opening brings it inside the loop's limits
//! (4000 µs, read back through aravis with `arv-tool-0.8` while the daemon
//! streams); its test pattern shows no targets, so the loop then holds it
//! (no write). The metrics report the exposure in effect and the loop's
//! state; the log says the loop is on; SIGTERM ends the daemon with exit 0.
//! The loop's steps on frames with targets are checked end to end in
//! `crates/pipeline/tests/gige_exposure.rs` (rendered frames over the
//! in-process camera). Only one GigE Vision peer can answer on 127.0.0.1:
//! this file holds one test, and cargo runs test binaries one after the
//! other.

mod common;

use common::{bin, free_tcp_port, scrape, scratch, FakeCamera, Killed};
use std::io::Read;
use std::net::UdpSocket;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The fake camera's exposure time through aravis, µs.
fn exposure_us() -> f64 {
    let out = Command::new("arv-tool-0.8")
        .args(["-a", "127.0.0.1", "control", "ExposureTimeAbs"])
        .stdin(Stdio::null())
        .output()
        .expect("arv-tool-0.8 (run .ci/deps.sh)");
    let text = String::from_utf8_lossy(&out.stdout);
    // "ExposureTimeAbs = 4000 min:10 max:1e+07"
    text.split_whitespace()
        .nth(2)
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no exposure in {text:?}"))
}

/// One gauge or counter of the metrics text.
fn metric(body: &str, name: &str) -> f64 {
    body.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.parse().ok())
        .unwrap_or_else(|| panic!("{name} not in\n{body}"))
}

#[test]
fn daemon_holds_the_gige_exposure_inside_its_limits() {
    let dir = scratch("gige-exposure");
    let camera = dir.join("camera.toml");
    std::fs::write(
        &camera,
        "[sensor]\nwidth = 512\nheight = 512\npixel_size = 0.0067\n[interior]\nc = 12.0\nx0 = 0.0\ny0 = 0.0\n",
    )
    .unwrap();
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let metrics_port = free_tcp_port();
    let config = dir.join("photopose.toml");
    std::fs::write(
        &config,
        format!(
            "[camera]\ncamera_file = \"{}\"\n\
             [source]\nkind = \"gige\"\n\
             [source.gige]\ncamera = \"GV01\"\nframe_rate = 20.0\nroi = [0, 0, 512, 512]\n\
             [source.gige.exposure_control]\nenabled = true\nmin_us = 2000.0\nmax_us = 4000.0\n\
             every_frames = 1\n\
             [pipeline]\nworkers = 2\nslots = 8\n\
             [output]\nudp = [\"{}\"]\n\
             [metrics]\nlisten = \"127.0.0.1:{metrics_port}\"\n",
            camera.display(),
            rx.local_addr().unwrap()
        ),
    )
    .unwrap();
    let fake = FakeCamera::start();
    assert_eq!(exposure_us(), 10_000.0, "the fake camera's own exposure");
    let mut daemon = Killed(
        bin()
            .args(["run", "--config"])
            .arg(&config)
            .env("RUST_LOG", "info")
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    // Frames flow.
    let mut buf = [0u8; 4096];
    let mut frames = 0;
    let t0 = Instant::now();
    while frames < 20 {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "no frames within 20 s"
        );
        if let Ok(n) = rx.recv(&mut buf) {
            let v: serde_json::Value = serde_json::from_slice(&buf[..n]).unwrap();
            if v["status"] == "too_few_targets" {
                frames += 1;
            }
        }
    }
    // Brought inside the limits at opening, then held: no targets.
    let first = exposure_us();
    assert_eq!(
        first, 4000.0,
        "the opening brings the exposure inside [2000, 4000] µs"
    );
    let t1 = Instant::now();
    while t1.elapsed() < Duration::from_secs(2) {
        let us = exposure_us();
        assert!((2000.0..=4000.0).contains(&us), "{us} µs");
        assert_eq!(us, first, "frames without targets change nothing");
        std::thread::sleep(Duration::from_millis(200));
    }
    let body = scrape(metrics_port).expect("the daemon answers /metrics");
    assert_eq!(metric(&body, "photopose_exposure_time_seconds"), 0.004);
    assert_eq!(metric(&body, "photopose_exposure_control_enabled"), 1.0);
    assert_eq!(
        metric(&body, "photopose_exposure_control_writes_total"),
        0.0
    );
    assert_eq!(
        metric(&body, "photopose_exposure_control_write_failures_total"),
        0.0
    );
    let kill = Command::new("kill")
        .args(["-TERM", &daemon.0.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let mut log = String::new();
    daemon
        .0
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut log)
        .unwrap();
    let status = daemon.0.wait().unwrap();
    drop(fake);
    assert!(status.success(), "exit status {status:?}\n{log}");
    assert!(
        log.contains("exposure control on") && log.contains("ExposureTimeAbs"),
        "the loop's start is logged:\n{log}"
    );
}
