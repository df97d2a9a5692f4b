//! A soak of the daemon under abuse, end to end with real parts: a GigE
//! Vision camera (`arv-fake-gv-camera-0.8 -i 127.0.0.1`) killed for 30 s in
//! every period, TCP pose-stream clients reconnecting every 100 ms, the
//! metrics endpoint scraped every 100 ms, and the RSI server driven every
//! 4 ms by the simulated KUKA controller (`photopose rsi-sim`). Checked:
//! the daemon never exits (0 restarts), its VmRSS, VmSize and thread count
//! after the camera came back are within 5 % of the same phase before the
//! camera was killed, every controller datagram is answered by the RSI
//! server (its own counters, scraped), the controller never stops on its
//! Timeout and late replies stay rare (counted; under 5 %).
//!
//! `cargo test --test soak_abuse` runs the 60 s version (camera away from
//! 15 s to 45 s). The 10-minute soak of the safety acceptance is the same
//! test with `PHOTOPOSE_SOAK_SECS=600` (camera away 30 s in every 2 minutes):
//!
//!     PHOTOPOSE_SOAK_SECS=600 cargo test --test soak_abuse -- --nocapture
//!
//! It prints its figures with `--nocapture`.

mod common;

use common::{
    bin, free_tcp_port, free_udp_port, metric, root, scrape, scratch, FakeCamera, Killed,
};
use std::io::{BufRead, BufReader};
use std::net::{TcpStream, UdpSocket};
use std::process::Stdio;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// VmRSS, VmSize (kB) and Threads of a process.
#[derive(Debug, Clone, Copy)]
struct Sample {
    rss_kb: u64,
    size_kb: u64,
    threads: u64,
}

fn sample(pid: u32) -> Option<Sample> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |key: &str| -> Option<u64> {
        text.lines()
            .find(|l| l.starts_with(key))?
            .split_whitespace()
            .nth(1)?
            .parse()
            .ok()
    };
    Some(Sample {
        rss_kb: field("VmRSS:")?,
        size_kb: field("VmSize:")?,
        threads: field("Threads:")?,
    })
}

