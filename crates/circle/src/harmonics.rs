//! The harmonic (Fourier) filter of a profile over the phase angle: the
//! least-squares series `a₀ + Σₖ (aₖ cos kθ + bₖ sin kθ)`, `k = 1..=K`, through
//! the samples. It keeps the undulations of up to `K` per revolution (UPR),
//! as roundness and ballbar software filter a profile, removes the
//! sample-to-sample noise, and works on unevenly spaced or repeated angles
//! as long as no gap in the circle is wider than half the shortest period.

use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use std::f64::consts::{PI, TAU};

/// One term of a series: `amplitude · cos(k θ − phase)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Term {
    /// Undulations per revolution `k`.
    pub order: u32,
    /// Amplitude (unit of the profile).
    pub amplitude: f64,
    /// Phase `φ` of `cos(kθ − φ)`, degrees.
    pub phase_deg: f64,
}

/// A fitted harmonic series.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Mean `a₀`.
    pub mean: f64,
    /// `(aₖ, bₖ)` for `k = 1..=K`.
    pub coefficients: Vec<(f64, f64)>,
}

/// Points of the uniform grid over which a series' extremes are found
/// (0.1° steps).
pub const GRID: usize = 3600;

impl Series {
    /// The least-squares series of order `order` through `(θ, y)` samples
    /// (`θ` in radians). `None` if there are too few samples or a gap in
    /// the angles wider than half the period of the highest order, where
    /// the series would be unconstrained.
    pub fn fit(angles: &[f64], values: &[f64], order: u32) -> Option<Series> {
        let m = 2 * order as usize + 1;
        if angles.len() != values.len() || angles.len() < 2 * m {
            return None;
        }
        if order > 0 && largest_gap(angles) >= PI / order as f64 {
            return None;
        }
        let mut n = DMatrix::<f64>::zeros(m, m);
        let mut rhs = DVector::<f64>::zeros(m);
        let mut row = DVector::<f64>::zeros(m);
        for (&t, &y) in angles.iter().zip(values) {
            basis(t, order, row.as_mut_slice());
            n.ger(1.0, &row, &row, 1.0);
            rhs.axpy(y, &row, 1.0);
        }
        let x = n.cholesky()?.solve(&rhs);
        Some(Series {
            mean: x[0],
            coefficients: (0..order as usize)
                .map(|k| (x[1 + 2 * k], x[2 + 2 * k]))
                .collect(),
        })
    }

    /// The series' value at `theta` (radians).
    pub fn eval(&self, theta: f64) -> f64 {
        self.mean
            + self
                .coefficients
                .iter()
                .enumerate()
                .map(|(k, (a, b))| {
                    let kt = (k + 1) as f64 * theta;
                    a * kt.cos() + b * kt.sin()
                })
                .sum::<f64>()
    }

    /// Minimum and maximum over a uniform grid of [`GRID`] angles.
    pub fn extremes(&self) -> (f64, f64) {
        (0..GRID)
            .map(|i| self.eval(TAU * i as f64 / GRID as f64))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| {
                (lo.min(y), hi.max(y))
            })
    }

    /// The terms as amplitude and phase.
    pub fn terms(&self) -> Vec<Term> {
        self.coefficients
            .iter()
            .enumerate()
            .map(|(k, &(a, b))| Term {
                order: k as u32 + 1,
                amplitude: a.hypot(b),
                phase_deg: b.atan2(a).to_degrees(),
            })
            .collect()
    }
}

/// `[1, cos θ, sin θ, cos 2θ, sin 2θ, …]` into `out`.
fn basis(theta: f64, order: u32, out: &mut [f64]) {
    out[0] = 1.0;
    for k in 1..=order as usize {
        let kt = k as f64 * theta;
        out[2 * k - 1] = kt.cos();
        out[2 * k] = kt.sin();
    }
}

/// The widest gap (radians) between neighbouring angles around the circle.
pub fn largest_gap(angles: &[f64]) -> f64 {
    if angles.is_empty() {
        return TAU;
    }
    let mut a: Vec<f64> = angles.iter().map(|t| t.rem_euclid(TAU)).collect();
    a.sort_by(f64::total_cmp);
    let wrap = a[0] + TAU - a[a.len() - 1];
    a.windows(2).map(|w| w[1] - w[0]).fold(wrap, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_band_limited_profile_is_reproduced_and_noise_is_averaged() {
        let truth = |t: f64| 0.01 * (2.0 * t - 0.3).cos() + 0.004 * (5.0 * t).sin() + 0.2;
        let angles: Vec<f64> = (0..2000).map(|i| 0.3 + i as f64 * TAU / 2000.0).collect();
        let clean: Vec<f64> = angles.iter().map(|&t| truth(t)).collect();
        let s = Series::fit(&angles, &clean, 15).unwrap();
        for i in 0..100 {
            let t = i as f64 * 0.0628;
            assert!((s.eval(t) - truth(t)).abs() < 1e-12);
        }
        let terms = s.terms();
        assert!(
            (terms[1].amplitude - 0.01).abs() < 1e-12
                && (terms[1].phase_deg - 0.3f64.to_degrees()).abs() < 1e-9
        );
        assert!((terms[4].amplitude - 0.004).abs() < 1e-12);
        // Noise: alternating ±0.05 is far above order 15 and filtered out.
        let noisy: Vec<f64> = clean
            .iter()
            .enumerate()
            .map(|(i, y)| y + if i % 2 == 0 { 0.05 } else { -0.05 })
            .collect();
        let s = Series::fit(&angles, &noisy, 15).unwrap();
        let (lo, hi) = s.extremes();
        let (tlo, thi) = Series::fit(&angles, &clean, 15).unwrap().extremes();
        assert!(
            (lo - tlo).abs() < 1e-6 && (hi - thi).abs() < 1e-6,
            "{lo} {hi}"
        );
    }

    #[test]
    fn a_half_circle_cannot_be_filtered() {
        let angles: Vec<f64> = (0..500).map(|i| i as f64 * PI / 500.0).collect();
        let values = vec![0.0; 500];
        assert!(Series::fit(&angles, &values, 15).is_none());
        assert!((largest_gap(&angles) - (PI + PI / 500.0)).abs() < 1e-9);
    }
}
