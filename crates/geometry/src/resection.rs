//! Single-image resection: hypothesise-and-verify over the closed form, then
//! Gauss–Newton / Levenberg–Marquardt refinement of the collinearity
//! equations with analytic Jacobians, data snooping of gross errors, and
//! a-posteriori precision.
//!
//! The rotation is re-based at the current estimate each iteration:
//! `R = R0 · cayley(a, b, c)` with the increments `(a, b, c)` solved around
//! zero, so any attitude works although the Cayley form cannot express a
//! half turn. Small rotations `ω = 2 (a, b, c)` are rotations of the camera
//! about the axes of the object (field) frame.
//!
//! A [`Resection`] is a workspace: once it has seen an observation set of a
//! given size, solving another of that size or smaller allocates nothing.

use crate::camera::Camera;
use crate::closed_form;
use crate::error::GeometryError;
use crate::exterior::Exterior;
use crate::linearised::{Linearised, Normals, PointJacobian};
use crate::precision::{std_center, std_rotation_deg, to_omega};
use crate::rng::SplitMix64;
use crate::rotation::cayley;
use nalgebra::{Matrix3, Matrix6, SymmetricEigen, Vector2, Vector3, Vector6};

pub use crate::observation::{Observation, Status};

/// Tuning of the resection; the defaults suit the project's cameras.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResectionOptions {
    /// Inlier gate of hypothesise-and-verify, pixels.
    pub ransac_threshold_px: f64,
    /// Confidence at which hypothesise-and-verify stops early.
    pub ransac_confidence: f64,
    /// Most hypotheses tried.
    pub ransac_max_hypotheses: usize,
    /// Smallest share of the observations that must agree with the pose.
    pub min_inlier_ratio: f64,
    /// Critical value of the standardised residual in data snooping.
    pub snooping_critical: f64,
    /// Floor of the a-posteriori σ0 used in snooping, pixels (keeps
    /// noise-free data from turning rounding into "gross errors").
    pub sigma_floor_px: f64,
    /// Most points removed by data snooping, as a share of all points.
    pub max_snooped_ratio: f64,
    /// Iteration limit of the least-squares refinement.
    pub max_iterations: usize,
    /// Seed of the hypothesis sampler (the result is deterministic).
    pub seed: u64,
}

impl Default for ResectionOptions {
    fn default() -> Self {
        ResectionOptions {
            ransac_threshold_px: 4.0,
            ransac_confidence: 0.9999,
            ransac_max_hypotheses: 500,
            min_inlier_ratio: 0.5,
            snooping_critical: 4.5,
            sigma_floor_px: 0.005,
            max_snooped_ratio: 0.2,
            max_iterations: 50,
            seed: 0x5EED_0F90_5E00,
        }
    }
}

/// The result of a resection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResectionReport {
    /// The exterior orientation.
    pub exterior: Exterior,
    /// A-posteriori covariance of `(Xc, Yc, Zc, ωX, ωY, ωZ)` (mm², rad²),
    /// `ω` the small rotations of the camera about the field's axes in the
    /// sense `R ← R·(I + [ω]ₓ)`; [`crate::pose::camera_pose_covariance`]
    /// gives the camera pose's.
    pub covariance: Matrix6<f64>,
    /// A-posteriori σ0 of an image coordinate, mm.
    pub sigma0: f64,
    /// σ0 in pixels.
    pub sigma0_px: f64,
    /// RMS of the image-coordinate residuals, pixels.
    pub rms_px: f64,
    /// Points used in the final adjustment.
    pub n_points: usize,
    /// Points rejected (hypothesise-and-verify and data snooping).
    pub n_rejected: usize,
    /// Gauss–Newton / LM iterations of the final adjustment.
    pub iterations: usize,
    /// Hypotheses tried.
    pub hypotheses: usize,
}

impl ResectionReport {
    /// The squared Mahalanobis distance of this pose from `truth` under
    /// its covariance ([`Exterior::deviation_from`]); infinite when the
    /// covariance is not positive definite. χ²(6)-distributed for a
    /// consistent estimate.
    pub fn mahalanobis_sq(&self, truth: &Exterior) -> f64 {
        let err = self.exterior.deviation_from(truth);
        self.covariance
            .cholesky()
            .map(|ch| err.dot(&ch.solve(&err)))
            .unwrap_or(f64::INFINITY)
    }

    /// Standard deviations of `Xc, Yc, Zc`, mm.
    pub fn std_center(&self) -> Vector3<f64> {
        std_center(&self.covariance)
    }

