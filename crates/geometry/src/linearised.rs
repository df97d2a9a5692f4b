//! The collinearity equations linearised over many points at once, in
//! structure-of-arrays form so that the per-point arithmetic and the
//! normal-equation products vectorise. Used by the resection and by precision
//! prediction; imports neither.
//!
//! With `R = R0 · cayley(a, b, c)` linearised at zero increments, the
//! analytic derivative is `R0 · dcayley/da_k (0) = 2 R0 [e_k]ₓ`, so
//! `dZ/da_k = 2 (R0 e_k) × Z`: the partials of
//! [`crate::rotation::cayley_derivatives`] in their cheapest form (a test
//! checks that the two agree).

use crate::error::GeometryError;
use crate::exterior::Exterior;
use crate::observation::{Observation, Status};
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
///
/// Each point keeps its x and y equations interleaved,
/// `[ax0, ay0, ax1, ay1, …, ax5, ay5, vx, vy]`, so that one SIMD pair holds
/// the same column of both rows and `[A | v]ᵀ [A | v]` — normal matrix,
/// right-hand side and cost at once — accumulates in registers.
#[derive(Debug, Clone, Default)]
pub struct Linearised {
    /// Index into the observation slice of each used point.
    pub idx: Vec<usize>,
    /// Object point, ideal image point and the Cholesky factor
    /// `U = [[u00, u01], [0, u11]]` of the weight matrix (`W = UᵀU`) of
    /// each used point.
    pts: Vec<[f64; 8]>,
    /// Interleaved `[A | v]` rows of each point (the first `pts.len()`;
    /// the rest are left from a larger set).
    rows: Vec<[f64; 14]>,
    /// The rows of a candidate being tried ([`Linearised::evaluate_trial`]).
    trial: Vec<[f64; 14]>,
    /// Whether every weight is the identity (whitening skipped).
    unit_weights: bool,
}

/// Accumulates the rows `I` and `K` (`K > I`; only `I` when `K == I`) of
/// `[A | v]ᵀ [A | v]` (upper part) in one sweep over the points; few
/// enough accumulators to stay in registers.
#[inline(always)]
fn sweep<const I: usize, const K: usize>(rows: &[[f64; 14]], p: &mut [[f64; 7]; 7]) {
    let mut acc0 = [f64x2::ZERO; 7];
    let mut acc1 = [f64x2::ZERO; 7];
    for r in rows {
        let a: [f64x2; 7] = std::array::from_fn(|k| f64x2::new([r[2 * k], r[2 * k + 1]]));
        for j in I..7 {
            acc0[j] += a[I] * a[j];
        }
        if K > I {
            for j in K..7 {
                acc1[j] += a[K] * a[j];
            }
        }
    }
    for j in I..7 {
        p[I][j] = acc0[j].reduce_add();
        p[j][I] = p[I][j];
    }
    if K > I {
        for j in K..7 {
            p[K][j] = acc1[j].reduce_add();
            p[j][K] = p[K][j];
        }
    }
}

