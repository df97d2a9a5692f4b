//! The daemon under a service manager, end to end with a notification
//! socket bound by the test (as systemd binds it): `WATCHDOG=1` keeps coming
//! while the GigE camera is absent for 30 s (camera absence is a state in
//! `STATUS=`, not a hang); a wedged output thread or detection worker (the
//! fault-injection hook `PHOTOPOSE_TEST_WEDGE`) stops the pings; SIGTERM
//! right after start ends with exit 0; SIGHUP reloads a changed
//! configuration and keeps the running one when the new one is invalid.
//!
//! The GigE test looks for a camera that is not there: no GigE Vision peer
//! is started by this file, and cargo runs test binaries one after another,
//! so the fake camera of `daemon_gige.rs` is never seen here.

mod common;

use common::{bin, scratch};
use std::io::Read;
use std::net::UdpSocket;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A notification socket like systemd's, bound in a scratch folder.
struct NotifySocket {
    socket: UnixDatagram,
    path: PathBuf,
}

impl NotifySocket {
    fn bind(dir: &Path) -> NotifySocket {
        let path = dir.join("notify.sock");
        let socket = UnixDatagram::bind(&path).unwrap();
        socket
            .set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        NotifySocket { socket, path }
    }

    /// Every message received for `span`.
    fn collect(&self, span: Duration) -> Vec<String> {
        let end = Instant::now() + span;
        let mut buf = [0u8; 4096];
        let mut out = Vec::new();
        while Instant::now() < end {
            if let Ok(n) = self.socket.recv(&mut buf) {
                out.push(String::from_utf8_lossy(&buf[..n]).into_owned());
            }
        }
        out
    }
}

fn pings(messages: &[String]) -> usize {
    messages.iter().filter(|m| *m == "WATCHDOG=1").count()
}

/// The daemon, killed on drop if a test fails half way.
struct Daemon(Option<Child>);

impl Daemon {
    fn start(
        config: &Path,
        notify: &NotifySocket,
        watchdog_usec: u64,
        wedge: Option<&str>,
    ) -> Self {
        let mut cmd = bin();
        cmd.args(["run", "--config"])
            .arg(config)
            .env("NOTIFY_SOCKET", &notify.path)
            .env("WATCHDOG_USEC", watchdog_usec.to_string())
            .env_remove("WATCHDOG_PID")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        if let Some(w) = wedge {
            cmd.env("PHOTOPOSE_TEST_WEDGE", w);
        }
        Daemon(Some(cmd.spawn().unwrap()))
    }

    fn signal(&self, sig: &str) {
        let pid = self.0.as_ref().unwrap().id().to_string();
        assert!(Command::new("kill")
            .args([sig, &pid])
            .status()
            .unwrap()
            .success());
    }

