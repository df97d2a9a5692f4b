//! The command line as an operator meets it (issue 14, items 2, 3, 8):
//! an IO error says its cause once; output into a closed pipe ends quietly
//! (no panic); a configuration holds only what differs from the defaults;
//! host names are taken where an address is asked; a missing camera file
//! names its key; the daemon's start line names its files, camera id,
//! source and every address it serves; progress is never drawn into a
//! pipe.

mod common;

use common::{bin, fixture, scratch};
use std::net::UdpSocket;
use std::process::{Output, Stdio};
use std::time::Duration;

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Runs the binary with stdout into a pipe whose reader is already gone.
fn into_closed_pipe(args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    bin()
        .args(args)
        .env("RUST_LOG", "warn")
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap()
}

#[test]
fn output_into_a_closed_pipe_ends_quietly() {
    let dir = scratch("closed-pipe");
    let frame = dir.join("frame.pgm");
    let o = bin()
        .args(["render", "--pose", "0,0,1000,0,0,0", "--out"])
        .arg(&frame)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let obs = fixture("observations/oblique-0.1px.csv");
    let cases: [Vec<&str>; 4] = [
        vec!["detect", frame.to_str().unwrap()],
        vec!["resect", "--observations", obs.to_str().unwrap()],
        vec!["field", "new"],
        vec![
            "simulate",
            "--pose",
            "0,0,1000,0,0,0",
            "--sigma-px",
            "0.05",
            "--json",
        ],
    ];
    for args in cases {
        let o = into_closed_pipe(&args);
        let err = text(&o.stderr);
        assert!(
            matches!(o.status.code(), Some(0 | 141)),
            "{args:?}: status {:?}, {err}",
            o.status
        );
        assert!(
            !err.contains("panicked") && !err.to_lowercase().contains("broken pipe"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn an_io_error_says_its_cause_once() {
    let dir = scratch("cause-once");
    let out = dir.join("missing-folder").join("frame.pgm");
    let o = bin()
        .args(["render", "--pose", "0,0,1000,0,0,0", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.matches("os error 2").count(), 1, "{err}");
    let missing = dir.join("missing.toml");
    let o = bin().arg("check-config").arg(&missing).output().unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(
        err.matches(missing.to_str().unwrap()).count(),
        1,
        "the path is said once: {err}"
    );
}

#[test]
fn a_config_with_only_what_differs_runs_and_takes_host_names() {
    let dir = scratch("minimal-config");
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let config = dir.join("photopose.toml");
    // No [source], no [pipeline], no [record], no [rsi]: their defaults.
    std::fs::write(
        &config,
        format!(
            "[output]\nudp = [\"localhost:{}\"]\n",
            rx.local_addr().unwrap().port()
        ),
    )
    .unwrap();
    let o = bin().arg("check-config").arg(&config).output().unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    // A [source] table with nothing in it is the default source too.
    let bare = dir.join("bare.toml");
    std::fs::write(&bare, "[source]\n[pipeline]\n").unwrap();
    let o = bin().arg("check-config").arg(&bare).output().unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let o = bin()
        .args(["run", "--frames", "2", "--config"])
        .arg(&config)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let mut buf = [0u8; 8192];
    let n = rx
        .recv(&mut buf)
        .expect("a pose datagram sent to localhost");
    let v: serde_json::Value = serde_json::from_slice(&buf[..n]).unwrap();
    assert!(v["seq"].is_u64(), "{v}");
}

#[test]
fn a_bad_address_or_a_missing_camera_file_names_its_key() {
    let dir = scratch("keys");
    let bad = dir.join("bad-host.toml");
    std::fs::write(&bad, "[metrics]\nlisten = \"no-such-host.invalid:9464\"\n").unwrap();
    let o = bin().arg("check-config").arg(&bad).output().unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("metrics.listen") && err.contains("no-such-host.invalid:9464"),
        "{err}"
    );
    let camera = dir.join("nowhere").join("camera.toml");
    let config = dir.join("camera.toml");
    std::fs::write(
        &config,
        format!("[camera]\ncamera_file = \"{}\"\n", camera.display()),
    )
    .unwrap();
    for args in [
        vec!["check-config".to_string(), config.display().to_string()],
        vec![
            "record".into(),
            "--frames".into(),
            "1".into(),
            "--out".into(),
            dir.join("r.mcap").display().to_string(),
            "--config".into(),
            config.display().to_string(),
        ],
    ] {
        let o = bin().args(&args).output().unwrap();
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains("camera.camera_file") && err.contains(camera.to_str().unwrap()),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn rsi_sim_takes_a_host_name() {
    let port = common::free_udp_port();
    let o = bin()
        .args(["rsi-sim", "--cycles", "30", "--timeout", "10", "--server"])
        .arg(format!("localhost:{port}"))
        .output()
        .unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!("nothing answers at 127.0.0.1:{port}")),
        "{err}"
    );
    assert!(
        !err.contains('\x1b'),
        "no progress drawn into a pipe: {err:?}"
    );
    let o = bin()
        .args([
            "rsi-sim",
            "--cycles",
            "3",
            "--server",
            "no-such-host.invalid:49152",
        ])
        .output()
        .unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--server") && err.contains("no-such-host.invalid"),
        "{err}"
    );
}

#[test]
fn the_start_line_names_files_camera_source_and_every_address_served() {
    let dir = scratch("start-line");
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    let port = rx.local_addr().unwrap().port();
    let config = dir.join("photopose.toml");
    std::fs::write(
        &config,
        format!(
            "[camera]\nid = \"cell-7\"\n[output]\nudp = [\"localhost:{port}\"]\ntcp_listen = \"127.0.0.1:0\"\n\
             [metrics]\nlisten = \"localhost:0\"\n"
        ),
    )
    .unwrap();
    let o = bin()
        .args(["run", "--frames", "2", "--config"])
        .arg(&config)
        .env("RUST_LOG", "info")
        .output()
        .unwrap();
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    let lines: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("photopose running"))
        .collect();
    assert_eq!(lines.len(), 1, "one start line: {err}");
    let line = lines[0];
    for want in [
        format!("config={}", config.display()),
        "camera_file=built-in config/camera.toml".into(),
        "field_file=built-in config/plate.csv".into(),
        "camera_id=cell-7".into(),
        "source=synthetic".into(),
        format!("udp to 127.0.0.1:{port}"),
        "tcp stream on 127.0.0.1:".into(),
        "metrics on http://127.0.0.1:".into(),
    ] {
        assert!(line.contains(&want), "{want:?} missing from {line}");
    }
    // The bound ports, not the configured 0.
    assert!(
        !line.contains("127.0.0.1:0,") && !line.contains("127.0.0.1:0/"),
        "{line}"
    );
}

#[test]
fn progress_is_not_drawn_into_a_pipe() {
    let dir = scratch("progress");
    let o = bin()
        .args(["record", "--frames", "3", "--out"])
        .arg(dir.join("r.mcap"))
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains('\x1b') && !err.contains('\r'), "{err:?}");
    let o = bin()
        .args(["bench", "--frames", "2", "--rounds", "1"])
        .output()
        .unwrap();
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains('\x1b') && !err.contains('\r'), "{err:?}");
}

#[test]
fn calibrate_stations_always_ends_with_a_last_line() {
    let dir = scratch("stations-line");
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    // A "daemon" that sends one line without RIst, then closes.
    let server = std::thread::spawn(move || {
        use std::io::Write;
        let (mut s, _) = listener.accept().unwrap();
        let _ = s.write_all(b"{\"seq\":0,\"status\":\"too_few_targets\"}\n");
    });
    let out = dir.join("stations.csv");
    let o = bin()
        .args([
            "calibrate",
            "stations",
            "--count",
            "2",
            "--timeout-s",
            "20",
            "--stream",
        ])
        .arg(addr.to_string())
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    server.join().unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&format!("0 of 2 stations written to {}", out.display())),
        "{err}"
    );
    assert!(!err.contains('\x1b') && !err.contains('\r'), "{err:?}");
}