    /// Standard deviations of the rotations about the field's X, Y, Z axes, degrees.
    pub fn std_rotation_deg(&self) -> Vector3<f64> {
        std_rotation_deg(&self.covariance)
    }
}

/// The resection workspace (see the module doc).
#[derive(Debug, Clone)]
pub struct Resection {
    c: f64,
    pixel_size: f64,
    options: ResectionOptions,
    status: Vec<Status>,
    rejected: Vec<u64>,
    lin: Linearised,
}

/// The largest first step (relative to the camera distance, and in
/// radians) after which a refinement from given rows takes a chord step
/// ([`Resection::refine_from`]).
const CHORD_STEP: f64 = 1e-4;

/// `e` moved by the step `delta` of `(Xc, Yc, Zc, a, b, c)` (the rotation
/// by its Cayley increment).
fn stepped(e: &Exterior, delta: &Vector6<f64>) -> Exterior {
    Exterior {
        rotation: e.rotation * cayley(delta[3], delta[4], delta[5]),
        center: e.center + delta.fixed_rows::<3>(0),
    }
}

/// Whether the step `delta` moves the centre by at most `bound` of the
/// camera distance `scale` and turns by at most `bound` radians.
fn within(delta: &Vector6<f64>, bound: f64, scale: f64) -> bool {
    delta.fixed_rows::<3>(0).norm() <= bound * scale && delta.fixed_rows::<3>(3).norm() <= bound
}

impl Resection {
    /// A workspace for `camera` (principal distance and pixel size are
    /// taken from it).
    pub fn new(camera: &Camera, options: ResectionOptions) -> Self {
        Resection {
            c: camera.interior.c,
            pixel_size: camera.sensor.pixel_size,
            options,
            status: Vec::new(),
            rejected: Vec::new(),
            lin: Linearised::default(),
        }
    }

    /// The options in force.
    pub fn options(&self) -> &ResectionOptions {
        &self.options
    }

    /// Ids of the observations rejected by the last solve, in input order.
    pub fn rejected_ids(&self) -> &[u64] {
        &self.rejected
    }

    /// What the last solve did with each observation.
    pub fn status(&self) -> &[Status] {
        &self.status
    }

    fn reset(&mut self, n: usize) {
        self.status.clear();
        self.status.resize(n, Status::Used);
        self.rejected.clear();
        // Room for every observation to be rejected, taken with the status
        // on the first solve: a later frame's first rejection must not
        // allocate (no allocation per frame once warm).
        self.rejected.reserve(n);
    }

    /// Full resection: closed form inside hypothesise-and-verify, refinement,
    /// re-classification, data snooping, precision.
    pub fn solve(&mut self, obs: &[Observation]) -> Result<ResectionReport, GeometryError> {
        self.reset(obs.len());
        check_input(obs)?;
        let (start, hypotheses) = self.hypothesise(obs)?;
        // Refine on the consensus set, then re-classify every point with the
        // refined pose (a closed form from four points extrapolates poorly).
        let gate = self.options.ransac_threshold_px * self.pixel_size;
        let mut e = start;
        let mut adjusted = None;
        for _ in 0..3 {
            let result = self.adjust(obs, &mut e, &[], false)?;
            let mut changed = false;
            for (k, o) in obs.iter().enumerate() {
                let ok = e
                    .project_ideal(self.c, &o.object)
                    .is_some_and(|m| (o.image - m).norm() < gate);
                let s = if ok { Status::Used } else { Status::Outlier };
                changed |= s != self.status[k];
                self.status[k] = s;
            }
            if !changed {
                // The workspace holds the adjustment of exactly this set.
                adjusted = Some(result);
                break;
            }
        }
        self.check_consensus(obs.len(), hypotheses)?;
        let mut report = self.snoop(obs, e, adjusted)?;
        report.hypotheses = hypotheses;
        // Retro-reflective targets face +Z: a camera below them sees nothing.
        let back = obs
            .iter()
            .zip(&self.status)
            .filter(|(o, s)| **s == Status::Used && report.exterior.center.z <= o.object.z)
            .count();
        if back > 0 {
            return Err(GeometryError::BackSide { count: back });
        }
        Ok(report)
    }

    /// Refinement from a given start, all observations used at first; data
    /// snooping still removes gross errors.
    pub fn refine(
        &mut self,
        obs: &[Observation],
        start: Exterior,
    ) -> Result<ResectionReport, GeometryError> {
        self.refine_from(obs, start, &[])
    }

