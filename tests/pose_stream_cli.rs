//! The pose stream as an integrator meets it: the Python reader printed in
//! `docs/streams.md` (standard library only) runs unchanged against a
//! running daemon's TCP stream, and every line the stream sends validates
//! against the message's JSON Schema with a sound covariance.

mod common;

use common::{bin, free_tcp_port, scratch, Killed};
use std::io::BufRead;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The one ```python block of docs/streams.md.
fn python_reader() -> String {
    let doc = std::fs::read_to_string(common::root().join("docs/streams.md")).unwrap();
    let start = doc
        .find("```python\n")
        .expect("a python block in docs/streams.md")
        + 10;
    let len = doc[start..].find("```").expect("the block ends");
    doc[start..start + len].to_string()
}

/// `photopose run` on the synthetic source with its TCP stream on `port`.
fn daemon(port: u16, name: &str) -> Killed {
    let dir = scratch(name);
    let config = dir.join("photopose.toml");
    std::fs::write(
        &config,
        format!(
            "[camera]\nid = \"cell-7\"\n[source]\nkind = \"synthetic\"\n[source.synthetic]\nrate_hz = 20.0\n\
             [output]\nudp = []\ntcp_listen = \"127.0.0.1:{port}\"\n"
        ),
    )
    .unwrap();
    let child = Killed(
        bin()
            .args(["run", "--config"])
            .arg(&config)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let t0 = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(t0.elapsed() < Duration::from_secs(20), "no pose stream");
        std::thread::sleep(Duration::from_millis(50));
    }
    child
}

#[test]
fn the_python_reader_of_the_docs_reads_the_daemons_stream() {
    let Ok(version) = Command::new("python3").arg("--version").output() else {
        println!("skipped: python3 is not installed, the documented reader cannot run");
        return;
    };
    assert!(version.status.success());
    let dir = scratch("python-reader");
    let script = dir.join("reader.py");
    std::fs::write(&script, python_reader()).unwrap();
    let port = free_tcp_port();
    let _daemon = daemon(port, "python-reader-daemon");
    let mut reader = Killed(
        Command::new("python3")
            .arg(&script)
            .args(["127.0.0.1", &port.to_string(), "5"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = reader.0.try_wait().unwrap() {
            break s;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "the reader hangs");
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut out = String::new();
    let mut err = String::new();
    use std::io::Read;
    reader
        .0
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut out)
        .unwrap();
    reader
        .0
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    assert!(status.success(), "{out}{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 5, "{out}");
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("cell-7 frame ") && l.contains(" mm, sigma (")),
        "{out}"
    );
}

#[test]
fn every_line_of_the_tcp_stream_validates_against_the_schema() {
    let port = free_tcp_port();
    let _daemon = daemon(port, "tcp-schema");
    let stream = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let mut ok = 0;
    for line in std::io::BufReader::new(stream).lines().take(20) {
        let line = line.unwrap();
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        common::check_pose_message(&v);
        assert_eq!(v["camera"], "cell-7");
        assert_eq!(v["child_frame_id"], "cell-7");
        if v["status"] == "ok" {
            ok += 1;
            println!("an ok pose message is {} bytes", line.len() + 1);
        }
    }
    assert!(ok > 0, "no ok message among 20");
}
