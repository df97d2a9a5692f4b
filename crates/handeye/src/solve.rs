//! The whole hand-eye calibration: input checks, closed form, refinement,
//! gross-error detection by station, precision and the per-station report.
//!
//! Gross errors: with the fit's weighted sum of squares `Ω` and redundancy
//! `f = 6n − 12`, station `i`'s statistic is `T_i = v_iᵀ Q_vv,i⁻¹ v_i`
//! (`Q_vv,i = Σ_i − J_i N⁻¹ J_iᵀ`, the cofactor of its residuals); without
//! the station the variance factor is `s_i² = (Ω − T_i) / (f − 6)`, and
//! `F_i = T_i / (6 s_i²)` follows F(6, f − 6) when the station is sound.
//! The station with the largest `F_i` above the critical value at
//! `alpha` is rejected and the fit repeated (at most `max_rejected_share`
//! of the stations). The test is thus independent of how well the
//! a-priori standard deviations fit the scale of the residuals.

use crate::closed_form::closed_form;
use crate::refine::{linearise, refine, Matrix12, RobotPrecision};
use crate::stats::f_critical;
use crate::{HandEyeError, Station};
use nalgebra::{Isometry3, Matrix6};
use photopose_geometry::pose::{xyzabc_from_isometry, xyzabc_std};

/// Options of [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandEyeOptions {
    /// Robot repeatability: standard deviation of a TCP coordinate, mm.
    pub robot_std_mm: f64,
    /// Robot repeatability: standard deviation of a small rotation, degrees.
    pub robot_std_deg: f64,
    /// Station pairs turning less than this are not used to judge the
    /// spread of rotation axes, degrees.
    pub min_rotation_deg: f64,
    /// Smallest spread of the relative rotation axes accepted, degrees.
    pub min_axis_spread_deg: f64,
    /// Significance level of the gross-error test of one station.
    pub alpha: f64,
    /// Largest share of the stations that may be rejected.
    pub max_rejected_share: f64,
    /// Iterations of the adjustment.
    pub max_iterations: usize,
}

impl Default for HandEyeOptions {
    fn default() -> Self {
        HandEyeOptions {
            robot_std_mm: 0.02,
            robot_std_deg: 0.005,
            min_rotation_deg: 5.0,
            min_axis_spread_deg: 10.0,
            alpha: 0.001,
            max_rejected_share: 0.25,
            max_iterations: 100,
        }
    }
}

/// One station's residual at the solution.
#[derive(Debug, Clone, PartialEq)]
pub struct StationResidual {
    /// The station's name.
    pub name: String,
    /// TCP position predicted from the camera minus the robot's, base
    /// frame, mm.
    pub translation_mm: [f64; 3],
    /// Rotation from the robot's TCP orientation to the predicted one
    /// (rotation vector, base frame), degrees.
    pub rotation_deg: [f64; 3],
    /// Length of `translation_mm`.
    pub norm_mm: f64,
    /// Length of `rotation_deg`.
    pub norm_deg: f64,
    /// The gross-error statistic `F` (for a rejected station: its residual
    /// against the fit without it); `None` without redundancy for the test.
    pub test: Option<f64>,
    /// Used in the final fit (false: rejected as a gross error).
    pub used: bool,
}

/// The hand-eye calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct HandEye {
    /// `X = T_tcp←camera`: the camera (projection centre, axes of `Rᵀ`) in
    /// the TCP frame.
    pub camera_in_tcp: Isometry3<f64>,
    /// `Z = T_base←plate`: the plate in the robot's base frame.
    pub plate_in_base: Isometry3<f64>,
    /// A-posteriori covariance `σ0² N⁻¹` of `(t_X, ω_X, t_Z, ω_Z)` (mm²,
    /// rad²; `ω_X` small rotations about the TCP's axes, `ω_Z` about the
    /// base's axes).
    pub covariance: Matrix12,
    /// A-posteriori σ0 (1 when the a-priori standard deviations fit).
    pub sigma0: f64,
    /// Redundancy `6n − 12` of the final fit.
    pub redundancy: usize,
    /// Stations used in the final fit.
    pub n_used: usize,
    /// Per station, in input order.
    pub residuals: Vec<StationResidual>,
    /// Names of the rejected stations, in the order of rejection.
    pub rejected: Vec<String>,
    /// RMS over the used stations of the TCP position discrepancy, mm.
    pub rms_mm: f64,
    /// RMS over the used stations of the TCP rotation discrepancy, degrees.
    pub rms_deg: f64,
    /// Critical value of the gross-error test of the final fit (`None`
    /// without redundancy for it).
    pub critical: Option<f64>,
    /// Spread of the relative rotation axes, degrees.
    pub axis_spread_deg: f64,
    /// Iterations of the final adjustment.
    pub iterations: usize,
}

