//! End-to-end tests of `photopose calibrate hand-eye`: the real binary on
//! generated station files — camera pose columns with seeded noise, a
//! gross error, degenerate motion, a bad file — and a station set whose
//! first stations are frames rendered in-process (the image path: detect,
//! identify, resect, then the fit).

mod common;

use common::{bin, scratch};
use nalgebra::{Isometry3, Vector3};
use photopose_formats::hand_eye::load_hand_eye;
use photopose_geometry::pose::{
    camera_pose, isometry_from_xyzabc, perturbed, wrap_deg, xyzabc_from_isometry,
};
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::Exterior;
use photopose_handeye::stations::{CameraSource, StationRow};
use photopose_handeye::STATIONS_HEADER;
use serde_json::Value;
use std::path::Path;
use std::process::Output;

const CAM_STD_MM: f64 = 0.04;
const CAM_STD_DEG: f64 = 0.004;
const X_TRUE: [f64; 6] = [35.0, -80.0, 160.0, 91.0, 2.5, 178.5];
const Z_TRUE: [f64; 6] = [1100.0, 200.0, 15.0, 25.0, 0.8, -0.6];

fn truth() -> (Isometry3<f64>, Isometry3<f64>) {
    (isometry_from_xyzabc(X_TRUE), isometry_from_xyzabc(Z_TRUE))
}

/// A camera looking at the plate from about 600 mm, tilted up to 25°,
/// rolled up to ±90°.
fn view(rng: &mut SplitMix64) -> Exterior {
    let target = Vector3::new((rng.unit() - 0.5) * 60.0, (rng.unit() - 0.5) * 40.0, 0.0);
    let tilt = (rng.unit() * 25.0f64).to_radians();
    let azimuth = rng.unit() * std::f64::consts::TAU;
    let dir = Vector3::new(
        tilt.sin() * azimuth.cos(),
        tilt.sin() * azimuth.sin(),
        tilt.cos(),
    );
    let roll = ((rng.unit() * 2.0 - 1.0) * 90.0f64).to_radians();
    Exterior::look_at(
        target + dir * (580.0 + rng.unit() * 60.0),
        target,
        Vector3::new(roll.sin(), roll.cos(), 0.0),
    )
    .unwrap()
}

fn noisy(t: &Isometry3<f64>, rng: &mut SplitMix64, mm: f64, deg: f64) -> Isometry3<f64> {
    let mut n = || rng.normal();
    let dt = Vector3::new(n(), n(), n()) * mm;
    let dw = Vector3::new(n(), n(), n()) * deg.to_radians();
    perturbed(t, &dt, &dw)
}

/// The robot's (noisy) TCP pose for a camera at `e`.
fn robot_pose(e: &Exterior, rng: &mut SplitMix64) -> [f64; 6] {
    let (x, z) = truth();
    let b = camera_pose(e);
    xyzabc_from_isometry(&noisy(&(z * b * x.inverse()), rng, 0.02, 0.005))
}

/// A station row with the camera pose columns (noisy, with their stds).
fn pose_row(name: &str, e: &Exterior, rng: &mut SplitMix64) -> StationRow {
    let robot = robot_pose(e, rng);
    let b = camera_pose(e);
    StationRow {
        line: 0,
        name: name.into(),
        robot_xyzabc: robot,
        camera: CameraSource::Pose {
            xyzabc: xyzabc_from_isometry(&noisy(&b, rng, CAM_STD_MM, CAM_STD_DEG)),
            std: Some([
                CAM_STD_MM,
                CAM_STD_MM,
                CAM_STD_MM,
                CAM_STD_DEG,
                CAM_STD_DEG,
                CAM_STD_DEG,
            ]),
        },
    }
}

fn write_rows(path: &Path, rows: &[StationRow]) {
    let mut text = format!("{STATIONS_HEADER}\n");
    for r in rows {
        text += &r.csv_line().unwrap();
        text.push('\n');
    }
    std::fs::write(path, text).unwrap();
}