/// Fills `rows` with the whitened Jacobian rows and residuals of `pts` at `e`.
fn linearise_into(
    pts: &[[f64; 8]],
    unit: bool,
    rows: &mut [[f64; 14]],
    c: f64,
    e: &Exterior,
) -> Result<(), GeometryError> {
    let r = &e.rotation;
    let (cx, cy, cz) = (e.center.x, e.center.y, e.center.z);
    let rr = [
        [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
        [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
        [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
    ];
    // Column k's (r0, r1), (r1, r2) and (r2, r0) as SIMD pairs.
    let rxy: [f64x2; 3] = std::array::from_fn(|k| f64x2::new([rr[0][k], rr[1][k]]));
    let ryz: [f64x2; 3] = std::array::from_fn(|k| f64x2::new([rr[1][k], rr[2][k]]));
    let rzx: [f64x2; 3] = std::array::from_fn(|k| f64x2::new([rr[2][k], rr[0][k]]));
    let two = f64x2::splat(2.0);
    let mut behind = 0usize;
    for (p, row) in pts.iter().zip(rows.iter_mut()) {
        let (ux, uy, uz) = (p[0] - cx, p[1] - cy, p[2] - cz);
        // The x and y parts (of the camera point, of the two Jacobian
        // rows) as SIMD pairs: each lane computes exactly the scalar
        // expression, operation for operation.
        let zxy = rxy[0] * f64x2::splat(ux) + rxy[1] * f64x2::splat(uy) + rxy[2] * f64x2::splat(uz);
        let zz = rr[2][0] * ux + rr[2][1] * uy + rr[2][2] * uz;
        let [zx, zy] = zxy.to_array();
        behind += (zz >= 0.0) as usize;
        let inv = 1.0 / zz;
        let g = zxy * f64x2::splat(inv);
        let [gx, gy] = g.to_array();
        let f = f64x2::splat(-c * inv);
        // (r1, r2) · (zz, zx) − (r2, r0) · (zy, zz): the x and y of
        // (R e_k) × Z.
        let (zzx, zyz) = (f64x2::new([zz, zx]), f64x2::new([zy, zz]));
        for k in 0..3 {
            let (r0, r1, r2) = (rr[0][k], rr[1][k], rr[2][k]);
            // Centre: dZ/dC_k = -R e_k.
            let centre = f * (g * f64x2::splat(r2) - rxy[k]);
            // Rotation increment k: dZ = 2 (R e_k) × Z.
            let dzxy = two * (ryz[k] * zzx - rzx[k] * zyz);
            let dzz = 2.0 * (r0 * zy - r1 * zx);
            let turn = f * (dzxy - g * f64x2::splat(dzz));
            [row[2 * k], row[2 * k + 1]] = centre.to_array();
            [row[6 + 2 * k], row[7 + 2 * k]] = turn.to_array();
        }
        row[12] = p[3] + c * gx;
        row[13] = p[4] + c * gy;
        // Whitening by the weight's Cholesky factor: (x, y) ← U (x, y).
        if unit {
            continue;
        }
        let (u00, u01, u11) = (p[5], p[6], p[7]);
        for k in 0..7 {
            let (x, y) = (row[2 * k], row[2 * k + 1]);
            row[2 * k] = u00 * x + u01 * y;
            row[2 * k + 1] = u11 * y;
        }
    }
    if behind > 0 {
        return Err(GeometryError::BehindCamera { count: behind });
    }
    Ok(())
}

/// The normal equations of the current Jacobian and residuals. No allocation.
fn normals_of(rows: &[[f64; 14]]) -> Normals {
    let mut p = [[0.0f64; 7]; 7];
    // Rows 0 | 1, 6 | 2, 5 | 3, 4: each sweep holds at most 14 of the 16
    // SSE registers (accumulators and the columns it reads), none spilled.
    // Every sum runs over the points in order whatever the grouping.
    sweep::<0, 0>(rows, &mut p);
    sweep::<1, 6>(rows, &mut p);
    sweep::<2, 5>(rows, &mut p);
    sweep::<3, 4>(rows, &mut p);
    Normals {
        n: Matrix6::from_fn(|i, j| p[i][j]),
        g: Vector6::from_fn(|i, _| p[i][6]),
        cost: p[6][6],
        count: rows.len(),
    }
}

impl Linearised {
    /// Loads the used observations.
    pub fn load(&mut self, obs: &[Observation], status: &[Status]) {
        self.idx.clear();
        self.pts.clear();
        self.unit_weights = true;
        for (k, (o, s)) in obs.iter().zip(status).enumerate() {
            if *s != Status::Used {
                continue;
            }
            self.idx.push(k);
            let w = &o.weight;
            let (u00, u01, u11) = if *w == nalgebra::Matrix2::identity() {
                (1.0, 0.0, 1.0)
            } else {
                self.unit_weights = false;
                let u00 = w[(0, 0)].sqrt();
                let u01 = w[(0, 1)] / u00;
                (u00, u01, (w[(1, 1)] - u01 * u01).max(0.0).sqrt())
            };
            self.pts.push([
                o.object.x, o.object.y, o.object.z, o.image.x, o.image.y, u00, u01, u11,
            ]);
        }
        // `evaluate` overwrites every row of the loaded points: the rows
        // only grow (a set of fewer points uses the first rows; growing
        // them again would zero them again each frame).
        let n = self.idx.len();
        if self.rows.len() < n {
            self.rows.resize(n, [0.0; 14]);
            self.trial.resize(n, [0.0; 14]);
        }
    }

    /// Number of points loaded.
    pub fn len(&self) -> usize {
        self.idx.len()
    }

    /// Whether no point is loaded.
    pub fn is_empty(&self) -> bool {
        self.idx.is_empty()
    }

    /// Linearises at `e` (principal distance `c`) and forms the normal equations.
    pub fn evaluate(&mut self, c: f64, e: &Exterior) -> Result<Normals, GeometryError> {
        let rows = &mut self.rows[..self.pts.len()];
        linearise_into(&self.pts, self.unit_weights, rows, c, e)?;
        Ok(normals_of(rows))
    }

    /// Like [`Linearised::evaluate`] for a candidate, into separate rows that
    /// [`Linearised::accept_trial`] makes current.
    pub fn evaluate_trial(&mut self, c: f64, e: &Exterior) -> Result<Normals, GeometryError> {
        let rows = &mut self.trial[..self.pts.len()];
        linearise_into(&self.pts, self.unit_weights, rows, c, e)?;
        Ok(normals_of(rows))
    }

    /// Makes the rows of the last trial the current ones.
    pub fn accept_trial(&mut self) {
        std::mem::swap(&mut self.rows, &mut self.trial);
    }

    /// Moves the residuals by a small parameter step `delta` (linear
    /// prediction: `v - A δ`) and returns the new cost.
    pub fn shift(&mut self, delta: &Vector6<f64>) -> f64 {
        let d: [f64x2; 6] = std::array::from_fn(|k| f64x2::splat(delta[k]));
        let mut cost = f64x2::ZERO;
        for r in &mut self.rows[..self.pts.len()] {
            let mut v = f64x2::new([r[12], r[13]]);
            for (k, dk) in d.iter().enumerate() {
                v -= f64x2::new([r[2 * k], r[2 * k + 1]]) * *dk;
            }
            [r[12], r[13]] = v.to_array();
            cost += v * v;
        }
        cost.reduce_add()
    }

    /// Data snooping: the point with the largest standardised residual
    /// `w = |v| / (σ sqrt(q_vv))`, `q_vv = 1 - aᵀ Q a` (unit weights), over
    /// both image coordinates; returns its index among the loaded points and `w`.
    /// `l_inv`: the inverse of the lower Cholesky factor `L` of the normal
    /// matrix (`N = L Lᵀ`, so `Q = N⁻¹ = L⁻ᵀ L⁻¹` and `aᵀ Q a = |L⁻¹ a|²`).
    ///
    /// Why this form: `|L⁻¹ a|²` takes 21 products and 21 sums of both
    /// rows at once against 42 and 21 of the quadratic form in `Q`, and the
    /// squares `v² / q_vv` of both rows take one division and no root; the
    /// root is taken of the worst only (tracking: 1.31 M → 1.06 M
    /// instructions per 50 frames; SSE2's two-operand products keep it from
    /// halving). [`Linearised::worst_standardised_plain`]
    /// is the reference (the same up to rounding).
    pub fn worst_standardised(&self, l_inv: &Matrix6<f64>, sigma: f64) -> Option<(usize, f64)> {
        // The lower triangle of L⁻¹ row by row, in both lanes.
        let mut lp = [f64x2::ZERO; 21];
        let mut t = 0;
        for i in 0..6 {
            for j in 0..=i {
                lp[t] = f64x2::splat(l_inv[(i, j)]);
                t += 1;
            }
        }
        let one = f64x2::splat(1.0);
        let floor = f64x2::splat(1e-12);
        let mut worst: Option<(usize, f64)> = None;
        for (k, r) in self.rows[..self.pts.len()].iter().enumerate() {
            let a: [f64x2; 6] = std::array::from_fn(|i| f64x2::new([r[2 * i], r[2 * i + 1]]));
            let mut quad = f64x2::ZERO;
            let mut t = 0;
            for i in 0..6 {
                let mut z = lp[t] * a[0];
                t += 1;
                for aj in &a[1..=i] {
                    z += lp[t] * *aj;
                    t += 1;
                }
                quad += z * z;
            }
            let v = f64x2::new([r[12], r[13]]);
            // `max` as `maxpd`: NaN gives the floor, as `f64::max` does.
            let w2 = (v * v / (one - quad).fast_max(floor)).to_array();
            let w2 = if w2[1] > w2[0] { w2[1] } else { w2[0] };
            if worst.is_none_or(|(_, ww)| w2 > ww) {
                worst = Some((k, w2));
            }
        }
        worst.map(|(k, w2)| (k, w2.sqrt() / sigma))
    }

    /// [`Linearised::worst_standardised`] in the plain form: the quadratic
    /// form in `q = N⁻¹` and one square root per row (the reference).
    pub fn worst_standardised_plain(&self, q: &Matrix6<f64>, sigma: f64) -> Option<(usize, f64)> {
        let mut worst: Option<(usize, f64)> = None;
        for k in 0..self.pts.len() {
            let (ax, ay, vx, vy) = self.row(k);
            let (qx, qy) = ((ax.transpose() * q * ax)[0], (ay.transpose() * q * ay)[0]);
            let w = (vx.abs() / (1.0 - qx).max(1e-12).sqrt())
                .max(vy.abs() / (1.0 - qy).max(1e-12).sqrt())
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
        let ax = Vector6::from_fn(|k, _| r[2 * k]);
        let ay = Vector6::from_fn(|k, _| r[2 * k + 1]);
        (ax, ay, r[12], r[13])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotation::{cayley, cayley_derivatives};
    use nalgebra::{Vector2, Vector3};

    /// The standardised residuals through `L⁻¹` pick the same point as the
    /// quadratic form in `N⁻¹`, with the same `w` up to rounding: unit and
    /// general weights, a gross error and none.
    #[test]
    fn worst_standardised_equals_the_plain_form() {
        let e = Exterior::new(cayley(0.05, -0.1, 0.3), Vector3::new(30.0, -40.0, 1200.0));
        let mut state = 0x1234_5678_u64;
        let mut unit = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for (weighted, gross) in [(false, false), (false, true), (true, false), (true, true)] {
            let obs: Vec<Observation> = (0..60)
                .map(|k| {
                    let object = Vector3::new(600.0 * unit(), 600.0 * unit(), 5.0 * unit());
                    let ideal = e.project_ideal(12.0, &object).unwrap();
                    let mut noise = Vector2::new(unit(), unit()) * 2e-4;
                    if gross && k == 17 {
                        noise.x += 0.05;
                    }
                    let weight = if weighted && k % 3 == 0 {
                        nalgebra::Matrix2::new(2.0, 0.3, 0.3, 1.5)
                    } else {
                        nalgebra::Matrix2::identity()
                    };
                    Observation {
                        id: k,
                        object,
                        image: ideal + noise,
                        weight,
                    }
                })
                .collect();
            let mut lin = Linearised::default();
            lin.load(&obs, &vec![Status::Used; obs.len()]);
            let nm = lin.evaluate(12.0, &e).unwrap();
            let ch = nm.n.cholesky().unwrap();
            let l_inv = ch.l().solve_lower_triangular(&Matrix6::identity()).unwrap();
            let fast = lin.worst_standardised(&l_inv, 1e-3).unwrap();
            let plain = lin.worst_standardised_plain(&ch.inverse(), 1e-3).unwrap();
            assert_eq!(fast.0, plain.0, "{weighted} {gross}");
            assert!(
                (fast.1 - plain.1).abs() <= 1e-12 * plain.1,
                "{fast:?} {plain:?}"
            );
            if gross {
                assert_eq!(fast.0, 17);
            }
        }
    }

    #[test]
    fn partials_equal_the_cayley_derivatives_and_finite_differences() {
        // A tilted, turned camera looking down at the point.
        let r = cayley(0.2, -0.15, 0.8);
        let center = Vector3::new(10.0, -20.0, 900.0);
        let o = Observation {
            id: 1,
            object: Vector3::new(120.0, 45.0, 3.0),
            image: Vector2::new(0.1, -0.2),
            weight: nalgebra::Matrix2::identity(),
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
