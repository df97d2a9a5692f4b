//! Precision prediction without images: the covariance of the exterior
//! orientation that a configuration (camera, pose, visible targets, image
//! noise) gives, by error propagation through the collinearity equations.

use crate::camera::Camera;
use crate::error::GeometryError;
use crate::exterior::Exterior;
use crate::resection::{cofactor, normal_matrix};
use nalgebra::{Matrix6, Vector3};

/// Predicted precision of a resection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    /// Covariance of `(Xc, Yc, Zc, ωX, ωY, ωZ)`, mm² and rad² (a-priori:
    /// from the assumed image noise, not from residuals).
    pub covariance: Matrix6<f64>,
    /// Points that contributed.
    pub n_points: usize,
}

impl Prediction {
    /// Standard deviations of `Xc, Yc, Zc`, mm.
    pub fn std_center(&self) -> Vector3<f64> {
        Vector3::new(
            self.covariance[(0, 0)].sqrt(),
            self.covariance[(1, 1)].sqrt(),
            self.covariance[(2, 2)].sqrt(),
        )
    }

    /// Standard deviations of the rotations about the field's axes, degrees.
    pub fn std_rotation_deg(&self) -> Vector3<f64> {
        Vector3::new(
            self.covariance[(3, 3)].sqrt().to_degrees(),
            self.covariance[(4, 4)].sqrt().to_degrees(),
            self.covariance[(5, 5)].sqrt().to_degrees(),
        )
    }
}

/// The points of `field` that `camera` at `exterior` sees: in front and
/// inside the sensor by `margin_px`. Writes them into `out` (cleared first).
pub fn visible_points(
    camera: &Camera,
    exterior: &Exterior,
    field: impl IntoIterator<Item = Vector3<f64>>,
    margin_px: f64,
    out: &mut Vec<Vector3<f64>>,
) {
    out.clear();
    for p in field {
        if let Some(px) = exterior.project_pixel(camera, &p) {
            if camera.contains_pixel(px, margin_px) {
                out.push(p);
            }
        }
    }
}

/// Predicted covariance for image noise `sigma_px` (per coordinate) over
/// `points` (which must be visible).
pub fn predict(
    camera: &Camera,
    exterior: &Exterior,
    points: &[Vector3<f64>],
    sigma_px: f64,
) -> Result<Prediction, GeometryError> {
    if points.len() < 4 {
        return Err(GeometryError::TooFewPoints {
            got: points.len(),
            need: 4,
        });
    }
    let n = normal_matrix(camera.interior.c, exterior, points)?;
    let q = cofactor(&n)?;
    let s = sigma_px * camera.sensor.pixel_size;
    Ok(Prediction {
        covariance: q * (s * s),
        n_points: points.len(),
    })
}
