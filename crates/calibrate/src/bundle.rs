//! The self-calibrating bundle adjustment: camera parameters, every image's
//! exterior orientation and optionally the target coordinates, by
//! Levenberg–Marquardt over sparse normal equations.
//!
//! Structure of the normal equations: the six exterior unknowns of an image
//! couple only with the camera parameters and the targets that image sees.
//! Each iteration accumulates per image its 6×6 block `U_i`, its coupling
//! `B_i` with the *reduced* unknowns (free camera parameters, then the free
//! target coordinates) and the reduced block `S`; the exterior unknowns are
//! eliminated (Schur complement `S - Σ B_i U_i⁻¹ B_iᵀ`), the reduced system
//! is solved (Jacobi-scaled Cholesky) and the exteriors are recovered by
//! back-substitution. With free targets the datum defect (translation,
//! rotation, scale) is removed by inner constraints: `G Gᵀ` is added to the
//! reduced matrix, `G` an orthonormal basis of the similarity motions of the
//! targets; every step then satisfies `Gᵀ δ = 0`, and `(S + G Gᵀ)⁻¹` is a
//! generalised inverse of `S`, whose camera block (camera parameters are
//! invariant to the datum) is their cofactor matrix.
//!
//! Gross errors: after convergence, data snooping takes out, in each image,
//! the observation with the largest standardised residual above the critical
//! value, then adjusts again, until none is left. The redundancy of an
//! observation is that of its image given the camera (`1 - a U_i⁻¹ aᵀ` per
//! coordinate): the camera parameters, shared by thousands of observations,
//! take a negligible share of it.

use crate::error::CalibrateError;
use crate::model::linearise;
use crate::params::{values, with_values, Fixed, Param, N_PARAMS};
use nalgebra::{DMatrix, DVector, Matrix6, SMatrix, Vector2, Vector3, Vector6};
use photopose_geometry::rotation::cayley;
use photopose_geometry::{Camera, Exterior};

/// One target measured in one image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointObservation {
    /// Index into the adjustment's target list.
    pub target: usize,
    /// Measured image coordinates `(x', y')`, mm (before any correction).
    pub measured: Vector2<f64>,
    /// Whether the observation takes part (false: rejected by snooping).
    pub used: bool,
    /// Eccentricity of the target's image (centre of the imaged ellipse
    /// minus image of the circle's centre), mm, taken off `measured`.
    pub eccentricity: Vector2<f64>,
}

impl PointObservation {
    /// The measured position with the eccentricity taken off: the image of
    /// the target's centre that the model predicts.
    pub fn centre(&self) -> Vector2<f64> {
        self.measured - self.eccentricity
    }
}

/// The observations of one image and its exterior orientation.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageBlock {
    /// The exterior orientation (start value in, adjusted value out).
    pub exterior: Exterior,
    /// The observed targets; each target at most once.
    pub points: Vec<PointObservation>,
}

/// Tuning of the adjustment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BundleOptions {
    /// Parameters held at their initial value.
    pub fixed: Fixed,
    /// Adjust the target coordinates too (free network, inner constraints).
    pub free_targets: bool,
    /// Iteration limit of one Levenberg–Marquardt run.
    pub max_iterations: usize,
    /// Critical value of the standardised residual in data snooping (0: no snooping).
    pub snooping_critical: f64,
    /// Floor of σ0 used in snooping, pixels.
    pub sigma_floor_px: f64,
    /// Most observations snooped out of one image, as a share of its observations.
    pub max_snooped_ratio: f64,
}

impl Default for BundleOptions {
    fn default() -> Self {
        BundleOptions {
            fixed: Fixed::none(),
            free_targets: false,
            max_iterations: 100,
            snooping_critical: 4.5,
            sigma_floor_px: 0.01,
            max_snooped_ratio: 0.2,
        }
    }
}

