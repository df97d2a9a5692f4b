//! Criterion benchmarks of the geometry core on the default plate and camera
//! (230 targets seen from 1 m, σ = 0.1 px): the closed form alone, the
//! least-squares refinement from the closed-form start, and the full
//! resection (hypothesise-and-verify, refinement, snooping, precision).

#![allow(missing_docs)] // criterion_group! generates an undocumented public function

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use photopose_field::design::default_plate;
use photopose_geometry::closed_form::resect_four_coplanar;
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::{Camera, Exterior, Observation, Resection, ResectionOptions};

fn setup() -> (Camera, Vec<Observation>) {
    let camera = photopose_formats::default_camera();
    let truth = Exterior::from_kuka_pose([10.0, -10.0, 1000.0, 12.0, 2.0, -2.0]);
    let mut rng = SplitMix64::new(9);
    let mut obs = Vec::new();
    for t in default_plate().targets() {
        let Some(px) = truth.project_pixel(&camera, &t.position) else {
            continue;
        };
        if camera.contains_pixel(px, 2.0) {
            obs.push(Observation::from_pixel(
                &camera,
                t.id,
                t.position,
                px.x + 0.1 * rng.normal(),
                px.y + 0.1 * rng.normal(),
            ));
        }
    }
    assert_eq!(obs.len(), 230, "all targets visible");
    (camera, obs)
}

fn corners(obs: &[Observation]) -> ([nalgebra::Vector3<f64>; 4], [nalgebra::Vector2<f64>; 4]) {
    let pick = |sx: f64, sy: f64| {
        obs.iter()
            .max_by(|a, b| {
                (sx * a.object.x + sy * a.object.y).total_cmp(&(sx * b.object.x + sy * b.object.y))
            })
            .unwrap()
    };
    let q = [
        pick(1.0, 1.0),
        pick(-1.0, 1.0),
        pick(-1.0, -1.0),
        pick(1.0, -1.0),
    ];
    (q.map(|o| o.object), q.map(|o| o.image))
}

fn benches(cr: &mut Criterion) {
    let (camera, obs) = setup();
    let (ob, im) = corners(&obs);
    let c = camera.interior.c;
    cr.bench_function("closed_form_four_points", |b| {
        b.iter(|| resect_four_coplanar(black_box(c), black_box(&ob), black_box(&im)).unwrap())
    });
    let start = resect_four_coplanar(c, &ob, &im).unwrap();
    let mut rs = Resection::new(&camera, ResectionOptions::default());
    rs.refine(&obs, start).unwrap();
    cr.bench_function("refine_230_points", |b| {
        b.iter(|| rs.refine(black_box(&obs), black_box(start)).unwrap())
    });
    cr.bench_function("resect_full_230_points", |b| {
        b.iter(|| rs.solve(black_box(&obs)).unwrap())
    });
}

criterion_group! {
    name = group;
    config = Criterion::default().sample_size(200).warm_up_time(std::time::Duration::from_secs(1)).measurement_time(std::time::Duration::from_secs(3));
    targets = benches
}
criterion_main!(group);
