//! `photopose demo` end to end (the README's first command), on a faster
//! circle so the test stays short: the whole chain runs (rendered frames →
//! poses → UDP/TCP streams, RSI answering the simulated controller), the
//! pose stream, hand-eye file, reports and plots are written, and the
//! circular test finds the injected radial deviation at the TCP.

mod common;

use common::{bin, scratch};

#[test]
fn the_demo_runs_the_chain_and_finds_the_injected_deviation() {
    let dir = scratch("demo");
    let out_dir = dir.join("demo-out");
    let out = bin()
        .args(["demo", "--feed", "160", "--rate", "25", "--out"])
        .arg(&out_dir)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for f in [
        "poses.jsonl",
        "hand-eye.toml",
        "report.txt",
        "report.json",
        "circle.svg",
        "radial.svg",
        "angular.svg",
    ] {
        let p = out_dir.join(f);
        assert!(
            std::fs::metadata(&p).is_ok_and(|m| m.len() > 0),
            "{} missing",
            p.display()
        );
    }
    // Every frame became a pose and went through the stream.
    let lines = std::fs::read_to_string(out_dir.join("poses.jsonl")).unwrap();
    let ok = lines
        .lines()
        .filter(|l| l.contains("\"status\":\"ok\""))
        .count();
    // 2π · 149.9 mm at 160 mm/s, 25 frames/s.
    assert_eq!(ok, 148, "{stdout}");
    // Every message is a valid `photopose.pose.v2`; while the simulated
    // controller runs they carry the robot with the correction's state.
    let mut measure_only = 0;
    for l in lines.lines() {
        let v: serde_json::Value = serde_json::from_str(l).unwrap();
        common::check_pose_message(&v);
        if v["robot"]["correction"] == "measure_only" {
            measure_only += 1;
        }
    }
    assert!(measure_only > 0, "no message with the robot measuring only");
    // The injected pattern's F (the cell's default, 168.2 µm) is found at
    // the TCP by the filtered profile, within the pose noise.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("report.json")).unwrap())
            .unwrap();
    let g = report["tcp"]["g_filtered_um"].as_f64().unwrap();
    assert!((g - 168.2).abs() < 15.0, "G filtered {g} µm\n{stdout}");
    assert!(
        stdout.contains("RSI:") && stdout.contains("injected F"),
        "{stdout}"
    );
}
