//! Exterior orientation: the camera's rotation and projection centre in the
//! object (test field) frame, and the collinearity equations.

use crate::camera::Camera;
use crate::rotation;
use nalgebra::{Matrix3, Vector2, Vector3};

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
        let q = self.to_camera(p);
        (q.z < 0.0).then(|| Vector2::new(-c * q.x / q.z, -c * q.y / q.z))
    }

    /// Pixel position at which `camera` sees the object point `p`.
    #[inline]
    pub fn project_pixel(&self, camera: &Camera, p: &Vector3<f64>) -> Option<Vector2<f64>> {
        let m = camera.project_camera_point(&self.to_camera(p))?;
        Some(camera.image_to_pixel(m))
    }
}
