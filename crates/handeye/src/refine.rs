//! The nonlinear least-squares refinement of `X = T_tcp←camera` and
//! `Z = T_base←plate` over all stations.
//!
//! Residual of station `i` (6-vector, base frame): the TCP pose predicted
//! from the camera, `P_i = Z B_i X⁻¹`, against the robot's `A_i`:
//! `τ = t_P − t_A` (mm), `ρ = log(R_P R_Aᵀ)` (rad). Its covariance is
//! propagated from both measurements (the linearised Gauss–Helmert model):
//! the robot's isotropic repeatability enters directly; the camera pose's
//! covariance of centre `δc` and small rotations `ω` about the plate's axes
//! enters as `τ += R_Z δc − [l]ₓ R_Z ω`, `ρ += R_Z ω`, `l` the lever from
//! the projection centre to the TCP (base frame).
//!
//! Unknowns, in this order: `t_X` (mm, TCP frame), `ω_X` (small rotation
//! about the TCP's axes: `R_X ← exp(ω_X) R_X`), `t_Z` (mm, base frame),
//! `ω_Z` (about the base's axes). Jacobian (analytic):
//!
//! ```text
//!        t_X          ω_X            t_Z   ω_Z
//! τ:   −R_P     −R_P [t_X]ₓ           I   −[t_P − t_Z]ₓ
//! ρ:     0          −R_P              0         I
//! ```
//!
//! Gauss–Newton with Levenberg–Marquardt damping; each step re-bases the
//! rotations, so any attitude works.

use crate::{HandEyeError, Station};
use nalgebra::{Isometry3, Matrix3, Matrix6, SMatrix, SVector, Vector3, Vector6};
use photopose_geometry::pose::perturbed;

/// The 12 × 12 matrices of the adjustment.
pub type Matrix12 = SMatrix<f64, 12, 12>;
/// A 12-vector of the unknowns' order.
pub type Vector12 = SVector<f64, 12>;
/// The Jacobian of one station's residual.
pub type Jacobian = SMatrix<f64, 6, 12>;

/// A-priori precision of the robot's poses (repeatability).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotPrecision {
    /// Standard deviation of a TCP position coordinate, mm.
    pub std_mm: f64,
    /// Standard deviation of a small rotation about an axis, degrees.
    pub std_deg: f64,
}

/// One station's linearisation at the current estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linearised {
    /// Residual `(τ, ρ)`, mm and rad.
    pub residual: Vector6<f64>,
    /// Covariance of the residual from the measurements, mm², rad².
    pub covariance: Matrix6<f64>,
    /// Derivative of the residual with respect to the unknowns.
    pub jacobian: Jacobian,
}

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The residual, its covariance and Jacobian of one station at `(x, z)`.
pub fn linearise(
    station: &Station,
    x: &Isometry3<f64>,
    z: &Isometry3<f64>,
    robot: RobotPrecision,
) -> Linearised {
    let a = &station.robot;
    let b = &station.camera.pose;
    let p = z * b * x.inverse();
    let rp = p.rotation.to_rotation_matrix().into_inner();
    let rz = z.rotation.to_rotation_matrix().into_inner();
    let tp = p.translation.vector;
    let tz = z.translation.vector;
    let tx = x.translation.vector;
    let tau = tp - a.translation.vector;
    let rho = (p.rotation * a.rotation.inverse()).scaled_axis();
    let mut residual = Vector6::zeros();
    residual.fixed_rows_mut::<3>(0).copy_from(&tau);
    residual.fixed_rows_mut::<3>(3).copy_from(&rho);

    let mut j = Jacobian::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&-rp);
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-rp * skew(&tx)));
    j.fixed_view_mut::<3, 3>(0, 6)
        .copy_from(&Matrix3::identity());
    j.fixed_view_mut::<3, 3>(0, 9).copy_from(&-skew(&(tp - tz)));
    j.fixed_view_mut::<3, 3>(3, 3).copy_from(&-rp);
    j.fixed_view_mut::<3, 3>(3, 9)
        .copy_from(&Matrix3::identity());

    // Camera pose covariance into the residual.
    let centre = z * nalgebra::Point3::from(b.translation.vector);
    let lever = tp - centre.coords;
    let mut jb = Matrix6::zeros();
    jb.fixed_view_mut::<3, 3>(0, 0).copy_from(&rz);
    jb.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-skew(&lever) * rz));
    jb.fixed_view_mut::<3, 3>(3, 3).copy_from(&rz);
    let mut covariance = jb * station.camera.covariance * jb.transpose();
    let st = robot.std_mm * robot.std_mm;
    let sr = robot.std_deg.to_radians().powi(2);
    for k in 0..3 {
        covariance[(k, k)] += st;
        covariance[(3 + k, 3 + k)] += sr;
    }
    Linearised {
        residual,
        covariance,
        jacobian: j,
    }
}

/// Applies a step of the unknowns to `(x, z)`.
pub fn apply(
    x: &Isometry3<f64>,
    z: &Isometry3<f64>,
    d: &Vector12,
) -> (Isometry3<f64>, Isometry3<f64>) {
    let dtx = Vector3::new(d[0], d[1], d[2]);
    let dwx = Vector3::new(d[3], d[4], d[5]);
    let dtz = Vector3::new(d[6], d[7], d[8]);
    let dwz = Vector3::new(d[9], d[10], d[11]);
    (perturbed(x, &dtx, &dwx), perturbed(z, &dtz, &dwz))
}