    /// [`Resection::refine`] whose first pass takes the rows at `start`
    /// from `jacobians` (`jacobians[k]` of `obs[k]`, formed at `start` by
    /// [`crate::precision::UncertainProjector::covariance_and_jacobian_at`]
    /// while projecting the targets, as tracking does anyway) instead of
    /// forming them again. When the first step from `start` is small (at
    /// most 1e-4 of the camera distance and 1e-4 rad: `start` a
    /// close prediction), the second is a chord step, solved with the same
    /// normal matrix from the residuals at the new pose alone, and taken
    /// when it is tiny: one pass over the points fewer, the result within
    /// about 2e-4 σ of [`Resection::refine`]'s (the covariance within the
    /// first step's relative size). Otherwise the same result, bit for
    /// bit. Without them (`jacobians` empty) it is [`Resection::refine`].
    ///
    /// The input is checked as [`Resection::solve`] checks it, while the
    /// first adjustment loads it (every observation is used at first).
    pub fn refine_from(
        &mut self,
        obs: &[Observation],
        start: Exterior,
        jacobians: &[PointJacobian],
    ) -> Result<ResectionReport, GeometryError> {
        self.reset(obs.len());
        check_count(obs)?;
        let mut e = start;
        let adjusted = self.adjust(obs, &mut e, jacobians, true)?;
        self.snoop(obs, e, Some(adjusted))
    }

    fn check_consensus(&self, total: usize, _hypotheses: usize) -> Result<(), GeometryError> {
        let used = self.status.iter().filter(|s| **s == Status::Used).count();
        let need = ((self.options.min_inlier_ratio * total as f64).ceil() as usize).max(4);
        if used < need {
            return Err(GeometryError::NoConsensus {
                inliers: used,
                total,
            });
        }
        Ok(())
    }

    /// Hypothesise-and-verify over the closed form. Leaves the consensus set
    /// in `status` and returns the best hypothesis.
    fn hypothesise(&mut self, obs: &[Observation]) -> Result<(Exterior, usize), GeometryError> {
        let n = obs.len();
        let shape = Shape::of(obs)?;
        let gate2 = (self.options.ransac_threshold_px * self.pixel_size).powi(2);
        let mut rng = SplitMix64::new(self.options.seed);
        let sample_size = if shape.planar { 4 } else { 6 };
        let mut best: Option<(usize, f64, Exterior)> = None;
        let mut needed = self.options.ransac_max_hypotheses;
        let mut tried = 0;
        let mut attempts = 0;
        while tried < needed.min(self.options.ransac_max_hypotheses)
            && attempts < 20 * self.options.ransac_max_hypotheses
        {
            attempts += 1;
            let idx = if tried == 0 && attempts == 1 {
                shape.spread_sample(obs)
            } else {
                let mut idx = [0usize; 6];
                random_distinct(&mut rng, n, &mut idx[..sample_size]);
                idx
            };
            let hyp = if shape.planar {
                let ob = [0, 1, 2, 3].map(|k| obs[idx[k]].object);
                let im = [0, 1, 2, 3].map(|k| obs[idx[k]].image);
                if !shape.well_spread(&ob) {
                    continue;
                }
                closed_form::resect_four_coplanar(self.c, &ob, &im)
            } else {
                let ob = [0, 1, 2, 3, 4, 5].map(|k| obs[idx[k]].object);
                let im = [0, 1, 2, 3, 4, 5].map(|k| obs[idx[k]].image);
                closed_form::dlt(self.c, &ob, &im)
            };
            tried += 1;
            let Ok(e) = hyp else { continue };
            // Verify: count points within the gate; ties broken by residual.
            let mut inliers = 0;
            let mut score = 0.0;
            for o in obs {
                let q = e.to_camera(&o.object);
                if q.z >= 0.0 {
                    continue;
                }
                let m = Vector2::new(-self.c * q.x / q.z, -self.c * q.y / q.z);
                let r2 = (o.image - m).norm_squared();
                if r2 < gate2 {
                    inliers += 1;
                    score += r2;
                }
            }
            let better = match &best {
                None => inliers > 0,
                Some((bi, bs, _)) => inliers > *bi || (inliers == *bi && score < *bs),
            };
            if better {
                best = Some((inliers, score, e));
                let w = inliers as f64 / n as f64;
                let p_fail = 1.0 - w.powi(sample_size as i32);
                needed = if p_fail <= 1e-12 {
                    0
                } else {
                    ((1.0 - self.options.ransac_confidence).ln() / p_fail.ln()).ceil() as usize
                };
            }
        }
        let Some((inliers, _, e)) = best else {
            return Err(GeometryError::NoConsensus {
                inliers: 0,
                total: n,
            });
        };
        for (k, o) in obs.iter().enumerate() {
            let ok = e
                .project_ideal(self.c, &o.object)
                .is_some_and(|m| (o.image - m).norm_squared() < gate2);
            self.status[k] = if ok { Status::Used } else { Status::Outlier };
        }
        if inliers < 4 {
            return Err(GeometryError::NoConsensus { inliers, total: n });
        }
        self.check_consensus(n, tried)?;
        Ok((e, tried))
    }

