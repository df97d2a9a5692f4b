//! Criterion benchmark of `Detector::detect` on 1300 × 1030 8-bit frames of
//! the default plate (230 targets) rendered by `photopose-render` (blur
//! σ = 0.6 px, noise σ = 2 DN): frontal at 1 m, 45° at 1 m, frontal at
//! 0.6 m. Run with `cargo bench -p photopose-vision --bench detect`; the
//! median per frame is the number that counts: criterion prints the mean's
//! interval and keeps the median in
//! `target/criterion/detect/<frame>/new/estimates.json` (`median`).

#![allow(missing_docs)] // criterion_group! generates an undocumented public function

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use photopose_field::design::default_plate;
use photopose_geometry::{Camera, Exterior, Vector3};
use photopose_render::{RenderOptions, Renderer};
use photopose_vision::{Detector, DetectorOptions};

/// The camera of `config/camera.toml`.
fn camera() -> Camera {
    Camera::reference()
}

fn benches(cr: &mut Criterion) {
    let field = default_plate();
    let mut renderer = Renderer::new(camera(), &field, RenderOptions::default()).expect("renderer");
    let mut det = Detector::new(1300, 1030, DetectorOptions::for_field(&field)).expect("detector");
    let mut group = cr.benchmark_group("detect");
    for (name, eye, up) in [
        ("frontal_1.0m", Vector3::new(0.0, 0.0, 1000.0), Vector3::y()),
        ("45deg_1.0m", Vector3::new(0.0, -707.0, 707.0), Vector3::z()),
        ("frontal_0.6m", Vector3::new(0.0, 0.0, 600.0), Vector3::y()),
    ] {
        let ext = Exterior::look_at(eye, Vector3::zeros(), up).expect("pose");
        let mut img = renderer.new_image();
        renderer.render(&ext, &mut img).expect("render");
        let visible = renderer.truth().iter().filter(|t| t.visible).count();
        let found = det.detect(img.view()).expect("detect").targets.len();
        assert!(
            found >= visible,
            "{name}: {found} targets, {visible} visible"
        );
        group.bench_function(name, |b| {
            b.iter(|| {
                det.detect(black_box(img.view()))
                    .expect("detect")
                    .targets
                    .len()
            })
        });
    }
    group.finish();
}

criterion_group!(detect, benches);
criterion_main!(detect);
