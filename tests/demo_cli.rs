//! `photopose demo` end to end (the README's first command), shortened by
//! its hidden flags (a 40 mm circle at 160 mm/s, 10 frames/s) so the test
//! stays short: hand-eye stations gathered from the daemon's stream and
//! solved, the circle measure-only, corrected and corrected without latency
//! compensation, each through the daemon and the simulated controller over
//! loopback UDP; the pose streams, hand-eye file, reports and plots are
//! written and `--json` ends the output with one object of finite figures.

mod common;

use common::{bin, scratch};

#[test]
fn the_demo_runs_every_phase_and_ends_with_its_figures_as_json() {
    let dir = scratch("demo");
    let out_dir = dir.join("demo-out");
    let out = bin()
        .args([
            "demo",
            "--feed",
            "160",
            "--rate",
            "10",
            "--radius-mm",
            "40",
            "--json",
            "--out",
        ])
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
        "poses-stations.jsonl",
        "poses-measure-only.jsonl",
        "poses-corrected.jsonl",
        "poses-uncompensated.jsonl",
        "stations.csv",
        "hand-eye.toml",
        "radial.svg",
        "measure-only/report.txt",
        "corrected/report.txt",
        "uncompensated/report.txt",
    ] {
        let p = out_dir.join(f);
        assert!(
            std::fs::metadata(&p).is_ok_and(|m| m.len() > 0),
            "{} missing\n{stdout}",
            p.display()
        );
    }
    // Every message is a valid `photopose.pose.v2`; the stations' phase
    // carries the robot (RIst) measuring only, the corrected one tracking.
    for (file, state) in [
        ("poses-stations.jsonl", "measure_only"),
        ("poses-corrected.jsonl", "tracking"),
    ] {
        let lines = std::fs::read_to_string(out_dir.join(file)).unwrap();
        let mut seen = 0;
        for l in lines.lines() {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            common::check_pose_message(&v);
            if v["robot"]["correction"] == state {
                seen += 1;
            }
        }
        assert!(seen > 0, "no message of {file} with the robot {state}");
    }
    // The output ends with one JSON object holding the figures.
    let last = stdout.lines().last().unwrap_or_default();
    let v: serde_json::Value = serde_json::from_str(last).expect("the last line is JSON");
    for key in [
        "f_true_measure_only_um",
        "f_true_corrected_um",
        "f_true_uncompensated_um",
        "f_measured_measure_only_um",
        "f_measured_corrected_um",
        "hand_eye_sigma0",
    ] {
        let x = v[key].as_f64().unwrap_or(f64::NAN);
        assert!(x.is_finite() && x >= 0.0, "{key}: {}\n{stdout}", v[key]);
    }
    assert!(v["hand_eye_within_3sigma"].is_boolean(), "{v}");
    assert!(v["stations"].as_u64().unwrap() >= 3, "{v}");
    // Measure-only leaves the injected pattern (F ≈ 168 µm) in place.
    let f_b = v["f_true_measure_only_um"].as_f64().unwrap();
    assert!(f_b > 100.0, "{v}");
}
