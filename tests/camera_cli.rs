//! `photopose camera list` and `photopose camera grab` against a real GigE
//! Vision peer, `arv-fake-gv-camera-0.8 -i 127.0.0.1` (a child of this
//! test), including `[source.gige.features]` checked against the camera's
//! node map. Only one GigE Vision peer can answer on 127.0.0.1: this file
//! holds one test, and cargo runs test binaries one after the other (as
//! `daemon_gige.rs` does).

mod common;

use common::{bin, scratch, FakeCamera};
use std::path::Path;
use std::process::Output;

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn grab(config: &Path, out: &Path, count: u32) -> Output {
    bin()
        .args(["camera", "grab", "--timeout-s", "10", "--count"])
        .arg(count.to_string())
        .arg("--out")
        .arg(out)
        .arg("--config")
        .arg(config)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap()
}

#[test]
fn camera_list_and_grab_with_features_on_a_fake_gige_camera() {
    let dir = scratch("camera-cli");
    let _fake = FakeCamera::start();

    // list: the fake camera with its model, vendor, serial and address.
    let o = bin().args(["camera", "list"]).output().unwrap();
    let out = text(&o.stdout);
    assert!(o.status.success(), "{}{}", out, text(&o.stderr));
    let row = out
        .lines()
        .find(|l| l.contains("Aravis-Fake-GV01"))
        .unwrap_or_else(|| panic!("the fake camera is listed: {out}"));
    for want in ["GigEVision", "Aravis", "Fake", "GV01", "127.0.0.1"] {
        assert!(row.split('\t').any(|f| f == want), "{want} in {row:?}");
    }

    // grab: N stills of the camera's size (its 512×512 default), each with
    // the exposure aid; GenICam features set by name on the way.
    let camera = dir.join("camera.toml");
    std::fs::write(
        &camera,
        "[sensor]\nwidth = 512\nheight = 512\npixel_size = 0.0067\n[interior]\nc = 12.0\nx0 = 0.0\ny0 = 0.0\n",
    )
    .unwrap();
    let config = |features: &str| {
        let path = dir.join("photopose.toml");
        std::fs::write(
            &path,
            format!(
                "[camera]\ncamera_file = \"{}\"\n[source]\nkind = \"gige\"\n\
                 [source.gige]\ncamera = \"GV01\"\nroi = [0, 0, 512, 512]\n\
                 [source.gige.features]\n{features}",
                camera.display()
            ),
        )
        .unwrap();
        path
    };
    let stills = dir.join("stills");
    let good = config(
        "TriggerSelector = \"FrameStart\"\nTriggerMode = \"Off\"\nTestRegister = 42\nExposureTimeAbs = 2000.0\n",
    );
    let o = grab(&good, &stills, 3);
    let out = text(&o.stdout);
    assert!(o.status.success(), "{out}{}", text(&o.stderr));
    for k in 1..=3 {
        let path = stills.join(format!("still-{k:03}.pgm"));
        let bytes = std::fs::read(&path).unwrap();
        assert!(
            bytes.starts_with(b"P5\n512 512\n255\n"),
            "{}",
            path.display()
        );
        assert_eq!(bytes.len(), 15 + 512 * 512);
        let line = out
            .lines()
            .find(|l| l.starts_with(path.to_str().unwrap()))
            .unwrap_or_else(|| panic!("a line for {}: {out}", path.display()));
        assert!(
            line.contains("512×512") && line.contains("saturated"),
            "{line}"
        );
        assert!(line.contains("/255"), "peak against full scale: {line}");
    }
    assert!(!stills.join("still-004.pgm").exists());
    assert!(out.contains("3 stills"), "{out}");

    // A feature the camera lacks, an entry an enumeration lacks, a
    // read-only feature: the opening fails naming the feature.
    for (features, name, why) in [
        ("NoSuchFeature = 1\n", "NoSuchFeature", "no such feature"),
        ("TriggerMode = \"Sometimes\"\n", "TriggerMode", "Sometimes"),
        ("SensorWidth = 100\n", "SensorWidth", "read-only"),
    ] {
        let o = grab(&config(features), &dir.join("refused"), 1);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{features}: {err}");
        assert!(
            err.contains(&format!("source.gige.features.{name}")) && err.contains(why),
            "{features}: {err}"
        );
    }
}
