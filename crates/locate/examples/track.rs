//! A small driver for profiling tracking mode: renders frames of the
//! default plate seen from 1000 mm while the camera moves 0.04 mm per frame
//! along a circle (as `photopose bench` tracks at 1000 frames/s and 40 mm/s),
//! locates the first whole and tracks the rest, many rounds. Run it under
//! `perf record` or `valgrind --tool=callgrind --toggle-collect='*Locator*track*'`
//! in a release build. Arguments: frames (default 20), rounds (default 200).

use photopose_field::design::default_plate;
use photopose_geometry::{Camera, Exterior, Vector3};
use photopose_locate::track::{Motion, Prior, TrackOptions};
use photopose_locate::{LocateOptions, Locator};
use photopose_render::{RenderOptions, Renderer};

fn main() {
    let mut args = std::env::args().skip(1);
    let frames: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(20);
    let rounds: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(200);
    let field = default_plate();
    let mut renderer =
        Renderer::new(Camera::reference(), &field, RenderOptions::default()).expect("renderer");
    let mut images = Vec::new();
    for k in 0..frames {
        let a = k as f64 * 0.001;
        let eye = Vector3::new(-60.0 + 40.0 * a.cos(), 40.0 * a.sin(), 1000.0);
        let e = Exterior::look_at(
            eye,
            Vector3::new(eye.x, eye.y, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
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
    let cam = Camera::reference();
    let (c, px) = (cam.interior.c, cam.sensor.pixel_size);
    let mut locator = Locator::new(cam, field, LocateOptions::default()).expect("locator");
    let first = locator.locate(images[0].view()).expect("locate");
    let pose = *first.pose.expect("a pose of the first frame");
    let threshold = first.detections.threshold;
    let options = TrackOptions::default();
    let (mut tracked, mut targets) = (0usize, 0usize);
    let mut check = 0.0f64;
    // Further check values: the rotations, σ0, the covariances and the
    // tracked targets' centres (bit-identical results keep all of them).
    let (mut rot, mut sig, mut cov, mut cen) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for _ in 0..rounds {
        let mut motion = Motion {
            last: (0, pose.exterior),
            before: None,
        };
        for (k, img) in images.iter().enumerate().skip(1) {
            let (exterior, motion_px) = motion.predict(k as u64, c, px, 1000.0);
            let prior = Prior {
                exterior,
                covariance: pose.covariance,
                motion_px,
                threshold,
            };
            if let Ok(p) = locator.track(img.view(), &prior, &options).copied() {
                tracked += 1;
                targets += p.n_points;
                check += p.exterior.center.sum();
                rot += p.exterior.rotation.sum();
                sig += p.sigma0;
                cov += p.covariance.sum();
                cen += locator
                    .identified()
                    .iter()
                    .map(|t| t.col * 3.0 + t.row)
                    .sum::<f64>();
                motion = Motion {
                    last: (k as u64, p.exterior),
                    before: Some(motion.last),
                };
            }
        }
    }
    println!(
        "{frames} frames × {rounds} rounds: {tracked} tracked, {:.0} targets each, Σ centres {check:.12}",
        targets as f64 / tracked.max(1) as f64
    );
    println!(
        "Σ rotations {rot:.15e}, Σ σ0 {sig:.15e}, Σ covariances {cov:.15e}, Σ targets {cen:.15e}"
    );
}
