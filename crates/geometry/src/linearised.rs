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
use nalgebra::{Matrix3, Matrix6, Vector6};
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
    /// Object point, ideal image point and the Cholesky factor
    /// `U = [[u00, u01], [0, u11]]` of the weight matrix (`W = UᵀU`) of
    /// each used point; none when the points are the observations
    /// themselves (`direct`).
    pts: Vec<[f64; 8]>,
    /// Points loaded.
    n: usize,
    /// Whether the loaded points are the observations the evaluations are
    /// given, every one used and of unit weight (a refinement's first
    /// set, mostly): read from there, not copied.
    direct: bool,
    /// Interleaved `[A | v]` rows of each point (the first `n`; the rest
    /// are left from a larger set).
    rows: Vec<[f64; 14]>,
    /// The rows of a candidate being tried ([`Linearised::evaluate_trial`]).
    trial: Vec<[f64; 14]>,
    /// Whether every weight is the identity (whitening skipped).
    unit_weights: bool,
    /// A step the residuals are still to be moved by
    /// ([`Linearised::shift_later`]).
    pending: Option<Vector6<f64>>,
}

/// Accumulates the rows `I` and `K` (`K > I`; only `I` when `K == I`) of
/// `[A | v]ᵀ [A | v]` (upper part) in one sweep over the points; few
/// enough accumulators to stay in registers.
#[inline(always)]
fn sweep<const I: usize, const K: usize>(rows: &[[f64; 14]], p: &mut [[f64; 7]; 7]) {
    let mut acc0 = [f64x2::ZERO; 7];
    let mut acc1 = [f64x2::ZERO; 7];
    let mut add = |r: &[f64; 14]| {
        let a: [f64x2; 7] = std::array::from_fn(|k| f64x2::new([r[2 * k], r[2 * k + 1]]));
        for j in I..7 {
            acc0[j] += a[I] * a[j];
        }
        if K > I {
            for j in K..7 {
                acc1[j] += a[K] * a[j];
            }
        }
    };
    // Two points a turn (half the loop's own instructions), in order.
    let pairs = rows.chunks_exact(2);
    let last = pairs.remainder();
    for pair in pairs {
        add(&pair[0]);
        add(&pair[1]);
    }
    if let [r] = last {
        add(r);
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

/// A pose's rotation `R` as the Jacobian rows are formed from it: its
/// entries, and per column `k` the pairs `(r0, r1)`, `(r1, r2)` and
/// `(r2, r0)` of that column.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RotationPairs {
    rr: [[f64; 3]; 3],
    rxy: [f64x2; 3],
    ryz: [f64x2; 3],
    rzx: [f64x2; 3],
}

impl RotationPairs {
    pub(crate) fn of(r: &Matrix3<f64>) -> Self {
        let rr = [
            [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
            [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
            [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
        ];
        RotationPairs {
            rr,
            rxy: std::array::from_fn(|k| f64x2::new([rr[0][k], rr[1][k]])),
            ryz: std::array::from_fn(|k| f64x2::new([rr[1][k], rr[2][k]])),
            rzx: std::array::from_fn(|k| f64x2::new([rr[2][k], rr[0][k]])),
        }
    }

    /// `R u` as the x and y pair and the z of the camera point, each sum
    /// in the order of nalgebra's product (`(r0 u0 + r1 u1) + r2 u2`).
    #[inline(always)]
    fn apply(&self, u: [f64; 3]) -> (f64x2, f64) {
        let rr = &self.rr;
        let zxy = self.rxy[0] * f64x2::splat(u[0])
            + self.rxy[1] * f64x2::splat(u[1])
            + self.rxy[2] * f64x2::splat(u[2]);
        (zxy, rr[2][0] * u[0] + rr[2][1] * u[1] + rr[2][2] * u[2])
    }

    /// The partials of the ideal image point `−c (x, y) / z` at the camera
    /// point `(zxy, zz)`, with `f = −c / zz` and `g = zxy / zz` in both
    /// lanes, as `J`'s six columns of both rows: per axis `k` the centre's
    /// `dZ/dC_k = −R e_k`, `f (g r2 − (r0, r1))`, then the rotation's by
    /// `ω_k` about the field axis `k` (`R(ω) = R (I + [ω]ₓ)` moves the
    /// point along `(R e_k) × Z`), `f (w_xy − g w_z)` of that cross
    /// product's x and y pair and z. The projected covariance's `J`; the
    /// resection's rows take the rotation columns twice
    /// ([`PointJacobian::of`]: rotations by `ω = 2 (a, b, c)`).
    #[inline(always)]
    pub(crate) fn jacobian(&self, zxy: f64x2, zz: f64, f: f64x2, g: f64x2) -> [f64x2; 6] {
        let rr = &self.rr;
        let [zx, zy] = zxy.to_array();
        // (r1, r2) · (zz, zx) − (r2, r0) · (zy, zz): the x and y of
        // (R e_k) × Z.
        let (zzx, zyz) = (f64x2::new([zz, zx]), f64x2::new([zy, zz]));
        let centre = |k: usize| f * (g * f64x2::splat(rr[2][k]) - self.rxy[k]);
        let turn = |k: usize| {
            let w_xy = self.ryz[k] * zzx - self.rzx[k] * zyz;
            let w_z = rr[0][k] * zy - rr[1][k] * zx;
            f * (w_xy - g * f64x2::splat(w_z))
        };
        [centre(0), centre(1), centre(2), turn(0), turn(1), turn(2)]
    }
}

/// One point's Jacobian rows at a pose as [`Linearised::evaluate`] forms
/// them there (interleaved, not whitened), and `c · g`, `g` the point's
/// `(x, y) / z` in camera coordinates, which its residuals add to the
/// image coordinates: formed where the point is projected with that pose
/// anyway (tracking), so that the adjustment's first pass only copies
/// them ([`Linearised::evaluate_from`]).
#[derive(Debug, Clone, Copy)]
pub struct PointJacobian {
    a: [f64x2; 6],
    cg: f64x2,
}

impl PointJacobian {
    /// From `J` of [`RotationPairs::jacobian`] at the point and `g`
    /// (principal distance `c`): the resection's columns, the rotation's
    /// by the Cayley increment `a_k = ω_k / 2` twice `J`'s.
    ///
    /// Twice `f (w_xy − g w_z)` is, bit for bit, the former
    /// `f (2 w_xy − g · 2 w_z)`: doubling is exact and commutes with
    /// every rounding short of an overflow or a subnormal intermediate
    /// (products near 1e-308; the points' are near 1). One sum instead of
    /// the rotation's columns formed a second time
    /// (`doubled_rotation_columns_are_the_former_ones`).
    #[inline(always)]
    pub(crate) fn of(c: f64, g: f64x2, j: &[f64x2; 6]) -> Self {
        PointJacobian {
            a: [j[0], j[1], j[2], j[3] + j[3], j[4] + j[4], j[5] + j[5]],
            cg: f64x2::splat(c) * g,
        }
    }

    /// The interleaved row of the point with image coordinates `image`.
    #[inline(always)]
    fn write(&self, image: (f64, f64), row: &mut [f64; 14]) {
        for k in 0..3 {
            [row[2 * k], row[2 * k + 1]] = self.a[k].to_array();
            [row[6 + 2 * k], row[7 + 2 * k]] = self.a[3 + k].to_array();
        }
        let [cgx, cgy] = self.cg.to_array();
        row[12] = image.0 + cgx;
        row[13] = image.1 + cgy;
    }
}

/// Whitening by the weight's Cholesky factor of a point (`p[5..8]`):
/// `(x, y) ← U (x, y)` for every column.
#[inline(always)]
fn whiten(p: &[f64; 8], row: &mut [f64; 14]) {
    for k in 0..7 {
        (row[2 * k], row[2 * k + 1]) = whitened(p, row[2 * k], row[2 * k + 1]);
    }
}

/// `U (x, y)` of a point's weight factor (`p[5..8]`).
#[inline(always)]
fn whitened(p: &[f64; 8], x: f64, y: f64) -> (f64, f64) {
    (p[5] * x + p[6] * y, p[7] * y)
}

/// A loaded point of `o` (weight factor `u`): object point, ideal image
/// point, `[u00, u01, u11]`.
#[inline(always)]
fn point(o: &Observation, u: [f64; 3]) -> [f64; 8] {
    [
        o.object.x, o.object.y, o.object.z, o.image.x, o.image.y, u[0], u[1], u[2],
    ]
}

/// Fills `rows` with the whitened Jacobian rows and residuals of `pts` at `e`.
fn linearise_into(
    pts: impl Iterator<Item = [f64; 8]>,
    unit: bool,
    rows: &mut [[f64; 14]],
    c: f64,
    e: &Exterior,
) -> Result<(), GeometryError> {
    let rot = RotationPairs::of(&e.rotation);
    let (cx, cy, cz) = (e.center.x, e.center.y, e.center.z);
    let mut behind = 0usize;
    for (p, row) in pts.zip(rows.iter_mut()) {
        // The x and y parts (of the camera point, of the two Jacobian
        // rows) as SIMD pairs: each lane computes exactly the scalar
        // expression, operation for operation.
        let (zxy, zz) = rot.apply([p[0] - cx, p[1] - cy, p[2] - cz]);
        behind += (zz >= 0.0) as usize;
        let inv = 1.0 / zz;
        let g = zxy * f64x2::splat(inv);
        let f = f64x2::splat(-c * inv);
        PointJacobian::of(c, g, &rot.jacobian(zxy, zz, f, g)).write((p[3], p[4]), row);
        if !unit {
            whiten(&p, row);
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
    /// Loads the used observations; with `check`, an observation no
    /// resection can use (non-finite, a weight not symmetric positive
    /// definite) is an error, as the resection's input check has it.
    pub fn load(
        &mut self,
        obs: &[Observation],
        status: &[Status],
        mut check: bool,
    ) -> Result<(), GeometryError> {
        self.pts.clear();
        self.pending = None;
        self.unit_weights = true;
        self.direct = false;
        if status.len() == obs.len() && status.iter().all(|s| *s == Status::Used) {
            // Every observation: of unit weight, they are the points.
            let mut unit = true;
            for (k, o) in obs.iter().enumerate() {
                let u = o.unit_weight();
                if check && !o.usable(u) {
                    return Err(GeometryError::NonFinite { index: k });
                }
                unit &= u;
            }
            check = false;
            self.direct = unit;
        }
        if self.direct {
            self.n = obs.len();
            // Room for a later set of these that is not (a snooped
            // point, a weight): no allocation once warm.
            self.pts.reserve(obs.len());
        } else {
            for (k, (o, s)) in obs.iter().zip(status).enumerate() {
                if *s != Status::Used {
                    continue;
                }
                let unit = o.unit_weight();
                if check && !o.usable(unit) {
                    return Err(GeometryError::NonFinite { index: k });
                }
                let w = &o.weight;
                let u = if unit {
                    [1.0, 0.0, 1.0]
                } else {
                    self.unit_weights = false;
                    let u00 = w[(0, 0)].sqrt();
                    let u01 = w[(0, 1)] / u00;
                    [u00, u01, (w[(1, 1)] - u01 * u01).max(0.0).sqrt()]
                };
                self.pts.push(point(o, u));
            }
            self.n = self.pts.len();
        }
        // `evaluate` overwrites every row of the loaded points: the rows
        // only grow (a set of fewer points uses the first rows; growing
        // them again would zero them again each frame).
        let n = self.n;
        if self.rows.len() < n {
            self.rows.resize(n, [0.0; 14]);
            self.trial.resize(n, [0.0; 14]);
        }
        Ok(())
    }

    /// Linearises the loaded points of `obs` at `e` into `rows`.
    fn linearise(
        &self,
        obs: &[Observation],
        rows: &mut [[f64; 14]],
        c: f64,
        e: &Exterior,
    ) -> Result<(), GeometryError> {
        if self.direct {
            let pts = obs.iter().map(|o| point(o, [1.0, 0.0, 1.0]));
            linearise_into(pts, true, rows, c, e)
        } else {
            linearise_into(self.pts.iter().copied(), self.unit_weights, rows, c, e)
        }
    }

    /// Number of points loaded.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether no point is loaded.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Linearises at `e` (principal distance `c`) and forms the normal
    /// equations; `obs` are the observations last loaded.
    pub fn evaluate(
        &mut self,
        c: f64,
        e: &Exterior,
        obs: &[Observation],
    ) -> Result<Normals, GeometryError> {
        self.pending = None;
        let mut rows = std::mem::take(&mut self.rows);
        let done = self.linearise(obs, &mut rows[..self.n], c, e);
        self.rows = rows;
        done?;
        Ok(normals_of(&self.rows[..self.n]))
    }

    /// [`Linearised::evaluate`] at the pose `first` was formed at: each
    /// loaded point's row copied from its [`PointJacobian`] (`first[i]`
    /// for the `i`-th loaded point), the same bits without the arithmetic.
    /// Debug builds form the rows at `e` as well and check that they agree.
    pub fn evaluate_from(
        &mut self,
        c: f64,
        e: &Exterior,
        obs: &[Observation],
        first: &[PointJacobian],
    ) -> Result<Normals, GeometryError> {
        self.pending = None;
        let n = self.n;
        if first.len() != n {
            return self.evaluate(c, e, obs);
        }
        let rows = &mut self.rows[..n];
        if self.direct {
            for ((o, row), j) in obs.iter().zip(rows.iter_mut()).zip(first) {
                j.write((o.image.x, o.image.y), row);
            }
        } else {
            for ((p, row), j) in self.pts.iter().zip(rows.iter_mut()).zip(first) {
                j.write((p[3], p[4]), row);
                if !self.unit_weights {
                    whiten(p, row);
                }
            }
        }
        if cfg!(debug_assertions) {
            let mut check = std::mem::take(&mut self.trial);
            let same = self.linearise(obs, &mut check[..n], c, e).is_ok()
                && self.rows[..n]
                    .iter()
                    .flatten()
                    .zip(check[..n].iter().flatten())
                    .all(|(a, b)| a.to_bits() == b.to_bits());
            self.trial = check;
            assert!(same, "a PointJacobian not formed at this pose");
        }
        Ok(normals_of(&self.rows[..n]))
    }

    /// Like [`Linearised::evaluate`] for a candidate, into separate rows that
    /// [`Linearised::accept_trial`] makes current.
    pub fn evaluate_trial(
        &mut self,
        c: f64,
        e: &Exterior,
        obs: &[Observation],
    ) -> Result<Normals, GeometryError> {
        let mut trial = std::mem::take(&mut self.trial);
        let done = self.linearise(obs, &mut trial[..self.n], c, e);
        self.trial = trial;
        done?;
        Ok(normals_of(&self.trial[..self.n]))
    }

    /// The residuals at `e` with the current rows' Jacobian (a chord
    /// step's: the Jacobian is not formed again) into the trial rows, which
    /// [`Linearised::accept_trial`] makes current; `Aᵀv` and `vᵀv` of them.
    /// Each point's projection alone, no partials and no normal matrix.
    /// Where the current rows were formed a small step from `e`, `A` there
    /// differs from `A` at `e` by about that step's size relative to the
    /// camera distance, and so does a step solved with it.
    pub fn residuals_trial(
        &mut self,
        c: f64,
        e: &Exterior,
        obs: &[Observation],
    ) -> Result<(Vector6<f64>, f64), GeometryError> {
        let n = self.n;
        let rot = e.rotation;
        let (mut g, mut cost, mut behind) = ([f64x2::ZERO; 6], f64x2::ZERO, 0usize);
        let mut one = |p: [f64; 8], row: &[f64; 14], trial: &mut [f64; 14]| {
            let z = rot * (nalgebra::Vector3::new(p[0], p[1], p[2]) - e.center);
            behind += (z.z >= 0.0) as usize;
            let inv = 1.0 / z.z;
            // `image + c g` as `PointJacobian::write` forms it.
            let (mut vx, mut vy) = (p[3] + c * (z.x * inv), p[4] + c * (z.y * inv));
            if !self.unit_weights {
                (vx, vy) = whitened(&p, vx, vy);
            }
            trial[..12].copy_from_slice(&row[..12]);
            (trial[12], trial[13]) = (vx, vy);
            let v = f64x2::new([vx, vy]);
            for (k, g) in g.iter_mut().enumerate() {
                *g += f64x2::new([row[2 * k], row[2 * k + 1]]) * v;
            }
            cost += v * v;
        };
        let (rows, trial) = (&self.rows[..n], &mut self.trial[..n]);
        if self.direct {
            for ((o, row), t) in obs.iter().zip(rows).zip(trial.iter_mut()) {
                one(point(o, [1.0, 0.0, 1.0]), row, t);
            }
        } else {
            for ((p, row), t) in self.pts.iter().zip(rows).zip(trial.iter_mut()) {
                one(*p, row, t);
            }
        }
        if behind > 0 {
            return Err(GeometryError::BehindCamera { count: behind });
        }
        let lanes = |v: f64x2| {
            let [a, b] = v.to_array();
            a + b
        };
        Ok((Vector6::from_fn(|k, _| lanes(g[k])), lanes(cost)))
    }

    /// Makes the rows of the last trial the current ones.
    pub fn accept_trial(&mut self) {
        self.pending = None;
        std::mem::swap(&mut self.rows, &mut self.trial);
    }

    /// Moves the residuals by a small parameter step `delta` (linear
    /// prediction: `v − A δ`) in the next pass that reads them
    /// ([`Linearised::worst_standardised`], which gives the new cost),
    /// not in a pass of its own (tracking: the two passes' 1.33 M
    /// instructions per 50 frames → 1.29 M). Forming rows or loading
    /// points drops it.
    pub fn shift_later(&mut self, delta: &Vector6<f64>) {
        self.pending = Some(*delta);
    }

    /// Data snooping: the point with the largest standardised residual
    /// `w = |v| / (σ sqrt(q_vv))`, `q_vv = 1 - aᵀ Q a` (unit weights), over
    /// both image coordinates, as its index among the loaded points and
    /// `(σ w)²` (σ from the cost); and, when a shift was pending
    /// ([`Linearised::shift_later`]), the cost `vᵀv` of the residuals it
    /// moved (first), summed as the adjustment sums it.
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
    pub fn worst_standardised(
        &mut self,
        l_inv: &Matrix6<f64>,
    ) -> (Option<f64>, Option<(usize, f64)>) {
        match self.pending.take() {
            Some(delta) => {
                let d: [f64x2; 6] = std::array::from_fn(|k| f64x2::splat(delta[k]));
                let (cost, worst) = self.standardised::<true>(l_inv, &d);
                (Some(cost), worst)
            }
            None => (None, self.standardised::<false>(l_inv, &[f64x2::ZERO; 6]).1),
        }
    }

    /// [`Linearised::worst_standardised`], moving the residuals by `d` first
    /// if `SHIFT` (then also their new cost).
    #[inline(always)]
    fn standardised<const SHIFT: bool>(
        &mut self,
        l_inv: &Matrix6<f64>,
        d: &[f64x2; 6],
    ) -> (f64, Option<(usize, f64)>) {
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
        let mut cost = f64x2::ZERO;
        let mut worst: Option<(usize, f64)> = None;
        for (k, r) in self.rows[..self.n].iter_mut().enumerate() {
            let a: [f64x2; 6] = std::array::from_fn(|i| f64x2::new([r[2 * i], r[2 * i + 1]]));
            let mut v = f64x2::new([r[12], r[13]]);
            if SHIFT {
                for (ak, dk) in a.iter().zip(d) {
                    v -= *ak * *dk;
                }
                [r[12], r[13]] = v.to_array();
                cost += v * v;
            }
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
            // `max` as `maxpd`: NaN gives the floor, as `f64::max` does.
            let w2 = (v * v / (one - quad).fast_max(floor)).to_array();
            let w2 = if w2[1] > w2[0] { w2[1] } else { w2[0] };
            if worst.is_none_or(|(_, ww)| w2 > ww) {
                worst = Some((k, w2));
            }
        }
        (cost.reduce_add(), worst)
    }

    /// [`Linearised::worst_standardised`] in the plain form: the quadratic
    /// form in `q = N⁻¹` and one square root per row (the reference).
    pub fn worst_standardised_plain(&self, q: &Matrix6<f64>, sigma: f64) -> Option<(usize, f64)> {
        let mut worst: Option<(usize, f64)> = None;
        for k in 0..self.n {
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
            lin.load(&obs, &vec![Status::Used; obs.len()], true)
                .unwrap();
            let nm = lin.evaluate(12.0, &e, &obs).unwrap();
            let ch = nm.n.cholesky().unwrap();
            let l_inv = ch.l().solve_lower_triangular(&Matrix6::identity()).unwrap();
            let (cost, fast) = lin.worst_standardised(&l_inv);
            assert_eq!(cost, None);
            let fast = fast.map(|(k, w2)| (k, w2.sqrt() / 1e-3)).unwrap();
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

    /// Observations read where they are (all used, unit weights) give the
    /// rows and normal equations of the same points copied into the
    /// workspace (another observation not used makes it copy them), and a
    /// refinement's checks fail alike.
    #[test]
    fn observations_read_in_place_are_the_copied_points() {
        let e = Exterior::new(cayley(-0.1, 0.05, 0.2), Vector3::new(10.0, 20.0, 1100.0));
        let mut rng = crate::rng::SplitMix64::new(12);
        let obs: Vec<Observation> = (0..30)
            .map(|k| {
                let object = Vector3::new(300.0 * rng.normal(), 300.0 * rng.normal(), 0.0);
                Observation {
                    id: k,
                    object,
                    image: e.project_ideal(12.0, &object).unwrap()
                        + Vector2::new(rng.normal(), rng.normal()) * 1e-3,
                    weight: nalgebra::Matrix2::identity(),
                }
            })
            .collect();
        let mut more = vec![obs[3]];
        more.extend_from_slice(&obs);
        let mut status = vec![Status::Used; more.len()];
        status[0] = Status::Outlier;
        let (mut direct, mut copied) = (Linearised::default(), Linearised::default());
        direct
            .load(&obs, &vec![Status::Used; obs.len()], true)
            .unwrap();
        copied.load(&more, &status, true).unwrap();
        assert!(direct.direct && !copied.direct);
        let a = direct.evaluate(12.0, &e, &obs).unwrap();
        let b = copied.evaluate(12.0, &e, &more).unwrap();
        let bits = |m: &[f64]| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(a.n.as_slice()), bits(b.n.as_slice()));
        assert_eq!((a.cost.to_bits(), a.count), (b.cost.to_bits(), b.count));
        assert_eq!(
            bits(direct.rows[..30].as_flattened()),
            bits(copied.rows[..30].as_flattened())
        );
        let mut bad = obs.clone();
        bad[4].image.y = f64::INFINITY;
        assert!(matches!(
            direct.load(&bad, &vec![Status::Used; obs.len()], true),
            Err(GeometryError::NonFinite { index: 4 })
        ));
    }

    /// The sweeps' normal equations, two points a turn, are the plain sums
    /// over the points in order (each entry's x rows in one lane, y rows in
    /// the other, the lanes added last): odd and even counts, none.
    #[test]
    fn normal_equations_are_the_plain_sums() {
        let mut rng = crate::rng::SplitMix64::new(31);
        for n in 0..9 {
            let rows: Vec<[f64; 14]> = (0..n)
                .map(|_| std::array::from_fn(|_| rng.normal() * 10f64.powf(4.0 * rng.unit())))
                .collect();
            let nm = normals_of(&rows);
            for i in 0..7 {
                for j in i..7 {
                    let (mut x, mut y) = (0.0, 0.0);
                    for r in &rows {
                        x += r[2 * i] * r[2 * j];
                        y += r[2 * i + 1] * r[2 * j + 1];
                    }
                    let got = match (i, j) {
                        (6, 6) => nm.cost,
                        (_, 6) => nm.g[i],
                        _ => nm.n[(i, j)],
                    };
                    assert_eq!(got.to_bits(), (x + y).to_bits(), "n {n}, ({i}, {j})");
                    if j < 6 {
                        assert_eq!(nm.n[(j, i)].to_bits(), got.to_bits());
                    }
                }
            }
            assert_eq!(nm.count, n);
        }
    }

    /// A shift left to the snooping pass moves the residuals and sums their
    /// cost exactly as a pass of its own did (`v − A δ`, column by column,
    /// each row pair's squares in its lane), and only once; forming rows
    /// again drops it.
    #[test]
    fn a_shift_left_for_later_is_the_shift() {
        let e = Exterior::new(cayley(0.1, 0.2, -0.3), Vector3::new(-20.0, 50.0, 900.0));
        let mut rng = crate::rng::SplitMix64::new(8);
        let obs: Vec<Observation> = (0..50)
            .map(|k| {
                let object = Vector3::new(300.0 * rng.normal(), 300.0 * rng.normal(), 0.0);
                let ideal = e.project_ideal(12.0, &object).unwrap();
                Observation {
                    id: k,
                    object,
                    image: ideal + Vector2::new(rng.normal(), rng.normal()) * 1e-3,
                    weight: nalgebra::Matrix2::identity(),
                }
            })
            .collect();
        let delta = Vector6::from_fn(|k, _| 1e-7 * (k as f64 - 2.5));
        let mut lin = Linearised::default();
        lin.load(&obs, &vec![Status::Used; obs.len()], true)
            .unwrap();
        let nm = lin.evaluate(12.0, &e, &obs).unwrap();
        // The plain shift, as a pass of its own.
        let d: [f64x2; 6] = std::array::from_fn(|k| f64x2::splat(delta[k]));
        let mut want_cost = f64x2::ZERO;
        let mut want_rows = lin.rows.clone();
        for r in &mut want_rows[..obs.len()] {
            let mut v = f64x2::new([r[12], r[13]]);
            for (k, dk) in d.iter().enumerate() {
                v -= f64x2::new([r[2 * k], r[2 * k + 1]]) * *dk;
            }
            [r[12], r[13]] = v.to_array();
            want_cost += v * v;
        }
        let l_inv =
            nm.n.cholesky()
                .unwrap()
                .l()
                .solve_lower_triangular(&Matrix6::identity())
                .unwrap();
        lin.shift_later(&delta);
        let (cost, _) = lin.worst_standardised(&l_inv);
        assert_eq!(
            cost.map(f64::to_bits),
            Some(want_cost.reduce_add().to_bits())
        );
        let bits = |r: &[[f64; 14]]| r.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&lin.rows[..obs.len()]), bits(&want_rows[..obs.len()]));
        // Applied once; dropped by forming the rows again.
        assert_eq!(lin.worst_standardised(&l_inv).0, None);
        lin.shift_later(&delta);
        lin.evaluate(12.0, &e, &obs).unwrap();
        assert_eq!(lin.worst_standardised(&l_inv).0, None);
    }

    /// The rows a projector forms while projecting are the adjustment's
    /// own at its pose, bit for bit, and so are the normal equations of
    /// the first pass from them: unit and general weights, turned and
    /// axis-aligned poses (exact zeros in `R`), points near the image
    /// centre (zeros in `g`).
    #[test]
    fn rows_formed_while_projecting_are_the_adjustments() {
        use crate::precision::UncertainProjector;
        use crate::rng::SplitMix64;
        let mut rng = SplitMix64::new(5);
        for case in 0..200 {
            let e = if case % 4 == 0 {
                Exterior::look_at(
                    Vector3::new(10.0 * case as f64, 0.0, 1000.0),
                    Vector3::new(10.0 * case as f64, 0.0, 0.0),
                    Vector3::x(),
                )
                .unwrap()
            } else {
                Exterior::new(
                    cayley(0.2 * rng.normal(), 0.2 * rng.normal(), 0.2 * rng.normal()),
                    Vector3::new(50.0 * rng.normal(), 50.0 * rng.normal(), 1000.0),
                )
            };
            let cov = Matrix6::from_fn(|i, j| if i == j { 1e-3 } else { 1e-5 });
            let projector = UncertainProjector::new(12.0, &e, &cov);
            let (mut obs, mut rows) = (Vec::new(), Vec::new());
            for k in 0..40 {
                let object = if k == 0 {
                    // On the optical axis.
                    e.center - e.rotation.row(2).transpose() * 1000.0
                } else {
                    Vector3::new(300.0 * rng.normal(), 300.0 * rng.normal(), rng.normal())
                };
                let Some((z, ideal)) = projector.project_point(&object) else {
                    continue;
                };
                let (cov_z, row) = projector.covariance_and_jacobian_at(&z);
                assert_eq!(cov_z, projector.covariance_at(&z));
                let weight = if case % 2 == 1 && k % 3 == 0 {
                    nalgebra::Matrix2::new(0.25, 0.0, 0.0, 0.25)
                } else {
                    nalgebra::Matrix2::identity()
                };
                obs.push(Observation {
                    id: k,
                    object,
                    image: ideal + Vector2::new(rng.normal(), rng.normal()) * 1e-3,
                    weight,
                });
                rows.push(row);
            }
            let status = vec![Status::Used; obs.len()];
            let (mut plain, mut from) = (Linearised::default(), Linearised::default());
            plain.load(&obs, &status, true).unwrap();
            from.load(&obs, &status, true).unwrap();
            let want = plain.evaluate(12.0, &e, &obs).unwrap();
            let got = from.evaluate_from(12.0, &e, &obs, &rows).unwrap();
            let bits = |m: &[f64]| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(want.n.as_slice()),
                bits(got.n.as_slice()),
                "case {case}"
            );
            assert_eq!(bits(want.g.as_slice()), bits(got.g.as_slice()));
            assert_eq!(want.cost.to_bits(), got.cost.to_bits());
            for i in 0..obs.len() {
                assert_eq!(
                    bits(&plain.rows[i]),
                    bits(&from.rows[i]),
                    "case {case} row {i}"
                );
            }
        }
    }

    /// The resection's rotation columns as twice the covariance's `J`
    /// equal the former form `f (2 w_xy − g · 2 w_z)` bit for bit, over
    /// random poses and points, near and far, also with zeros in the
    /// rotation (axis-aligned cameras).
    #[test]
    fn doubled_rotation_columns_are_the_former_ones() {
        let mut rng = crate::rng::SplitMix64::new(77);
        let mut seen = 0;
        for case in 0..20000 {
            let r = if case % 7 == 0 {
                Matrix3::identity()
            } else {
                cayley(rng.normal(), rng.normal(), rng.normal())
            };
            let rot = RotationPairs::of(&r);
            let scale = 10f64.powf(rng.normal() * 3.0);
            let u = [
                scale * rng.normal(),
                scale * rng.normal(),
                -scale * rng.unit() - 1e-3,
            ];
            let (zxy, zz) = rot.apply(u);
            if zz >= 0.0 {
                continue;
            }
            seen += 1;
            let c = 12.0;
            let inv = 1.0 / zz;
            let (g, f) = (zxy * f64x2::splat(inv), f64x2::splat(-c * inv));
            let got = PointJacobian::of(c, g, &rot.jacobian(zxy, zz, f, g));
            let rr = &rot.rr;
            let [zx, zy] = zxy.to_array();
            let (zzx, zyz) = (f64x2::new([zz, zx]), f64x2::new([zy, zz]));
            let two = f64x2::splat(2.0);
            for (k, (r0, r1)) in rr[0].iter().zip(&rr[1]).enumerate() {
                let w_xy = rot.ryz[k] * zzx - rot.rzx[k] * zyz;
                let w_z = r0 * zy - r1 * zx;
                let former = f * (two * w_xy - g * f64x2::splat(2.0 * w_z));
                let bits = |v: f64x2| v.to_array().map(f64::to_bits);
                assert_eq!(bits(former), bits(got.a[3 + k]), "case {case} k {k}");
            }
        }
        assert!(seen > 10000, "{seen}");
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
        lin.load(&[o], &[Status::Used], true).unwrap();
        lin.evaluate(12.0, &e, &[o]).unwrap();
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
