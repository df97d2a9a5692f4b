//! Monte Carlo check of the predicted precision: a known exterior
//! orientation, the field's points projected through the camera, Gaussian
//! image noise of a given σ from a seeded generator, resected many times;
//! the empirical standard deviations and mean errors of the centre and of
//! the small rotations about the field axes, to set beside
//! [`crate::precision::predict`].

use crate::camera::Camera;
use crate::exterior::Exterior;
use crate::observation::Observation;
use crate::resection::{Resection, ResectionOptions};
use crate::rng::SplitMix64;
use nalgebra::Vector3;

/// What the trials gave (mm for the centre, radians for the rotations).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonteCarlo {
    /// Trials that gave a pose.
    pub solved: usize,
    /// Trials that did not.
    pub failed: usize,
    /// Empirical σ of `X, Y, Z`, mm.
    pub std_center: [f64; 3],
    /// Empirical σ of the small rotations `ωX, ωY, ωZ`, rad.
    pub std_rotation: [f64; 3],
    /// Mean error of `X, Y, Z`, mm.
    pub mean_error_center: [f64; 3],
    /// Mean error of `ωX, ωY, ωZ`, rad.
    pub mean_error_rotation: [f64; 3],
}

/// Resects `trials` noisy images of `points` (id, field position) seen
/// from `truth` with image noise `sigma_px`, drawing from `rng`.
pub fn monte_carlo(
    camera: &Camera,
    truth: &Exterior,
    points: &[(u64, Vector3<f64>)],
    sigma_px: f64,
    trials: usize,
    rng: &mut SplitMix64,
) -> MonteCarlo {
    let mut rs = Resection::new(camera, ResectionOptions::default());
    let mut obs = Vec::with_capacity(points.len());
    let mut sum = [0.0f64; 6];
    let mut sum2 = [0.0f64; 6];
    let mut ok = 0usize;
    for _ in 0..trials {
        obs.clear();
        for (id, p) in points {
            let Some(px) = truth.project_pixel(camera, p) else {
                continue;
            };
            obs.push(Observation::from_pixel(
                camera,
                *id,
                *p,
                px.x + sigma_px * rng.normal(),
                px.y + sigma_px * rng.normal(),
            ));
        }
        let Ok(r) = rs.solve(&obs) else { continue };
        ok += 1;
        let e = r.exterior.deviation_from(truth);
        for k in 0..6 {
            sum[k] += e[k];
            sum2[k] += e[k] * e[k];
        }
    }
    let n = ok.max(2) as f64;
    let mean: [f64; 6] = std::array::from_fn(|k| sum[k] / n);
    let std: [f64; 6] = std::array::from_fn(|k| {
        ((sum2[k] - n * mean[k] * mean[k]) / (n - 1.0))
            .max(0.0)
            .sqrt()
    });
    MonteCarlo {
        solved: ok,
        failed: trials - ok,
        std_center: [std[0], std[1], std[2]],
        std_rotation: [std[3], std[4], std[5]],
        mean_error_center: [mean[0], mean[1], mean[2]],
        mean_error_rotation: [mean[3], mean[4], mean[5]],
    }
}
