//! Recordings are inputs wherever images are: `detect`, `resect` and
//! `calibrate camera` take a `.mcap` file (every frame, or `--frames`),
//! each frame named `FILE#SEQ`; `export --format png` writes PNG frames
//! that detect the same as the recording's frames.

mod common;

use common::{bin, scratch};
use serde_json::Value;
use std::path::Path;

fn lines(args: &[&str], files: &[&Path]) -> Vec<Value> {
    let out = bin().args(args).args(files).output().unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn detect_resect_and_calibrate_read_recordings() {
    let dir = scratch("recording-inputs");
    let rec = dir.join("rec.mcap");
    let out = bin()
        .args(["record", "--frames", "4", "--out"])
        .arg(&rec)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let name = rec.display().to_string();

    // Every frame, named by its sequence number.
    let all = lines(&["detect"], &[&rec]);
    let names: Vec<String> = all
        .iter()
        .map(|l| l["image"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(
        names,
        (0..4).map(|k| format!("{name}#{k}")).collect::<Vec<_>>()
    );
    for l in &all {
        assert_eq!(l["ok"], true, "{l}");
        assert!(l["n_identified"].as_u64().unwrap() > 30, "{l}");
    }
    // A selection.
    let some = lines(&["detect", "--frames", "1-2"], &[&rec]);
    assert_eq!(some.len(), 2);
    assert_eq!(some[0], all[1]);
    assert_eq!(some[1], all[2]);
    let pose = lines(&["resect", "--frames", "3"], &[&rec]);
    assert_eq!(pose.len(), 1);
    assert_eq!(pose[0]["image"], format!("{name}#3"));
    assert_eq!(pose[0]["ok"], true, "{}", pose[0]);

    // Exported as PNG, a frame detects as it does in the recording.
    let png = dir.join("png");
    let out = bin()
        .arg("export")
        .arg(&rec)
        .arg("--out")
        .arg(&png)
        .args(["--format", "png"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let first = png.join("frame-000000.png");
    assert!(std::fs::read(&first).unwrap().starts_with(b"\x89PNG"));
    let from_png = lines(&["detect"], &[&first]);
    assert_eq!(from_png[0]["targets"], all[0]["targets"]);

    // A bad selection names itself.
    let out = bin()
        .args(["detect", "--frames", "2-x"])
        .arg(&rec)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("2-x"));

    // The calibration reads the recording's frames (four frames of one
    // view cannot determine a camera: it says so, after detecting them).
    let out = bin()
        .args(["calibrate", "camera"])
        .arg(&rec)
        .arg("--out")
        .arg(dir.join("cam.toml"))
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("all 4 images"), "{text}");
    assert!(!text.contains(&format!("skipped {name}")), "{text}");
    println!("{text}");
    std::fs::remove_dir_all(&dir).unwrap();
}
