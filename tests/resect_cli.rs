//! End-to-end tests of `photopose resect` and `photopose simulate`: the real
//! binary on real files, the output contract (keys), and bad inputs that
//! must give `ok: false` with a reason naming the file, line or key while the
//! batch goes on.

mod common;

use common::{bin, fixture, scratch};

use serde_json::Value;
use std::path::Path;

fn lines(out: &std::process::Output) -> Vec<Value> {
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON: {l}: {e}")))
        .collect()
}

#[test]
fn resect_recovers_the_simulated_pose_with_the_fixed_keys() {
    let obs = fixture("observations/oblique-0.1px.csv");
    let out = bin()
        .args(["resect", "--observations"])
        .arg(&obs)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = &lines(&out)[0];
    for key in [
        "image",
        "ok",
        "frame_id",
        "pose",
        "rms_px",
        "n_rejected",
        "rejected_ids",
        "camera_xyzabc_mm_deg",
    ] {
        assert!(v.get(key).is_some(), "missing key {key} in {v}");
    }
    // The pose object is the pose message's, key for key.
    for key in [
        "position_mm",
        "quaternion_xyzw",
        "rotation_field_to_camera",
        "covariance",
        "covariance_order",
        "std_position_mm",
        "std_rotation_deg",
        "sigma0_px",
        "n_targets",
    ] {
        assert!(
            v["pose"].get(key).is_some(),
            "missing key pose.{key} in {v}"
        );
    }
    common::check_pose_object(&v["pose"]);
    assert_eq!(v["ok"], true);
    assert_eq!(v["image"], obs.display().to_string());
    // The fixture was simulated at X,Y,Z = 150,-300,900 (see fixtures/README.md).
    let c = numbers(&v["pose"]["position_mm"]);
    let s = numbers(&v["pose"]["std_position_mm"]);
    for (k, want) in [150.0, -300.0, 900.0].iter().enumerate() {
        assert!(
            (c[k] - want).abs() < 4.0 * s[k],
            "axis {k}: {} vs {want} (σ {})",
            c[k],
            s[k]
        );
    }
    let sigma0 = v["pose"]["sigma0_px"].as_f64().unwrap();
    assert!(
        (0.08..0.12).contains(&sigma0),
        "σ0 {sigma0} px for 0.1 px noise"
    );
    let r = v["pose"]["rotation_field_to_camera"].as_array().unwrap();
    assert_eq!(r.len(), 3);
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// The ids of the good fixture at pseudo-random image positions.
fn garbage(good: &str) -> String {
    let mut out = String::from("id,col,row\n");
    let mut state = 12345u64;
    for line in good.lines().skip(1).step_by(5) {
        let id = line.split(',').next().unwrap();
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let col = (state >> 33) % 1300;
        let row = (state >> 13) % 1030;
        out.push_str(&format!("{id},{col}.5,{row}.25\n"));
    }
    out
}

#[test]
fn bad_inputs_give_reasons_and_the_batch_goes_on() {
    let dir = scratch("bad");
    let good = fixture("observations/oblique-0.1px.csv");
    let good_text = std::fs::read_to_string(&good).unwrap();
    let mut first_rows = good_text.lines().skip(1);
    let row = |line: Option<&str>| line.unwrap().to_string();
    let (r1, r2, r3) = (
        row(first_rows.next()),
        row(first_rows.next()),
        row(first_rows.next()),
    );
    let cases: Vec<(&str, String, &str)> = vec![
        ("empty.csv", String::new(), "empty"),
        (
            "three.csv",
            format!("id,col,row\n{r1}\n{r2}\n{r3}\n"),
            "too few usable points: 3",
        ),
        (
            "nan.csv",
            format!("id,col,row\n{r1}\n1001,NaN,5\n"),
            "nan.csv:3: col `NaN` is not finite",
        ),
        (
            "text.csv",
            format!("id,col,row\n{r1}\n1001,12.5,abc\n"),
            "text.csv:3: row `abc` is not a number",
        ),
        (
            "dup.csv",
            format!("id,col,row\n{r1}\n{r1}\n"),
            "dup.csv:3: duplicate id",
        ),
        (
            "unknown.csv",
            format!("id,col,row\n{r1}\n999999,1,2\n"),
            "unknown.csv:3: id 999999 is not in the test field",
        ),
        // Four targets along one row of the plate.
        (
            "collinear.csv",
            "id,col,row\n1001,100,100\n1002,200,100\n1003,300,100\n1004,400,100\n".into(),
            "collinear",
        ),
        // Random positions: no pose explains them.
        ("garbage.csv", garbage(&good_text), "no consistent pose"),
    ];
    let mut args = vec!["resect".to_string(), "--observations".to_string()];
    let mut want = Vec::new();
    for (name, text, reason) in &cases {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        args.push(p.display().to_string());
        want.push((p.display().to_string(), *reason));
        // A good input after every bad one: the batch must go on.
        args.push(good.display().to_string());
    }
    args.push(dir.join("missing.csv").display().to_string());
    let out = bin().args(&args).output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(1),
        "a failed input makes the exit status non-zero"
    );
    let v = lines(&out);
    assert_eq!(v.len(), 2 * cases.len() + 1, "one line per input");
    for (k, (path, reason)) in want.iter().enumerate() {
        let bad = &v[2 * k];
        assert_eq!(bad["image"], *path);
        assert_eq!(bad["ok"], false, "{bad}");
        let err = bad["error"].as_str().unwrap();
        assert!(
            err.contains(reason),
            "{path}: error {err:?} lacks {reason:?}"
        );
        assert!(
            err.contains(Path::new(path).file_name().unwrap().to_str().unwrap()),
            "error names the file: {err}"
        );
        assert_eq!(
            v[2 * k + 1]["ok"],
            true,
            "the good input after {path} failed: {}",
            v[2 * k + 1]
        );
    }
    let last = v.last().unwrap();
    assert_eq!(last["ok"], false);
    assert!(last["error"]
        .as_str()
        .unwrap()
        .contains("missing.csv: cannot read"));
}

