//! Times `Detector::detect` on 1300 × 1030 frames of the default plate
//! rendered by `photopose-render` (blur σ = 0.6 px, noise σ = 2 DN). Run in
//! release: `cargo run --release -p photopose-vision --example time_detect
//! [-- ITERATIONS [POSE]]` (POSE 0, 1 or 2 times one frame only; the benchmark `benches/detect.rs` gives the numbers
//! that count; this is for profilers such as `perf` and callgrind).

// A timing example: the clock is the example's, not the crate's.
#![allow(clippy::disallowed_types, clippy::disallowed_methods)]

use photopose_field::design::default_plate;
use photopose_geometry::{Camera, Exterior, Vector3};
use photopose_render::{RenderOptions, Renderer};
use photopose_vision::{Detector, DetectorOptions};
use std::time::Instant;

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("iterations"))
        .unwrap_or(200);
    let only: Option<usize> = std::env::args()
        .nth(2)
        .map(|a| a.parse().expect("pose index"));
    let cam = Camera::reference();
    let field = default_plate();
    let mut renderer = Renderer::new(cam, &field, RenderOptions::default()).expect("renderer");
    let mut det = Detector::new(1300, 1030, DetectorOptions::for_field(&field)).expect("detector");
    for (k, (name, eye, up)) in [
        (
            "frontal 1.0 m",
            Vector3::new(0.0, 0.0, 1000.0),
            Vector3::y(),
        ),
        ("45° 1.0 m", Vector3::new(0.0, -707.0, 707.0), Vector3::z()),
        ("frontal 0.6 m", Vector3::new(0.0, 0.0, 600.0), Vector3::y()),
    ]
    .into_iter()
    .enumerate()
    {
        if only.is_some_and(|o| o != k) {
            continue;
        }
        let ext = Exterior::look_at(eye, Vector3::zeros(), up).expect("pose");
        let mut img = renderer.new_image();
        renderer.render(&ext, &mut img).expect("render");
        let visible = renderer.truth().iter().filter(|t| t.visible).count();
        let mut times = Vec::with_capacity(n);
        let mut targets = 0;
        for _ in 0..n {
            let t0 = Instant::now();
            targets = det.detect(img.view()).expect("detect").targets.len();
            times.push(t0.elapsed().as_secs_f64());
        }
        times.sort_by(f64::total_cmp);
        let decoded = det
            .detections()
            .targets
            .iter()
            .filter(|t| t.id.is_some())
            .count();
        println!(
            "{name}: median {:.3} ms per frame, {targets} targets ({visible} visible), {decoded} decoded",
            times[n / 2] * 1e3
        );
    }
}
