//! Helpers shared by the end-to-end tests of the `photopose` binary: the
//! binary, per-test scratch folders and the shipped files.

#![allow(dead_code)] // each test binary uses its own subset

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The `photopose` binary under test.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_photopose"))
}

/// An empty folder for one test (unique per process and name).
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("photopose-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The repository's root.
pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A file under `fixtures/`.
pub fn fixture(name: &str) -> PathBuf {
    root().join("fixtures").join(name)
}

const FAKE: &str = "arv-fake-gv-camera-0.8";
const TOOL: &str = "arv-tool-0.8";

/// `arv-fake-gv-camera-0.8 -i 127.0.0.1`, killed on drop.
pub struct FakeCamera(Child);

impl FakeCamera {
    pub fn start() -> Self {
        // Wrapped at once: dropping it kills and reaps the child on any path.
        let me = FakeCamera(
            Command::new(FAKE)
                .args(["-i", "127.0.0.1"])
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap_or_else(|e| panic!("cannot run {FAKE} ({e}): run .ci/deps.sh")),
        );
        let t0 = Instant::now();
        loop {
            let out = Command::new(TOOL)
                .args(["-a", "127.0.0.1", "control", "Width"])
                .stdin(Stdio::null())
                .output()
                .unwrap_or_else(|e| panic!("cannot run {TOOL} ({e}): run .ci/deps.sh"));
            if out.status.success() && String::from_utf8_lossy(&out.stdout).contains("Width") {
                return me;
            }
            assert!(t0.elapsed() < Duration::from_secs(10), "{FAKE} silent");
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for FakeCamera {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A port free on 127.0.0.1 now (TCP).
pub fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A port free on 127.0.0.1 now (UDP).
pub fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A child process, killed and reaped on drop (a test that fails half way
/// leaves nothing running).
pub struct Killed(pub Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// One HTTP GET of `/metrics` on 127.0.0.1:`port`: the body of a 200.
pub fn scrape(port: u16) -> Option<String> {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    s.write_all(b"GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        .ok()?;
    let mut text = String::new();
    s.read_to_string(&mut text).ok()?;
    text.starts_with("HTTP/1.1 200")
        .then(|| text.split("\r\n\r\n").nth(1).unwrap_or("").to_string())
}

/// The value of the sample `name` (no labels) in a scrape.
pub fn metric(body: &str, name: &str) -> Option<f64> {
    body.lines()
        .find(|l| l.split_whitespace().next() == Some(name))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

/// The pose message's JSON Schema (`docs/schema/pose-message.v2.json`),
/// compiled once per test binary.
fn pose_schema() -> &'static jsonschema::Validator {
    static SCHEMA: std::sync::OnceLock<jsonschema::Validator> = std::sync::OnceLock::new();
    SCHEMA.get_or_init(|| {
        let text = std::fs::read_to_string(root().join("docs/schema/pose-message.v2.json"))
            .expect("the pose message's schema");
        let schema: serde_json::Value = serde_json::from_str(&text).expect("the schema is JSON");
        jsonschema::draft202012::new(&schema).expect("the schema compiles")
    })
}

/// Checks one pose message (`photopose.pose.v2`) against the JSON Schema
/// and, when it has a pose, its covariance: 36 numbers, symmetric and
/// positive definite (a Cholesky factorisation succeeds), with the
/// standard deviations of its diagonal.
pub fn check_pose_message(v: &serde_json::Value) {
    let errors: Vec<String> = pose_schema()
        .iter_errors(v)
        .map(|e| format!("{e} at {}", e.instance_path()))
        .collect();
    assert!(errors.is_empty(), "schema violations {errors:?} in {v}");
    if let Some(pose) = v.get("pose").filter(|p| !p.is_null()) {
        check_pose_object(pose);
    }
}

/// Checks the `pose` object of a message or a `resect` line: the
/// covariance is symmetric and positive definite and its diagonal gives
/// the standard deviations.
pub fn check_pose_object(pose: &serde_json::Value) {
    let c = covariance(pose);
    for i in 0..6 {
        for j in 0..6 {
            let (a, b) = (c[(i, j)], c[(j, i)]);
            assert!(a == b, "covariance not symmetric at ({i}, {j}): {a} vs {b}");
        }
    }
    assert!(
        nalgebra::Cholesky::new(c).is_some(),
        "covariance not positive definite: {c}"
    );
    let std = |key: &str, k: usize| pose[key][k].as_f64().unwrap();
    for k in 0..3 {
        let s = c[(k, k)].sqrt();
        assert!((std("std_position_mm", k) - s).abs() <= 1e-12 * s, "σ {k}");
        let r = c[(k + 3, k + 3)].sqrt().to_degrees();
        assert!(
            (std("std_rotation_deg", k) - r).abs() <= 1e-12 * r,
            "σ rot {k}"
        );
    }
}

/// The 6×6 covariance of a `pose` object (row-major on the wire).
pub fn covariance(pose: &serde_json::Value) -> nalgebra::Matrix6<f64> {
    let flat: Vec<f64> = pose["covariance"]
        .as_array()
        .expect("a covariance array")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect();
    assert_eq!(flat.len(), 36, "the covariance has 36 numbers");
    nalgebra::Matrix6::from_row_slice(&flat)
}

/// A pose message without what differs between two runs over the same
/// frames: the sending instants and the host's monotonic stamps.
pub fn without_run_times(mut v: serde_json::Value) -> serde_json::Value {
    if let Some(t) = v.get_mut("time").and_then(|t| t.as_object_mut()) {
        for k in [
            "sent_utc_ns",
            "sent_mono_ns",
            "handover_mono_ns",
            "exposure_mono_ns",
        ] {
            t.remove(k);
        }
    }
    if let Some(r) = v.get_mut("robot").and_then(|r| r.as_object_mut()) {
        r.remove("age_ms");
    }
    v
}

/// The JSON messages arriving at a UDP socket, collected on a thread while
/// a daemon runs: left queued, a few dozen pose messages of about 2 kB each
/// would overflow the socket's default receive buffer. Each is checked
/// against the pose message schema.
pub struct UdpMessages {
    done: std::sync::Arc<std::sync::atomic::AtomicBool>,
    reader: std::thread::JoinHandle<Vec<serde_json::Value>>,
}

impl UdpMessages {
    /// Starts collecting what arrives at `rx`.
    pub fn collect(rx: &std::net::UdpSocket) -> UdpMessages {
        use std::sync::atomic::{AtomicBool, Ordering};
        let done = std::sync::Arc::new(AtomicBool::new(false));
        let rx = rx.try_clone().unwrap();
        let stop = std::sync::Arc::clone(&done);
        let reader = std::thread::spawn(move || {
            rx.set_read_timeout(Some(Duration::from_millis(300)))
                .unwrap();
            let mut buf = [0u8; 8192];
            let mut messages = Vec::new();
            loop {
                match rx.recv(&mut buf) {
                    Ok(n) => {
                        let v: serde_json::Value =
                            serde_json::from_slice(&buf[..n]).expect("a JSON pose message");
                        check_pose_message(&v);
                        messages.push(v);
                    }
                    Err(_) if stop.load(Ordering::Acquire) => break,
                    Err(_) => {}
                }
            }
            messages
        });
        UdpMessages { done, reader }
    }

    /// The messages in arrival order, once the socket has been quiet for
    /// 300 ms after this call.
    pub fn finish(self) -> Vec<serde_json::Value> {
        self.done.store(true, std::sync::atomic::Ordering::Release);
        self.reader.join().unwrap()
    }
}