    /// Levenberg–Marquardt over the used observations, updating `e`.
    /// Returns the iterations and the normal equations at the solution; the
    /// workspace `lin` then holds the Jacobian and residuals at `e` (after a
    /// last tiny step, the residuals and the cost are those before it, the
    /// step pending in `lin`: [`Linearised::shift_later`]).
    /// `first`: the rows at `e` of every used observation, or none;
    /// `check`: whether to check the used observations as
    /// [`check_input`] does (those of a first adjustment).
    fn adjust(
        &mut self,
        obs: &[Observation],
        e: &mut Exterior,
        first: &[PointJacobian],
        check: bool,
    ) -> Result<(usize, Normals), GeometryError> {
        let c = self.c;
        let scale = e.center.norm().max(1.0);
        let mut lambda = 1e-6;
        let mut it = 0;
        self.lin.load(obs, &self.status, check)?;
        if self.lin.len() < 4 {
            return Err(GeometryError::TooFewPoints {
                got: self.lin.len(),
                need: 4,
            });
        }
        let mut current = if first.is_empty() {
            self.lin.evaluate(c, e, obs)?
        } else {
            self.lin.evaluate_from(c, e, obs, first)?
        };
        while it < self.options.max_iterations {
            it += 1;
            let mut a = current.n;
            for k in 0..6 {
                a[(k, k)] *= 1.0 + lambda;
            }
            let Some(ch) = a.cholesky() else {
                if lambda > 1e8 {
                    return Err(GeometryError::Singular);
                }
                lambda = (lambda * 100.0).max(1e-6);
                continue;
            };
            let delta = ch.solve(&current.g);
            let candidate = stepped(e, &delta);
            // Steps this small only move the pose by rounding noise: take
            // the step and stop, moving the residuals by the linear
            // prediction (exact to the second order of the step).
            // Gauss–Newton converges quadratically here, so after a step of
            // 1e-6 of the camera distance what remains is ~1e-12 of it.
            let tiny = within(&delta, 1e-6, scale);
            if tiny && lambda <= 1e-6 {
                *e = candidate;
                // The residuals and their cost move in the next pass that
                // reads them (the data snooping's).
                self.lin.shift_later(&delta);
                return Ok((it, current));
            }
            // A refinement from rows formed at a nearby pose (tracking's
            // prediction) whose first step is small: the step after it
            // solved with the same normal matrix (a chord step: only the
            // residuals at the candidate formed). Taken when that step is
            // tiny; it then differs from Gauss–Newton's by the first step's
            // relative size times itself (at most 1e-4 · 1e-6 of the camera
            // distance), and the normal matrix by the first step's relative
            // size. Otherwise the candidate is evaluated in full below.
            let small = within(&delta, CHORD_STEP, scale);
            if !first.is_empty() && it == 1 && small && lambda <= 1e-6 {
                if let Ok((g, cost)) = self.lin.residuals_trial(c, &candidate, obs) {
                    let second = ch.solve(&g);
                    if within(&second, 1e-6, scale) && cost <= current.cost * (1.0 + 1e-12) {
                        *e = stepped(&candidate, &second);
                        self.lin.accept_trial();
                        self.lin.shift_later(&second);
                        let chord = Normals { g, cost, ..current };
                        return Ok((it + 1, chord));
                    }
                }
            }
            // The normal equations at the candidate carry its cost: one pass
            // serves both the acceptance test and the next step.
            match self.lin.evaluate_trial(c, &candidate, obs) {
                Ok(next) if next.cost <= current.cost * (1.0 + 1e-12) => {
                    *e = candidate;
                    self.lin.accept_trial();
                    let small_gain = current.cost - next.cost <= 1e-10 * current.cost;
                    lambda = (lambda * 0.1).max(1e-12);
                    current = next;
                    if tiny || small_gain {
                        return Ok((it, current));
                    }
                }
                _ if tiny => return Ok((it, current)),
                _ => {
                    lambda *= 10.0;
                    if lambda > 1e10 {
                        // No step lowers the cost: we sit at the minimum to
                        // machine precision.
                        return Ok((it, current));
                    }
                }
            }
        }
        Err(GeometryError::NotConverged { iterations: it })
    }