/// The result of an adjustment.
#[derive(Debug, Clone, PartialEq)]
pub struct BundleResult {
    /// The adjusted camera.
    pub camera: Camera,
    /// A-posteriori covariance of the ten camera parameters (rows and
    /// columns of fixed parameters are zero).
    pub covariance: SMatrix<f64, N_PARAMS, N_PARAMS>,
    /// A-posteriori σ0 of an image coordinate, mm.
    pub sigma0: f64,
    /// Observations used (targets × images).
    pub n_observations: usize,
    /// Unknowns (minus the datum defect).
    pub n_unknowns: usize,
    /// Levenberg–Marquardt iterations, all runs together (in a
    /// [`crate::Calibration`]: of all identification rounds).
    pub iterations: usize,
    /// Observations newly rejected by data snooping in this adjustment.
    pub n_snooped: usize,
}

/// The adjustment's problem: the targets and the images.
#[derive(Debug, Clone)]
pub struct Bundle {
    /// The camera (start values in, adjusted out).
    pub camera: Camera,
    /// Target coordinates (adjusted when free).
    pub targets: Vec<Vector3<f64>>,
    /// The images.
    pub images: Vec<ImageBlock>,
}

/// Per-image parts of the normal equations.
struct ImageNormals {
    u: Matrix6<f64>,
    g: Vector6<f64>,
    /// Reduced-unknown index of each row of `b`.
    rows: Vec<usize>,
    b: Vec<Vector6<f64>>,
}

struct Normals {
    images: Vec<ImageNormals>,
    s: DMatrix<f64>,
    g: DVector<f64>,
    cost: f64,
}

/// Largest variance inflation of a camera parameter (its variance with the
/// other unknowns free over its variance with them known) still called
/// determinable; a multiple correlation above `1 - 1e-8`.
const MAX_VARIANCE_INFLATION: f64 = 1e8;

/// The reduced matrix, its right-hand side and the inverted exterior blocks.
type Reduced = (DMatrix<f64>, DVector<f64>, Vec<Matrix6<f64>>);

/// Layout of the reduced unknowns.
struct Layout {
    free: Vec<Param>,
    /// Reduced index of each target's X (targets fixed: `None`).
    target: Vec<Option<usize>>,
    n: usize,
}

impl Bundle {
    fn layout(&self, options: &BundleOptions) -> Layout {
        let free = options.fixed.free_params();
        let mut n = free.len();
        let mut seen = vec![false; self.targets.len()];
        for im in &self.images {
            for p in im.points.iter().filter(|p| p.used) {
                seen[p.target] = true;
            }
        }
        let target = seen
            .iter()
            .map(|&s| {
                (options.free_targets && s).then(|| {
                    n += 3;
                    n - 3
                })
            })
            .collect();
        Layout { free, target, n }
    }

    /// Sum of squared residuals of the used observations (`None` if a point
    /// falls behind its camera).
    pub fn cost(&self) -> Option<f64> {
        let mut sum = 0.0;
        for im in &self.images {
            for p in im.points.iter().filter(|p| p.used) {
                let v = crate::model::residual(
                    &self.camera,
                    &im.exterior,
                    &self.targets[p.target],
                    &p.centre(),
                )?;
                sum += v.norm_squared();
            }
        }
        Some(sum)
    }

