//! The collinearity equations linearised over many points at once, in
//! structure-of-arrays form so that the per-point arithmetic and the
//! normal-equation products vectorise. Owned by [`crate::resection`].
//!
//! With `R = R0 · cayley(a, b, c)` linearised at zero increments, the
//! analytic derivative is `R0 · dcayley/da_k (0) = 2 R0 [e_k]ₓ`, so
//! `dZ/da_k = 2 (R0 e_k) × Z`: the partials of
//! [`crate::rotation::cayley_derivatives`] in their cheapest form (a test
//! checks that the two agree).

use crate::error::GeometryError;
use crate::exterior::Exterior;
use crate::resection::{Observation, Status};
use nalgebra::{Matrix6, Vector6};
use wide::f64x2;

/// Normal equations of the six exterior unknowns `(Xc, Yc, Zc, a, b, c)`.
#[derive(Debug, Clone, Copy)]
pub struct Normals {
    /// `AᵀA` (unit weights).
    pub n: Matrix6<f64>,
    /// `Aᵀv`.
    pub g: Vector6<f64>,
    /// `vᵀv`, mm².
    pub cost: f64,
    /// Points.
    pub count: usize,
}

/// Workspace: the used points and their Jacobian rows and residuals.
#[derive(Debug, Clone, Default)]
pub struct Linearised {
    /// Index into the observation slice of each used point.
    pub idx: Vec<usize>,
    /// Object point and ideal image point of each used point.
    pts: Vec<[f64; 5]>,
    /// Jacobian rows of `x` then `y` (six columns each) of each point.
    rows: Vec<[f64; 12]>,
    /// Residuals observed − computed.
    v: Vec<[f64; 2]>,
}

impl Linearised {
    /// Copies the loaded points of `other` (same observations, same status).
    pub fn load_from(&mut self, other: &Linearised) {
        self.idx.clone_from(&other.idx);
        self.pts.clone_from(&other.pts);
        let n = self.idx.len();
        self.rows.resize(n, [0.0; 12]);
        self.v.resize(n, [0.0; 2]);
    }

    /// Loads the used observations.
    pub fn load(&mut self, obs: &[Observation], status: &[Status]) {
        self.idx.clear();
        self.pts.clear();
        for (k, (o, s)) in obs.iter().zip(status).enumerate() {
            if *s != Status::Used {
                continue;
            }
            self.idx.push(k);
            self.pts
                .push([o.object.x, o.object.y, o.object.z, o.image.x, o.image.y]);
        }
        // `evaluate` overwrites every row: only grow or shrink, never clear.
        let n = self.idx.len();
        self.rows.resize(n, [0.0; 12]);
        self.v.resize(n, [0.0; 2]);
    }

    /// Number of points loaded.
    pub fn len(&self) -> usize {
        self.idx.len()
    }

    /// Whether no point is loaded.
    pub fn is_empty(&self) -> bool {
        self.idx.is_empty()
    }

