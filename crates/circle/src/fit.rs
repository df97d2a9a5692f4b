//! Least-squares fits: the plane of 3-D points (smallest principal axis of
//! their scatter) and the circle of 2-D points in that plane — the ISO 230-4
//! least-squares circle, minimising the sum of squared orthogonal (radial)
//! distances: an algebraic (Kåsa) start, then Gauss–Newton on the geometric
//! distances.

use crate::error::CircleError;
use nalgebra::{Matrix3, SymmetricEigen, Vector2, Vector3};

/// A fitted plane with an in-plane frame `(u, v, normal)` (right-handed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// Centroid of the points (a point of the plane), mm.
    pub point: Vector3<f64>,
    /// Unit normal, oriented towards the field's `+Z` (or `+X`, `+Y` for a
    /// plane that contains `Z`).
    pub normal: Vector3<f64>,
    /// First in-plane axis: the field's `X` projected into the plane (its
    /// `Y` if the plane is nearly perpendicular to `X`).
    pub u: Vector3<f64>,
    /// Second in-plane axis, `normal × u`.
    pub v: Vector3<f64>,
}

impl Plane {
    /// Least-squares plane of `points` (at least 3, not collinear).
    pub fn fit(points: &[Vector3<f64>]) -> Result<Plane, CircleError> {
        if points.len() < 3 {
            return Err(CircleError::TooFewSamples {
                what: "plane fit",
                got: points.len(),
                need: 3,
            });
        }
        let n = points.len() as f64;
        let point = points.iter().sum::<Vector3<f64>>() / n;
        let mut scatter = Matrix3::zeros();
        for p in points {
            let d = p - point;
            scatter += d * d.transpose();
        }
        let eig = SymmetricEigen::new(scatter);
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let (small, mid, large) = (
            eig.eigenvalues[order[0]].max(0.0),
            eig.eigenvalues[order[1]].max(0.0),
            eig.eigenvalues[order[2]].max(0.0),
        );
        if mid.partial_cmp(&(1e-18 * large.max(1e-300))) != Some(std::cmp::Ordering::Greater)
            || !large.is_finite()
        {
            return Err(CircleError::Collinear {
                spread_mm: ((small + mid) / n).sqrt(),
            });
        }
        let mut normal: Vector3<f64> = eig.eigenvectors.column(order[0]).into_owned().normalize();
        let sign = [normal.z, normal.x, normal.y]
            .into_iter()
            .find(|c| c.abs() > 1e-9)
            .unwrap_or(1.0);
        if sign < 0.0 {
            normal = -normal;
        }
        let project = |a: Vector3<f64>| a - normal * normal.dot(&a);
        let ux = project(Vector3::x());
        let u = if ux.norm() > 0.1 {
            ux.normalize()
        } else {
            project(Vector3::y()).normalize()
        };
        let v = normal.cross(&u);
        Ok(Plane {
            point,
            normal,
            u,
            v,
        })
    }

    /// In-plane coordinates `(u, v)` of `p`, mm.
    pub fn to_plane(&self, p: &Vector3<f64>) -> Vector2<f64> {
        let d = p - self.point;
        Vector2::new(self.u.dot(&d), self.v.dot(&d))
    }

    /// Signed distance of `p` from the plane along the normal, mm.
    pub fn distance(&self, p: &Vector3<f64>) -> f64 {
        self.normal.dot(&(p - self.point))
    }

    /// The 3-D point of in-plane coordinates `(u, v)`.
    pub fn to_space(&self, q: &Vector2<f64>) -> Vector3<f64> {
        self.point + self.u * q.x + self.v * q.y
    }
}

/// A least-squares circle in the plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Circle {
    /// Centre in plane coordinates, mm.
    pub center: Vector2<f64>,
    /// Radius, mm.
    pub radius: f64,
    /// Standard deviations of the centre's `u`, `v` and of the radius, mm
    /// (a-posteriori: `σ0² (JᵀJ)⁻¹`, `σ0² = Σd² / (n − 3)`).
    pub std: [f64; 3],
    /// Root mean square of the radial deviations, mm.
    pub rms: f64,
    /// Gauss–Newton iterations after the algebraic start.
    pub iterations: usize,
}

/// Iteration limit of the Gauss–Newton circle fit.
const MAX_ITERATIONS: usize = 100;
/// Relative step size (to `1 + r`) below which a step is taken whole,
/// without the line search (1e-6: 41 nm for a 40 mm circle).
const WHOLE_STEP: f64 = 1e-6;
/// Relative step size (to `1 + r`) below which steps that stop shrinking
/// mean the fit has converged to round-off (1e-9: 40 pm for a 40 mm circle).
const ROUND_OFF_STEP: f64 = 1e-9;