impl HandEye {
    /// `X` as KUKA `X, Y, Z, A, B, C` (mm, degrees) in the TCP frame.
    pub fn camera_in_tcp_xyzabc(&self) -> [f64; 6] {
        xyzabc_from_isometry(&self.camera_in_tcp)
    }

    /// `Z` as KUKA `X, Y, Z, A, B, C` (mm, degrees) in the base frame.
    pub fn plate_in_base_xyzabc(&self) -> [f64; 6] {
        xyzabc_from_isometry(&self.plate_in_base)
    }

    /// Covariance of `(t_X, ω_X)`.
    pub fn camera_in_tcp_covariance(&self) -> Matrix6<f64> {
        self.covariance.fixed_view::<6, 6>(0, 0).into_owned()
    }

    /// Covariance of `(t_Z, ω_Z)`.
    pub fn plate_in_base_covariance(&self) -> Matrix6<f64> {
        self.covariance.fixed_view::<6, 6>(6, 6).into_owned()
    }

    /// Standard deviations of [`HandEye::camera_in_tcp_xyzabc`].
    pub fn camera_in_tcp_std_xyzabc(&self) -> [f64; 6] {
        xyzabc_std(&self.camera_in_tcp, &self.camera_in_tcp_covariance())
    }

    /// Standard deviations of [`HandEye::plate_in_base_xyzabc`].
    pub fn plate_in_base_std_xyzabc(&self) -> [f64; 6] {
        xyzabc_std(&self.plate_in_base, &self.plate_in_base_covariance())
    }

    /// Standard deviations of the 12 unknowns `(t_X, ω_X, t_Z, ω_Z)`, mm and
    /// degrees (`ω` about the TCP's and the base's axes).
    pub fn std_unknowns(&self) -> [f64; 12] {
        std::array::from_fn(|k| {
            let s = self.covariance[(k, k)].max(0.0).sqrt();
            if matches!(k, 3..=5 | 9..=11) {
                s.to_degrees()
            } else {
                s
            }
        })
    }
}

fn check_inputs(stations: &[Station], o: &HandEyeOptions) -> Result<(), HandEyeError> {
    let positive = |name: &'static str, value: f64| {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(HandEyeError::BadOption {
                name,
                value,
                what: "must be a positive number",
            })
        }
    };
    positive("robot_std_mm", o.robot_std_mm)?;
    positive("robot_std_deg", o.robot_std_deg)?;
    positive("min_rotation_deg", o.min_rotation_deg)?;
    positive("min_axis_spread_deg", o.min_axis_spread_deg)?;
    if !(o.alpha > 0.0 && o.alpha < 0.5) {
        return Err(HandEyeError::BadOption {
            name: "alpha",
            value: o.alpha,
            what: "must be in (0, 0.5)",
        });
    }
    if !(0.0..1.0).contains(&o.max_rejected_share) {
        return Err(HandEyeError::BadOption {
            name: "max_rejected_share",
            value: o.max_rejected_share,
            what: "must be in [0, 1)",
        });
    }
    for s in stations {
        let bad = |what: &str| HandEyeError::BadStation {
            station: s.name.clone(),
            what: what.into(),
        };
        let finite = |t: &Isometry3<f64>| {
            t.translation.vector.iter().all(|v| v.is_finite())
                && t.rotation.coords.iter().all(|v| v.is_finite())
        };
        if !finite(&s.robot) {
            return Err(bad("the robot pose is not finite"));
        }
        if !finite(&s.camera.pose) {
            return Err(bad("the camera pose is not finite"));
        }
        let c = &s.camera.covariance;
        if c.iter().any(|v| !v.is_finite()) || (0..6).any(|k| c[(k, k)] < 0.0) {
            return Err(bad(
                "the camera pose's covariance is not finite or has a negative variance",
            ));
        }
    }
    Ok(())
}

