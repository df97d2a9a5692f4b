//! End-to-end tests of `photopose calibrate camera`: images rendered
//! in-process with a known camera, the real binary on them, the camera file
//! it writes, the report, and the diagnoses of degenerate inputs.

mod common;

use common::{bin, scratch};
use nalgebra::Vector3;
use photopose_field::Field;
use photopose_geometry::{Camera, Distortion, Exterior, Interior};
use photopose_render::{RenderOptions, Renderer};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn plate() -> Field {
    Field::parse_csv(include_str!("../config/plate.csv"), "plate.csv").unwrap()
}

/// Renders the field from each station into `dir`; returns the paths.
fn render_set(camera: &Camera, stations: &[Exterior], dir: &Path, seed: u64) -> Vec<PathBuf> {
    let field = plate();
    let options = RenderOptions {
        seed,
        ..RenderOptions::default()
    };
    let mut r = Renderer::new(*camera, &field, options).unwrap();
    let mut image = r.new_image();
    stations
        .iter()
        .enumerate()
        .map(|(k, e)| {
            let mut o = options;
            o.seed = seed + k as u64;
            r.set_options(o).unwrap();
            r.render(e, &mut image).unwrap();
            let p = dir.join(format!("cal{k:02}.pgm"));
            photopose_formats::save_image(&p, &image).unwrap();
            p
        })
        .collect()
}

/// RMS (per coordinate, px) of the detected blob centres against the
/// rendered truth (the image of each circle's centre), over the frames of
/// [`render_set`] with the same seed: the measurement noise the adjustment's
/// σ0 should come close to.
fn detection_error_rms(camera: &Camera, stations: &[Exterior], seed: u64) -> (f64, usize) {
    let field = plate();
    let mut r = Renderer::new(*camera, &field, RenderOptions::default()).unwrap();
    let mut det = photopose_vision::Detector::new(
        camera.sensor.width,
        camera.sensor.height,
        photopose_vision::DetectorOptions::for_field(&field),
    )
    .unwrap();
    let mut image = r.new_image();
    let (mut ss, mut n) = (0.0, 0usize);
    for (k, e) in stations.iter().enumerate() {
        r.set_options(RenderOptions {
            seed: seed + k as u64,
            ..RenderOptions::default()
        })
        .unwrap();
        let truth: Vec<_> = r.render(e, &mut image).unwrap().to_vec();
        for d in &det.detect(image.view()).unwrap().targets {
            let nearest = truth
                .iter()
                .filter(|t| t.visible)
                .map(|t| (t.col - d.col, t.row - d.row))
                .min_by(|a, b| a.0.hypot(a.1).total_cmp(&b.0.hypot(b.1)));
            if let Some((dc, dr)) = nearest {
                if dc.hypot(dr) < 1.0 {
                    ss += dc * dc + dr * dr;
                    n += 1;
                }
            }
        }
    }
    ((ss / (2 * n.max(1)) as f64).sqrt(), n)
}

/// A blank frame of the camera's size (no plate).
fn blank(camera: &Camera, dir: &Path) -> PathBuf {
    let field = plate();
    let r = Renderer::new(*camera, &field, RenderOptions::default()).unwrap();
    let image = r.new_image();
    let p = dir.join("blank.pgm");
    photopose_formats::save_image(&p, &image).unwrap();
    p
}

/// The nominal camera file: the sensor, c 12.3 mm, no distortion.
fn nominal(camera: &Camera, dir: &Path) -> PathBuf {
    let mut c = *camera;
    c.interior = Interior {
        c: 12.3,
        x0: 0.0,
        y0: 0.0,
    };
    c.distortion = Distortion::default();
    let p = dir.join("nominal.toml");
    std::fs::write(&p, photopose_formats::camera_to_toml(&c)).unwrap();
    p
}

struct Run {
    out: std::process::Output,
    camera: PathBuf,
    report: PathBuf,
    plots: PathBuf,
}

fn run(dir: &Path, initial: &Path, images: &[PathBuf], extra: &[&str]) -> Run {
    let camera = dir.join("calibrated.toml");
    let report = dir.join("report.json");
    let plots = dir.join("plots");
    let out = bin()
        .env("SOURCE_DATE_EPOCH", "1700000000")
        .args(["calibrate", "camera", "--initial"])
        .arg(initial)
        .arg("--out")
        .arg(&camera)
        .arg("--report-json")
        .arg(&report)
        .arg("--plot-dir")
        .arg(&plots)
        .args(extra)
        .args(images)
        .output()
        .unwrap();
    Run {
        out,
        camera,
        report,
        plots,
    }
}

/// Every parameter within 3 reported standard deviations of the truth;
/// returns the largest |error| / σ.
fn check_within_3_sigma(truth: &Camera, report: &Value) -> f64 {
    let t = photopose_calibrate::params::values(truth);
    let mut worst: f64 = 0.0;
    for (k, p) in report["parameters"].as_array().unwrap().iter().enumerate() {
        let v = p["value"].as_f64().unwrap();
        let Some(sd) = p["std"].as_f64() else {
            assert_eq!(v, t[k], "fixed {} kept", p["name"]);
            continue;
        };
        let z = (v - t[k]).abs() / sd;
        worst = worst.max(z);
        assert!(
            z <= 3.0,
            "{}: {v} vs true {} (σ {sd:e}, {z:.2} σ)",
            p["name"],
            t[k]
        );
    }
    worst
}

