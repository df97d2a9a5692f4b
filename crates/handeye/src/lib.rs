//! photopose-handeye: hand-eye and base registration of a robot carrying the
//! camera — the `AX = ZB` problem.
//!
//! Frames (docs/hand-eye.md): for station `i` the robot reports the TCP in
//! its base, `A_i = T_base←tcp,i` (KUKA `X, Y, Z, A, B, C`), and photopose
//! measures the camera in the plate, `B_i = T_plate←camera,i` (rotation `Rᵀ`,
//! translation the projection centre). The unknowns are
//! `X = T_tcp←camera` (camera on the flange) and `Z = T_base←plate` (plate
//! in the robot base); every station gives `A_i · X = Z · B_i`.
//!
//! [`solve()`] does it in three steps:
//! 1. **degenerate-motion check and closed form** ([`closed_form`]):
//!    Park–Martin on the relative motions of all station pairs
//!    (`A_j⁻¹A_i · X = X · B_j⁻¹B_i`), `Z` then from the mean of `A_i X B_i⁻¹`;
//!    rotations about parallel axes only are refused;
//! 2. **refinement** ([`refine`]): Gauss–Newton / Levenberg–Marquardt over
//!    both transforms and all stations, each station's residual (the TCP
//!    pose predicted from the camera minus the robot's) weighted by its
//!    covariance propagated from the robot's repeatability and the camera
//!    pose's covariance; covariance of the 12 unknowns `σ0² N⁻¹`;
//! 3. **gross-error detection**: a station whose externally studentised
//!    residual statistic exceeds the F-distribution's critical value is
//!    rejected (named) and the fit repeated.
//!
//! Poses and their covariances convert with `photopose_geometry::pose`
//! (KUKA `X, Y, Z, A, B, C`, camera pose of a resection, σ of `X … C`).
//!
//! Invariant: no IO (no files, sockets, threads, clocks); the station CSV
//! format ([`stations`]) parses text handed in.

pub mod closed_form;
pub mod gather;
pub mod refine;
pub mod solve;
pub mod stations;
pub mod stats;

pub use solve::{solve, HandEye, HandEyeOptions, StationResidual};
pub use stations::{parse_stations, StationRow, STATIONS_HEADER};

use nalgebra::{Isometry3, Matrix6};
use photopose_geometry::{pose, Exterior};
use thiserror::Error;

/// A camera pose measured by photopose: `T_plate←camera` with its covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPose {
    /// The camera in the plate frame (rotation `Rᵀ`, translation the
    /// projection centre, mm).
    pub pose: Isometry3<f64>,
    /// Covariance of `(t, φ)` (mm², rad²): the projection centre and small
    /// rotations `φ` of the camera frame about the plate's axes,
    /// `M ← exp([φ]ₓ)·M` (`photopose_geometry::pose`). A resection's
    /// covariance of `(C, ω)` has the opposite sign of `ω`:
    /// [`CameraPose::from_exterior`] converts it.
    pub covariance: Matrix6<f64>,
}

impl CameraPose {
    /// The camera pose of a resection (a frame located by photopose):
    /// `(Rᵀ, centre)` with the resection's a-posteriori covariance.
    pub fn from_resection(report: &photopose_geometry::ResectionReport) -> Self {
        Self::from_exterior(&report.exterior, &report.covariance)
    }

    /// The camera pose `(Rᵀ, centre)` of an exterior orientation whose
    /// covariance of `(Xc, Yc, Zc, ωX, ωY, ωZ)` (a resection's or a
    /// prediction's) is `exterior_covariance`.
    pub fn from_exterior(exterior: &Exterior, exterior_covariance: &Matrix6<f64>) -> Self {
        CameraPose {
            pose: pose::camera_pose(exterior),
            covariance: pose::camera_pose_covariance(exterior_covariance),
        }
    }

    /// A camera pose with independent standard deviations of the centre
    /// (mm) and of the rotations about the plate's axes (degrees).
    pub fn with_stds(pose: Isometry3<f64>, std_center_mm: [f64; 3], std_rot_deg: [f64; 3]) -> Self {
        let mut covariance = Matrix6::zeros();
        for k in 0..3 {
            covariance[(k, k)] = std_center_mm[k] * std_center_mm[k];
            let r = std_rot_deg[k].to_radians();
            covariance[(3 + k, 3 + k)] = r * r;
        }
        CameraPose { pose, covariance }
    }
}

/// One station: the robot's TCP pose and the camera pose measured there.
#[derive(Debug, Clone, PartialEq)]
pub struct Station {
    /// The station's name (reports name rejected stations by it).
    pub name: String,
    /// `T_base←tcp` as the robot reports it (`RIst`).
    pub robot: Isometry3<f64>,
    /// `T_plate←camera` as photopose measured it.
    pub camera: CameraPose,
}