impl Circle {
    /// The least-squares circle of `points` (plane coordinates, mm; at
    /// least 3): Kåsa's algebraic fit as a start, then Gauss–Newton on the
    /// orthogonal distances `|p − c| − r` (step halving if a step does not
    /// lower the sum of squares; near the minimum, where the sum no longer
    /// resolves a step's gain, steps taken whole until they reach the
    /// tolerance or stop shrinking at round-off).
    pub fn fit(points: &[Vector2<f64>]) -> Result<Circle, CircleError> {
        if points.len() < 3 {
            return Err(CircleError::TooFewSamples {
                what: "circle fit",
                got: points.len(),
                need: 3,
            });
        }
        let n = points.len();
        // Work around the centroid for conditioning.
        let mean = points.iter().sum::<Vector2<f64>>() / n as f64;
        // Kåsa: x² + y² + D x + E y + F = 0 in the least-squares sense.
        let mut nm = Matrix3::zeros();
        let mut rhs = Vector3::zeros();
        for p in points {
            let q = p - mean;
            let row = Vector3::new(q.x, q.y, 1.0);
            nm += row * row.transpose();
            rhs -= row * q.norm_squared();
        }
        let sol = nm
            .cholesky()
            .map(|c| c.solve(&rhs))
            .ok_or(CircleError::Collinear { spread_mm: 0.0 })?;
        let mut c = Vector2::new(-sol.x / 2.0, -sol.y / 2.0);
        let r2 = c.norm_squared() - sol.z;
        if !(r2 > 0.0 && r2.is_finite()) {
            return Err(CircleError::Collinear { spread_mm: 0.0 });
        }
        let mut r = r2.sqrt();
        let cost = |c: &Vector2<f64>, r: f64| -> f64 {
            points
                .iter()
                .map(|p| {
                    let d = (p - mean - c).norm() - r;
                    d * d
                })
                .sum()
        };
        let mut current = cost(&c, r);
        let mut iterations = 0;
        let mut last_step = f64::INFINITY;
        let mut jtj = Matrix3::zeros();
        loop {
            jtj.fill(0.0);
            let mut jtd = Vector3::zeros();
            for p in points {
                let q = p - mean - c;
                let rho = q.norm();
                if rho < 1e-300 {
                    continue;
                }
                let j = Vector3::new(-q.x / rho, -q.y / rho, -1.0);
                let d = rho - r;
                jtj += j * j.transpose();
                jtd += j * d;
            }
            let Some(chol) = jtj.cholesky() else {
                return Err(CircleError::Collinear { spread_mm: 0.0 });
            };
            let step = -chol.solve(&jtd);
            let step_size = step.norm();
            // Converged: a step at the tolerance, or steps that no longer
            // shrink once below `ROUND_OFF_STEP` (the normal equations'
            // round-off: with points far from the origin the step wanders
            // at about 1e-11 mm and may never reach the tolerance).
            if step_size <= 1e-13 * (1.0 + r)
                || (step_size <= ROUND_OFF_STEP * (1.0 + r) && step_size >= 0.5 * last_step)
            {
                break;
            }
            last_step = step_size;
            iterations += 1;
            if iterations > MAX_ITERATIONS {
                return Err(CircleError::NotConverged {
                    iterations: MAX_ITERATIONS,
                    step_mm: step_size,
                });
            }
            if step_size <= WHOLE_STEP * (1.0 + r) {
                // Near the minimum the sum of squares no longer resolves
                // what a step gains (its change is below the sum's own
                // round-off): the Gauss–Newton step is taken whole.
                c += Vector2::new(step.x, step.y);
                r += step.z;
                current = cost(&c, r);
                continue;
            }
            let mut t = 1.0;
            loop {
                let c_new = c + Vector2::new(step.x, step.y) * t;
                let r_new = r + step.z * t;
                let new = cost(&c_new, r_new);
                if new <= current || t < 1e-6 {
                    c = c_new;
                    r = r_new;
                    current = new;
                    break;
                }
                t *= 0.5;
            }
            if t < 1e-6 {
                break;
            }
        }
        let dof = (n as f64 - 3.0).max(1.0);
        let s0 = current / dof;
        let q = jtj.try_inverse().unwrap_or_else(Matrix3::zeros);
        Ok(Circle {
            center: c + mean,
            radius: r,
            std: [
                (s0 * q[(0, 0)]).sqrt(),
                (s0 * q[(1, 1)]).sqrt(),
                (s0 * q[(2, 2)]).sqrt(),
            ],
            rms: (current / n as f64).sqrt(),
            iterations,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_exact_tilted_circle_is_recovered() {
        let axis = Vector3::new(0.2, -0.1, 1.0).normalize();
        let a = axis.cross(&Vector3::x()).normalize();
        let b = axis.cross(&a);
        let centre = Vector3::new(12.0, -40.0, 700.0);
        let pts: Vec<_> = (0..50)
            .map(|i| {
                let t = i as f64 * 0.3;
                centre + (a * t.cos() + b * t.sin()) * 149.9
            })
            .collect();
        let plane = Plane::fit(&pts).unwrap();
        assert!((plane.normal - axis).norm() < 1e-10, "{}", plane.normal);
        let q: Vec<_> = pts.iter().map(|p| plane.to_plane(p)).collect();
        let c = Circle::fit(&q).unwrap();
        assert!((c.radius - 149.9).abs() < 1e-10);
        assert!((plane.to_space(&c.center) - centre).norm() < 1e-10);
        assert!(c.rms < 1e-10);
    }

    #[test]
    fn an_arc_with_noise_is_fitted_geometrically() {
        // A 90° arc: Kåsa's algebraic fit is biased there, the geometric fit
        // must not be (noise-free points off by a known radial pattern).
        let pts: Vec<_> = (0..200)
            .map(|i| {
                let t = i as f64 / 199.0 * std::f64::consts::FRAC_PI_2;
                let r = 100.0 + 0.5 * (4.0 * t * 4.0).sin();
                Vector2::new(3.0 + r * t.cos(), 4.0 + r * t.sin())
            })
            .collect();
        let c = Circle::fit(&pts).unwrap();
        assert!((c.radius - 100.0).abs() < 0.05, "{}", c.radius);
        assert!(c.iterations >= 1);
        // The geometric fit is a minimum: the gradient vanishes.
        let g: Vector3<f64> = pts
            .iter()
            .map(|p| {
                let q = p - c.center;
                let rho = q.norm();
                Vector3::new(-q.x / rho, -q.y / rho, -1.0) * (rho - c.radius)
            })
            .sum();
        assert!(g.norm() < 1e-8, "{g}");
    }

    #[test]
    fn degenerate_input_is_refused() {
        let line: Vec<_> = (0..10).map(|i| Vector3::new(i as f64, 0.0, 0.0)).collect();
        assert!(matches!(
            Plane::fit(&line),
            Err(CircleError::Collinear { .. })
        ));
        assert!(matches!(
            Circle::fit(&[Vector2::zeros(), Vector2::x()]),
            Err(CircleError::TooFewSamples { got: 2, .. })
        ));
    }

    #[test]
    fn uneven_point_sets_far_from_the_origin_converge_to_the_minimum() {
        // A dozen to twenty points of a little more than one turn (the
        // circle test's frames), far from the origin, with a radial
        // pattern and noise: in about one case in twelve the step stops
        // shrinking at its round-off (about 1e-11 mm) above the step
        // tolerance; the fit must stop there as converged, at the minimum,
        // not fail after 100 iterations.
        let mut s = 12345u64;
        let mut u = || {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for case in 0..400 {
            let n = 12 + (u() * 10.0) as usize;
            let (cx, cy) = (u() * 4000.0 - 2000.0, u() * 4000.0 - 2000.0);
            let r = 10.0 + u() * 200.0;
            let noise = 10f64.powf(-4.0 + 3.0 * u());
            let turn = std::f64::consts::TAU / (n as f64 - 2.0 * u());
            let pts: Vec<_> = (0..n)
                .map(|i| {
                    let t = i as f64 * turn;
                    let rr = r + noise * (u() - 0.5) + 0.2 * (2.0 * t + 1.0).sin() * u();
                    Vector2::new(cx + rr * t.cos(), cy + rr * t.sin())
                })
                .collect();
            let c = Circle::fit(&pts).unwrap_or_else(|e| panic!("case {case}: {e}"));
            // At the minimum the Gauss–Newton step left is round-off.
            let (mut jtj, mut g) = (Matrix3::zeros(), Vector3::zeros());
            for p in &pts {
                let q = p - c.center;
                let rho = q.norm();
                let j = Vector3::new(-q.x / rho, -q.y / rho, -1.0);
                jtj += j * j.transpose();
                g += j * (rho - c.radius);
            }
            let step = jtj.cholesky().expect("normal equations").solve(&g);
            assert!(step.norm() < 1e-9, "case {case}: step left {step}");
        }
    }
}