#[test]
fn calibrates_rendered_images_and_names_the_image_without_plate() {
    let dir = scratch("calibrate-camera");
    let truth = photopose_formats::default_camera();
    let stations = photopose_calibrate::views::stations(8, Vector3::zeros(), 650.0, 950.0);
    let mut images = render_set(&truth, &stations, &dir, 100);
    images.insert(3, blank(&truth, &dir));
    let initial = nominal(&truth, &dir);
    let r = run(&dir, &initial, &images, &["--fix", "k3,b1,b2"]);
    let stderr = String::from_utf8_lossy(&r.out.stderr);
    let stdout = String::from_utf8_lossy(&r.out.stdout);
    assert!(r.out.status.success(), "{stderr}\n{stdout}");
    // The camera file loads and round-trips.
    let cam = photopose_formats::load_camera(&r.camera).unwrap();
    let again =
        photopose_formats::parse_camera(&photopose_formats::camera_to_toml(&cam), "again").unwrap();
    assert_eq!(cam, again);
    let report: Value = serde_json::from_str(&std::fs::read_to_string(&r.report).unwrap()).unwrap();
    check_within_3_sigma(&truth, &report);
    // The report and the camera file agree (serde_json's float parsing
    // may differ in the last bit).
    let c = report["parameters"][0]["value"].as_f64().unwrap();
    assert!(
        (c - cam.interior.c).abs() < 1e-12,
        "{c} vs {}",
        cam.interior.c
    );
    // The blank image is skipped and named; the others are used.
    let skipped = report["skipped"].as_array().unwrap();
    assert_eq!(skipped.len(), 1, "{skipped:?}");
    assert!(skipped[0]["image"].as_str().unwrap().ends_with("blank.pgm"));
    assert!(
        stdout.contains("blank.pgm") && stdout.contains("SKIPPED"),
        "{stdout}"
    );
    assert_eq!(report["images"].as_array().unwrap().len(), 8);
    // Residuals of a well-fitting model: sub-tenth of a pixel.
    let rms = report["rms_px"].as_f64().unwrap();
    assert!(rms < 0.1, "rms {rms}");
    assert!(report["n_observations"].as_u64().unwrap() > 8 * 150);
    for f in ["residuals.svg", "radial.svg"] {
        let text = std::fs::read_to_string(r.plots.join(f)).unwrap();
        assert!(text.starts_with("<svg") && text.contains("<circle"), "{f}");
        // Provenance in the plot, the camera and the date in its title.
        assert!(
            text.contains("<metadata id=\"photopose-provenance\">"),
            "{f}"
        );
        assert!(
            text.contains("camera calibrated.toml (1300 × 1030 px")
                && text.contains("2023-11-14T22:13:20Z"),
            "{f}"
        );
    }
    check_provenance(&r, &images, &initial, &report, &stdout);
}

/// The camera file's `[calibration]` section and the report's provenance:
/// tool, date, image and observation counts, σ of the estimated parameters,
/// every readable input with the SHA-256 of its bytes.
fn check_provenance(r: &Run, images: &[PathBuf], initial: &Path, report: &Value, stdout: &str) {
    let file = photopose_formats::load_camera_file(&r.camera).unwrap();
    let rec = file.calibration.expect("a [calibration] section");
    assert_eq!(rec.date, "2023-11-14T22:13:20Z");
    assert_eq!(rec.tool, format!("photopose {}", env!("CARGO_PKG_VERSION")));
    assert_eq!(rec.images, 8);
    assert_eq!(
        rec.observations as u64,
        report["n_observations"].as_u64().unwrap()
    );
    // serde_json's float parsing may differ from TOML's in the last bit.
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs());
    assert!(close(rec.sigma0_px, report["sigma0_px"].as_f64().unwrap()));
    assert_eq!(rec.fixed, ["k3", "b1", "b2"]);
    let std = rec.std.values();
    for (k, p) in report["parameters"].as_array().unwrap().iter().enumerate() {
        match (std[k], p["std"].as_f64()) {
            (Some(a), Some(b)) => assert!(close(a, b), "{}: {a} vs {b}", p["name"]),
            (a, b) => assert_eq!(a, b, "{}", p["name"]),
        }
    }
    assert!(std[0].unwrap() > 0.0 && std[9].is_none());
    // The initial camera first, then every image (the blank one too: it was
    // read), each with the SHA-256 of its bytes.
    let expected: Vec<&Path> = std::iter::once(initial)
        .chain(images.iter().map(PathBuf::as_path))
        .collect();
    assert_eq!(rec.inputs.len(), expected.len());
    for p in &expected {
        let want = photopose_formats::provenance::sha256_hex(&std::fs::read(p).unwrap());
        let got = rec
            .inputs
            .iter()
            .find(|i| Path::new(&i.path) == *p)
            .unwrap_or_else(|| panic!("{} not among the inputs", p.display()));
        assert_eq!(got.sha256, want);
        assert!(stdout.contains(&format!("{}  sha256 {want}", p.display())));
    }
    assert_eq!(report["provenance"]["date"], "2023-11-14T22:13:20Z");
    assert_eq!(
        report["provenance"]["inputs"].as_array().unwrap().len(),
        expected.len()
    );
    assert!(stdout.starts_with("made by photopose "), "{stdout}");
}

