//! What a resection is given and what becomes of it: one control point seen
//! in the image ([`Observation`]) and its fate in the adjustment
//! ([`Status`]). The lowest layer of the solver: `linearised`, `precision`
//! and `resection` build on it and it imports none of them.

use crate::camera::Camera;
use nalgebra::{Matrix2, Vector2, Vector3};
use wide::{f64x2, CmpEq};

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

    /// Whether the weight is the identity (compared as `==` does: both
    /// pairs of entries at once).
    #[inline(always)]
    pub(crate) fn unit_weight(&self) -> bool {
        let w = self.weight.as_slice();
        let (a, b) = (f64x2::new([w[0], w[1]]), f64x2::new([w[2], w[3]]));
        let same = a.cmp_eq(f64x2::new([1.0, 0.0])) & b.cmp_eq(f64x2::new([0.0, 1.0]));
        same.move_mask() == 3
    }

    /// Whether a resection can use this observation: finite coordinates
    /// and a weight that is the identity (`unit`, from
    /// [`Observation::unit_weight`]) or symmetric positive definite.
    #[inline(always)]
    pub(crate) fn usable(&self, unit: bool) -> bool {
        let (p, m) = (&self.object, &self.image);
        // A NaN or infinity anywhere makes the sum non-finite.
        let finite = (p.x + p.y + p.z + m.x + m.y).is_finite();
        let w = &self.weight;
        let weighted = unit
            || (w.iter().all(|v| v.is_finite())
                && (w[(0, 1)] - w[(1, 0)]).abs() <= 1e-12 * w.abs().max()
                && w[(0, 0)] > 0.0
                && w.determinant() > 0.0);
        finite && weighted
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The pairwise comparison is `==` on the matrix: signed zeros equal,
    /// a NaN or any other value anywhere not.
    #[test]
    fn unit_weight_is_equality_with_the_identity() {
        let values = [1.0, 0.0, -0.0, f64::NAN, 2.0, -1.0, 1.0 + f64::EPSILON];
        let mut units = 0;
        for &a in &values {
            for &b in &values {
                for &c in &values {
                    for &d in &values {
                        let o = Observation {
                            id: 0,
                            object: Vector3::zeros(),
                            image: Vector2::zeros(),
                            weight: Matrix2::new(a, b, c, d),
                        };
                        let want = o.weight == Matrix2::identity();
                        assert_eq!(o.unit_weight(), want, "{a} {b} {c} {d}");
                        units += want as usize;
                    }
                }
            }
        }
        assert_eq!(units, 4);
    }
}
