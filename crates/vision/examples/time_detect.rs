//! Times `Detector::detect` on rendered 1300 × 1030 frames of the default
//! plate (the renderer of the integration tests). Run in release:
//! `cargo run --release -p photopose-vision --example time_detect`.

#[path = "../tests/common/mod.rs"]
mod common;

use photopose_field::design::default_plate;
use photopose_geometry::{Camera, Distortion, Exterior, Interior, Sensor, Vector3};
use photopose_vision::{Detector, DetectorOptions};
use std::time::Instant;

fn main() {
    let cam = Camera::new(
        Sensor {
            width: 1300,
            height: 1030,
            pixel_size: 0.0067,
        },
        Interior {
            c: 12.0,
            x0: 0.021,
            y0: -0.014,
        },
        Distortion {
            k1: -1.2e-4,
            k2: 3.0e-7,
            p1: 5.0e-6,
            p2: -3.0e-6,
            ..Distortion::default()
        },
    )
    .expect("camera");
    let field = default_plate();
    let mut det = Detector::new(1300, 1030, DetectorOptions::for_field(&field)).expect("detector");
    for (name, eye, up) in [
        (
            "frontal 1.0 m",
            Vector3::new(0.0, 0.0, 1000.0),
            Vector3::y(),
        ),
        ("45° 1.0 m", Vector3::new(0.0, -707.0, 707.0), Vector3::z()),
        ("frontal 0.6 m", Vector3::new(0.0, 0.0, 600.0), Vector3::y()),
    ] {
        let ext = Exterior::look_at(eye, Vector3::zeros(), up).expect("pose");
        let (img, _) = common::render(&cam, &ext, &field, &common::Look::default());
        let n = 200;
        let mut targets = 0;
        let t0 = Instant::now();
        for _ in 0..n {
            targets = det.detect(img.view()).expect("detect").targets.len();
        }
        let per = t0.elapsed().as_secs_f64() / n as f64;
        let decoded = det
            .detections()
            .targets
            .iter()
            .filter(|t| t.id.is_some())
            .count();
        println!(
            "{name}: {:.3} ms per frame, {targets} targets, {decoded} decoded",
            per * 1e3
        );
    }
}
