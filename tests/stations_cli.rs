//! Hand-eye stations gathered live: the daemon (`photopose run`, synthetic
//! camera standing over the plate, RSI server on) answers a simulated KUKA
//! controller whose robot stands still; `photopose calibrate stations`
//! reads the daemon's TCP pose stream, which carries the robot's `RIst`,
//! and writes a station once the robot has stood still long enough.

mod common;

use common::{bin, scratch};
use photopose_rsi::controller::{SimConfig, SimController};
use photopose_rsi::server::RsiClock;
use std::net::{SocketAddr, TcpListener, UdpSocket};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// `n` pose messages from a new client of the TCP stream at `addr`, each
/// checked against the schema.
fn read_messages(addr: SocketAddr, n: usize) -> Vec<serde_json::Value> {
    use std::io::BufRead;
    let stream = std::net::TcpStream::connect(addr).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let mut lines = std::io::BufReader::new(stream).lines();
    (0..n)
        .map(|_| {
            let line = lines.next().expect("a pose line").unwrap();
            let v: serde_json::Value = serde_json::from_str(&line).unwrap();
            common::check_pose_message(&v);
            v
        })
        .collect()
}

#[test]
fn a_station_is_taken_while_the_robot_stands_still() {
    let dir = scratch("stations");
    let hand_eye = dir.join("hand-eye.toml");
    std::fs::write(
        &hand_eye,
        "[camera_in_tcp]\nxyzabc = [60.0, 0.0, -80.0, 0.0, 0.0, 180.0]\n\
         std_xyzabc = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n\
         [plate_in_base]\nxyzabc = [400.0, 0.0, -200.0, 0.0, 0.0, 0.0]\n\
         std_xyzabc = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n",
    )
    .unwrap();
    let tcp: SocketAddr = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let rsi: SocketAddr = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let config = dir.join("photopose.toml");
    std::fs::write(
        &config,
        format!(
            "[source]\nkind = \"synthetic\"\n[source.synthetic]\nrate_hz = 25.0\nradius_mm = 0.0\n\
             [output]\ntcp_listen = \"{tcp}\"\n\
             [rsi]\nenabled = true\nbind = \"127.0.0.1\"\nport = {}\ncontrollers = [\"127.0.0.1\"]\n\
             measure_only = true\nhand_eye = \"{}\"\n",
            rsi.port(),
            hand_eye.display()
        ),
    )
    .unwrap();
    let mut daemon = bin()
        .args(["run", "--config"])
        .arg(&config)
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The robot stands still (no drift), 4 ms cycles for 20 s at most.
    let controller = SimController::spawn(
        SimConfig {
            cycles: 5000,
            timeout: 1_000_000,
            error_drift_per_s: [0.0; 6],
            ..SimConfig::new(rsi)
        },
        RsiClock::new(),
    )
    .unwrap();
    let t0 = Instant::now();
    while std::net::TcpStream::connect(tcp).is_err() {
        assert!(t0.elapsed() < Duration::from_secs(20), "no pose stream");
        std::thread::sleep(Duration::from_millis(50));
    }
    let stations = dir.join("stations.csv");
    let out = bin()
        .args([
            "calibrate",
            "stations",
            "--stream",
            &tcp.to_string(),
            "--count",
            "1",
        ])
        .args(["--still-s", "0.5", "--timeout-s", "15", "--out"])
        .arg(&stations)
        .output()
        .unwrap();
    let actual = controller.state().actual;
    // The stream's messages carry the robot with its IPOC and age while the
    // controller sends; once it has been silent longer than the session
    // timeout (`session_idle_ms`, 100 ms) the robot is gone from them.
    let with_robot = read_messages(tcp, 10);
    let robot = with_robot
        .iter()
        .find_map(|v| v.get("robot"))
        .unwrap_or_else(|| panic!("no message with the robot: {with_robot:?}"));
    assert!(robot["ipoc"].as_u64().unwrap() > 0, "{robot}");
    assert!(robot["age_ms"].as_f64().unwrap() <= 100.0, "{robot}");
    assert!(robot["correction"].is_string(), "{robot}");
    let _ = controller.stop();
    std::thread::sleep(Duration::from_millis(300));
    for v in read_messages(tcp, 5) {
        assert!(v.get("robot").is_none(), "a silent controller's robot: {v}");
    }
    let _ = Command::new("kill")
        .args(["-TERM", &daemon.id().to_string()])
        .status();
    let status = daemon.wait().unwrap();
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(status.success());
    let text = std::fs::read_to_string(&stations).unwrap();
    let rows = photopose_handeye::parse_stations(&text, "stations.csv").unwrap();
    assert_eq!(rows.len(), 1, "{text}");
    // The simulated robot's actual TCP (its RIst, printed to 4 decimals).
    let got = photopose_geometry::pose::isometry_from_xyzabc(rows[0].robot_xyzabc);
    assert!(
        (got.translation.vector - actual.translation.vector).norm() < 1e-3,
        "{got:?} vs {actual:?}"
    );
    assert!(
        got.rotation.angle_to(&actual.rotation).to_degrees() < 1e-3,
        "{got:?} vs {actual:?}"
    );
    let photopose_handeye::stations::CameraSource::Pose { xyzabc, std } = &rows[0].camera else {
        panic!("pose columns expected")
    };
    // The synthetic camera stands 1000 mm above the plate's origin.
    assert!(xyzabc[2] > 990.0 && xyzabc[2] < 1010.0, "{xyzabc:?}");
    assert!(std.is_some_and(|s| s[0] > 0.0 && s[0] < 0.1), "{std:?}");
}