    /// Linearises at `e` (principal distance `c`) and forms the normal
    /// equations in the same pass.
    pub fn evaluate(&mut self, c: f64, e: &Exterior) -> Result<Normals, GeometryError> {
        let r = &e.rotation;
        let (cx, cy, cz) = (e.center.x, e.center.y, e.center.z);
        let rr = [
            [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
            [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
            [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
        ];
        // Two SIMD lanes per quantity: the x row and the y row of a point.
        let mut acc = [f64x2::ZERO; 21];
        let mut g = [f64x2::ZERO; 6];
        let mut cost = f64x2::ZERO;
        let mut behind = 0usize;
        for ((p, row), v) in self.pts.iter().zip(&mut self.rows).zip(&mut self.v) {
            let (ux, uy, uz) = (p[0] - cx, p[1] - cy, p[2] - cz);
            let zx = rr[0][0] * ux + rr[0][1] * uy + rr[0][2] * uz;
            let zy = rr[1][0] * ux + rr[1][1] * uy + rr[1][2] * uz;
            let zz = rr[2][0] * ux + rr[2][1] * uy + rr[2][2] * uz;
            behind += (zz >= 0.0) as usize;
            let inv = 1.0 / zz;
            let gg = f64x2::new([zx * inv, zy * inv]);
            let f = f64x2::splat(-c * inv);
            let vv = f64x2::new([p[3], p[4]]) + f64x2::splat(c) * gg;
            // a[k] = (dx/dp_k, dy/dp_k).
            let mut a = [f64x2::ZERO; 6];
            for k in 0..3 {
                let (r0, r1, r2) = (rr[0][k], rr[1][k], rr[2][k]);
                // Centre: dZ/dC_k = -R e_k.
                a[k] = f * (gg * f64x2::splat(r2) - f64x2::new([r0, r1]));
                // Rotation increment k: dZ = 2 (R e_k) × Z.
                let dz = f64x2::new([2.0 * (r1 * zz - r2 * zy), 2.0 * (r2 * zx - r0 * zz)]);
                let dzz = f64x2::splat(2.0 * (r0 * zy - r1 * zx));
                a[3 + k] = f * (dz - gg * dzz);
            }
            let mut m = 0;
            for i in 0..6 {
                for j in i..6 {
                    acc[m] += a[i] * a[j];
                    m += 1;
                }
                g[i] += a[i] * vv;
            }
            cost += vv * vv;
            for k in 0..6 {
                let [x, y] = a[k].to_array();
                row[k] = x;
                row[6 + k] = y;
            }
            *v = vv.to_array();
        }
        if behind > 0 {
            return Err(GeometryError::BehindCamera { count: behind });
        }
        let mut nm = Matrix6::zeros();
        let mut m = 0;
        for i in 0..6 {
            for j in i..6 {
                nm[(i, j)] = acc[m].reduce_add();
                nm[(j, i)] = nm[(i, j)];
                m += 1;
            }
        }
        Ok(Normals {
            n: nm,
            g: Vector6::from_fn(|i, _| g[i].reduce_add()),
            cost: cost.reduce_add(),
            count: self.len(),
        })
    }

    /// Moves the residuals by a small parameter step `delta` (linear
    /// prediction: `v - A δ`) and returns the new cost.
    pub fn shift(&mut self, delta: &Vector6<f64>) -> f64 {
        let mut cost = 0.0;
        for (row, v) in self.rows.iter().zip(&mut self.v) {
            let mut dx = 0.0;
            let mut dy = 0.0;
            for k in 0..6 {
                dx += row[k] * delta[k];
                dy += row[6 + k] * delta[k];
            }
            v[0] -= dx;
            v[1] -= dy;
            cost += v[0] * v[0] + v[1] * v[1];
        }
        cost
    }

    /// Data snooping: the point with the largest standardised residual
    /// `w = |v| / (σ sqrt(q_vv))`, `q_vv = 1 - aᵀ Q a` (unit weights), over
    /// both image coordinates; returns its index among the loaded points and `w`.
    pub fn worst_standardised(&self, q: &Matrix6<f64>, sigma: f64) -> Option<(usize, f64)> {
        let mut qp = [0.0f64; 21];
        let mut m = 0;
        for i in 0..6 {
            for j in i..6 {
                qp[m] = if i == j { q[(i, i)] } else { 2.0 * q[(i, j)] };
                m += 1;
            }
        }
        let mut worst: Option<(usize, f64)> = None;
        for (k, (row, v)) in self.rows.iter().zip(&self.v).enumerate() {
            let a: [f64x2; 6] = std::array::from_fn(|i| f64x2::new([row[i], row[6 + i]]));
            let mut quad = f64x2::ZERO;
            let mut m = 0;
            for i in 0..6 {
                for j in i..6 {
                    quad += f64x2::splat(qp[m]) * a[i] * a[j];
                    m += 1;
                }
            }
            let [qx, qy] = quad.to_array();
            let w = (v[0].abs() / (1.0 - qx).max(1e-12).sqrt())
                .max(v[1].abs() / (1.0 - qy).max(1e-12).sqrt())
                / sigma;
            if worst.is_none_or(|(_, ww)| w > ww) {
                worst = Some((k, w));
            }
        }
        worst
    }

    /// The two Jacobian rows and residuals of point `i`.
    pub fn row(&self, i: usize) -> (Vector6<f64>, Vector6<f64>, f64, f64) {
        let r = &self.rows[i];
        let ax = Vector6::from_fn(|k, _| r[k]);
        let ay = Vector6::from_fn(|k, _| r[6 + k]);
        (ax, ay, self.v[i][0], self.v[i][1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotation::{cayley, cayley_derivatives};
    use nalgebra::{Vector2, Vector3};

    #[test]
    fn partials_equal_the_cayley_derivatives_and_finite_differences() {
        // A tilted, turned camera looking down at the point.
        let r = cayley(0.2, -0.15, 0.8);
        let center = Vector3::new(10.0, -20.0, 900.0);
        let o = Observation {
            id: 1,
            object: Vector3::new(120.0, 45.0, 3.0),
            image: Vector2::new(0.1, -0.2),
        };
        let e = Exterior::new(r, center);
        assert!(e.to_camera(&o.object).z < 0.0);
        let mut lin = Linearised::default();
        lin.load(&[o], &[Status::Used]);
        lin.evaluate(12.0, &e).unwrap();
        let (ax, ay, _, _) = lin.row(0);
        // The general analytic derivative R0 · dcayley/da_k at zero.
        let d = cayley_derivatives(0.0, 0.0, 0.0);
        let u = o.object - e.center;
        let z = e.rotation * u;
        for k in 0..3 {
            let dz = e.rotation * d[k] * u;
            let dx = -12.0 * (dz.x * z.z - z.x * dz.z) / (z.z * z.z);
            let dy = -12.0 * (dz.y * z.z - z.y * dz.z) / (z.z * z.z);
            assert!((ax[3 + k] - dx).abs() < 1e-12 * dx.abs().max(1.0), "k={k}");
            assert!((ay[3 + k] - dy).abs() < 1e-12 * dy.abs().max(1.0), "k={k}");
        }
        // Central differences over all six unknowns.
        let h = 1e-6;
        let proj = |p: &[f64; 6]| {
            let r = e.rotation * cayley(p[3], p[4], p[5]);
            let z = r * (o.object - (e.center + Vector3::new(p[0], p[1], p[2])));
            Vector2::new(-12.0 * z.x / z.z, -12.0 * z.y / z.z)
        };
        for k in 0..6 {
            let mut p = [0.0; 6];
            p[k] = h;
            let plus = proj(&p);
            p[k] = -h;
            let minus = proj(&p);
            let fd = (plus - minus) / (2.0 * h);
            assert!(
                (fd.x - ax[k]).abs() < 1e-6 * fd.x.abs().max(1e-3),
                "x k={k}: {} vs {}",
                fd.x,
                ax[k]
            );
            assert!(
                (fd.y - ay[k]).abs() < 1e-6 * fd.y.abs().max(1e-3),
                "y k={k}: {} vs {}",
                fd.y,
                ay[k]
            );
        }
    }
}
