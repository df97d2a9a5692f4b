//! Run time of the calibration proper (start values, identification rounds,
//! adjustments, snooping, precision) without detection: 20 synthetic images
//! of the default plate (230 targets) from `views::stations`, blob centres
//! projected with a strongly distorted camera plus 0.02 px noise.
//!
//! `cargo run --release -p photopose-calibrate --example adjust_time [-- --free-targets]`

// A timing example: the clock is the example's, not the crate's.
#![allow(clippy::disallowed_types, clippy::disallowed_methods)]

use nalgebra::Vector3;
use photopose_calibrate::{calibrate, views, Blob, CalibrationOptions, ImageDetections, Report};
use photopose_field::{Field, TargetKind};
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::{Camera, Distortion, Interior, Sensor};
use std::time::Instant;

fn main() {
    let free = std::env::args().any(|a| a == "--free-targets");
    let field = Field::parse_csv(include_str!("../../../config/plate.csv"), "plate.csv").unwrap();
    let sensor = Sensor {
        width: 1300,
        height: 1030,
        pixel_size: 0.0067,
    };
    let truth = photopose_calibrate::cases::strong_lens(sensor);
    let nominal = Camera::new(
        sensor,
        Interior {
            c: 12.3,
            x0: 0.0,
            y0: 0.0,
        },
        Distortion::default(),
    )
    .unwrap();
    let mut rng = SplitMix64::new(42);
    let images: Vec<ImageDetections> = views::stations(20, Vector3::zeros(), 650.0, 950.0)
        .iter()
        .enumerate()
        .map(|(k, e)| ImageDetections {
            name: format!("img{k:02}"),
            blobs: field
                .targets()
                .iter()
                .filter_map(|t| {
                    let ideal = e.project_ideal(truth.interior.c, &t.position)?
                        + photopose_locate::eccentricity(
                            truth.interior.c,
                            e,
                            &t.position,
                            t.radius,
                        )?;
                    let p = truth.image_to_pixel(truth.distort(ideal)?);
                    truth.contains_pixel(p, 12.0).then(|| Blob {
                        col: p.x + 0.02 * rng.normal(),
                        row: p.y + 0.02 * rng.normal(),
                        kind: t.kind,
                        id: (t.kind == TargetKind::Coded).then_some(t.id),
                    })
                })
                .collect(),
        })
        .collect();
    let blobs: usize = images.iter().map(|i| i.blobs.len()).sum();
    let mut options = CalibrationOptions::default();
    options.bundle.free_targets = free;
    // Warm-up, then the median of five runs.
    let mut times = Vec::new();
    let mut report = None;
    for _ in 0..6 {
        let t0 = Instant::now();
        let cal = calibrate(&nominal, &field, &images, &options).expect("calibrates");
        times.push(t0.elapsed().as_secs_f64());
        report = Some(Report::new(&cal, &options.bundle.fixed, &[]));
    }
    times.remove(0);
    times.sort_by(f64::total_cmp);
    let r = report.unwrap();
    println!(
        "20 images, {blobs} blobs, free targets {free}: {} observations, {} unknowns, {} iterations, σ0 {:.4} px; calibrate() median {:.3} s (min {:.3}, max {:.3})",
        r.n_observations,
        r.n_unknowns,
        r.iterations,
        r.sigma0_px,
        times[2],
        times[0],
        times[4]
    );
}