    fn normals(&self, layout: &Layout) -> Option<Normals> {
        let nf = layout.free.len();
        let mut s = DMatrix::zeros(layout.n, layout.n);
        let mut g = DVector::zeros(layout.n);
        let mut cost = 0.0;
        let mut images = Vec::with_capacity(self.images.len());
        let mut jc = nalgebra::DMatrix::<f64>::zeros(2, nf);
        for im in &self.images {
            let mut u = Matrix6::zeros();
            let mut ge = Vector6::zeros();
            let mut rows: Vec<usize> = (0..nf).collect();
            let mut b = vec![Vector6::zeros(); nf];
            for p in im.points.iter().filter(|p| p.used) {
                let lin = linearise(
                    &self.camera,
                    &im.exterior,
                    &self.targets[p.target],
                    &p.centre(),
                )?;
                let je = &lin.exterior;
                cost += lin.v.norm_squared();
                u += je.transpose() * je;
                ge += je.transpose() * lin.v;
                for (k, par) in layout.free.iter().enumerate() {
                    jc.set_column(k, &lin.camera.column(par.index()));
                }
                // Camera block.
                for a in 0..nf {
                    let ca = jc.column(a);
                    for bb in a..nf {
                        let v = ca.dot(&jc.column(bb));
                        s[(a, bb)] += v;
                    }
                    g[a] += ca.dot(&lin.v);
                    b[a] += je.transpose() * ca;
                }
                if let Some(t) = layout.target[p.target] {
                    let jp = &lin.point;
                    let tt = jp.transpose() * jp;
                    for i in 0..3 {
                        for j in i..3 {
                            s[(t + i, t + j)] += tt[(i, j)];
                        }
                        g[t + i] += jp.column(i).dot(&lin.v);
                        for a in 0..nf {
                            s[(a, t + i)] += jc.column(a).dot(&jp.column(i));
                        }
                        rows.push(t + i);
                        b.push(je.transpose() * jp.column(i));
                    }
                }
            }
            images.push(ImageNormals { u, g: ge, rows, b });
        }
        // Mirror the upper triangle.
        for i in 0..layout.n {
            for j in 0..i {
                s[(i, j)] = s[(j, i)];
            }
        }
        Some(Normals { images, s, g, cost })
    }

    /// The inner-constraint basis `G` (orthonormal columns) over the free
    /// target coordinates, or `None` when the targets are fixed.
    fn datum_basis(&self, layout: &Layout) -> Option<DMatrix<f64>> {
        let free: Vec<(usize, Vector3<f64>)> = layout
            .target
            .iter()
            .zip(&self.targets)
            .filter_map(|(t, x)| t.map(|t| (t, *x)))
            .collect();
        if free.is_empty() {
            return None;
        }
        let mean = free.iter().map(|(_, x)| x).sum::<Vector3<f64>>() / free.len() as f64;
        let spread = free
            .iter()
            .map(|(_, x)| (x - mean).norm())
            .fold(0.0, f64::max)
            .max(1e-9);
        let mut g = DMatrix::zeros(layout.n, 7);
        for &(t, x) in &free {
            let d = (x - mean) / spread;
            for k in 0..3 {
                g[(t + k, k)] = 1.0;
                g[(t + k, 6)] = d[k];
            }
            // Small rotations ω × d.
            g[(t + 1, 3)] = -d.z;
            g[(t + 2, 3)] = d.y;
            g[(t, 4)] = d.z;
            g[(t + 2, 4)] = -d.x;
            g[(t, 5)] = -d.y;
            g[(t + 1, 5)] = d.x;
        }
        let q = g.qr().q();
        Some(q)
    }

    /// The reduced system `S - Σ B_i U_i⁻¹ B_iᵀ` (damped by `1 + lambda`
    /// on every diagonal, the inner constraints added), its right-hand side
    /// and the inverted exterior blocks; `None` if an exterior block is singular.
    fn reduce(nm: &Normals, lambda: f64, datum: Option<&DMatrix<f64>>) -> Option<Reduced> {
        let n = nm.s.nrows();
        let mut s = nm.s.clone();
        for i in 0..n {
            s[(i, i)] *= 1.0 + lambda;
        }
        let mut rhs = -nm.g.clone();
        let mut u_inv = Vec::with_capacity(nm.images.len());
        for im in &nm.images {
            let mut u = im.u;
            for i in 0..6 {
                u[(i, i)] *= 1.0 + lambda;
            }
            let ui = u.cholesky()?.inverse();
            // y_k = U⁻¹ b_k for each reduced row k of this image.
            let y: Vec<Vector6<f64>> = im.b.iter().map(|b| ui * b).collect();
            for (a, (&ra, ya)) in im.rows.iter().zip(&y).enumerate() {
                rhs[ra] += ya.dot(&im.g);
                for (&rb, bb) in im.rows[a..].iter().zip(&im.b[a..]) {
                    let v = ya.dot(bb);
                    s[(ra, rb)] -= v;
                    if ra != rb {
                        s[(rb, ra)] -= v;
                    }
                }
            }
            u_inv.push(ui);
        }
        if let Some(g) = datum {
            let scale = (0..n).map(|i| s[(i, i)]).sum::<f64>() / n as f64;
            s += g * g.transpose() * scale;
        }
        Some((s, rhs, u_inv))
    }

