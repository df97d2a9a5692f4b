//! End-to-end test of `photopose circle-test`: a pose stream written from
//! the simulated cell (with pose noise and some lines without a pose), run
//! through the real binary with a hand-eye file; checks the report's keys,
//! the files written, the recovered circular deviation G, the radial
//! deviation F against the nominal circle, and the provenance.

mod common;

use common::{bin, scratch};
use nalgebra::Matrix6;
use photopose_circle::cell::{perturb, CameraMount, Cell};
use photopose_geometry::rng::SplitMix64;
use photopose_stream::message::COVARIANCE_ORDER;
use photopose_stream::{PoseEstimate, PoseMessage, PoseStatus};
use serde_json::Value;
use std::io::Write;

/// Writes the cell's camera poses as the daemon's JSON lines, with noise of
/// 5 µm and 0.0005° per axis, every 100th frame `too_few_targets` and one
/// `stale` line.
fn write_stream(cell: &Cell, path: &std::path::Path) -> usize {
    let samples = cell.samples().unwrap();
    let mut cov = Matrix6::zeros();
    for k in 0..3 {
        cov[(k, k)] = 0.005f64.powi(2);
        cov[(3 + k, 3 + k)] = 0.0005f64.to_radians().powi(2);
    }
    let mut rng = SplitMix64::new(5);
    let mut file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut buf = Vec::new();
    let mut used = 0;
    let camera: std::sync::Arc<str> = std::sync::Arc::from("camera");
    let mut flat = [0.0; 36];
    for (k, v) in flat.iter_mut().enumerate() {
        *v = cov[(k / 6, k % 6)];
    }
    let mut last = None;
    for (i, s) in samples.iter().enumerate() {
        let t = (s.time_s * 1e9) as u64;
        let mut m = if i % 100 == 50 {
            PoseMessage::new(&camera, i as u64, PoseStatus::TooFewTargets)
        } else {
            let e = photopose_geometry::pose::exterior_from_camera_pose(&perturb(
                &s.camera, &cov, &mut rng,
            ));
            let r = e.rotation;
            let [w, x, y, z] =
                photopose_geometry::rotation::quaternion_wxyz_from_matrix(&r.transpose()).unwrap();
            let mut m = PoseMessage::new(&camera, i as u64, PoseStatus::Ok);
            m.pose = Some(PoseEstimate {
                position_mm: e.center.into(),
                quaternion_xyzw: [x, y, z, w],
                rotation_field_to_camera: [0, 1, 2].map(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)]]),
                covariance: flat,
                covariance_order: COVARIANCE_ORDER,
                std_position_mm: [0.005; 3],
                std_rotation_deg: [0.0005; 3],
                sigma0_px: 0.02,
                n_targets: 200,
            });
            used += 1;
            m
        };
        m.time.handover_utc_ns = Some(t);
        m.time.camera_clock_ns = Some(t);
        m.encode_line(&mut buf);
        common::check_pose_message(&serde_json::from_slice(&buf).unwrap());
        file.write_all(&buf).unwrap();
        if i == 1000 {
            let stale = PoseMessage::stale(&camera, last.as_ref());
            stale.encode_line(&mut buf);
            common::check_pose_message(&serde_json::from_slice(&buf).unwrap());
            file.write_all(&buf).unwrap();
        }
        last = Some(m);
    }
    used
}