/// Computes `X = T_tcp←camera` and `Z = T_base←plate` from the stations.
pub fn solve(stations: &[Station], options: &HandEyeOptions) -> Result<HandEye, HandEyeError> {
    check_inputs(stations, options)?;
    if stations.len() < 3 {
        return Err(HandEyeError::TooFewStations {
            got: stations.len(),
            need: 3,
        });
    }
    let robot_poses: Vec<_> = stations.iter().map(|s| s.robot).collect();
    let camera_poses: Vec<_> = stations.iter().map(|s| s.camera.pose).collect();
    let start = closed_form(
        &robot_poses,
        &camera_poses,
        options.min_rotation_deg,
        options.min_axis_spread_deg,
    )?;
    let robot = RobotPrecision {
        std_mm: options.robot_std_mm,
        std_deg: options.robot_std_deg,
    };
    let max_rejected = (options.max_rejected_share * stations.len() as f64).floor() as usize;
    let mut used = vec![true; stations.len()];
    let mut rejected: Vec<String> = Vec::new();
    let (mut x, mut z) = (start.camera_in_tcp, start.plate_in_base);
    loop {
        let active: Vec<&Station> = stations
            .iter()
            .zip(&used)
            .filter_map(|(s, &u)| u.then_some(s))
            .collect();
        let n_used = active.len();
        if n_used < 3 {
            return Err(HandEyeError::TooFewStations {
                got: n_used,
                need: 3,
            });
        }
        let fit = refine(&active, x, z, robot, options.max_iterations)?;
        (x, z) = (fit.x, fit.z);
        let redundancy = 6 * n_used - 12;
        let sigma0_sq = fit.omega / redundancy as f64;
        let ninv = fit
            .normal
            .try_inverse()
            .ok_or_else(|| HandEyeError::DegenerateMotion {
                what: "the normal equations of the adjustment are singular".into(),
            })?;
        let critical =
            (redundancy > 6).then(|| f_critical(options.alpha, 6.0, (redundancy - 6) as f64));
        // Residuals and test statistics of every station.
        let mut residuals = Vec::with_capacity(stations.len());
        let mut worst: Option<(usize, f64)> = None;
        for (k, s) in stations.iter().enumerate() {
            let l = linearise(s, &x, &z, robot);
            let jn = l.jacobian * ninv * l.jacobian.transpose();
            let test = if used[k] {
                // Q_vv of a used station; T_i against the fit without it.
                (l.covariance - jn).try_inverse().and_then(|q| {
                    let t = (l.residual.transpose() * q * l.residual)[(0, 0)];
                    (redundancy > 6).then(|| {
                        let s2 = (fit.omega - t).max(0.0) / (redundancy - 6) as f64;
                        t / (6.0 * s2.max(f64::MIN_POSITIVE))
                    })
                })
            } else {
                // A rejected station's residual is predicted: Σ + J N⁻¹ Jᵀ.
                (l.covariance + jn).try_inverse().map(|q| {
                    let t = (l.residual.transpose() * q * l.residual)[(0, 0)];
                    t / (6.0 * sigma0_sq.max(f64::MIN_POSITIVE))
                })
            };
            if used[k] {
                if let Some(f) = test {
                    if worst.is_none_or(|(_, w)| f > w) {
                        worst = Some((k, f));
                    }
                }
            }
            let t = [l.residual[0], l.residual[1], l.residual[2]];
            let r = [
                l.residual[3].to_degrees(),
                l.residual[4].to_degrees(),
                l.residual[5].to_degrees(),
            ];
            residuals.push(StationResidual {
                name: s.name.clone(),
                translation_mm: t,
                rotation_deg: r,
                norm_mm: (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt(),
                norm_deg: (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt(),
                test,
                used: used[k],
            });
        }
        if let (Some(c), Some((k, f))) = (critical, worst) {
            if f > c && rejected.len() < max_rejected && n_used > 3 {
                used[k] = false;
                rejected.push(stations[k].name.clone());
                continue;
            }
        }
        let mean_sq = |f: &dyn Fn(&StationResidual) -> f64| {
            let (sum, n) = residuals
                .iter()
                .filter(|r| r.used)
                .fold((0.0, 0usize), |(s, n), r| (s + f(r).powi(2), n + 1));
            (sum / n as f64).sqrt()
        };
        let rms_mm = mean_sq(&|r| r.norm_mm);
        let rms_deg = mean_sq(&|r| r.norm_deg);
        return Ok(HandEye {
            camera_in_tcp: x,
            plate_in_base: z,
            covariance: ninv * sigma0_sq,
            sigma0: sigma0_sq.sqrt(),
            redundancy,
            n_used,
            residuals,
            rejected,
            rms_mm,
            rms_deg,
            critical,
            axis_spread_deg: start.axis_spread_deg,
            iterations: fit.iterations,
        });
    }
}