    /// Adjust, then remove the worst standardised residual above the critical
    /// value, one point at a time; finally compute the precision.
    /// `adjusted`: the result of an adjustment of the current set that left
    /// the workspace at `e` (saves repeating it).
    fn snoop(
        &mut self,
        obs: &[Observation],
        mut e: Exterior,
        mut adjusted: Option<(usize, Normals)>,
    ) -> Result<ResectionReport, GeometryError> {
        let n_total = obs.len();
        let max_snooped = (self.options.max_snooped_ratio * n_total as f64).floor() as usize;
        let mut snooped = 0;
        loop {
            let (iterations, mut nm) = match adjusted.take() {
                Some(done) => done,
                None => self.adjust(obs, &mut e, &[], false)?,
            };
            let redundancy = 2 * nm.count - 6;
            if redundancy == 0 {
                return Err(GeometryError::TooFewPoints {
                    got: nm.count,
                    need: 4,
                });
            }
            let ch = nm.n.cholesky().ok_or(GeometryError::Singular)?;
            let q = ch.inverse();
            // L⁻¹ of N = L Lᵀ (L lower triangular with a positive diagonal).
            let l_inv = ch
                .l()
                .solve_lower_triangular(&Matrix6::identity())
                .ok_or(GeometryError::Singular)?;
            // Data snooping: standardised residuals w = v / (σ sqrt(q_vv)),
            // in the pass that moves the residuals by a last small step.
            let (shifted, worst) = self.lin.worst_standardised(&l_inv);
            if let Some(cost) = shifted {
                nm.cost = cost;
            }
            let sigma0 = (nm.cost / redundancy as f64).sqrt();
            let sigma_test = sigma0.max(self.options.sigma_floor_px * self.pixel_size);
            let worst = worst
                .map(|(i, w2)| (i, w2.sqrt() / sigma_test))
                .filter(|(_, w)| *w > self.options.snooping_critical)
                .map(|(i, w)| (nth_used(&self.status, i), w));
            match worst {
                Some((k, _)) if snooped < max_snooped && nm.count > 4 => {
                    self.status[k] = Status::Snooped;
                    snooped += 1;
                }
                _ => {
                    // Every observation used (the points loaded are all of
                    // them): none to look for.
                    if nm.count < n_total {
                        for (o, s) in obs.iter().zip(&self.status) {
                            if *s != Status::Used {
                                self.rejected.push(o.id);
                            }
                        }
                    }
                    let covariance = to_omega(&q) * (sigma0 * sigma0);
                    return Ok(ResectionReport {
                        exterior: e,
                        covariance,
                        sigma0,
                        sigma0_px: sigma0 / self.pixel_size,
                        rms_px: (nm.cost / (2 * nm.count) as f64).sqrt() / self.pixel_size,
                        n_points: nm.count,
                        n_rejected: n_total - nm.count,
                        iterations,
                        hypotheses: 0,
                    });
                }
            }
        }
    }
}

/// The index of the `i`-th used observation (the `i`-th point the
/// workspace loaded): looked up only for a point data snooping removes.
fn nth_used(status: &[Status], i: usize) -> usize {
    status
        .iter()
        .enumerate()
        .filter(|(_, s)| **s == Status::Used)
        .nth(i)
        .map(|(k, _)| k)
        .expect("a loaded point is a used observation")
}

/// Rejects inputs that no method can use.
fn check_input(obs: &[Observation]) -> Result<(), GeometryError> {
    check_count(obs)?;
    match obs.iter().position(|o| !o.usable(o.unit_weight())) {
        Some(index) => Err(GeometryError::NonFinite { index }),
        None => Ok(()),
    }
}

/// Rejects fewer than four observations.
fn check_count(obs: &[Observation]) -> Result<(), GeometryError> {
    if obs.len() < 4 {
        return Err(GeometryError::TooFewPoints {
            got: obs.len(),
            need: 4,
        });
    }
    Ok(())
}

