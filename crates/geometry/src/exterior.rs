//! Exterior orientation: the camera's rotation and projection centre in the
//! object (test field) frame, and the collinearity equations.

use crate::camera::Camera;
use crate::rotation;
use nalgebra::{Matrix3, Vector2, Vector3, Vector6};

/// Exterior orientation of a camera.
///
/// `rotation` is `R` of `docs/conventions.md`: it maps object-frame vectors into the camera
/// frame (rows are the camera axes in object coordinates); `center` is the
/// projection centre in the object frame. The camera's pose in the object
/// frame is `(Rᵀ, center)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Exterior {
    /// `R`, object → camera.
    pub rotation: Matrix3<f64>,
    /// Projection centre `(Xc, Yc, Zc)`, mm.
    pub center: Vector3<f64>,
}

impl Exterior {
    /// How far this pose is from `truth`: the centre's offset `X, Y, Z`
    /// (mm) and the small rotation `ωX, ωY, ωZ` (rad) about the field axes
    /// that takes `truth`'s rotation to this one (the skew part of
    /// `R_truthᵀ·R`), in the order of a resection's covariance.
    pub fn deviation_from(&self, truth: &Exterior) -> Vector6<f64> {
        let d = self.center - truth.center;
        let dr = truth.rotation.transpose() * self.rotation;
        Vector6::new(
            d.x,
            d.y,
            d.z,
            (dr[(2, 1)] - dr[(1, 2)]) / 2.0,
            (dr[(0, 2)] - dr[(2, 0)]) / 2.0,
            (dr[(1, 0)] - dr[(0, 1)]) / 2.0,
        )
    }

    /// From `R` and the projection centre.
    pub fn new(rotation: Matrix3<f64>, center: Vector3<f64>) -> Self {
        Exterior { rotation, center }
    }

    /// From a camera pose in the object frame given as KUKA `X, Y, Z, A, B, C`
    /// (mm, degrees): the camera frame's axes are `M = Rz(A) Ry(B) Rx(C)`, and
    /// `R = Mᵀ`.
    pub fn from_kuka_pose(xyzabc: [f64; 6]) -> Self {
        let m = rotation::matrix_from_kuka_abc_deg(xyzabc[3], xyzabc[4], xyzabc[5]);
        Exterior {
            rotation: m.transpose(),
            center: Vector3::new(xyzabc[0], xyzabc[1], xyzabc[2]),
        }
    }

    /// The camera pose as KUKA `X, Y, Z, A, B, C` (mm, degrees).
    pub fn to_kuka_pose(&self) -> [f64; 6] {
        let [a, b, c] = rotation::kuka_abc_deg_from_matrix(&self.rotation.transpose());
        [self.center.x, self.center.y, self.center.z, a, b, c]
    }

    /// A camera at `eye` looking at `target`, with the image `y'` axis as close
    /// to `up` as possible.
    pub fn look_at(eye: Vector3<f64>, target: Vector3<f64>, up: Vector3<f64>) -> Option<Self> {
        let z = (eye - target).try_normalize(1e-12)?; // camera z points backwards
        let x = up.cross(&z).try_normalize(1e-12)?;
        let y = z.cross(&x);
        let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        Some(Exterior {
            rotation: r,
            center: eye,
        })
    }

    /// Object point into camera coordinates (`z` backwards, in front: `z < 0`).
    #[inline]
    pub fn to_camera(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * (p - self.center)
    }

    /// Ideal (corrected) image coordinates of an object point by the
    /// collinearity equations; `None` if it is not in front of the camera.
    #[inline]
    pub fn project_ideal(&self, c: f64, p: &Vector3<f64>) -> Option<Vector2<f64>> {
        ideal_of_camera_point(c, &self.to_camera(p))
    }

    /// Pixel position at which `camera` sees the object point `p`.
    #[inline]
    pub fn project_pixel(&self, camera: &Camera, p: &Vector3<f64>) -> Option<Vector2<f64>> {
        let m = camera.project_camera_point(&self.to_camera(p))?;
        Some(camera.image_to_pixel(m))
    }
}

/// Ideal image coordinates of the camera point `q` (`R (P − C)`, see
/// [`Exterior::to_camera`]) for principal distance `c`; `None` if it is
/// not in front of the camera.
#[inline]
pub fn ideal_of_camera_point(c: f64, q: &Vector3<f64>) -> Option<Vector2<f64>> {
    (q.z < 0.0).then(|| Vector2::new(-c * q.x / q.z, -c * q.y / q.z))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deviation_is_the_centre_offset_and_the_small_rotation() {
        let truth = Exterior::from_kuka_pose([10.0, -20.0, 900.0, 30.0, -5.0, 170.0]);
        assert_eq!(truth.deviation_from(&truth), Vector6::zeros());
        // Turned by 1 µrad about the field's Y axis and moved 0.5 mm along Z.
        let w: f64 = 1e-6;
        let turn = Matrix3::new(w.cos(), 0.0, w.sin(), 0.0, 1.0, 0.0, -w.sin(), 0.0, w.cos());
        let moved = Exterior::new(
            truth.rotation * turn,
            truth.center + Vector3::new(0.0, 0.0, 0.5),
        );
        let d = moved.deviation_from(&truth);
        let want = Vector6::new(0.0, 0.0, 0.5, 0.0, w, 0.0);
        assert!((d - want).norm() < 1e-12, "{d}");
    }
}
