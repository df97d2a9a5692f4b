//! The plane of a planar test field and its 2-D plate frame, shared by the
//! renderer and the SVG drawing so that both draw the same pattern.
//!
//! The plane is fitted to the target centres (centroid and the direction of
//! least spread); its normal `n` points to the `+Z` side (the side the
//! targets face). The in-plane axes are `u` = the field's `+X` projected
//! into the plane (`+Y` if the plane is nearly perpendicular to `X`) and
//! `v = n × u`; for a plate in `Z = const` they are `+X` and `+Y`.

use crate::RenderError;
use nalgebra::{Matrix3, SymmetricEigen, Vector2, Vector3};
use photopose_field::Field;

/// Largest distance of a target from the fitted plane, mm.
pub const PLANARITY_TOLERANCE_MM: f64 = 0.01;

/// The plate frame of a planar field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plate {
    /// Centroid of the target centres (field frame, mm).
    pub origin: Vector3<f64>,
    /// First in-plane axis (unit).
    pub u: Vector3<f64>,
    /// Second in-plane axis (unit), `n × u`.
    pub v: Vector3<f64>,
    /// Normal (unit), towards `+Z`.
    pub n: Vector3<f64>,
}

impl Plate {
    /// Fits the plate's plane; errors if the field is empty or a target
    /// lies more than [`PLANARITY_TOLERANCE_MM`] off the plane.
    pub fn fit(field: &Field) -> Result<Self, RenderError> {
        if field.is_empty() {
            return Err(RenderError::EmptyField);
        }
        let targets = field.targets();
        let origin =
            targets.iter().fold(Vector3::zeros(), |a, t| a + t.position) / targets.len() as f64;
        let mut cov = Matrix3::zeros();
        for t in targets {
            let d = t.position - origin;
            cov += d * d.transpose();
        }
        let eig = SymmetricEigen::new(cov);
        let k = (0..3)
            .min_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]))
            .unwrap_or(2);
        let mut n = eig.eigenvectors.column(k).into_owned();
        // Fewer than three targets, or all on a line: no plane to fit, take
        // the field's XY plane.
        if targets.len() < 3 || eig.eigenvalues.iter().filter(|l| **l > 1e-9).count() < 2 {
            n = Vector3::z();
        }
        if n.z < 0.0 {
            n = -n;
        }
        for t in targets {
            let d = (t.position - origin).dot(&n).abs();
            if d > PLANARITY_TOLERANCE_MM {
                return Err(RenderError::NotPlanar {
                    id: t.id,
                    distance: d,
                });
            }
        }
        let seed_axis = if n.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let u = (seed_axis - n * n.dot(&seed_axis)).normalize();
        let v = n.cross(&u);
        Ok(Plate { origin, u, v, n })
    }

    /// A field point in plate coordinates (mm, relative to `origin`).
    pub fn to_plate(&self, p: &Vector3<f64>) -> Vector2<f64> {
        let d = p - self.origin;
        Vector2::new(d.dot(&self.u), d.dot(&self.v))
    }

    /// A plate point back in the field frame.
    pub fn to_field(&self, q: &Vector2<f64>) -> Vector3<f64> {
        self.origin + self.u * q.x + self.v * q.y
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use photopose_field::design::default_plate;
    use photopose_field::{Target, TargetKind};

    #[test]
    fn flat_plate_keeps_x_and_y_and_a_bent_one_is_refused() {
        let field = default_plate();
        let p = Plate::fit(&field).unwrap();
        assert!((p.u - Vector3::x()).norm() < 1e-12 && (p.v - Vector3::y()).norm() < 1e-12);
        let t = &field.targets()[7];
        let q = p.to_plate(&t.position);
        assert!((p.to_field(&q) - t.position).norm() < 1e-12);
        let mut targets = field.targets().to_vec();
        targets[3].position.z += 0.5;
        let bent = Field::new(targets).unwrap();
        assert!(matches!(
            Plate::fit(&bent),
            Err(RenderError::NotPlanar { .. })
        ));
        // A tilted plane: normal towards +Z, axes orthonormal.
        let tilted: Vec<Target> = [(0.0, 0.0), (100.0, 0.0), (0.0, 100.0), (70.0, 50.0)]
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| Target {
                id: 1001 + i as u64,
                position: Vector3::new(x, y, 10.0 + 0.5 * x - 0.2 * y),
                kind: TargetKind::Uncoded,
                radius: 2.0,
            })
            .collect();
        let p = Plate::fit(&Field::new(tilted).unwrap()).unwrap();
        let want = Vector3::new(-0.5, 0.2, 1.0).normalize();
        assert!((p.n - want).norm() < 1e-9, "{}", p.n);
        assert!(p.u.dot(&p.v).abs() < 1e-12 && (p.u.cross(&p.v) - p.n).norm() < 1e-12);
    }
}
