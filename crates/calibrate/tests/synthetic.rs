//! The calibration on synthetic detections: blobs projected with a known
//! camera from the stations of `views`, with seeded Gaussian noise.

use nalgebra::Vector3;
use photopose_calibrate::{
    calibrate, params::values, views, Blob, CalibrateError, CalibrationOptions, Fixed,
    ImageDetections, Param, Report,
};
use photopose_field::{Field, TargetKind};
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::{Camera, Distortion, Exterior, Interior, Sensor};

fn plate() -> Field {
    Field::parse_csv(include_str!("../../../config/plate.csv"), "plate.csv").unwrap()
}

fn strong_camera() -> Camera {
    photopose_calibrate::cases::strong_lens(Sensor {
        width: 1300,
        height: 1030,
        pixel_size: 0.0067,
    })
}

fn nominal(truth: &Camera) -> Camera {
    Camera::new(
        truth.sensor,
        Interior {
            c: 12.4,
            x0: 0.0,
            y0: 0.0,
        },
        Distortion::default(),
    )
    .unwrap()
}

/// Blobs of `field` seen from `e` by `camera`, noise σ `noise_px`.
fn detections(
    name: &str,
    camera: &Camera,
    field: &Field,
    e: &Exterior,
    noise_px: f64,
    rng: &mut SplitMix64,
) -> ImageDetections {
    let blobs = field
        .targets()
        .iter()
        .filter_map(|t| {
            // The blob's centre is the centre of the imaged ellipse.
            let ideal = e.project_ideal(camera.interior.c, &t.position)?
                + photopose_locate::eccentricity(camera.interior.c, e, &t.position, t.radius)?;
            let p = camera.image_to_pixel(camera.distort(ideal)?);
            camera.contains_pixel(p, 12.0).then(|| Blob {
                col: p.x + noise_px * rng.normal(),
                row: p.y + noise_px * rng.normal(),
                kind: t.kind,
                id: (t.kind == TargetKind::Coded).then_some(t.id),
            })
        })
        .collect();
    ImageDetections {
        name: name.into(),
        blobs,
    }
}

fn images(camera: &Camera, n: usize, noise_px: f64, seed: u64) -> Vec<ImageDetections> {
    let field = plate();
    let mut rng = SplitMix64::new(seed);
    views::stations(n, Vector3::zeros(), 650.0, 950.0)
        .iter()
        .enumerate()
        .map(|(k, e)| detections(&format!("img{k:02}"), camera, &field, e, noise_px, &mut rng))
        .collect()
}

fn assert_within_3_sigma(truth: &Camera, cal: &photopose_calibrate::Calibration) {
    let t = values(truth);
    let v = values(&cal.result.camera);
    for p in Param::ALL {
        let i = p.index();
        let sd = cal.result.covariance[(i, i)].sqrt();
        assert!(sd > 0.0, "{}", p.name());
        assert!(
            (v[i] - t[i]).abs() <= 3.0 * sd,
            "{}: {} vs true {} (σ {sd:.2e}, {:.1} σ)",
            p.name(),
            v[i],
            t[i],
            (v[i] - t[i]).abs() / sd
        );
    }
}

#[test]
fn strong_lens_and_off_centre_principal_point_are_recovered_within_3_sigma() {
    let truth = strong_camera();
    let noise = 0.05;
    let imgs = images(&truth, 12, noise, 7);
    let cal = calibrate(
        &nominal(&truth),
        &plate(),
        &imgs,
        &CalibrationOptions::default(),
    )
    .expect("calibrates");
    assert_within_3_sigma(&truth, &cal);
    let report = Report::new(&cal, &Fixed::none(), &[]);
    // σ0 near the simulated noise (a coordinate's σ).
    assert!(
        (report.sigma0_px / noise - 1.0).abs() < 0.1,
        "σ0 {} px",
        report.sigma0_px
    );
    // The uncoded targets were identified: far more than the coded ones.
    assert!(
        report.n_observations > 12 * 120,
        "{}",
        report.n_observations
    );
    assert!(report.skipped.is_empty());
    let json = serde_json::to_string(&report).unwrap();
    assert!(json.contains("\"sigma0_px\""));
    assert!(report.to_text().contains("k1"));
}

#[test]
fn gross_errors_are_snooped_and_named_per_image() {
    let truth = strong_camera();
    let mut imgs = images(&truth, 8, 0.05, 11);
    // Move two blobs of image 3 by 2 px: a gross error, still inside the gate.
    let moved: Vec<(f64, f64)> = imgs[3].blobs[40..42]
        .iter()
        .map(|b| (b.col, b.row))
        .collect();
    for b in &mut imgs[3].blobs[40..42] {
        b.col += 2.0;
    }
    let cal = calibrate(
        &nominal(&truth),
        &plate(),
        &imgs,
        &CalibrationOptions::default(),
    )
    .expect("calibrates");
    let report = Report::new(&cal, &Fixed::none(), &[]);
    let rejected = &report.images[3].rejected_ids;
    assert_eq!(rejected.len(), 2, "{rejected:?}");
    assert_eq!(report.n_rejected, 2);
    for im in &report.images[..3] {
        assert!(
            im.rejected_ids.is_empty(),
            "{}: {:?}",
            im.image,
            im.rejected_ids
        );
    }
    let _ = moved;
    assert_within_3_sigma(&truth, &cal);
    assert!(!report.warnings.iter().any(|w| w.contains("fits badly")));
}

