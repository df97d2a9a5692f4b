//! Replay from the command line: at speed `max` with the default overflow
//! policy a recording is replayed complete (0 dropped) and twice gives the
//! same pose output; `run --frames N` stops any source after N frames.

mod common;

use common::{bin, scratch, UdpMessages};
use std::net::UdpSocket;
use std::path::Path;

/// Runs `photopose run` on `config` (plus `args`), collecting the UDP
/// messages while it runs (about 2 kB each: left queued, a few dozen would
/// overflow the socket's default receive buffer); returns them without
/// their run-dependent times (sending, monotonic stamps) and the run's
/// summary.
fn replay(config: &Path, rx: &UdpSocket, args: &[&str]) -> (Vec<String>, String) {
    let messages = UdpMessages::collect(rx);
    let out = bin()
        .args(["run", "--config"])
        .arg(config)
        .args(args)
        .output()
        .unwrap();
    let lines: Vec<String> = (messages.finish().into_iter())
        .map(|v| common::without_run_times(v).to_string())
        .collect();
    let summary = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{summary}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (lines, summary)
}

#[test]
fn a_replay_at_full_speed_is_complete_and_the_same_twice() {
    let dir = scratch("replay-cli");
    let recording = dir.join("rec.mcap");
    let out = bin()
        .args(["record", "--frames", "30", "--out"])
        .arg(&recording)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    // No [pipeline] section: the default overflow policy.
    let config = dir.join("replay.toml");
    std::fs::write(
        &config,
        format!(
            "[source]\nkind = \"replay\"\n[source.replay]\npath = \"{}\"\nspeed = \"max\"\n\
             [output]\nudp = [\"{}\"]\n",
            recording.display(),
            rx.local_addr().unwrap()
        ),
    )
    .unwrap();
    let (first, summary) = replay(&config, &rx, &[]);
    assert!(summary.contains("30 frames in, 0 dropped"), "{summary}");
    assert_eq!(first.len(), 30);
    let (second, _) = replay(&config, &rx, &[]);
    assert_eq!(first, second, "two replays, the same output");
    // --frames holds for a replay too (it used to apply to the synthetic
    // source only).
    let (five, summary) = replay(&config, &rx, &["--frames", "5"]);
    assert!(summary.contains("5 frames in"), "{summary}");
    assert_eq!(five.len(), 5);
    assert_eq!(five[..], first[..5]);
}