    /// Solves the damped normal equations; returns the reduced step and the
    /// exterior steps, or `None` if the system is not positive definite.
    fn solve(
        nm: &Normals,
        lambda: f64,
        datum: Option<&DMatrix<f64>>,
    ) -> Option<(DVector<f64>, Vec<Vector6<f64>>)> {
        let (s, rhs, u_inv) = Self::reduce(nm, lambda, datum)?;
        let n = s.nrows();
        let d: DVector<f64> = DVector::from_fn(n, |i, _| 1.0 / s[(i, i)].max(1e-300).sqrt());
        let scaled = DMatrix::from_fn(n, n, |i, j| s[(i, j)] * d[i] * d[j]);
        let chol = scaled.cholesky()?;
        let y = chol.solve(&rhs.component_mul(&d));
        let dr = y.component_mul(&d);
        let de = nm
            .images
            .iter()
            .zip(&u_inv)
            .map(|(im, ui)| {
                let mut r = -im.g;
                for (&k, b) in im.rows.iter().zip(&im.b) {
                    r -= b * dr[k];
                }
                ui * r
            })
            .collect();
        Some((dr, de))
    }

    fn apply(&self, layout: &Layout, dr: &DVector<f64>, de: &[Vector6<f64>]) -> Bundle {
        let mut v = values(&self.camera);
        for (k, p) in layout.free.iter().enumerate() {
            v[p.index()] += dr[k];
        }
        let camera = with_values(&self.camera, &v);
        let targets = self
            .targets
            .iter()
            .zip(&layout.target)
            .map(|(x, t)| match t {
                Some(t) => x + Vector3::new(dr[*t], dr[t + 1], dr[t + 2]),
                None => *x,
            })
            .collect();
        let images = self
            .images
            .iter()
            .zip(de)
            .map(|(im, d)| ImageBlock {
                exterior: Exterior::new(
                    im.exterior.rotation * cayley(d[3], d[4], d[5]),
                    im.exterior.center + Vector3::new(d[0], d[1], d[2]),
                ),
                points: im.points.clone(),
            })
            .collect();
        Bundle {
            camera,
            targets,
            images,
        }
    }

    /// Levenberg–Marquardt to convergence; returns the iterations.
    fn levenberg_marquardt(&mut self, options: &BundleOptions) -> Result<usize, CalibrateError> {
        let layout = self.layout(options);
        let datum = self.datum_basis(&layout);
        let mut lambda = 1e-4;
        let mut iterations = 0;
        let mut nm = self.normals(&layout).ok_or_else(|| {
            CalibrateError::Diverged("targets behind a camera at the start".into())
        })?;
        while iterations < options.max_iterations {
            iterations += 1;
            let mut accepted = false;
            while lambda < 1e12 {
                let Some((dr, de)) = Self::solve(&nm, lambda, datum.as_ref()) else {
                    lambda *= 10.0;
                    continue;
                };
                let trial = self.apply(&layout, &dr, &de);
                match trial.cost() {
                    Some(c) if c <= nm.cost => {
                        let gain = nm.cost - c;
                        *self = trial;
                        lambda = (lambda / 10.0).max(1e-12);
                        accepted = true;
                        nm = self.normals(&layout).ok_or_else(|| {
                            CalibrateError::Diverged("targets behind a camera".into())
                        })?;
                        if gain <= 1e-12 * nm.cost.max(1e-300) {
                            return Ok(iterations);
                        }
                        break;
                    }
                    _ => lambda *= 10.0,
                }
            }
            if !accepted {
                // No step lowers the cost: at the minimum to rounding.
                return Ok(iterations);
            }
        }
        Ok(iterations)
    }

