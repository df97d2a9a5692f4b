//! Times the renderer on the default camera and plate (run with
//! `cargo run --release -p photopose-render --example time_render [K...]`).
//! Timing lives here, not in tests: the pure crate reads no clock.

// A timing example: the clock is the example's, not the crate's.
#![allow(clippy::disallowed_types, clippy::disallowed_methods)]

use photopose_field::design::default_plate;
use photopose_geometry::{Camera, Exterior};
use photopose_render::{RenderOptions, Renderer};
use std::time::Instant;

fn main() {
    let camera = Camera::reference();
    let poses = [
        ("frontal 1000 mm", [0.0, 0.0, 1000.0, 0.0, 0.0, 0.0]),
        ("oblique 30°", [0.0, -500.0, 870.0, 0.0, 0.0, 30.0]),
        ("near 700 mm", [20.0, 10.0, 700.0, 15.0, 5.0, -5.0]),
    ];
    // Supersampling factors to time: the arguments, or 1, 4 and 8.
    let mut factors: Vec<u32> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("supersampling factors as arguments"))
        .collect();
    if factors.is_empty() {
        factors = vec![1, 4, 8];
    }
    for supersample in factors {
        let options = RenderOptions {
            supersample,
            ..RenderOptions::default()
        };
        let mut renderer = Renderer::new(camera, &default_plate(), options).expect("renderer");
        let mut img = renderer.new_image();
        for (name, pose) in poses {
            let e = Exterior::from_kuka_pose(pose);
            renderer.render(&e, &mut img).expect("render");
            let n = 20;
            let t0 = Instant::now();
            for _ in 0..n {
                renderer.render(&e, &mut img).expect("render");
            }
            let ms = t0.elapsed().as_secs_f64() * 1e3 / n as f64;
            let visible = renderer.truth().iter().filter(|t| t.visible).count();
            println!(
                "supersample {supersample}: {name}: {ms:.2} ms per 1300×1030 frame, {visible} targets visible"
            );
        }
    }
}
