//! A small driver for instruction counts of the full-frame path: renders
//! the frames of `photopose bench` (default camera and plate, the same
//! seeded poses) and locates each of them a few times. Run it under
//! `valgrind --tool=callgrind --toggle-collect='*Locator*locate*'` in a
//! release build to compare the detector's cost before and after a change
//! on a loaded machine (instruction counts are deterministic; times are
//! not). Arguments: frames (default 8), rounds (default 2).

use photopose_field::design::default_plate;
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::{Camera, Exterior, Vector3};
use photopose_locate::{LocateOptions, Locator};
use photopose_render::{RenderOptions, Renderer};

fn main() {
    let mut args = std::env::args().skip(1);
    let frames: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(8);
    let rounds: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(2);
    let field = default_plate();
    let mut renderer =
        Renderer::new(Camera::reference(), &field, RenderOptions::default()).expect("renderer");
    let mut rng = SplitMix64::new(7);
    let mut images = Vec::new();
    for k in 0..frames {
        let distance = 800.0 + 400.0 * rng.unit();
        let tilt = (30.0 * rng.unit()).to_radians();
        let az = std::f64::consts::TAU * rng.unit();
        let eye = Vector3::new(tilt.sin() * az.cos(), tilt.sin() * az.sin(), tilt.cos()) * distance;
        let roll = std::f64::consts::TAU * rng.unit();
        let e = Exterior::look_at(
            eye,
            Vector3::zeros(),
            Vector3::new(roll.cos(), roll.sin(), 0.0),
        )
        .expect("pose");
        renderer
            .set_options(RenderOptions {
                seed: k as u64 + 1,
                ..RenderOptions::default()
            })
            .expect("options");
        let mut img = renderer.new_image();
        renderer.render(&e, &mut img).expect("render");
        images.push(img);
    }
    let mut locator =
        Locator::new(Camera::reference(), field, LocateOptions::default()).expect("locator");
    let (mut ok, mut check) = (0, 0.0f64);
    // Check values of the poses (final and coarse): centres, rotations, σ0
    // and covariances.
    let mut poses = 0.0f64;
    for _ in 0..rounds {
        for img in &images {
            let loc = locator.locate(img.view()).expect("locate");
            ok += loc.targets.len();
            check += loc.targets.iter().map(|t| t.col + t.row).sum::<f64>();
            for p in [loc.pose, loc.coarse].into_iter().flatten() {
                poses += p.exterior.center.sum()
                    + p.exterior.rotation.sum()
                    + p.sigma0
                    + p.covariance.sum();
            }
        }
    }
    println!("{frames} frames × {rounds} rounds, {ok} identified targets, Σ centres {check:.9}");
    println!("Σ poses {poses:.15e}");
}