/// The spatial layout of the control points: planar or not, and a frame to
/// judge how well a sample spreads.
#[derive(Debug, Clone, Copy)]
struct Shape {
    planar: bool,
    centroid: Vector3<f64>,
    axis1: Vector3<f64>,
    axis2: Vector3<f64>,
    /// Standard deviations of the points along `axis1` and `axis2`.
    spread1: f64,
    spread2: f64,
}

impl Shape {
    fn of(obs: &[Observation]) -> Result<Self, GeometryError> {
        let n = obs.len() as f64;
        let centroid = obs.iter().fold(Vector3::zeros(), |a, o| a + o.object) / n;
        let mut cov = Matrix3::zeros();
        for o in obs {
            let d = o.object - centroid;
            cov += d * d.transpose();
        }
        cov /= n;
        let eig = SymmetricEigen::new(cov);
        let mut order = [0usize, 1, 2];
        order.sort_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
        let l = order.map(|i| eig.eigenvalues[i].max(0.0));
        if l[0] <= 0.0 {
            return Err(GeometryError::Degenerate("all control points coincide"));
        }
        if l[1] < 1e-10 * l[0] {
            return Err(GeometryError::Degenerate(
                "all control points are collinear",
            ));
        }
        // A plate with a few tenths of a millimetre of unevenness over half
        // a metre is planar for the closed form; the refinement takes care of
        // the rest. Non-coplanar closed forms need six points.
        let planar = l[2] < 1e-4 * l[1] || obs.len() < 6;
        Ok(Shape {
            planar,
            centroid,
            axis1: eig.eigenvectors.column(order[0]).into_owned(),
            axis2: eig.eigenvectors.column(order[1]).into_owned(),
            spread1: l[0].sqrt(),
            spread2: l[1].sqrt(),
        })
    }

    #[inline]
    fn local(&self, p: &Vector3<f64>) -> Vector2<f64> {
        let d = p - self.centroid;
        Vector2::new(
            d.dot(&self.axis1) / self.spread1,
            d.dot(&self.axis2) / self.spread2,
        )
    }

    /// A sample whose smallest triangle is a fair share of the layout.
    fn well_spread(&self, p: &[Vector3<f64>; 4]) -> bool {
        let q = p.map(|x| self.local(&x));
        [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]
            .iter()
            .all(|&(a, b, c)| {
                let e1 = q[b] - q[a];
                let e2 = q[c] - q[a];
                (e1.x * e2.y - e1.y * e2.x).abs() > 0.05
            })
    }

    /// The first, deterministic sample: the points farthest out along the
    /// four (or six) diagonal directions of the layout.
    fn spread_sample(&self, obs: &[Observation]) -> [usize; 6] {
        let dirs = [
            Vector2::new(1.0, 1.0),
            Vector2::new(-1.0, 1.0),
            Vector2::new(-1.0, -1.0),
            Vector2::new(1.0, -1.0),
            Vector2::new(1.0, 0.0),
            Vector2::new(-1.0, 0.0),
        ];
        let mut idx = [0usize; 6];
        for (slot, d) in dirs.iter().enumerate() {
            let mut best = f64::NEG_INFINITY;
            for (k, o) in obs.iter().enumerate() {
                if idx[..slot].contains(&k) {
                    continue;
                }
                let s = self.local(&o.object).dot(d);
                if s > best {
                    best = s;
                    idx[slot] = k;
                }
            }
        }
        if !self.planar {
            // For the non-coplanar closed form prefer the two points farthest
            // from the plane of the others.
            let normal = self.axis1.cross(&self.axis2);
            let mut hi = (f64::NEG_INFINITY, 0);
            let mut lo = (f64::INFINITY, 0);
            for (k, o) in obs.iter().enumerate() {
                if idx[..4].contains(&k) {
                    continue;
                }
                let h = (o.object - self.centroid).dot(&normal);
                if h > hi.0 {
                    hi = (h, k);
                }
                if h < lo.0 {
                    lo = (h, k);
                }
            }
            idx[4] = hi.1;
            idx[5] = if lo.1 == hi.1 { idx[5] } else { lo.1 };
        }
        idx
    }
}

/// Fills `out` with distinct indices below `n`.
fn random_distinct(rng: &mut SplitMix64, n: usize, out: &mut [usize]) {
    for k in 0..out.len() {
        loop {
            let i = rng.below(n);
            if !out[..k].contains(&i) {
                out[k] = i;
                break;
            }
        }
    }
}
