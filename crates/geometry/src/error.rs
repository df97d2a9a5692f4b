//! The error type of the geometry crate.

use thiserror::Error;

/// Why a geometric computation could not give an answer.
///
/// Every variant says what was wrong with the input; none of them is a panic
/// in disguise.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum GeometryError {
    /// A camera parameter is out of its valid range.
    #[error("camera parameter `{key}` = {value} is invalid: {why}")]
    InvalidCamera {
        /// The parameter's key as in the camera file (`sensor.pixel_size`, ...).
        key: &'static str,
        /// The offending value.
        value: f64,
        /// What the valid range is.
        why: &'static str,
    },
    /// Fewer usable points than the method needs.
    #[error("too few usable points: {got}, need at least {need}")]
    TooFewPoints {
        /// Points available.
        got: usize,
        /// Points needed.
        need: usize,
    },
    /// The control points are (nearly) collinear or otherwise degenerate.
    #[error("degenerate point configuration: {0}")]
    Degenerate(&'static str),
    /// A coordinate is NaN or infinite.
    #[error("non-finite coordinate in point {index}")]
    NonFinite {
        /// Index of the point in the input slice.
        index: usize,
    },
    /// No hypothesis explained enough of the observations.
    #[error("no consistent pose: best hypothesis explains {inliers} of {total} points")]
    NoConsensus {
        /// Inliers of the best hypothesis.
        inliers: usize,
        /// Points tried.
        total: usize,
    },
    /// The iterative refinement did not converge.
    #[error("least-squares refinement did not converge in {iterations} iterations")]
    NotConverged {
        /// Iterations spent.
        iterations: usize,
    },
    /// The solution places control points behind the camera.
    #[error("{count} control points lie behind the camera")]
    BehindCamera {
        /// How many.
        count: usize,
    },
    /// The solution puts the camera on the back side of the targets (they
    /// face `+Z`): the observations are mirrored or wrongly identified.
    #[error("the only consistent pose puts the camera behind {count} targets (targets face +Z; mirrored or misidentified image?)")]
    BackSide {
        /// How many targets face away from the camera.
        count: usize,
    },
    /// The normal equations are singular (the configuration determines no pose).
    #[error("normal equations are singular: the configuration does not determine the pose")]
    Singular,
}
