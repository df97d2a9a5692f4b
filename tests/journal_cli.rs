//! Logs under systemd: when stderr is the journal (`JOURNAL_STREAM` names
//! its device and inode, as systemd sets it), every line starts with its
//! syslog priority so `journalctl -p warning` finds warnings and errors;
//! anywhere else the lines are plain.

mod common;

use common::{bin, scratch};
use std::os::unix::fs::MetadataExt;
use std::process::Stdio;

/// Runs `photopose ARGS` with stderr into a file, `JOURNAL_STREAM` naming
/// that file (`journal`) or another one; returns the exit status and the log.
fn run(args: &[&str], journal: bool, name: &str) -> (std::process::ExitStatus, String) {
    let dir = scratch(name);
    // No listening sockets: the tests run side by side.
    let config = dir.join("photopose.toml");
    std::fs::write(
        &config,
        "[source]\nkind = \"synthetic\"\n[output]\nudp = []\n",
    )
    .unwrap();
    let args: Vec<String> = args
        .iter()
        .map(|a| a.replace("CONFIG", &config.display().to_string()))
        .collect();
    let log = dir.join("stderr.log");
    let file = std::fs::File::create(&log).unwrap();
    let m = file.metadata().unwrap();
    let stream = if journal {
        format!("{}:{}", m.dev(), m.ino())
    } else {
        format!("{}:{}", m.dev(), m.ino() + 1)
    };
    let status = bin()
        .args(args)
        .env("JOURNAL_STREAM", stream)
        .env("RUST_LOG", "info")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(file)
        .status()
        .unwrap();
    (status, std::fs::read_to_string(&log).unwrap())
}

#[test]
fn lines_carry_their_priority_when_stderr_is_the_journal() {
    let (status, log) = run(
        &["run", "--config", "CONFIG", "--frames", "3"],
        true,
        "journal-run",
    );
    assert!(status.success(), "{log}");
    assert!(!log.is_empty());
    for line in log.lines() {
        assert!(
            ["<3>", "<4>", "<6>", "<7>"]
                .iter()
                .any(|p| line.starts_with(p)),
            "line without a priority: {line:?}"
        );
    }
    assert!(log.lines().any(|l| l.starts_with("<6>")), "{log}");
    let (status, log) = run(
        &["run", "--config", "/nonexistent/photopose.toml"],
        true,
        "journal-error",
    );
    assert!(!status.success());
    assert!(log.starts_with("<3>photopose: error:"), "{log}");
}

#[test]
fn lines_are_plain_elsewhere() {
    let (status, log) = run(
        &["run", "--config", "CONFIG", "--frames", "3"],
        false,
        "journal-plain",
    );
    assert!(status.success(), "{log}");
    assert!(log.lines().all(|l| !l.starts_with('<')), "{log}");
}