#[test]
fn images_square_onto_the_plate_are_diagnosed_not_solved() {
    let dir = scratch("calibrate-parallel");
    let truth = photopose_formats::default_camera();
    let stations: Vec<Exterior> = (0..4)
        .map(|k| {
            let roll = 90.0 * k as f64;
            Exterior::from_kuka_pose([
                20.0 * k as f64,
                -10.0,
                700.0 + 50.0 * k as f64,
                roll,
                0.0,
                0.0,
            ])
        })
        .collect();
    let images = render_set(&truth, &stations, &dir, 7);
    let r = run(&dir, &nominal(&truth, &dir), &images, &[]);
    let stderr = String::from_utf8_lossy(&r.out.stderr);
    assert!(!r.out.status.success());
    assert!(
        stderr.contains("perpendicularly") && stderr.contains("principal distance"),
        "{stderr}"
    );
    assert!(
        !r.camera.exists(),
        "no camera file from a failed calibration"
    );
}

#[test]
fn fewer_than_three_usable_images_is_an_error_naming_the_skipped_ones() {
    let dir = scratch("calibrate-few");
    let truth = photopose_formats::default_camera();
    let stations = photopose_calibrate::views::stations(4, Vector3::zeros(), 650.0, 950.0);
    let mut images = render_set(&truth, &stations[1..3], &dir, 3);
    images.push(blank(&truth, &dir));
    images.push(dir.join("missing.pgm"));
    let r = run(&dir, &nominal(&truth, &dir), &images, &[]);
    let stderr = String::from_utf8_lossy(&r.out.stderr);
    assert!(!r.out.status.success());
    assert!(
        stderr.contains("only 2 usable image(s), need at least 3"),
        "{stderr}"
    );
    assert!(
        stderr.contains("blank.pgm") && stderr.contains("missing.pgm"),
        "{stderr}"
    );
}

/// The acceptance of issue 6, by hand: `cargo test --release --test
/// calibrate_cli -- --ignored --nocapture`. 20 images of the default plate
/// with varied roll, tilt and distance; the default camera, then a strongly
/// distorted lens with an off-centre principal point.
#[test]
#[ignore]
fn acceptance_twenty_images() {
    let strong =
        photopose_calibrate::cases::strong_lens(photopose_formats::default_camera().sensor);
    for (name, truth) in [
        ("default", photopose_formats::default_camera()),
        ("strong", strong),
    ] {
        let dir = scratch(&format!("calibrate-acceptance-{name}"));
        let stations = photopose_calibrate::views::stations(20, Vector3::zeros(), 650.0, 950.0);
        let images = render_set(&truth, &stations, &dir, 1000);
        let t0 = std::time::Instant::now();
        let r = run(&dir, &nominal(&truth, &dir), &images, &[]);
        let secs = t0.elapsed().as_secs_f64();
        let stderr = String::from_utf8_lossy(&r.out.stderr);
        let stdout = String::from_utf8_lossy(&r.out.stdout);
        println!("=== {name}: command {secs:.3} s\n{stderr}{stdout}");
        assert!(r.out.status.success());
        let cam = photopose_formats::load_camera(&r.camera).unwrap();
        let again =
            photopose_formats::parse_camera(&photopose_formats::camera_to_toml(&cam), "again")
                .unwrap();
        assert_eq!(cam, again);
        let report: Value =
            serde_json::from_str(&std::fs::read_to_string(&r.report).unwrap()).unwrap();
        let t = photopose_calibrate::params::values(&truth);
        for (k, p) in report["parameters"].as_array().unwrap().iter().enumerate() {
            let v = p["value"].as_f64().unwrap();
            let sd = p["std"].as_f64().unwrap_or(0.0);
            println!(
                "{name} {:>3}: true {:+.6e} est {:+.6e} σ {:.2e} |err|/σ {:.2}",
                p["name"].as_str().unwrap(),
                t[k],
                v,
                sd,
                (v - t[k]).abs() / sd
            );
        }
        let worst = check_within_3_sigma(&truth, &report);
        let (noise, n) = detection_error_rms(&truth, &stations, 1000);
        println!(
            "{name}: worst |err|/σ {worst:.2}; sigma0 {:.4} px, residual RMS {:.4} px; \
             detected-vs-true centre RMS {noise:.4} px over {n} targets",
            report["sigma0_px"].as_f64().unwrap(),
            report["rms_px"].as_f64().unwrap()
        );
    }
}
