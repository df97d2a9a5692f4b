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
//! Invariant: no IO (no files, sockets, threads, clocks); the station CSV
//! format ([`stations`]) parses text handed in.

pub mod closed_form;
pub mod gather;
pub mod kuka;
pub mod refine;
pub mod solve;
pub mod stations;
pub mod stats;

pub use kuka::{isometry_from_xyzabc, xyzabc_from_isometry, xyzabc_std};
pub use solve::{solve, HandEye, HandEyeOptions, StationResidual};
pub use stations::{parse_stations, StationRow, STATIONS_HEADER};

use nalgebra::{Isometry3, Matrix6};
use thiserror::Error;

/// A camera pose measured by photopose: `T_plate←camera` with its covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPose {
    /// The camera in the plate frame (rotation `Rᵀ`, translation the
    /// projection centre, mm).
    pub pose: Isometry3<f64>,
    /// Covariance of `(Xc, Yc, Zc, ωX, ωY, ωZ)` (mm², rad²): the projection
    /// centre and small rotations of the camera about the plate's axes, as
    /// `photopose_geometry::ResectionReport::covariance`.
    pub covariance: Matrix6<f64>,
}

impl CameraPose {
    /// The camera pose of a resection (a frame located by photopose):
    /// `(Rᵀ, centre)` with the resection's a-posteriori covariance.
    pub fn from_resection(report: &photopose_geometry::ResectionReport) -> Self {
        let e = &report.exterior;
        CameraPose {
            pose: kuka::isometry(&e.rotation.transpose(), &e.center),
            covariance: report.covariance,
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
