//! End-to-end: `photopose render` → `photopose detect` through the real
//! binary, the per-input error lines of a mixed batch, and `field new`
//! reproducing the shipped plate byte for byte. Complements
//! `render_cli.rs` and the detect test in `resect_cli.rs`.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "photopose-render-detect-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn photopose<I, S>(args: I) -> Output
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    Command::new(env!("CARGO_BIN_EXE_photopose"))
        .args(args)
        .output()
        .unwrap()
}

fn lines(out: &Output) -> Vec<Value> {
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect()
}

fn render(out: &Path, pose: &str, extra: &[&str]) -> Value {
    let mut args = vec!["render", "--pose", pose, "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let o = photopose(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let truth = out.with_extension("truth.json");
    serde_json::from_str(&std::fs::read_to_string(truth).unwrap()).unwrap()
}

/// Every identified target lies within 0.1 px of its true projected centre
/// (so no id is wrong), and ≥ 95 % of the visible targets are identified.
fn check_against_truth(line: &Value, truth: &Value) {
    let truth_targets = truth["targets"].as_array().unwrap();
    let visible = truth_targets
        .iter()
        .filter(|t| t["visible"] == true)
        .count();
    let mut identified = 0;
    for t in line["targets"].as_array().unwrap() {
        let Some(id) = t["id"].as_u64() else { continue };
        let tr = truth_targets
            .iter()
            .find(|x| x["id"].as_u64() == Some(id))
            .unwrap_or_else(|| panic!("id {id} is not in the field"));
        let d = (t["col"].as_f64().unwrap() - tr["col"].as_f64().unwrap())
            .hypot(t["row"].as_f64().unwrap() - tr["row"].as_f64().unwrap());
        assert!(d < 0.1, "id {id} is {d:.3} px from its truth: a wrong id");
        identified += 1;
    }
    assert!(
        identified as f64 >= 0.95 * visible as f64,
        "{identified} of {visible} visible targets identified"
    );
}

#[test]
fn render_png_16_bit_then_detect_finds_the_true_ids() {
    let dir = temp_dir("png16");
    let frame = dir.join("frame.png");
    let truth = render(
        &frame,
        "-30,25,1050,-40,6,4",
        &["--bit-depth", "16", "--seed", "7"],
    );
    for key in ["pose_xyzabc", "center", "rotation", "targets"] {
        assert!(truth.get(key).is_some(), "{key} missing in the truth");
    }
    let img = photopose_formats::load_image(&frame).unwrap();
    assert_eq!((img.width(), img.height()), (1300, 1030));
    assert!(matches!(img.pixels(), photopose_frame::Pixels::Mono16(_)));
    let out = photopose(["detect".as_ref(), frame.as_os_str()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = lines(&out);
    assert_eq!(v.len(), 1);
    check_against_truth(&v[0], &truth);
    // Named outcomes and units, no Rust Debug text.
    for t in v[0]["targets"].as_array().unwrap() {
        let code = t["code"].as_str().unwrap();
        assert!(
            ["read", "no_ring", "not_in_field"].contains(&code) || code.starts_with("uncertain_"),
            "{t}"
        );
        assert!(!code.contains(' ') && !code.contains('{'), "{t}");
        assert!(t["angle_rad"].is_f64() && t.get("angle").is_none(), "{t}");
        if code == "read" {
            assert!(t["code_value"].is_u64(), "{t}");
        }
        // A frame exposed as rendered by default: no dot is clipped.
        assert_eq!(t["saturated"], false, "{t}");
    }
    assert_eq!(v[0]["n_saturated"], 0);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_mixed_batch_gives_one_error_line_per_bad_input_and_exit_1() {
    let dir = temp_dir("batch");
    let good = dir.join("good.pgm");
    let truth = render(&good, "10,-20,1000,30,5,-5", &[]);
    let truncated = dir.join("truncated.pgm");
    let bytes = std::fs::read(&good).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let small = dir.join("small.pgm");
    std::fs::write(
        &small,
        [b"P5\n640 480\n255\n".as_slice(), &vec![0u8; 640 * 480]].concat(),
    )
    .unwrap();
    let missing = dir.join("missing.pgm");
    let text = dir.join("text.pgm");
    std::fs::write(&text, "id,x,y,z,kind,radius\n1,0,0,0,coded,3\n").unwrap();
    let inputs = [&good, &truncated, &small, &missing, &text, &good];
    let out =
        photopose(std::iter::once("detect".as_ref()).chain(inputs.iter().map(|p| p.as_os_str())));
    assert_eq!(out.status.code(), Some(1));
    let v = lines(&out);
    assert_eq!(v.len(), inputs.len(), "one line per input");
    for (line, path) in v.iter().zip(inputs) {
        assert_eq!(line["image"], path.to_str().unwrap(), "input order");
    }
    for k in [0, 5] {
        assert_ne!(v[k]["ok"], false, "{}", v[k]);
        check_against_truth(&v[k], &truth);
    }
    let wants = [
        (1, "truncated"),
        (2, "640×480"),
        (3, "missing.pgm"),
        (4, "text.pgm"),
    ];
    for (k, want) in wants {
        assert_eq!(v[k]["ok"], false, "{}", v[k]);
        let e = v[k]["error"].as_str().unwrap();
        assert!(e.contains(want), "line {k}: {e:?} lacks {want:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn field_new_with_defaults_is_the_shipped_plate_byte_for_byte() {
    let dir = temp_dir("plate");
    let csv = dir.join("plate.csv");
    let out = photopose(["field", "new", "--out", csv.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        std::fs::read(&csv).unwrap(),
        include_bytes!("../config/plate.csv").to_vec()
    );
    let out = photopose(["field", "new", "--spacing", "12"]);
    assert!(!out.status.success());
    assert!(!String::from_utf8_lossy(&out.stderr).is_empty());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_bad_pose_is_a_clear_error() {
    let dir = temp_dir("pose");
    let out = photopose([
        "render",
        "--pose",
        "0,0,abc,0,0,0",
        "--out",
        dir.join("x.pgm").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("Z = `abc`"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
