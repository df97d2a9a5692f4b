//! The histogram on every fourth row and column (the default step): on
//! rendered frames of the default plate (the poses of `photopose bench`,
//! a close oblique view under a falling ring light, over-exposed targets;
//! 8-bit, 12- and 16-bit), Otsu's level and the frame's threshold lie
//! within one 8-bit grey value (1/255 of the full scale) of those on every
//! second row and column, and the background and noise estimates agree.

use photopose_field::design::default_plate;
use photopose_frame::Image;
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::{Camera, Exterior, Vector3};
use photopose_render::{RenderOptions, Renderer};
use photopose_vision::{Detector, DetectorOptions, FrameStatus};

/// Looking at `(x, y)` on the plate from `distance` mm, tilted by
/// `tilt_deg` towards azimuth `az_deg`, rolled by `roll` radians.
fn pose(distance: f64, tilt_deg: f64, az_deg: f64, (x, y): (f64, f64), roll: f64) -> Exterior {
    let (t, a) = (tilt_deg.to_radians(), az_deg.to_radians());
    let aim = Vector3::new(x, y, 0.0);
    let eye = aim + Vector3::new(t.sin() * a.cos(), t.sin() * a.sin(), t.cos()) * distance;
    Exterior::look_at(eye, aim, Vector3::new(roll.cos(), roll.sin(), 0.0)).unwrap()
}

#[test]
fn every_fourth_row_and_column_give_the_threshold_of_every_second() {
    let cam = Camera::reference();
    let field = default_plate();
    let mut renderer = Renderer::new(cam, &field, RenderOptions::default()).unwrap();
    // The poses of `photopose bench` (seeded as in its driver).
    let mut rng = SplitMix64::new(7);
    let mut frames: Vec<(String, Exterior, RenderOptions)> = Vec::new();
    for k in 0..6 {
        let distance = 800.0 + 400.0 * rng.unit();
        let tilt = 30.0 * rng.unit();
        let az = 360.0 * rng.unit();
        let roll = std::f64::consts::TAU * rng.unit();
        let o = RenderOptions {
            seed: k + 1,
            ..RenderOptions::default()
        };
        frames.push((
            format!("bench {k}"),
            pose(distance, tilt, az, (0.0, 0.0), roll),
            o,
        ));
    }
    frames.push((
        "oblique, falling ring light".into(),
        pose(600.0, 45.0, 90.0, (40.0, 0.0), 0.0),
        RenderOptions {
            beam_half_angle_deg: 20.0,
            seed: 61,
            ..RenderOptions::default()
        },
    ));
    for (k, d) in [750.0, 1100.0].into_iter().enumerate() {
        frames.push((
            format!("over-exposed {d} mm"),
            pose(d, 20.0 + 15.0 * k as f64, 40.0, (30.0, -20.0), 0.3),
            RenderOptions {
                target: 2.0,
                seed: 40 + k as u64,
                ..RenderOptions::default()
            },
        ));
    }
    let (w, h) = (cam.sensor.width, cam.sensor.height);
    let mut images = [
        renderer.new_image(),
        Image::new_mono16(w, h, 4095),
        Image::new_mono16(w, h, 65535),
    ];
    let step2 = DetectorOptions {
        histogram_step: 2,
        ..DetectorOptions::for_field(&field)
    };
    let step4 = DetectorOptions::for_field(&field);
    assert_eq!(step4.histogram_step, 4, "the default step");
    let mut fine = Detector::new(w, h, step2).unwrap();
    let mut coarse = Detector::new(w, h, step4).unwrap();
    let mut worst = 0.0f64;
    for (what, e, o) in &frames {
        renderer.set_options(*o).unwrap();
        for image in images.iter_mut() {
            renderer.render(e, image).unwrap();
            let max = image.max_value() as f64;
            let a = fine.threshold(image.view()).unwrap();
            let b = coarse.threshold(image.view()).unwrap();
            let grey = max / 255.0;
            let off = |x: u32, y: u32| (x as f64 - y as f64).abs() / grey;
            let what = format!("{what}, max {max}: step 2 {a:?}, step 4 {b:?}");
            assert_eq!(
                (a.status, b.status),
                (FrameStatus::Normal, FrameStatus::Normal),
                "{what}"
            );
            assert!(off(a.otsu, b.otsu) <= 1.0, "Otsu: {what}");
            assert!(
                off(a.threshold.level(), b.threshold.level()) <= 1.0,
                "level: {what}"
            );
            assert!(
                (a.background - b.background).abs() <= grey,
                "background: {what}"
            );
            assert!(
                (a.noise - b.noise).abs() <= 0.5 * grey.max(a.noise),
                "noise: {what}"
            );
            worst = worst.max(off(a.threshold.level(), b.threshold.level()));
        }
    }
    eprintln!("largest difference of the levels: {worst:.3} 8-bit grey values");
}