fn calibrate(stations: &Path, out: &Path, extra: &[&str]) -> Output {
    bin()
        .args(["calibrate", "hand-eye", "--stations"])
        .arg(stations)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

fn json(out: &Output) -> Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The written file's transforms lie within `k` of their σ of the truth.
fn check_recovered(file: &Path, k: f64) {
    let he = load_hand_eye(file).unwrap();
    for (label, t, want) in [
        ("camera_in_tcp", he.camera_in_tcp, X_TRUE),
        ("plate_in_base", he.plate_in_base, Z_TRUE),
    ] {
        for (i, w) in want.iter().enumerate() {
            let mut d = t.xyzabc[i] - w;
            if i >= 3 {
                d = wrap_deg(d);
            }
            assert!(
                d.abs() <= k * t.std_xyzabc[i],
                "{label}[{i}]: {} vs {w} (σ {})",
                t.xyzabc[i],
                t.std_xyzabc[i]
            );
            assert!(t.std_xyzabc[i] > 0.0 && t.std_xyzabc[i] < 0.5);
        }
    }
}

#[test]
fn pose_columns_give_both_transforms_within_their_sigma() {
    let dir = scratch("hand-eye-poses");
    let mut rng = SplitMix64::new(11);
    let rows: Vec<_> = (0..12)
        .map(|k| pose_row(&format!("s{:02}", k + 1), &view(&mut rng), &mut rng))
        .collect();
    let st = dir.join("stations.csv");
    write_rows(&st, &rows);
    let out = dir.join("handeye.toml");
    let v = json(&calibrate(&st, &out, &["--json"]));
    for key in [
        "camera_in_tcp",
        "plate_in_base",
        "sigma0",
        "redundancy",
        "stations",
        "used",
        "rejected",
        "rms_mm",
        "rms_deg",
        "residuals",
    ] {
        assert!(v.get(key).is_some(), "missing {key} in {v}");
    }
    assert_eq!(v["stations"], 12);
    assert_eq!(v["used"], 12);
    assert_eq!(v["redundancy"], 60);
    assert_eq!(v["rejected"].as_array().unwrap().len(), 0);
    assert_eq!(v["residuals"].as_array().unwrap().len(), 12);
    assert_eq!(v["residuals"][3]["station"], "s04");
    let sigma0 = v["sigma0"].as_f64().unwrap();
    assert!((0.6..1.5).contains(&sigma0), "σ0 {sigma0}");
    check_recovered(&out, 3.0);
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.contains("[camera_in_tcp]") && text.contains("stations = 12"));
    // Provenance: tool, UTC date, the station file with its SHA-256.
    let sha = photopose_formats::provenance::sha256_hex(&std::fs::read(&st).unwrap());
    let p = &v["provenance"];
    assert!(p["tool"].as_str().unwrap().starts_with("photopose "));
    assert!(photopose_formats::provenance::parse_rfc3339(p["date"].as_str().unwrap()).is_ok());
    assert_eq!(p["inputs"][0]["path"], st.display().to_string());
    assert_eq!(p["inputs"][0]["sha256"], sha);

    // The text report names the stations and the result.
    let o = calibrate(&st, &dir.join("again.toml"), &[]);
    assert!(o.status.success());
    let report = String::from_utf8_lossy(&o.stdout);
    assert!(
        report.starts_with("made by photopose ") && report.contains(&format!("sha256 {sha}")),
        "{report}"
    );
    assert!(report.contains("rejected stations: none"), "{report}");
    assert!(
        report.contains("s12") && report.contains("camera in TCP"),
        "{report}"
    );

    // Without the cam_std_* columns the command's a-priori values are used:
    // the same noise against a larger a-priori σ gives a smaller σ0.
    let no_std: Vec<_> = rows
        .iter()
        .map(|r| {
            let mut r = r.clone();
            if let CameraSource::Pose { std, .. } = &mut r.camera {
                *std = None;
            }
            r
        })
        .collect();
    let st2 = dir.join("no-std.csv");
    write_rows(&st2, &no_std);
    let v2 = json(&calibrate(
        &st2,
        &dir.join("no-std.toml"),
        &[
            "--json",
            "--camera-std-mm",
            "0.08",
            "--camera-std-deg",
            "0.008",
        ],
    ));
    let sigma0_2 = v2["sigma0"].as_f64().unwrap();
    assert!(sigma0_2 < 0.8 * sigma0, "σ0 {sigma0_2} vs {sigma0}");
    check_recovered(&dir.join("no-std.toml"), 3.0);
}

