//! `photopose bench --json`: the output ends with one JSON object holding
//! the whole frame's and tracking mode's medians (`full_frame_median_us`,
//! `tracking_median_us`), the targets per tracked frame (`tracking_targets_mean`,
//! the whole default plate) and every stage's median and 99th percentile.
//! Checks the shape of the output only, never the figures (the machine may
//! be loaded).

use std::process::Command;

#[test]
fn bench_json_ends_with_one_object_with_the_headline_figures() {
    let out = Command::new(env!("CARGO_BIN_EXE_photopose"))
        .args([
            "bench",
            "--frames",
            "1",
            "--rounds",
            "2",
            "--track-frames",
            "6",
            "--json",
        ])
        .output()
        .expect("the binary runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let last = stdout.lines().last().expect("output");
    let v: serde_json::Value = serde_json::from_str(last).expect("a JSON object");
    for key in [
        "full_frame_median_us",
        "full_frame_p99_us",
        "tracking_median_us",
        "tracking_p99_us",
    ] {
        assert!(v[key].as_f64().is_some_and(|t| t > 0.0), "{key}: {v}");
    }
    assert!(v["tracking_frames"].as_u64().unwrap() > 0, "{v}");
    // The bench's circle keeps the whole default plate (230 targets) in view.
    let targets = v["tracking_targets_mean"]
        .as_f64()
        .expect("targets per frame");
    assert!(targets >= 220.0, "{targets} targets per tracked frame");
    for stage in [
        "threshold",
        "labelling",
        "centroids",
        "decoding",
        "final_pose",
        "total",
    ] {
        let s = &v["stages_us"][stage];
        assert!(s["median_us"].as_f64().is_some(), "{stage}");
        assert!(s["p99_us"].as_f64().is_some(), "{stage}");
    }
}