#[test]
fn circle_test_of_a_simulated_stream_recovers_the_tcp_error() {
    let dir = scratch("circle-test");
    let cell = Cell::default();
    let poses = dir.join("poses.jsonl");
    let used = write_stream(&cell, &poses);
    let x = CameraMount::DEFAULT_XYZABC;
    let hand_eye = dir.join("hand_eye.toml");
    std::fs::write(
        &hand_eye,
        format!(
            "# written by the test\n[camera_in_tcp]\nxyzabc = [{}, {}, {}, {}, {}, {}]\nstd_xyzabc = [0.01, 0.01, 0.01, 0.001, 0.001, 0.001]\n\n\
             [plate_in_base]\nxyzabc = [800.0, 0.0, 0.0, 0.0, 0.0, 0.0]\nstd_xyzabc = [0.01, 0.01, 0.01, 0.001, 0.001, 0.001]\n",
            x[0], x[1], x[2], x[3], x[4], x[5]
        ),
    )
    .unwrap();
    let out_dir = dir.join("out");
    let out = bin()
        .env("SOURCE_DATE_EPOCH", "1700000000")
        .arg("circle-test")
        .arg(&poses)
        .arg("--hand-eye")
        .arg(&hand_eye)
        .arg("--out-dir")
        .arg(&out_dir)
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "inputs",
        "n_poses",
        "hand_eye_xyzabc",
        "magnify",
        "plots_of",
        "camera",
        "tcp",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    assert_eq!(v["n_poses"], used);
    assert_eq!(v["plots_of"], "tcp");
    assert_eq!(v["inputs"][0]["skipped"]["stale"], 1);
    assert_eq!(v["inputs"][0]["skipped"]["too_few_targets"], 24);
    let tcp = &v["tcp"];
    for key in [
        "n_samples",
        "plane",
        "center_mm",
        "radius_mm",
        "std_center_mm",
        "std_radius_mm",
        "direction",
        "coverage_deg",
        "harmonics_upr",
        "g_um",
        "g_filtered_um",
        "nominal",
        "f_um",
        "radial_mm",
        "out_of_plane_mm",
        "mean_orientation_abc_deg",
        "rotation_x_deg",
        "rotation_y_deg",
        "rotation_z_deg",
        "rotation_max_angle_deg",
        "samples",
    ] {
        assert!(tcp.get(key).is_some(), "missing tcp.{key}");
    }
    let injected = cell.error.radial_f_mm() * 1e3;
    let g = tcp["g_filtered_um"].as_f64().unwrap();
    assert!(
        (g - injected).abs() < 5.0,
        "G {g} µm vs injected {injected} µm"
    );
    // No nominal circle given: no F.
    assert_eq!(tcp["f_um"], Value::Null);
    assert_eq!(tcp["nominal"], Value::Null);
    assert!(tcp.get("f_mm").is_none() && tcp.get("f_filtered_mm").is_none());
    // Provenance: tool, date, the pose file and the hand-eye file hashed.
    let p = &v["provenance"];
    assert_eq!(p["date"], "2023-11-14T22:13:20Z");
    assert!(p["tool"].as_str().unwrap().starts_with("photopose "));
    let sha = |path: &std::path::Path| {
        photopose_formats::provenance::sha256_hex(&std::fs::read(path).unwrap())
    };
    assert_eq!(p["inputs"][0]["path"], poses.display().to_string());
    assert_eq!(p["inputs"][0]["sha256"], sha(&poses));
    assert_eq!(p["inputs"][1]["sha256"], sha(&hand_eye));
    let r = tcp["radius_mm"].as_f64().unwrap();
    assert!((r - 149.9).abs() < 0.002, "{r}");
    assert_eq!(tcp["direction"], "ccw");
    // The TCP circle is centred where it was commanded; the camera's 60 mm
    // further along X and 80 mm higher.
    let c = |t: &Value, k: usize| t["center_mm"][k].as_f64().unwrap();
    assert!((c(tcp, 0) + 60.0).abs() < 0.01 && (c(tcp, 2) - 520.0).abs() < 0.01);
    assert!(c(&v["camera"], 0).abs() < 0.01 && (c(&v["camera"], 2) - 600.0).abs() < 0.01);
    for name in [
        "report.txt",
        "report.json",
        "circle.svg",
        "radial.svg",
        "angular.svg",
    ] {
        let p = out_dir.join(name);
        let body = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert!(body.len() > 500, "{name} too short");
        if name.ends_with(".svg") {
            assert!(body.starts_with("<svg") && body.trim_end().ends_with("</svg>"));
            assert!(
                body.contains("<metadata id=\"photopose-provenance\">")
                    && body.contains(&sha(&poses))
            );
        }
    }
    let text = std::fs::read_to_string(out_dir.join("report.txt")).unwrap();
    assert!(text.contains("circular deviation G") && text.contains("of the TCP"));
    assert!(text.contains("radial deviation F   — (no nominal circle given for this path"));
    assert!(text.starts_with("made by photopose ") && text.contains(&sha(&hand_eye)));

    // The commanded circle as the nominal one: F from it, G unchanged.
    let c = cell.path.center_mm;
    let out = bin()
        .env("SOURCE_DATE_EPOCH", "1700000000")
        .arg("circle-test")
        .arg(&poses)
        .arg("--hand-eye")
        .arg(&hand_eye)
        .arg("--out-dir")
        .arg(dir.join("out-nominal"))
        .arg("--nominal-center")
        .arg(format!("{},{},{}", c[0], c[1], c[2]))
        .arg("--nominal-radius")
        .arg(cell.path.radius_mm.to_string())
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let n: Value = serde_json::from_slice(&out.stdout).unwrap();
    let tcp_n = &n["tcp"];
    assert_eq!(tcp_n["g_um"], tcp["g_um"]);
    assert_eq!(tcp_n["nominal"]["radius_mm"], cell.path.radius_mm);
    // The injected pattern about the commanded circle: F spans what G does
    // (within the pose noise), positive and negative.
    let (fmax, fmin) = (
        tcp_n["f_um"]["max"].as_f64().unwrap(),
        tcp_n["f_um"]["min"].as_f64().unwrap(),
    );
    let g = tcp["g_um"].as_f64().unwrap();
    assert!(fmax > 0.0 && fmin < 0.0, "F {fmax} {fmin}");
    assert!(
        ((fmax - fmin) - g).abs() < 0.2 * g,
        "F {fmax}..{fmin} vs G {g}"
    );
    // The nominal circle belongs to the TCP; the camera has none.
    assert_eq!(n["camera"]["f_um"], Value::Null);
    let text = std::fs::read_to_string(dir.join("out-nominal/report.txt")).unwrap();
    assert!(text.contains("radial deviation F   max +"), "{text}");
}

