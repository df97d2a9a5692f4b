//! `photopose bench --json`: one JSON object with every stage's median and
//! 99th percentile, the whole frame's median (`full_frame_median_us`) and
//! the tracking figure's key (null until tracking mode exists). Checks the
//! shape of the output only, never the figures (the machine may be loaded).

use std::process::Command;

#[test]
fn bench_json_ends_with_one_object_with_the_headline_figures() {
    let out = Command::new(env!("CARGO_BIN_EXE_photopose"))
        .args(["bench", "--frames", "1", "--rounds", "2", "--json"])
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
    let full = v["full_frame_median_us"]
        .as_f64()
        .expect("full_frame_median_us");
    assert!(full > 0.0);
    assert_eq!(full, v["total"]["median_us"].as_f64().unwrap());
    assert!(v["tracking_median_us"].is_null());
    for stage in [
        "threshold",
        "labelling",
        "centroids",
        "decoding",
        "final_pose",
    ] {
        assert!(v[stage]["median_us"].as_f64().is_some(), "{stage}");
        assert!(v[stage]["p99_us"].as_f64().is_some(), "{stage}");
    }
}