    /// Observations in use.
    pub fn n_used(&self) -> usize {
        self.images
            .iter()
            .map(|im| im.points.iter().filter(|p| p.used).count())
            .sum()
    }

    /// Adjusts, snoops, adjusts again, and computes the precision.
    pub fn adjust(&mut self, options: &BundleOptions) -> Result<BundleResult, CalibrateError> {
        let ps = self.camera.sensor.pixel_size;
        let mut iterations = self.levenberg_marquardt(options)?;
        let mut n_snooped = 0;
        if options.snooping_critical > 0.0 {
            for _round in 0..50 {
                let layout = self.layout(options);
                let (sigma0, _) = self.sigma0(&layout, options);
                let sigma = sigma0.max(options.sigma_floor_px * ps);
                let mut removed = 0;
                for im in &mut self.images {
                    let total = im.points.len();
                    let out = im.points.iter().filter(|p| !p.used).count();
                    if (out + 1) as f64 > options.max_snooped_ratio * total as f64 {
                        continue;
                    }
                    if let Some((k, w)) = worst_standardised(&self.camera, &self.targets, im) {
                        if w / sigma > options.snooping_critical {
                            im.points[k].used = false;
                            removed += 1;
                        }
                    }
                }
                if removed == 0 {
                    break;
                }
                n_snooped += removed;
                iterations += self.levenberg_marquardt(options)?;
            }
        }
        let layout = self.layout(options);
        let (sigma0, n_unknowns) = self.sigma0(&layout, options);
        let nm = self
            .normals(&layout)
            .ok_or_else(|| CalibrateError::Diverged("targets behind a camera".into()))?;
        let q = self.cofactor(&nm, &layout)?;
        let mut covariance = SMatrix::<f64, N_PARAMS, N_PARAMS>::zeros();
        for (a, pa) in layout.free.iter().enumerate() {
            for (b, pb) in layout.free.iter().enumerate() {
                covariance[(pa.index(), pb.index())] = q[(a, b)] * sigma0 * sigma0;
            }
        }
        Ok(BundleResult {
            camera: self.camera,
            covariance,
            sigma0,
            n_observations: self.n_used(),
            n_unknowns,
            iterations,
            n_snooped,
        })
    }

    /// σ0 (mm) and the number of unknowns net of the datum defect.
    fn sigma0(&self, layout: &Layout, options: &BundleOptions) -> (f64, usize) {
        let n_obs = 2 * self.n_used();
        let defect = if options.free_targets { 7 } else { 0 };
        let unknowns = layout.n + 6 * self.images.len() - defect;
        let cost = self.cost().unwrap_or(f64::NAN);
        let dof = n_obs.saturating_sub(unknowns).max(1);
        ((cost / dof as f64).sqrt(), unknowns)
    }