#[test]
fn bad_lines_and_hand_eye_files_are_named() {
    let dir = scratch("circle-test-bad");
    let poses = dir.join("bad.jsonl");
    std::fs::write(&poses, "{\"status\":\"stale\"}\nnot json\n").unwrap();
    let out = bin().arg("circle-test").arg(&poses).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.jsonl:2"), "{err}");

    std::fs::write(&poses, "{\"status\":\"stale\"}\n").unwrap();
    let out = bin().arg("circle-test").arg(&poses).output().unwrap();
    assert!(String::from_utf8_lossy(&out.stderr).contains("no usable pose"));

    let cell = Cell::default();
    write_stream(&cell, &poses);
    let hand_eye = dir.join("he.toml");
    std::fs::write(&hand_eye, "[camera_in_tcp]\nxyz = [1, 2, 3]\n").unwrap();
    let out = bin()
        .arg("circle-test")
        .arg(&poses)
        .arg("--hand-eye")
        .arg(&hand_eye)
        .arg("--out-dir")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("he.toml") && err.contains("xyzabc"), "{err}");
}

#[test]
fn resect_lines_are_read_and_a_sparse_circle_has_no_filtered_g() {
    let dir = scratch("circle-test-resect");
    let cell = Cell::default();
    let samples = cell.samples().unwrap();
    let mut text = String::new();
    for (i, s) in samples.iter().step_by(59).enumerate() {
        let e = photopose_geometry::pose::exterior_from_camera_pose(&s.camera);
        let r = e.rotation;
        let rows = [0, 1, 2].map(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)]]);
        let line = if i == 3 {
            serde_json::json!({"image": format!("f{i}.png"), "ok": false, "error": "too few targets"})
        } else {
            serde_json::json!({
                "image": format!("f{i}.png"), "ok": true,
                "pose": {
                    "position_mm": [e.center.x, e.center.y, e.center.z],
                    "rotation_field_to_camera": rows,
                },
            })
        };
        text.push_str(&format!("{line}\n"));
    }
    let poses = dir.join("resect.jsonl");
    std::fs::write(&poses, text).unwrap();
    let out = bin()
        .arg("circle-test")
        .arg(&poses)
        .arg("--out-dir")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    // 40 lines, one failed; 39 poses are too few for a 15-UPR filter.
    assert!(
        stdout.contains("40 lines, 39 poses used, skipped: 1 failed"),
        "{stdout}"
    );
    assert!(stdout.contains("G filtered           —"), "{stdout}");
    let v: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/report.json")).unwrap())
            .unwrap();
    assert_eq!(v["tcp"], Value::Null);
    assert_eq!(v["plots_of"], "camera");
    assert_eq!(v["camera"]["g_filtered_um"], Value::Null);
    // The camera's raw G over 39 noise-free poses: the injected pattern as
    // the camera sees it (the wobble's lever arm adds micrometres).
    let g = v["camera"]["g_um"].as_f64().unwrap();
    assert!((g - cell.error.radial_f_mm() * 1e3).abs() < 30.0, "{g}");
}

#[test]
fn a_recording_s_pose_messages_are_read_as_the_stream_is() {
    let dir = scratch("circle-test-recording");
    let cell = Cell::default();
    let poses = dir.join("poses.jsonl");
    write_stream(&cell, &poses);
    // The same lines as the recording's `/pose/message` channel.
    let recording = dir.join("poses.mcap");
    let mut rec = photopose_record::Recorder::create(&recording).unwrap();
    let text = std::fs::read_to_string(&poses).unwrap();
    for (k, line) in text.lines().enumerate() {
        rec.write_pose(&photopose_record::PoseRecord {
            seq: k as u64,
            camera_time_ns: 0,
            host_time_ns: k as u64,
            pose: None,
            json: line.as_bytes(),
        })
        .unwrap();
    }
    rec.finish().unwrap();
    let report = |input: &std::path::Path, out: &str| -> Value {
        let out = bin()
            .arg("circle-test")
            .arg(input)
            .arg("--out-dir")
            .arg(dir.join(out))
            .arg("--json")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let mut v: Value = serde_json::from_slice(&out.stdout).unwrap();
        v["inputs"][0]["path"] = Value::Null;
        // The provenance names each input file with its hash: a recording
        // and a pose-line file differ there, not in the analysis.
        v["inputs"][0]["sha256"] = Value::Null;
        v["provenance"] = Value::Null;
        v
    };
    assert_eq!(report(&recording, "rec"), report(&poses, "lines"));
    std::fs::remove_dir_all(&dir).unwrap();
}
