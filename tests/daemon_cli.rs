//! The daemon binary end to end: `photopose run` on the synthetic source
//! streams poses over UDP, stops on SIGTERM with exit 0; `check-config`
//! accepts the shipped example and names the key of a bad value; the
//! systemd unit passes `systemd-analyze verify`.

mod common;

use common::{bin, root, scratch};

use std::net::UdpSocket;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

#[test]
fn run_streams_poses_and_stops_on_sigterm() {
    let dir = scratch("run");
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let config = std::fs::read_to_string(root().join("config/photopose.toml"))
        .unwrap()
        .replace(
            "udp = [\"127.0.0.1:5005\"]",
            &format!("udp = [\"{}\"]", rx.local_addr().unwrap()),
        )
        .replace(
            "tcp_listen = \"127.0.0.1:5006\"",
            "tcp_listen = \"127.0.0.1:0\"",
        )
        .replace("listen = \"127.0.0.1:9464\"", "listen = \"127.0.0.1:0\"");
    let path = dir.join("photopose.toml");
    std::fs::write(&path, config).unwrap();
    let child = bin()
        .args(["run", "--config"])
        .arg(&path)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut buf = [0u8; 4096];
    let mut seqs = Vec::new();
    while seqs.len() < 10 {
        let n = rx.recv(&mut buf).expect("a pose datagram within 20 s");
        let v: serde_json::Value = serde_json::from_slice(&buf[..n]).unwrap();
        common::check_pose_message(&v);
        if v["status"] == "stale" {
            continue; // no fresh pose in time on a loaded machine: said, not hidden
        }
        assert_eq!(v["status"], "ok", "{v}");
        seqs.push(v["seq"].as_u64().unwrap());
    }
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "in order: {seqs:?}");
    let kill = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let out = child.wait_with_output().unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "exit status {:?}\n{log}", out.status);
    assert!(
        log.contains("signal received") && log.contains("photopose stopped"),
        "{log}"
    );
}