#[test]
fn an_image_that_fits_badly_is_named() {
    let truth = strong_camera();
    let mut imgs = images(&truth, 6, 0.05, 13);
    // Image 2 measured with 0.4 px noise instead of 0.05 px.
    let mut rng = SplitMix64::new(99);
    for b in &mut imgs[2].blobs {
        b.col += 0.4 * rng.normal();
        b.row += 0.4 * rng.normal();
    }
    let mut options = CalibrationOptions::default();
    options.bundle.snooping_critical = 0.0;
    let cal = calibrate(&nominal(&truth), &plate(), &imgs, &options).unwrap();
    let report = Report::new(&cal, &Fixed::none(), &[]);
    let bad: Vec<_> = report
        .warnings
        .iter()
        .filter(|w| w.contains("fits badly"))
        .collect();
    assert_eq!(bad.len(), 1, "{:?}", report.warnings);
    assert!(bad[0].contains("img02"), "{}", bad[0]);
}

#[test]
fn fixed_parameters_stay_and_report_no_deviation() {
    let mut truth = strong_camera();
    truth.distortion.k3 = 0.0;
    truth.distortion.b1 = 0.0;
    truth.distortion.b2 = 0.0;
    let imgs = images(&truth, 6, 0.05, 3);
    let mut options = CalibrationOptions::default();
    options.bundle.fixed = Fixed::parse_list("k3,b1,b2").unwrap();
    let cal = calibrate(&nominal(&truth), &plate(), &imgs, &options).unwrap();
    assert_eq!(cal.result.camera.distortion.k3, 0.0);
    assert_eq!(
        cal.result.covariance[(Param::K3.index(), Param::K3.index())],
        0.0
    );
    let report = Report::new(&cal, &options.bundle.fixed, &[]);
    assert!(report.parameters[Param::B1.index()].fixed);
    assert!(report.parameters[Param::B1.index()].std.is_none());
    assert!((cal.result.camera.interior.c - 12.0).abs() < 0.01);
}

#[test]
fn free_targets_keep_the_camera_within_3_sigma() {
    let truth = strong_camera();
    let imgs = images(&truth, 10, 0.05, 5);
    let mut options = CalibrationOptions::default();
    options.bundle.free_targets = true;
    let cal = calibrate(&nominal(&truth), &plate(), &imgs, &options).expect("calibrates");
    assert_within_3_sigma(&truth, &cal);
}

#[test]
fn images_parallel_to_the_plate_are_diagnosed() {
    let truth = strong_camera();
    let field = plate();
    let mut rng = SplitMix64::new(1);
    let imgs: Vec<_> = (0..6)
        .map(|k| {
            // Straight down onto the plate, rolled, at varied heights.
            let roll = (90.0 * k as f64).to_radians();
            let eye = Vector3::new(30.0 * k as f64 - 60.0, 10.0, 700.0 + 40.0 * k as f64);
            let up = Vector3::new(roll.sin(), roll.cos(), 0.0);
            let e = Exterior::look_at(eye, Vector3::new(eye.x, eye.y, 0.0), up).unwrap();
            detections(&format!("p{k}"), &truth, &field, &e, 0.05, &mut rng)
        })
        .collect();
    let e = calibrate(
        &nominal(&truth),
        &field,
        &imgs,
        &CalibrationOptions::default(),
    )
    .unwrap_err();
    assert!(matches!(e, CalibrateError::ParallelImages { .. }), "{e}");
    assert!(e.to_string().contains("principal distance"), "{e}");
    // Without the geometric check the normal equations show the same.
    let options = CalibrationOptions {
        min_tilt_deg: 0.0,
        ..CalibrationOptions::default()
    };
    let e = match calibrate(&nominal(&truth), &field, &imgs, &options) {
        Ok(cal) => panic!("a camera from parallel images: {:?}", cal.result.camera),
        Err(e) => e,
    };
    match &e {
        CalibrateError::NotDeterminable { combination } => {
            assert!(combination.split_whitespace().any(|w| w == "c"), "{e}")
        }
        other => panic!("{other}"),
    }
}

#[test]
fn too_few_images_and_images_without_plate_are_named() {
    let truth = strong_camera();
    let mut imgs = images(&truth, 2, 0.05, 2);
    imgs.push(ImageDetections {
        name: "empty.png".into(),
        blobs: vec![],
    });
    let e = calibrate(
        &nominal(&truth),
        &plate(),
        &imgs,
        &CalibrationOptions::default(),
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(e, CalibrateError::TooFewImages { usable: 2, .. }),
        "{msg}"
    );
    assert!(
        msg.contains("empty.png") && msg.contains("not found"),
        "{msg}"
    );
    // With enough images the empty one is skipped and named.
    let mut imgs = images(&truth, 6, 0.05, 2);
    imgs.insert(
        1,
        ImageDetections {
            name: "empty.png".into(),
            blobs: vec![],
        },
    );
    let cal = calibrate(
        &nominal(&truth),
        &plate(),
        &imgs,
        &CalibrationOptions::default(),
    )
    .unwrap();
    assert_eq!(cal.skipped.len(), 1);
    assert_eq!(cal.skipped[0].image, "empty.png");
    assert_eq!(cal.images.len(), 6);
}
