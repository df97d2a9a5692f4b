//! `photopose record` end to end: SIGTERM in the middle of a recording
//! ends it with exit 0 and leaves a complete, readable MCAP file whose
//! frames replay through the daemon; a corrupt recording is refused with a
//! line that names the file.

mod common;

use common::{bin, scratch};
use photopose_record::Recording;
use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Records from an endless synthetic source until SIGTERM; returns the file.
fn record_until_sigterm(dir: &std::path::Path) -> (std::path::PathBuf, usize) {
    let config = dir.join("synthetic.toml");
    std::fs::write(
        &config,
        "[source]\nkind = \"synthetic\"\n[source.synthetic]\nrate_hz = 40.0\nframes = 0\n",
    )
    .unwrap();
    let out = dir.join("run.mcap");
    let mut child = bin()
        .args(["record", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until frames are being written, then stop it mid-stream.
    let t0 = Instant::now();
    while std::fs::metadata(&out).map_or(0, |m| m.len()) < 5_000_000 {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no frames written within 60 s"
        );
        assert!(child.try_wait().unwrap().is_none(), "record ended early");
        std::thread::sleep(Duration::from_millis(20));
    }
    let kill = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let mut said = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut said)
        .unwrap();
    let status = child.wait().unwrap();
    assert!(status.success(), "exit status {status:?}");
    let n: usize = said
        .split(": ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("unexpected summary {said:?}"));
    (out, n)
}

#[test]
fn sigterm_mid_recording_leaves_a_complete_replayable_file() {
    let dir = scratch("record-sigterm");
    let (path, n) = record_until_sigterm(&dir);
    let rec = Recording::open(&path).expect("the recording is complete and readable");
    assert!(n >= 3, "{n} frames");
    assert_eq!(rec.len(), n, "every frame said recorded is in the file");
    let seqs: Vec<u64> = (0..rec.len()).map(|i| rec.meta(i).0.seq).collect();
    assert_eq!(seqs, (0..n as u64).collect::<Vec<_>>());
    // The file replays through the daemon: one ok pose per frame, in order.
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let config = dir.join("replay.toml");
    std::fs::write(
        &config,
        format!(
            "[source]\nkind = \"replay\"\n[source.replay]\npath = \"{}\"\nspeed = \"max\"\n\
             [pipeline]\noverflow = \"block\"\n[output]\nudp = [\"{}\"]\n",
            path.display(),
            rx.local_addr().unwrap()
        ),
    )
    .unwrap();
    let out = bin()
        .args(["run", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut buf = [0u8; 4096];
    let mut got = Vec::new();
    while got.len() < n {
        let len = rx.recv(&mut buf).expect("a pose per recorded frame");
        let v: serde_json::Value = serde_json::from_slice(&buf[..len]).unwrap();
        if v["status"] == "stale" {
            continue;
        }
        assert_eq!(v["status"], "ok", "{v}");
        got.push(v["seq"].as_u64().unwrap());
    }
    assert_eq!(got, seqs);
}

#[test]
fn a_corrupt_recording_is_refused_naming_the_file() {
    let dir = scratch("record-corrupt");
    let (path, _) = record_until_sigterm(&dir);
    let bytes = std::fs::read(&path).unwrap();
    let corrupt = dir.join("truncated.mcap");
    std::fs::write(&corrupt, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let config = dir.join("replay.toml");
    std::fs::write(
        &config,
        format!(
            "[source]\nkind = \"replay\"\n[source.replay]\npath = \"{}\"\n",
            corrupt.display()
        ),
    )
    .unwrap();
    let out = bin()
        .args(["run", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.lines()
            .any(|l| l.contains("error") && l.contains("truncated.mcap")),
        "one clear line naming the file: {err}"
    );
}