/// Why a hand-eye calibration could not be computed.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum HandEyeError {
    /// Fewer stations than the problem needs.
    #[error("{got} stations given, the hand-eye calibration needs at least {need} (10 or more recommended)")]
    TooFewStations {
        /// Stations given (or left after rejection).
        got: usize,
        /// Stations needed.
        need: usize,
    },
    /// A value that is not finite or not positive where it must be.
    #[error("station {station}: {what}")]
    BadStation {
        /// The station's name.
        station: String,
        /// What is wrong.
        what: String,
    },
    /// An option is out of range.
    #[error("option {name} = {value}: {what}")]
    BadOption {
        /// The option.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is required.
        what: &'static str,
    },
    /// The robot's rotations between stations do not determine the
    /// camera's orientation and position on the flange.
    #[error(
        "degenerate motion: {what} — the camera on the flange is not determinable; \
         rotate the robot about at least two clearly different axes between stations \
         (see docs/hand-eye.md)"
    )]
    DegenerateMotion {
        /// What was found (axis spread, rotation angles).
        what: String,
    },
    /// The adjustment did not converge.
    #[error("the adjustment did not converge in {iterations} iterations (last step {step:.3e})")]
    NoConvergence {
        /// Iterations done.
        iterations: usize,
        /// Norm of the last step.
        step: f64,
    },
    /// A line of a station file is not valid.
    #[error("{origin}:{line}: {what}")]
    StationFile {
        /// File name.
        origin: String,
        /// 1-based line (0: the whole file).
        line: usize,
        /// What is wrong, naming the column.
        what: String,
    },
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Vector3, Vector6};
    use photopose_geometry::rng::SplitMix64;
    use photopose_geometry::rotation::cayley;

    /// A resection report at a tilted pose whose covariance couples the
    /// centre with the rotations, as narrow-angle resections do.
    fn report() -> photopose_geometry::ResectionReport {
        let l = Matrix6::new(
            0.05, 0.0, 0.0, 0.0, 0.0, 0.0, //
            0.0, 0.05, 0.0, 0.0, 0.0, 0.0, //
            0.0, 0.0, 0.02, 0.0, 0.0, 0.0, //
            0.0, 8e-5, 0.0, 2e-5, 0.0, 0.0, //
            -8e-5, 0.0, 0.0, 0.0, 2e-5, 0.0, //
            0.0, 0.0, 0.0, 0.0, 0.0, 3e-5,
        );
        photopose_geometry::ResectionReport {
            exterior: Exterior::from_kuka_pose([20.0, -30.0, 600.0, 40.0, 10.0, 175.0]),
            covariance: l * l.transpose(),
            sigma0: 3e-4,
            sigma0_px: 0.05,
            rms_px: 0.05,
            n_points: 100,
            n_rejected: 0,
            iterations: 3,
            hypotheses: 1,
        }
    }

    /// The camera pose's covariance describes how the pose scatters when the
    /// resection's `(C, ω)` scatter as its covariance says (`R ← R·cayley(ω/2)`),
    /// in the convention `refine` perturbs poses with (`M ← exp(φ)·M`):
    /// 20000 seeded draws, within 3% of the larger σ of each pair. The
    /// resection's covariance copied as it was has the centre–rotation
    /// terms of the wrong sign and fails this.
    #[test]
    fn from_resection_covariance_describes_the_pose_scatter() {
        let r = report();
        let cam = CameraPose::from_resection(&r);
        let m0 = pose::camera_pose(&r.exterior);
        assert_eq!(cam.pose, m0);
        let l = r.covariance.cholesky().unwrap().l();
        let mut rng = SplitMix64::new(5);
        let n = 20_000;
        let mut sample = Matrix6::zeros();
        for _ in 0..n {
            let d = l * Vector6::from_fn(|_, _| rng.normal());
            let e = Exterior::new(
                r.exterior.rotation * cayley(d[3] / 2.0, d[4] / 2.0, d[5] / 2.0),
                r.exterior.center + Vector3::new(d[0], d[1], d[2]),
            );
            let p = pose::camera_pose(&e);
            let dt = p.translation.vector - m0.translation.vector;
            let phi = (p.rotation * m0.rotation.inverse()).scaled_axis();
            let v = Vector6::new(dt.x, dt.y, dt.z, phi.x, phi.y, phi.z);
            sample += v * v.transpose();
        }
        sample /= n as f64;
        let want = cam.covariance;
        // Each element's error in units of the σ product of its pair.
        let s = Matrix6::from_diagonal(&want.diagonal().map(|v| 1.0 / v.sqrt()));
        let worst = (s * (sample - want) * s).abs().max();
        assert!(worst < 0.03, "{worst}: {sample} vs {want}");
    }
}