#[test]
fn a_bad_camera_file_is_named_with_its_key() {
    let dir = scratch("badcam");
    let cam = dir.join("cam.toml");
    std::fs::write(
        &cam,
        "[sensor]\nwidth = 1300\nheight = 1030\npixel_size = -0.0067\n[interior]\nc = 12.0\nx0 = 0.0\ny0 = 0.0\n",
    )
    .unwrap();
    let out = bin()
        .args(["resect", "--camera"])
        .arg(&cam)
        .arg("--observations")
        .arg(fixture("observations/oblique-0.1px.csv"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let v = &lines(&out)[0];
    assert_eq!(v["ok"], false);
    let err = v["error"].as_str().unwrap();
    assert!(
        err.contains("cam.toml") && err.contains("sensor.pixel_size"),
        "{err}"
    );
}

#[test]
fn a_mirrored_image_is_refused_as_seen_from_behind_the_plate() {
    let dir = scratch("mirror");
    let good = std::fs::read_to_string(fixture("observations/oblique-0.1px.csv")).unwrap();
    let mut text = String::from("id,col,row\n");
    for line in good.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let col: f64 = f[1].parse().unwrap();
        text.push_str(&format!("{},{},{}\n", f[0], 1299.0 - col, f[2]));
    }
    let p = dir.join("mirrored.csv");
    std::fs::write(&p, text).unwrap();
    let out = bin()
        .args(["resect", "--observations"])
        .arg(&p)
        .output()
        .unwrap();
    let v = &lines(&out)[0];
    assert_eq!(v["ok"], false, "{v}");
    assert!(v["error"].as_str().unwrap().contains("behind"), "{v}");
}

#[test]
fn simulate_prints_the_table_and_refuses_a_plate_behind_the_camera() {
    let out = bin()
        .args(["simulate", "--json", "--sigma-px", "0.1"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v = &lines(&out)[0];
    assert_eq!(v["n_points"], 230);
    let s = v["predicted_std_center"].as_array().unwrap();
    assert!(s
        .iter()
        .all(|x| x.as_f64().unwrap() > 0.0 && x.as_f64().unwrap() < 1.0));
    // Camera below the plate, looking down: every target is behind it.
    let out = bin()
        .args(["simulate", "--pose", "0,0,-1000,0,0,0"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("behind the camera"), "{err}");
}

#[test]
fn simulated_observations_round_trip_through_resect() {
    let dir = scratch("sim");
    let obs = dir.join("obs.csv");
    let out = bin()
        .args([
            "simulate",
            "--pose",
            "-50,40,800,30,5,-10",
            "--sigma-px",
            "0.05",
            "--seed",
            "3",
            "--observations-out",
        ])
        .arg(&obs)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = bin()
        .args(["resect", "--observations"])
        .arg(&obs)
        .output()
        .unwrap();
    let v = &lines(&out)[0];
    assert_eq!(v["ok"], true, "{v}");
    let p = numbers(&v["camera_xyzabc_mm_deg"]);
    let want = [-50.0, 40.0, 800.0, 30.0, 5.0, -10.0];
    for k in 0..3 {
        assert!((p[k] - want[k]).abs() < 0.5, "{p:?}");
    }
    for k in 3..6 {
        assert!((p[k] - want[k]).abs() < 0.05, "{p:?}");
    }
}

/// Renders the default plate from `pose` into `path` (PGM or PNG by extension).
fn render_to(path: &Path, pose: [f64; 6], seed: u64) {
    let camera = photopose_formats::default_camera();
    let field = photopose_field::design::default_plate();
    let options = photopose_render::RenderOptions {
        seed,
        ..Default::default()
    };
    let mut r = photopose_render::Renderer::new(camera, &field, options).unwrap();
    let mut img = r.new_image();
    r.render(
        &photopose_geometry::Exterior::from_kuka_pose(pose),
        &mut img,
    )
    .unwrap();
    photopose_formats::save_image(path, &img).unwrap();
}

#[test]
fn resect_takes_images_and_says_why_one_fails() {
    let dir = scratch("images");
    let good = dir.join("good.pgm");
    let png = dir.join("good.png");
    render_to(&good, [15.0, -10.0, 950.0, 20.0, 4.0, -3.0], 1);
    render_to(&png, [-40.0, 30.0, 1100.0, -60.0, -8.0, 5.0], 2);
    let black = dir.join("black.pgm");
    std::fs::write(
        &black,
        [b"P5\n1300 1030\n255\n".as_slice(), &vec![0u8; 1300 * 1030]].concat(),
    )
    .unwrap();
    let small = dir.join("small.pgm");
    std::fs::write(
        &small,
        [b"P5\n64 48\n255\n".as_slice(), &vec![0u8; 64 * 48]].concat(),
    )
    .unwrap();
    let out = bin()
        .arg("resect")
        .args([&good, &black, &small, &png])
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = lines(&out);
    assert_eq!(v.len(), 4);
    assert_eq!(v[0]["ok"], true, "{}", v[0]);
    let c = numbers(&v[0]["pose"]["position_mm"]);
    assert!(
        (c[0] - 15.0).abs() < 0.1 && (c[1] + 10.0).abs() < 0.1 && (c[2] - 950.0).abs() < 0.1,
        "{c:?}"
    );
    assert!(v[0]["pose"]["n_targets"].as_u64().unwrap() > 200);
    assert_eq!(v[1]["ok"], false);
    assert!(
        v[1]["error"].as_str().unwrap().contains("black.pgm"),
        "{}",
        v[1]
    );
    assert_eq!(v[2]["ok"], false);
    let e = v[2]["error"].as_str().unwrap();
    assert!(e.contains("64×48") && e.contains("1300×1030"), "{e}");
    assert_eq!(v[3]["ok"], true, "{}", v[3]);
}

#[test]
fn detect_lists_every_target_with_true_ids() {
    let dir = scratch("detect");
    let frame = dir.join("frame.pgm");
    let out = bin()
        .args(["render", "--pose", "10,-20,1000,30,5,-5", "--out"])
        .arg(&frame)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let truth: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("frame.truth.json")).unwrap())
            .unwrap();
    let bad = dir.join("truncated.pgm");
    std::fs::write(&bad, b"P5\n1300 1030\n255\n\x01\x02").unwrap();
    let out = bin()
        .arg("detect")
        .arg(&frame)
        .arg(&bad)
        .arg(&frame)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let v = lines(&out);
    assert_eq!(v.len(), 3);
    assert_eq!(v[1]["ok"], false);
    assert!(
        v[1]["error"].as_str().unwrap().contains("truncated.pgm"),
        "{}",
        v[1]
    );
    assert_eq!(v[0]["targets"], v[2]["targets"], "same image, same answer");
    let targets = v[0]["targets"].as_array().unwrap();
    let truth_targets = truth["targets"].as_array().unwrap();
    let visible = truth_targets
        .iter()
        .filter(|t| t["visible"] == true)
        .count();
    let mut identified = 0;
    for t in targets {
        for key in ["id", "kind", "col", "row"] {
            assert!(t.get(key).is_some(), "{key} in {t}");
        }
        let Some(id) = t["id"].as_u64() else { continue };
        let tr = truth_targets
            .iter()
            .find(|x| x["id"].as_u64() == Some(id))
            .unwrap();
        let d = (t["col"].as_f64().unwrap() - tr["col"].as_f64().unwrap())
            .hypot(t["row"].as_f64().unwrap() - tr["row"].as_f64().unwrap());
        assert!(d < 0.1, "id {id} is {d} px from its truth: a wrong id");
        assert_eq!(t["kind"], tr["kind"]);
        identified += 1;
    }
    assert!(
        identified as f64 >= 0.95 * visible as f64,
        "{identified} of {visible} visible targets identified"
    );
}

/// A rendered frame resected both ways — by `photopose resect` and by the
/// library in this process — gives the same pose and exactly the
/// adjustment's covariance (1e-12), symmetric and positive definite; the
/// quaternion is that of `Rᵀ` (the camera's attitude in the field).
#[test]
fn resect_reports_the_adjustments_covariance_and_the_cameras_quaternion() {
    let dir = scratch("resect-covariance");
    let image = dir.join("frame.pgm");
    let kuka = [25.0, -15.0, 1000.0, 30.0, 6.0, -4.0];
    render_to(&image, kuka, 5);
    let out = bin().arg("resect").arg(&image).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = &lines(&out)[0];
    let pose = &v["pose"];
    common::check_pose_object(pose);
    let camera = photopose_formats::default_camera();
    let field = photopose_field::design::default_plate();
    let mut locator =
        photopose_locate::Locator::new(camera, field, photopose_locate::LocateOptions::default())
            .unwrap();
    let frame = photopose_formats::load_image(&image).unwrap();
    let located = locator.locate(frame.view()).unwrap();
    let report = *located.pose.expect("a pose of the rendered frame");
    // Equal to 1e-12 of the scale of each element, √(c_ii·c_jj) (the
    // adjustment's own pairs c_ij, c_ji differ by rounding only).
    let got = common::covariance(pose);
    let c = &report.covariance;
    for i in 0..6 {
        for j in 0..6 {
            let scale = (c[(i, i)] * c[(j, j)]).sqrt();
            assert!(
                (got[(i, j)] - c[(i, j)]).abs() <= 1e-12 * scale,
                "covariance ({i}, {j}): {} vs {}",
                got[(i, j)],
                c[(i, j)]
            );
        }
    }
    assert_eq!(
        pose["n_targets"].as_u64().unwrap() as usize,
        report.n_points
    );
    // (position, quaternion) is the camera's pose: Rᵀ maps camera axes
    // into the field, so the camera's −z (its viewing direction) points at
    // the plate (−Z for a camera above it).
    let q = numbers(&pose["quaternion_xyzw"]);
    let uq = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        q[3], q[0], q[1], q[2],
    ));
    let rt = report.exterior.rotation.transpose();
    let diff = (uq.to_rotation_matrix().into_inner() - rt).abs().max();
    assert!(diff < 1e-12, "quaternion is not of Rᵀ: {diff}");
    let view = uq * nalgebra::Vector3::new(0.0, 0.0, -1.0);
    assert!(view.z < -0.9, "viewing direction {view}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The batch of image files (on every core, buffers reused) gives the
/// bytes that one image at a time gives, in input order, for `resect` and
/// `detect`, with failures in between.
#[test]
fn a_batch_of_images_gives_the_lines_of_one_image_at_a_time() {
    let dir = scratch("batch");
    let a = dir.join("a.pgm");
    let b = dir.join("b.pgm");
    let c = dir.join("c.png");
    render_to(&a, [15.0, -10.0, 950.0, 20.0, 4.0, -3.0], 1);
    render_to(&b, [-40.0, 30.0, 1100.0, -60.0, -8.0, 5.0], 2);
    render_to(&c, [5.0, 20.0, 1000.0, 10.0, -4.0, 2.0], 3);
    let black = dir.join("black.pgm");
    std::fs::write(
        &black,
        [b"P5\n1300 1030\n255\n".as_slice(), &vec![0u8; 1300 * 1030]].concat(),
    )
    .unwrap();
    let small = dir.join("small.pgm");
    std::fs::write(
        &small,
        [b"P5\n64 48\n255\n".as_slice(), &vec![0u8; 64 * 48]].concat(),
    )
    .unwrap();
    let missing = dir.join("missing.pgm");
    let inputs = [&a, &b, &black, &a, &c, &small, &b, &missing, &a, &c, &b, &a];
    for command in ["resect", "detect"] {
        let batch = bin().arg(command).args(inputs).output().unwrap();
        assert_eq!(batch.status.code(), Some(1), "{command}");
        let mut single = Vec::new();
        for input in inputs {
            let one = bin().arg(command).arg(input).output().unwrap();
            single.extend_from_slice(&one.stdout);
        }
        assert_eq!(
            String::from_utf8_lossy(&batch.stdout),
            String::from_utf8_lossy(&single),
            "{command}"
        );
        assert_eq!(lines(&batch).len(), inputs.len());
    }
}