    /// SIGTERM, then the exit status and the log.
    fn stop(mut self) -> (std::process::ExitStatus, String) {
        self.signal("-TERM");
        let mut child = self.0.take().unwrap();
        let t0 = Instant::now();
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break s;
            }
            if t0.elapsed() > Duration::from_secs(20) {
                let _ = child.kill();
                break child.wait().unwrap();
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let mut log = String::new();
        child
            .stderr
            .take()
            .unwrap()
            .read_to_string(&mut log)
            .unwrap();
        (status, log)
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Some(mut c) = self.0.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// A synthetic-source configuration streaming UDP to `udp`.
fn synthetic_config(dir: &Path, udp: &str, rate_hz: f64) -> PathBuf {
    let path = dir.join("photopose.toml");
    std::fs::write(
        &path,
        format!(
            "[source]\nkind = \"synthetic\"\n[source.synthetic]\nrate_hz = {rate_hz}\n\
             [pipeline]\nworkers = 2\nslots = 8\n[output]\nudp = [\"{udp}\"]\n"
        ),
    )
    .unwrap();
    path
}

#[test]
fn the_watchdog_keeps_pinging_while_the_camera_is_absent() {
    let dir = scratch("watchdog-gige");
    let notify = NotifySocket::bind(&dir);
    let config = dir.join("photopose.toml");
    std::fs::write(
        &config,
        "[source]\nkind = \"gige\"\n\
         [source.gige]\ncamera = \"GV01\"\npacket_socket = false\n\
         lost_after_ms = 500.0\nbackoff_initial_ms = 100.0\nbackoff_max_ms = 1000.0\n",
    )
    .unwrap();
    // systemd's WatchdogSec=2s: a ping is due at least every 2 s.
    let daemon = Daemon::start(&config, &notify, 2_000_000, None);
    let messages = notify.collect(Duration::from_secs(30));
    let (status, log) = daemon.stop();
    assert!(status.success(), "exit {status:?}\n{log}");
    assert!(messages.iter().any(|m| m == "READY=1"), "{messages:?}");
    // One ping per second (half the interval) over 30 s.
    let n = pings(&messages);
    assert!(
        n >= 25,
        "{n} pings in 30 s without a camera\n{messages:?}\n{log}"
    );
    assert!(
        messages
            .iter()
            .any(|m| m.starts_with("STATUS=") && m.contains("camera absent")),
        "{messages:?}"
    );
    assert!(!log.contains("not turning"), "{log}");
}

#[test]
fn a_wedged_output_or_worker_thread_stops_the_pings() {
    for wedge in ["output", "worker"] {
        let dir = scratch(&format!("watchdog-wedge-{wedge}"));
        let notify = NotifySocket::bind(&dir);
        let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
        let config = synthetic_config(&dir, &rx.local_addr().unwrap().to_string(), 20.0);
        let daemon = Daemon::start(&config, &notify, 400_000, Some(wedge));
        // The thread wedges on its first frame; give it time to get there
        // (frames are rendered at 20 Hz), then listen.
        let first = notify.collect(Duration::from_secs(3));
        assert!(first.iter().any(|m| m == "READY=1"), "{first:?}");
        let later = notify.collect(Duration::from_secs(2));
        let (status, log) = daemon.stop();
        assert!(status.success(), "{wedge}: exit {status:?}\n{log}");
        assert_eq!(
            pings(&later),
            0,
            "{wedge}: pings while wedged: {later:?}\n{log}"
        );
        assert!(
            later.iter().any(|m| m.starts_with("STATUS=")),
            "{wedge}: STATUS goes on: {later:?}"
        );
        let name = if wedge == "output" {
            "output"
        } else {
            "detect-0"
        };
        assert!(
            log.contains("not turning") && log.contains(name),
            "{wedge}: the stuck thread is named\n{log}"
        );
    }
}

#[test]
fn the_same_daemon_unwedged_pings_all_along() {
    // The control of the test above: same configuration, no fault.
    let dir = scratch("watchdog-control");
    let notify = NotifySocket::bind(&dir);
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    let config = synthetic_config(&dir, &rx.local_addr().unwrap().to_string(), 20.0);
    let daemon = Daemon::start(&config, &notify, 400_000, None);
    let _ = notify.collect(Duration::from_secs(3));
    let later = notify.collect(Duration::from_secs(2));
    let (status, log) = daemon.stop();
    assert!(status.success(), "exit {status:?}\n{log}");
    assert!(pings(&later) >= 5, "{later:?}\n{log}");
}

#[test]
fn sigterm_right_after_start_exits_zero() {
    let dir = scratch("early-term");
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    let config = synthetic_config(&dir, &rx.local_addr().unwrap().to_string(), 20.0);
    for delay_ms in [50u64, 100, 200] {
        let child = bin()
            .args(["run", "--config"])
            .arg(&config)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let daemon = Daemon(Some(child));
        std::thread::sleep(Duration::from_millis(delay_ms));
        let (status, log) = daemon.stop();
        assert_eq!(
            status.code(),
            Some(0),
            "SIGTERM {delay_ms} ms after start: {status:?}\n{log}"
        );
    }
}

#[test]
fn sighup_reloads_a_valid_configuration_and_keeps_the_running_one_otherwise() {
    let dir = scratch("reload");
    let notify = NotifySocket::bind(&dir);
    let first = UdpSocket::bind("127.0.0.1:0").unwrap();
    let second = UdpSocket::bind("127.0.0.1:0").unwrap();
    for s in [&first, &second] {
        s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    }
    let config = synthetic_config(&dir, &first.local_addr().unwrap().to_string(), 20.0);
    let daemon = Daemon::start(&config, &notify, 0, None);
    let mut buf = [0u8; 8192];
    first
        .recv(&mut buf)
        .expect("poses to the first destination");
    // A valid new configuration: poses go to the second destination.
    synthetic_config(&dir, &second.local_addr().unwrap().to_string(), 20.0);
    daemon.signal("-HUP");
    second
        .recv(&mut buf)
        .expect("poses to the reloaded destination");
    // An invalid one: refused, the running configuration goes on.
    std::fs::write(
        &config,
        "[source]\nkind = \"synthetic\"\n[pipeline]\nworkers = 0\n",
    )
    .unwrap();
    daemon.signal("-HUP");
    let messages = notify.collect(Duration::from_secs(2));
    // Drain what was queued before, then poses still arrive.
    second
        .set_read_timeout(Some(Duration::from_millis(1)))
        .unwrap();
    while second.recv(&mut buf).is_ok() {}
    second
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    second
        .recv(&mut buf)
        .expect("poses go on after a refused reload");
    let (status, log) = daemon.stop();
    assert!(status.success(), "exit {status:?}\n{log}");
    assert!(log.contains("configuration reloaded"), "{log}");
    assert!(
        log.contains("reload refused") && log.contains("pipeline.workers"),
        "the refusal names the key\n{log}"
    );
    assert!(messages.iter().any(|m| m == "RELOADING=1"), "{messages:?}");
    assert!(messages.iter().any(|m| m == "READY=1"), "{messages:?}");
}
