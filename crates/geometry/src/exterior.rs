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

    /// An upper bound, mm, on how far [`Exterior::project_ideal`] moves the
    /// ideal image point of any object point within `radius` of `centre`
    /// from this pose to `other` (principal distance `c`), as computed:
    /// the rounding of both projections and of this bound included. `None`
    /// when it proves nothing (such a point may lie behind either camera,
    /// or a value is not finite).
    ///
    /// One bound for a whole plate instead of a projection per target: a
    /// check that every target stayed within a few pixels needs to project
    /// them only when the bound does not already prove it. With `u = P − C`
    /// of this pose, `|u| ≤ D = |centre − C| + radius`, the camera points
    /// move by `δ = z' − z = (R' − R) u + R' (C − C')`, at most
    /// `Δ = ‖R' − R‖ D + |R' (C − C')|`; the image point
    /// `−c (z_x, z_y) / z_z` moves by `c |δ| |z| / (|z'_z| |z_z|)` at most,
    /// with `|z| ≤ ‖R‖ D` and depths `|z_z| ≥ h`, `|z'_z| ≥ h − Δ`
    /// (`h` from the depth of `centre` less `radius`). No orthonormality of
    /// either rotation is assumed (Frobenius norms throughout).
    pub fn shift_bound(
        &self,
        other: &Exterior,
        c: f64,
        centre: &Vector3<f64>,
        radius: f64,
    ) -> Option<f64> {
        // Relative slack far above the few units of rounding of every
        // product and sum involved (1e-16 each).
        const SLACK: f64 = 1e-12;
        let (r0, r1) = (&self.rotation, &other.rotation);
        let (n0, n1) = (r0.norm(), r1.norm());
        let reach = (centre - self.center).norm();
        let d = (reach + radius) * (1.0 + SLACK);
        let moved = (other.center - self.center).norm();
        // What computing R (P − C) may be off by, per pose (a few units of
        // rounding of ‖R‖ |P − C|; 1e-14 is ten times that).
        let eta = 1e-14 * (n0 + n1) * (d + moved);
        let delta = ((r1 - r0).norm() * d + n1 * moved) * (1.0 + SLACK) + 2.0 * eta;
        // Depth of the centre along this camera's axis less the radius
        // (the third row's length bounds its reach), less the rounding.
        let axis = r0.row(2);
        let depth = -(axis * (centre - self.center))[0];
        let h = depth - axis.norm() * radius - SLACK * (depth.abs() + axis.norm() * radius) - eta;
        let z = n0 * d + eta;
        let near = h - delta;
        if !(near > 0.0 && c > 0.0) {
            return None;
        }
        // The image points themselves are rounded by a few units of their
        // size (at most c |z| / h).
        let bound = (c * delta * z / (near * h) + 1e-15 * c * z / near) * (1.0 + SLACK);
        bound.is_finite().then_some(bound)
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
    use nalgebra::Matrix6;

    /// No point of the ball moves further than the bound says, as
    /// `project_ideal` and `UncertainProjector::project_point` compute the
    /// two image points: poses a rounding apart, a little and far apart,
    /// rotations not quite orthonormal, points on the ball's surface.
    #[test]
    fn no_point_of_the_ball_moves_further_than_the_shift_bound() {
        use crate::precision::UncertainProjector;
        use crate::rng::SplitMix64;
        use crate::rotation::cayley;
        let mut rng = SplitMix64::new(23);
        let (mut proved, mut tightest) = (0, 0.0f64);
        for case in 0..3000 {
            let radius = 20.0 + 600.0 * rng.unit();
            let centre = Vector3::new(rng.normal(), rng.normal(), 0.1 * rng.normal()) * 100.0;
            let distance = 300.0 + 3000.0 * rng.unit();
            let eye = centre
                + Vector3::new(rng.normal(), rng.normal(), 0.0) * 0.3 * distance
                + Vector3::new(0.0, 0.0, distance);
            let up = Vector3::new(rng.normal(), rng.normal(), 0.0);
            let Some(mut e0) = Exterior::look_at(eye, centre, up) else {
                continue;
            };
            // Turns from none to a hundredth of a radian, moves from none to
            // 5 mm; every fifth case one unit of rounding or a rotation a
            // little off orthonormal.
            let scale = [0.0, 1e-7, 1e-5, 1e-3, 1e-2][case % 5];
            let turn = cayley(
                scale * rng.normal(),
                scale * rng.normal(),
                scale * rng.normal(),
            );
            let mut e1 = Exterior::new(
                e0.rotation * turn,
                e0.center + Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 500.0 * scale,
            );
            match case % 20 {
                3 => e1.rotation[(1, 2)] = f64::from_bits(e1.rotation[(1, 2)].to_bits() + 1),
                7 => e1.rotation += Matrix3::from_fn(|_, _| 1e-9 * rng.normal()),
                11 => e0.rotation += Matrix3::from_fn(|_, _| 1e-9 * rng.normal()),
                _ => {}
            }
            let c = 8.0 + 10.0 * rng.unit();
            let Some(bound) = e0.shift_bound(&e1, c, &centre, radius) else {
                continue;
            };
            proved += 1;
            let projector = UncertainProjector::new(c, &e0, &Matrix6::zeros());
            for k in 0..40 {
                let dir = Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
                let reach = if k % 2 == 0 { 1.0 } else { rng.unit().cbrt() };
                let p = centre + dir * radius * reach;
                let (Some(a), Some(b)) = (e0.project_ideal(c, &p), e1.project_ideal(c, &p)) else {
                    panic!("case {case}: a point of the ball is behind a camera");
                };
                let (_, seen) = projector.project_point(&p).expect("in front");
                for shift in [(b - a).norm(), (b - seen).norm()] {
                    assert!(shift <= bound, "case {case}: {shift} > {bound}");
                    tightest = tightest.max(shift / bound);
                }
            }
        }
        // The bound proves most cases and is not loose beyond use.
        assert!(proved > 2500, "{proved}");
        assert!(tightest > 0.1, "{tightest}");
    }

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