#[test]
fn the_daemon_survives_abuse_with_flat_resources() {
    let secs: u64 = std::env::var("PHOTOPOSE_SOAK_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60);
    // The camera is away from `period/4` for `away` in every period.
    let period = secs.min(120);
    let away = 30.min(period / 2);
    let dir = scratch("soak");
    let camera = dir.join("camera.toml");
    std::fs::write(
        &camera,
        "[sensor]\nwidth = 512\nheight = 512\npixel_size = 0.0067\n[interior]\nc = 12.0\nx0 = 0.0\ny0 = 0.0\n",
    )
    .unwrap();
    let (tcp_port, metrics_port, rsi_port) = (free_tcp_port(), free_tcp_port(), free_udp_port());
    let udp_sink = UdpSocket::bind("127.0.0.1:0").unwrap();
    let config = dir.join("photopose.toml");
    std::fs::write(
        &config,
        format!(
            "[camera]\ncamera_file = \"{}\"\n\
             [source]\nkind = \"gige\"\n\
             [source.gige]\ncamera = \"GV01\"\nframe_rate = 20.0\nroi = [0, 0, 512, 512]\n\
             exposure_us = 2000.0\npacket_socket = false\nbuffers = 8\n\
             lost_after_ms = 500.0\nbackoff_initial_ms = 100.0\nbackoff_max_ms = 1000.0\n\
             [pipeline]\nworkers = 2\nslots = 8\nmax_age_ms = 300.0\n\
             [output]\nudp = [\"{}\"]\ntcp_listen = \"127.0.0.1:{tcp_port}\"\n\
             [metrics]\nlisten = \"127.0.0.1:{metrics_port}\"\n\
             [rsi]\nenabled = true\nbind = \"127.0.0.1\"\nport = {rsi_port}\n\
             controllers = [\"127.0.0.1\"]\nhand_eye = \"{}\"\n",
            camera.display(),
            udp_sink.local_addr().unwrap(),
            root().join("config/bench/hand-eye.toml").display(),
        ),
    )
    .unwrap();
    let mut fake = Some(FakeCamera::start());
    let daemon = Killed(
        bin()
            .args(["run", "--config"])
            .arg(&config)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let pid = daemon.0.id();
    // Wait until the metrics answer: the daemon is up.
    let t0 = Instant::now();
    while scrape(metrics_port).is_none() {
        assert!(t0.elapsed() < Duration::from_secs(20), "daemon not serving");
        std::thread::sleep(Duration::from_millis(50));
    }
    let start = Instant::now();
    let done = Arc::new(AtomicBool::new(false));
    // Stream clients reconnecting every 100 ms.
    let lines = Arc::new(AtomicU64::new(0));
    let clients = {
        let (done, lines) = (done.clone(), lines.clone());
        std::thread::spawn(move || {
            let mut connects = 0u64;
            while !done.load(Ordering::Relaxed) {
                if let Ok(s) = TcpStream::connect(("127.0.0.1", tcp_port)) {
                    connects += 1;
                    s.set_read_timeout(Some(Duration::from_millis(90))).unwrap();
                    let mut line = String::new();
                    if BufReader::new(&s).read_line(&mut line).is_ok() && line.ends_with('\n') {
                        lines.fetch_add(1, Ordering::Relaxed);
                    }
                }
                std::thread::sleep(Duration::from_millis(100));
            }
            connects
        })
    };
    // Metrics scraped every 100 ms; the slowest scrape kept.
    let scraper = {
        let done = done.clone();
        std::thread::spawn(move || {
            let (mut n, mut failed, mut slowest) = (0u64, 0u64, Duration::ZERO);
            while !done.load(Ordering::Relaxed) {
                let t = Instant::now();
                match scrape(metrics_port) {
                    Some(_) => n += 1,
                    None => failed += 1,
                }
                slowest = slowest.max(t.elapsed());
                std::thread::sleep(Duration::from_millis(100));
            }
            (n, failed, slowest)
        })
    };
    // The controller: one datagram every 4 ms for the whole soak.
    let cycles = secs * 250;
    let controller = bin()
        .args(["rsi-sim", "--server", &format!("127.0.0.1:{rsi_port}")])
        .args(["--cycles", &cycles.to_string(), "--timeout", "1000000000"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The camera schedule and the resource samples (one a second).
    let mut before_kill: Option<Sample> = None;
    let mut kills = 0;
    while start.elapsed() < Duration::from_secs(secs) {
        std::thread::sleep(Duration::from_secs(1));
        let phase = start.elapsed().as_secs() % period;
        let s = sample(pid).expect("the daemon is alive (never restarted)");
        let camera_away = (period / 4..period / 4 + away).contains(&phase);
        if camera_away && fake.is_some() {
            fake = None; // killed
            kills += 1;
        } else if !camera_away && fake.is_none() {
            fake = Some(FakeCamera::start());
        } else if kills == 0 {
            before_kill = Some(s); // the last sample before the first kill
        }
    }
    // The last sample: the camera has streamed again for at least 15 s.
    let end = sample(pid).expect("the daemon is alive (never restarted)");
    let out = controller.wait_with_output().unwrap();
    let sim = String::from_utf8_lossy(&out.stdout).to_string();
    done.store(true, Ordering::Relaxed);
    let connects = clients.join().unwrap();
    let (scrapes, failed_scrapes, slowest) = scraper.join().unwrap();
    let body = scrape(metrics_port).expect("metrics after the soak");
    let rsi_cycles = metric(&body, "photopose_rsi_cycles_total").unwrap_or(0.0);
    let rsi_replies = metric(&body, "photopose_rsi_replies_total").unwrap_or(-1.0);
    let opens = metric(&body, "photopose_source_opens_total").unwrap_or(0.0);
    let base = before_kill.expect("a sample before the camera was killed");
    println!(
        "soak {secs} s: camera killed {kills}×{away} s (opened {opens} times); {connects} stream connections ({} got a line), {scrapes} scrapes ({failed_scrapes} failed, slowest {:.0} ms); RSI {rsi_cycles} cycles, {rsi_replies} replies; controller: {}",
        lines.load(Ordering::Relaxed),
        slowest.as_secs_f64() * 1e3,
        sim.trim()
    );
    println!("before the first kill: {base:?}; at the end, camera back: {end:?}");
    // 0 restarts: the same process all along, and it stops cleanly.
    assert!(sample(pid).is_some());
    assert!(kills >= 1 && opens >= 2.0, "camera killed and reopened");
    assert!(
        connects as f64 >= secs as f64 * 5.0,
        "{connects} connections"
    );
    assert_eq!(failed_scrapes, 0);
    // Every controller datagram answered, the controller never stopped.
    let sent: f64 = sim
        .split_whitespace()
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or(f64::INFINITY);
    assert!(rsi_cycles >= sent * 0.99, "{rsi_cycles} of {sent} seen");
    assert_eq!(rsi_cycles, rsi_replies, "every cycle answered");
    assert!(sim.contains("completed"), "{sim}");
    let late: f64 = sim
        .split(", ")
        .find(|p| p.ends_with(" late"))
        .and_then(|p| p.split_whitespace().next()?.parse().ok())
        .unwrap_or(f64::INFINITY);
    // Late replies are counted, not forbidden: timing on a shared CI
    // machine is not the daemon's; a gross failure (over 5 %) still shows.
    assert!(late <= cycles as f64 * 0.05, "late replies: {sim}");
    // Flat resources: the same phase (camera streaming) before and after.
    let within = |a: u64, b: u64| (b as f64) <= a as f64 * 1.05 && (b as f64) >= a as f64 * 0.95;
    assert!(within(base.rss_kb, end.rss_kb), "VmRSS {base:?} → {end:?}");
    assert!(
        within(base.size_kb, end.size_kb),
        "VmSize {base:?} → {end:?}"
    );
    assert!(
        within(base.threads, end.threads),
        "threads {base:?} → {end:?}"
    );
    drop(fake);
    let kill = std::process::Command::new("kill")
        .args(["-TERM", &pid.to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let mut daemon = daemon;
    let status = daemon.0.wait().unwrap();
    assert!(status.success(), "{status:?}");
}