    /// Cofactor matrix of the free camera parameters (undamped reduced
    /// system); a singular system names the undetermined combination.
    fn cofactor(&self, nm: &Normals, layout: &Layout) -> Result<DMatrix<f64>, CalibrateError> {
        let nf = layout.free.len();
        let datum = self.datum_basis(layout);
        let (s, _, _) = Self::reduce(nm, 0.0, datum.as_ref()).ok_or_else(|| {
            CalibrateError::Diverged("an image's exterior orientation is singular".into())
        })?;
        let n = s.nrows();
        let d: DVector<f64> = DVector::from_fn(n, |i, _| 1.0 / s[(i, i)].max(1e-300).sqrt());
        let scaled = DMatrix::from_fn(n, n, |i, j| s[(i, j)] * d[i] * d[j]);
        let name = |v: nalgebra::DVectorView<f64>| {
            let mut parts: Vec<(f64, &str)> = (0..nf)
                .map(|i| (v[i], layout.free[i].name()))
                .filter(|(c, _)| c.abs() > 0.1)
                .collect();
            parts.sort_by(|a, b| b.0.abs().total_cmp(&a.0.abs()));
            if parts.is_empty() {
                "the target coordinates' datum".to_string()
            } else {
                parts
                    .iter()
                    .map(|(c, n)| format!("{c:+.2} {n}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            }
        };
        let Some(chol) = scaled.clone().cholesky() else {
            // Singular: name the combination of the smallest eigenvalue.
            let eig = scaled.symmetric_eigen();
            let k = eig.eigenvalues.imin();
            return Err(CalibrateError::NotDeterminable {
                combination: name(eig.eigenvectors.column(k)),
            });
        };
        let inv = chol.inverse();
        // Determinability of the camera parameters: a (nearly) exact linear
        // dependence shows as a vanishing eigenvalue of their correlation matrix.
        let corr = DMatrix::from_fn(nf, nf, |i, j| {
            inv[(i, j)] / (inv[(i, i)] * inv[(j, j)]).sqrt()
        });
        // A parameter inseparable from the exterior orientations (or the
        // targets) shows as an inflated variance: its variance with all
        // other unknowns free against its variance with them known.
        for (i, p) in layout.free.iter().enumerate() {
            let inflation = nm.s[(i, i)] * inv[(i, i)] * d[i] * d[i];
            if inflation.is_nan() || inflation > MAX_VARIANCE_INFLATION {
                return Err(CalibrateError::NotDeterminable {
                    combination: format!(
                        "{} (inseparable from the images' orientations: variance inflated {:.0e} times)",
                        p.name(),
                        inflation
                    ),
                });
            }
        }
        if nf > 0 {
            let eig = corr.symmetric_eigen();
            let k = eig.eigenvalues.imin();
            if eig.eigenvalues[k].is_nan() || eig.eigenvalues[k] <= 1e-9 {
                return Err(CalibrateError::NotDeterminable {
                    combination: name(eig.eigenvectors.column(k)),
                });
            }
        }
        Ok(DMatrix::from_fn(nf, nf, |i, j| inv[(i, j)] * d[i] * d[j]))
    }
}

/// The used observation of `im` with the largest standardised residual
/// (unscaled by σ: `|v| / sqrt(q_vv)`), its index and value.
fn worst_standardised(
    camera: &Camera,
    targets: &[Vector3<f64>],
    im: &ImageBlock,
) -> Option<(usize, f64)> {
    let mut u = Matrix6::zeros();
    let mut lins = Vec::with_capacity(im.points.len());
    for (k, p) in im.points.iter().enumerate().filter(|(_, p)| p.used) {
        let lin = linearise(camera, &im.exterior, &targets[p.target], &p.centre())?;
        u += lin.exterior.transpose() * lin.exterior;
        lins.push((k, lin));
    }
    let ui = u.cholesky()?.inverse();
    let mut worst: Option<(usize, f64)> = None;
    for (k, lin) in lins {
        let h = lin.exterior * ui * lin.exterior.transpose();
        let wx = lin.v.x.abs() / (1.0 - h[(0, 0)]).max(1e-6).sqrt();
        let wy = lin.v.y.abs() / (1.0 - h[(1, 1)]).max(1e-6).sqrt();
        let w = wx.max(wy);
        if worst.is_none_or(|(_, b)| w > b) {
            worst = Some((k, w));
        }
    }
    worst
}