#[test]
fn a_station_with_a_wrong_robot_pose_is_rejected_by_name() {
    let dir = scratch("hand-eye-outlier");
    let mut rng = SplitMix64::new(12);
    let mut rows: Vec<_> = (0..12)
        .map(|k| pose_row(&format!("p{}", k + 1), &view(&mut rng), &mut rng))
        .collect();
    rows[6].robot_xyzabc[1] += 0.8; // 0.8 mm off in Y
    let st = dir.join("stations.csv");
    write_rows(&st, &rows);
    let out = dir.join("he.toml");
    let v = json(&calibrate(&st, &out, &["--json"]));
    assert_eq!(v["rejected"], serde_json::json!(["p7"]));
    assert_eq!(v["used"], 11);
    assert_eq!(v["residuals"][6]["used"], false);
    check_recovered(&out, 4.0);
    let o = calibrate(&st, &out, &[]);
    let report = String::from_utf8_lossy(&o.stdout);
    assert!(report.contains("rejected stations: p7"), "{report}");
    assert!(report.contains("REJECTED"), "{report}");
}

#[test]
fn degenerate_motion_and_bad_files_are_clear_errors() {
    let dir = scratch("hand-eye-bad");
    let mut rng = SplitMix64::new(13);
    // Only rolls about the optical axis of a camera looking straight down.
    let rows: Vec<_> = (0..10)
        .map(|k| {
            let roll = (k as f64 * 15.0 - 70.0).to_radians();
            let eye = Vector3::new(k as f64 * 8.0, -(k as f64) * 5.0, 600.0);
            let e = Exterior::look_at(
                eye,
                eye - Vector3::z() * 600.0,
                Vector3::new(roll.sin(), roll.cos(), 0.0),
            )
            .unwrap();
            pose_row(&format!("d{k}"), &e, &mut rng)
        })
        .collect();
    let st = dir.join("flat.csv");
    write_rows(&st, &rows);
    let out = dir.join("he.toml");
    let o = calibrate(&st, &out, &[]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("degenerate motion") && err.contains("parallel axes"),
        "{err}"
    );
    assert!(!out.exists(), "a file was written for a failed calibration");

    let bad = dir.join("bad.csv");
    std::fs::write(
        &bad,
        "station,robot_x,robot_y,robot_z,robot_a,robot_b,robot_c,image\n\
         s1,1,2,3,4,5,6,a.pgm\n\
         s2,1,2,3,4,5,six,b.pgm\n",
    )
    .unwrap();
    let o = calibrate(&bad, &out, &[]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("bad.csv:3: column `robot_c`: `six`"), "{err}");

    // A station naming a frame that is not there: the station and file named.
    let missing = dir.join("missing.csv");
    std::fs::write(
        &missing,
        "station,robot_x,robot_y,robot_z,robot_a,robot_b,robot_c,image\n\
         s1,1,2,3,4,5,6,nowhere.pgm\n",
    )
    .unwrap();
    let o = calibrate(&missing, &out, &[]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("missing.csv:2: station s1") && err.contains("nowhere.pgm"),
        "{err}"
    );
}

#[test]
fn stations_with_rendered_frames_are_measured_and_fitted() {
    use photopose_render::{RenderOptions, Renderer};
    let dir = scratch("hand-eye-frames");
    let camera = photopose_formats::default_camera();
    let field = photopose_field::Field::parse_csv(
        &std::fs::read_to_string(common::root().join("config/plate.csv")).unwrap(),
        "plate.csv",
    )
    .unwrap();
    let mut renderer = Renderer::new(camera, &field, RenderOptions::default()).unwrap();
    let mut image = renderer.new_image();
    let mut rng = SplitMix64::new(14);
    let mut rows = Vec::new();
    for k in 0..12 {
        let e = view(&mut rng);
        let name = format!("f{:02}", k + 1);
        if k < 4 {
            // The first four stations are frames: the robot pose is known,
            // the camera pose is measured from the image.
            renderer.render(&e, &mut image).unwrap();
            let file = format!("{name}.pgm");
            photopose_formats::save_image(&dir.join(&file), &image).unwrap();
            rows.push(StationRow {
                line: 0,
                name,
                robot_xyzabc: robot_pose(&e, &mut rng),
                camera: CameraSource::Image(file),
            });
        } else {
            rows.push(pose_row(&name, &e, &mut rng));
        }
    }
    let st = dir.join("stations.csv");
    write_rows(&st, &rows);
    let out = dir.join("he.toml");
    let v = json(&calibrate(&st, &out, &["--json"]));
    assert_eq!(v["stations"], 12);
    assert_eq!(v["rejected"].as_array().unwrap().len(), 0, "{v}");
    // The frames' stations fit like the others.
    for r in &v["residuals"].as_array().unwrap()[..4] {
        assert!(r["norm_mm"].as_f64().unwrap() < 0.3, "{r}");
    }
    check_recovered(&out, 3.5);
}
