//! End-to-end tests of `photopose render`, `photopose field svg` and
//! `photopose field new`, driving the real binary.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A fresh directory under the system temp dir, unique per test.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "photopose-render-cli-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn photopose(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_photopose"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn render_writes_an_image_of_the_camera_size_and_its_truth() {
    let dir = temp_dir("render");
    let frame = dir.join("frame.pgm");
    let out = photopose(&[
        "render",
        "--pose",
        "10,-20,1000,5,-3,2",
        "--out",
        p(&frame),
        "--seed",
        "7",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["ok"], true);
    let visible = summary["visible"].as_u64().unwrap();
    assert!(visible > 100, "{summary}");

    let img = photopose_formats::load_image(&frame).unwrap();
    assert_eq!(
        (img.width(), img.height(), img.max_value()),
        (1300, 1030, 255)
    );

    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("frame.truth.json")).unwrap())
            .unwrap();
    for key in [
        "pose_xyzabc",
        "center",
        "rotation",
        "camera",
        "targets",
        "options",
    ] {
        assert!(truth.get(key).is_some(), "truth lacks {key}");
    }
    assert_eq!(truth["pose_xyzabc"][2], 1000.0);
    assert_eq!(truth["rotation"].as_array().unwrap().len(), 3);
    let targets = truth["targets"].as_array().unwrap();
    assert_eq!(targets.len(), 230);
    for t in targets {
        for key in ["id", "kind", "col", "row", "visible"] {
            assert!(t.get(key).is_some(), "target lacks {key}: {t}");
        }
    }
    let n_visible = targets.iter().filter(|t| t["visible"] == true).count();
    assert_eq!(n_visible as u64, visible);
    // A visible target's dot is bright in the image.
    let t = targets
        .iter()
        .find(|t| t["visible"] == true && t["kind"] == "uncoded")
        .unwrap();
    let (c, r) = (t["col"].as_f64().unwrap(), t["row"].as_f64().unwrap());
    assert!(img.get(c.round() as u32, r.round() as u32) > 100);

    // Same seed, same bytes; 16-bit PNG with an explicit truth path.
    let again = dir.join("again.pgm");
    let out = photopose(&[
        "render",
        "--pose",
        "10,-20,1000,5,-3,2",
        "--out",
        p(&again),
        "--seed",
        "7",
    ]);
    assert!(out.status.success());
    assert_eq!(
        std::fs::read(&frame).unwrap(),
        std::fs::read(&again).unwrap()
    );
    let png = dir.join("frame16.png");
    let truth_path = dir.join("t.json");
    let out = photopose(&[
        "render",
        "--pose=-30,0,900,0,0,0",
        "--out",
        p(&png),
        "--bit-depth",
        "16",
        "--truth",
        p(&truth_path),
        "--noise-dn",
        "0",
        "--blur-px",
        "0",
        "--supersample",
        "2",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let img = photopose_formats::load_image(&png).unwrap();
    assert_eq!((img.width(), img.max_value()), (1300, 65535));
    assert!(truth_path.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_pose_and_bad_output_are_clear_errors() {
    let dir = temp_dir("bad");
    let frame = dir.join("f.pgm");
    for (pose, want) in [
        ("0,0,1000,0,0", "expected six comma-separated numbers"),
        ("0,0,1000,0,zero,0", "B = `zero` is not a finite number"),
        ("0,0,inf,0,0,0", "Z = `inf` is not a finite number"),
    ] {
        let out = photopose(&["render", "--pose", pose, "--out", p(&frame)]);
        assert!(!out.status.success(), "{pose} accepted");
        let err = text(&out.stderr);
        assert!(err.contains(want), "{pose}: {err}");
    }
    assert!(!frame.exists());
    let out = photopose(&[
        "render",
        "--pose",
        "0,0,1000,0,0,0",
        "--out",
        p(&dir.join("f.jpg")),
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("use .pgm or .png"),
        "{}",
        text(&out.stderr)
    );
    let out = photopose(&[
        "render",
        "--pose",
        "0,0,1000,0,0,0",
        "--out",
        p(&frame),
        "--bit-depth",
        "12",
    ]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("--bit-depth 12"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn field_svg_draws_the_plate_at_one_to_one() {
    let dir = temp_dir("svg");
    let svg = dir.join("plate.svg");
    let out = photopose(&["field", "svg", "--out", p(&svg)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let s = std::fs::read_to_string(&svg).unwrap();
    assert!(s.starts_with("<?xml") && s.trim_end().ends_with("</svg>"));
    // 544 × 384 mm between the outer centres; 5 mm surround (uncoded) left
    // and right, 12 mm quiet zones (coded) top and bottom, the bottom row's
    // labels (3.9 mm), 10 mm border: a 574 × 431.9 mm plate, in a white
    // margin of 15 mm and a 40 mm strip below with the annotations.
    assert!(s.contains(r#"width="604mm" height="486.9mm" viewBox="0 0 604 486.9""#));
    assert!(s.contains(r##"<rect x="0" y="0" width="574" height="431.9" fill="#000"/>"##));
    assert_eq!(s.matches("<circle").count(), 230);
    assert!(s.matches("<path").count() >= 30);
    // Scale-check bar, origin, axes, the field's name and checksum.
    let sha = photopose_formats::provenance::sha256_hex(include_bytes!("../config/plate.csv"));
    assert!(s.contains("measure: must be 100.0 mm"));
    assert!(s.contains("class=\"origin\"") && s.contains(">X</text>") && s.contains(">Y</text>"));
    assert!(s.contains("field: built-in plate") && s.contains(&sha[..12]));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["field_sha256"], sha);

    // On paper: A1 holds it (one landscape sheet), A2 needs two tiles and
    // A3 four, each page 1:1 in mm and labelled.
    for (paper, pages, size) in [
        (
            "A1",
            vec!["a1.svg"],
            r#"width="841mm" height="594mm" viewBox="0 0 841 594""#,
        ),
        (
            "A2",
            vec!["a2-r1c1.svg", "a2-r1c2.svg"],
            r#"width="420mm" height="594mm" viewBox="0 0 420 594""#,
        ),
        (
            "a3",
            vec!["a3-r1c1.svg", "a3-r1c2.svg", "a3-r2c1.svg", "a3-r2c2.svg"],
            r#"width="420mm" height="297mm" viewBox="0 0 420 297""#,
        ),
    ] {
        let out_path = dir.join(format!("{}.svg", paper.to_lowercase()));
        let out = photopose(&["field", "svg", "--out", p(&out_path), "--paper", paper]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["sheets"].as_array().unwrap().len(), pages.len(), "{v}");
        for name in pages {
            let page = std::fs::read_to_string(dir.join(name)).unwrap();
            assert!(page.contains(size), "{name}");
            if name.contains("-r") {
                let label = &name[3..7];
                assert!(page.contains(&format!(">{label} (row")), "{name}");
                assert!(page.contains("class=\"alignment\""), "{name}");
            }
        }
    }
    let out = photopose(&["field", "svg", "--out", p(&svg), "--paper", "B4"]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("one of A4, A3, A2, A1, A0"),
        "{}",
        text(&out.stderr)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn field_new_writes_a_loadable_design_and_refuses_crowded_ones() {
    let dir = temp_dir("new");
    let csv = dir.join("plate.csv");
    let out = photopose(&[
        "field",
        "new",
        "--cols",
        "6",
        "--rows",
        "5",
        "--spacing",
        "40",
        "--coded-radius",
        "3",
        "--uncoded-radius",
        "2",
        "--coded-step",
        "2",
        "--out",
        p(&csv),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let field = photopose_formats::load_field(&csv).unwrap();
    // 6 × 5 grid less the four corners.
    assert_eq!(field.len(), 26);
    assert!(field.coded().count() >= 4);
    // The design renders and draws.
    let frame = dir.join("f.png");
    let out = photopose(&[
        "render",
        "--field",
        p(&csv),
        "--pose",
        "0,0,800,0,0,0",
        "--out",
        p(&frame),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    // Without --out the CSV goes to stdout.
    let out = photopose(&["field", "new", "--cols", "3", "--rows", "3"]);
    assert!(out.status.success());
    assert!(text(&out.stdout).starts_with("id,x,y,z,kind,radius\n"));

    let out = photopose(&["field", "new", "--spacing", "12"]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(err.contains("plate design refused"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