#[test]
fn check_config_accepts_the_example_and_names_bad_keys() {
    let out = bin()
        .args(["check-config"])
        .arg(root().join("config/photopose.toml"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dir = scratch("check");
    let bad = dir.join("bad.toml");
    let text = std::fs::read_to_string(root().join("config/photopose.toml"))
        .unwrap()
        .replace("slots = 8", "slots = 1");
    std::fs::write(&bad, text).unwrap();
    let out = bin().args(["check-config"]).arg(&bad).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.toml") && err.contains("pipeline.slots"),
        "{err}"
    );
    let out = bin()
        .args(["check-config"])
        .arg(dir.join("missing.toml"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.toml: cannot read"));
    // RSI on without its hand-eye file, and with one that does not exist.
    let text = std::fs::read_to_string(root().join("config/photopose.toml")).unwrap();
    for (edit, want) in [
        ("enabled = true", "rsi.hand_eye"),
        (
            "enabled = true\nhand_eye = \"/nonexistent/hand-eye.toml\"",
            "/nonexistent/hand-eye.toml",
        ),
    ] {
        // (In the `[rsi]` section: other sections have an `enabled` too.)
        let rsi = text.find("[rsi]").expect("an [rsi] section");
        let edited = format!(
            "{}{}",
            &text[..rsi],
            text[rsi..].replacen("enabled = false", edit, 1)
        );
        std::fs::write(&bad, edited).unwrap();
        let out = bin().args(["check-config"]).arg(&bad).output().unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(want), "{err}");
    }
}

#[test]
fn the_benchmark_configurations_check() {
    // check-config opens a replay's recording as run does: the benchmark
    // configurations get a small recording of their own here.
    let dir = scratch("bench-configs");
    let recording = dir.join("rec.mcap");
    let out = bin()
        .args(["record", "--frames", "3", "--out"])
        .arg(&recording)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for entry in std::fs::read_dir(root().join("config/bench")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") && !path.ends_with("hand-eye.toml") {
            let text = std::fs::read_to_string(&path)
                .unwrap()
                .replace("target/bench/rec200.mcap", &recording.display().to_string())
                .replace("target/bench/cell.mcap", &recording.display().to_string());
            let copy = dir.join(path.file_name().unwrap());
            std::fs::write(&copy, text).unwrap();
            let out = bin()
                .current_dir(root())
                .args(["check-config", "--strict"])
                .arg(&copy)
                .output()
                .unwrap();
            assert!(
                out.status.success(),
                "{}: {}",
                path.display(),
                String::from_utf8_lossy(&out.stderr)
            );
        }
    }
}

#[test]
fn check_config_runs_the_validation_of_run() {
    let dir = scratch("check-parity");
    let config = dir.join("photopose.toml");
    // The recording of a replay is opened (it used to pass unread).
    std::fs::write(
        &config,
        "[source]\nkind = \"replay\"\n[source.replay]\npath = \"/nonexistent/run.mcap\"\n",
    )
    .unwrap();
    let out = bin().args(["check-config"]).arg(&config).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("/nonexistent/run.mcap"), "{err}");
    // The controller file's HOLDON pairing warning that run prints is
    // printed; --strict makes it an error.
    let xml = dir.join("RSI_EthernetConfig.xml");
    std::fs::write(
        &xml,
        "<ROOT><CONFIG><IP_NUMBER>127.0.0.1</IP_NUMBER><PORT>49152</PORT><SENTYPE>ImFree</SENTYPE>\
         <ONLYSEND>FALSE</ONLYSEND></CONFIG><SEND><ELEMENTS>\
         <ELEMENT TAG=\"DEF_RIst\" TYPE=\"DOUBLE\" INDX=\"INTERNAL\"/>\
         <ELEMENT TAG=\"DEF_RSol\" TYPE=\"DOUBLE\" INDX=\"INTERNAL\"/></ELEMENTS></SEND>\
         <RECEIVE><ELEMENTS>\
         <ELEMENT TAG=\"RKorr.X\" TYPE=\"DOUBLE\" INDX=\"1\" HOLDON=\"1\"/>\
         <ELEMENT TAG=\"RKorr.Y\" TYPE=\"DOUBLE\" INDX=\"2\" HOLDON=\"1\"/>\
         <ELEMENT TAG=\"RKorr.Z\" TYPE=\"DOUBLE\" INDX=\"3\" HOLDON=\"1\"/>\
         <ELEMENT TAG=\"RKorr.A\" TYPE=\"DOUBLE\" INDX=\"4\" HOLDON=\"1\"/>\
         <ELEMENT TAG=\"RKorr.B\" TYPE=\"DOUBLE\" INDX=\"5\" HOLDON=\"1\"/>\
         <ELEMENT TAG=\"RKorr.C\" TYPE=\"DOUBLE\" INDX=\"6\" HOLDON=\"1\"/>\
         </ELEMENTS></RECEIVE></ROOT>",
    )
    .unwrap();
    std::fs::write(
        &config,
        format!(
            "[source]\nkind = \"synthetic\"\n[rsi]\nenabled = true\nbind = \"127.0.0.1\"\n\
             controllers = [\"127.0.0.1\"]\nhand_eye = \"{}\"\nethernet_config = \"{}\"\n\
             mode = \"relative\"\n",
            root().join("config/bench/hand-eye.toml").display(),
            xml.display()
        ),
    )
    .unwrap();
    let out = bin().args(["check-config"]).arg(&config).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("warning") && err.contains("HOLDON"), "{err}");
    let out = bin()
        .args(["check-config", "--strict"])
        .arg(&config)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("HOLDON") && err.contains("--strict"), "{err}");
}

#[test]
fn the_systemd_unit_verifies() {
    let analyze = Path::new("/usr/bin/systemd-analyze");
    assert!(
        analyze.exists(),
        "systemd-analyze is missing: run .ci/deps.sh"
    );
    let dir = scratch("unit");
    let unit = std::fs::read_to_string(root().join("systemd/photopose.service"))
        .unwrap()
        .replace("/usr/bin/photopose", env!("CARGO_BIN_EXE_photopose"));
    let path = dir.join("photopose.service");
    std::fs::write(&path, unit).unwrap();
    let out = Command::new(analyze)
        .arg("verify")
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let out = Command::new(analyze)
        .args(["security", "--offline=true"])
        .arg(&path)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    let score: f64 = text
        .lines()
        .find_map(|l| l.split("exposure level for photopose.service:").nth(1))
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no score in {text}"));
    assert!(score <= 3.0, "hardening score {score} (want ≤ 3.0 'OK')");
}
