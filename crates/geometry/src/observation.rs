//! What a resection is given and what becomes of it: one control point seen
//! in the image ([`Observation`]) and its fate in the adjustment
//! ([`Status`]). The lowest layer of the solver: `linearised`, `precision`
//! and `resection` build on it and it imports none of them.

use crate::camera::Camera;
use nalgebra::{Matrix2, Vector2, Vector3};

/// One control point seen in the image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Target id (for reports).
    pub id: u64,
    /// Object (field) coordinates, mm.
    pub object: Vector3<f64>,
    /// Ideal (corrected) image coordinates, mm: see [`Camera::correct`].
    pub image: Vector2<f64>,
    /// Weight (information) matrix of the two image coordinates relative to
    /// an observation of unit weight: the covariance of `image` is
    /// `σ0² · weight⁻¹`. The identity for equally precise, uncorrelated
    /// coordinates; must be symmetric positive definite.
    pub weight: Matrix2<f64>,
}

impl Observation {
    /// An observation from a measured pixel position, corrected with `camera`.
    // Inline: called per tracked target from another crate (0.12 M of
    // tracking's instructions).
    #[inline]
    pub fn from_pixel(camera: &Camera, id: u64, object: Vector3<f64>, col: f64, row: f64) -> Self {
        Observation {
            id,
            object,
            image: camera.correct_pixel(col, row),
            weight: Matrix2::identity(),
        }
    }
}

/// What happened to an observation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// Used in the adjustment.
    Used,
    /// Did not agree with the closed-form hypothesis.
    Outlier,
    /// Removed by data snooping.
    Snooped,
}