/// The weighted sum of squares `Σ vᵀ Σ⁻¹ v` and the normal equations at
/// `(x, z)` over `stations`.
pub fn normal_equations(
    stations: &[&Station],
    x: &Isometry3<f64>,
    z: &Isometry3<f64>,
    robot: RobotPrecision,
) -> Result<(f64, Matrix12, Vector12), HandEyeError> {
    let mut n = Matrix12::zeros();
    let mut g = Vector12::zeros();
    let mut omega = 0.0;
    for s in stations {
        let l = linearise(s, x, z, robot);
        let w = l
            .covariance
            .try_inverse()
            .ok_or_else(|| HandEyeError::BadStation {
                station: s.name.clone(),
                what: "the covariance of its residual is singular (zero standard deviations?)"
                    .into(),
            })?;
        let jtw = l.jacobian.transpose() * w;
        n += jtw * l.jacobian;
        g += jtw * l.residual;
        omega += (l.residual.transpose() * w * l.residual)[(0, 0)];
    }
    Ok((omega, n, g))
}

/// The result of [`refine`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refined {
    /// Camera in the TCP frame.
    pub x: Isometry3<f64>,
    /// Plate in the base frame.
    pub z: Isometry3<f64>,
    /// Weighted sum of squared residuals `Ω`.
    pub omega: f64,
    /// The normal matrix at the solution.
    pub normal: Matrix12,
    /// Iterations done.
    pub iterations: usize,
}

/// Levenberg–Marquardt from `(x, z)` over `stations`.
pub fn refine(
    stations: &[&Station],
    mut x: Isometry3<f64>,
    mut z: Isometry3<f64>,
    robot: RobotPrecision,
    max_iterations: usize,
) -> Result<Refined, HandEyeError> {
    let (mut omega, mut n, mut g) = normal_equations(stations, &x, &z, robot)?;
    let mut lambda = 1e-6;
    let mut last_step = f64::INFINITY;
    for iteration in 1..=max_iterations {
        let mut damped = n;
        for k in 0..12 {
            damped[(k, k)] += lambda * n[(k, k)].max(1e-12);
        }
        let Some(step) = damped.cholesky().map(|c| c.solve(&-g)) else {
            return Err(HandEyeError::DegenerateMotion {
                what: "the normal equations of the adjustment are singular".into(),
            });
        };
        let (x2, z2) = apply(&x, &z, &step);
        let (omega2, n2, g2) = normal_equations(stations, &x2, &z2, robot)?;
        last_step = step.norm();
        if omega2 <= omega * (1.0 + 1e-12) || !omega.is_finite() {
            let converged = step.norm() < 1e-10 || (omega - omega2).abs() <= 1e-12 * omega.max(1.0);
            (x, z, omega, n, g) = (x2, z2, omega2, n2, g2);
            lambda = (lambda * 0.1).max(1e-12);
            if converged {
                return Ok(Refined {
                    x,
                    z,
                    omega,
                    normal: n,
                    iterations: iteration,
                });
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e12 {
                // No step reduces the cost: the current point is the minimum
                // to numerical precision.
                return Ok(Refined {
                    x,
                    z,
                    omega,
                    normal: n,
                    iterations: iteration,
                });
            }
        }
    }
    Err(HandEyeError::NoConvergence {
        iterations: max_iterations,
        step: last_step,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CameraPose;
    use photopose_geometry::pose::isometry_from_xyzabc;

    #[test]
    fn jacobian_matches_central_differences() {
        let x = isometry_from_xyzabc([40.0, -75.0, 130.0, 88.0, 3.0, -2.0]);
        let z = isometry_from_xyzabc([1200.0, 150.0, -20.0, 30.0, 1.0, -0.5]);
        let b = isometry_from_xyzabc([30.0, -60.0, 600.0, 20.0, 10.0, 170.0]);
        // A robot pose a little off the prediction, so the residual is not zero.
        let a = perturbed(
            &(z * b * x.inverse()),
            &Vector3::new(0.3, -0.2, 0.1),
            &Vector3::new(1e-3, -2e-3, 5e-4),
        );
        let s = Station {
            name: "s".into(),
            robot: a,
            camera: CameraPose::with_stds(b, [0.05; 3], [0.005; 3]),
        };
        let robot = RobotPrecision {
            std_mm: 0.02,
            std_deg: 0.005,
        };
        let l = linearise(&s, &x, &z, robot);
        let h = 1e-6;
        for k in 0..12 {
            let mut d = Vector12::zeros();
            d[k] = h;
            let (xp, zp) = apply(&x, &z, &d);
            let (xm, zm) = apply(&x, &z, &-d);
            let fd = (linearise(&s, &xp, &zp, robot).residual
                - linearise(&s, &xm, &zm, robot).residual)
                / (2.0 * h);
            let col = l.jacobian.column(k);
            let scale = col.abs().max().max(1.0);
            let err_t = (fd.fixed_rows::<3>(0) - col.fixed_rows::<3>(0)).abs().max();
            // The rotation rows use the small-residual approximation of the
            // logarithm's derivative: good to about |ρ| ≈ 2e-3.
            let err_r = (fd.fixed_rows::<3>(3) - col.fixed_rows::<3>(3)).abs().max();
            assert!(err_t < 1e-6 * scale, "column {k}: τ {err_t}\n{fd}\n{col}");
            assert!(err_r < 5e-3, "column {k}: ρ {err_r}\n{fd}\n{col}");
        }
    }
}
