//! Poses as rigid transforms: the camera's pose in the plate frame from the
//! exterior orientation of `docs/conventions.md`, KUKA `X, Y, Z, A, B, C` poses, and the
//! hand-eye step from camera to TCP.
//!
//! A pose `T_parent←child` is an [`Isometry3`] mapping child coordinates into
//! the parent frame; its rotation's columns are the child's axes in the
//! parent (KUKA's `M`).

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use photopose_geometry::{rotation, Exterior};

/// The camera's pose in the plate frame, `T_plate←camera = (Rᵀ, centre)`,
/// from the exterior orientation (`R`: plate → camera).
pub fn camera_pose(exterior: &Exterior) -> Isometry3<f64> {
    from_matrix(&exterior.rotation.transpose(), &exterior.center)
}

/// The exterior orientation (`R`, projection centre) of a camera pose
/// `T_plate←camera`: what a renderer renders.
pub fn exterior_of(camera_pose: &Isometry3<f64>) -> Exterior {
    Exterior::new(
        camera_pose
            .rotation
            .to_rotation_matrix()
            .into_inner()
            .transpose(),
        camera_pose.translation.vector,
    )
}

/// A pose from a rotation matrix (columns: the child's axes in the parent;
/// re-orthonormalised) and a position.
pub fn from_matrix(m: &Matrix3<f64>, position: &Vector3<f64>) -> Isometry3<f64> {
    let r = rotation::nearest_rotation(m).unwrap_or(*m);
    Isometry3::from_parts(
        Translation3::from(*position),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    )
}

/// A pose from KUKA `X, Y, Z, A, B, C` (mm, degrees; `M = Rz(A) Ry(B) Rx(C)`).
pub fn from_xyzabc(xyzabc: [f64; 6]) -> Isometry3<f64> {
    let m = rotation::matrix_from_kuka_abc_deg(xyzabc[3], xyzabc[4], xyzabc[5]);
    from_matrix(&m, &Vector3::new(xyzabc[0], xyzabc[1], xyzabc[2]))
}

/// KUKA `X, Y, Z, A, B, C` (mm, degrees) of a pose.
pub fn to_xyzabc(pose: &Isometry3<f64>) -> [f64; 6] {
    let m = pose.rotation.to_rotation_matrix().into_inner();
    let [a, b, c] = rotation::kuka_abc_deg_from_matrix(&m);
    let t = pose.translation.vector;
    [t.x, t.y, t.z, a, b, c]
}

/// The TCP's pose in the plate frame from the camera's and the hand-eye
/// transform `X = T_tcp←camera` (the camera in the TCP frame):
/// `T_plate←tcp = T_plate←camera · X⁻¹`.
pub fn tcp_from_camera(camera: &Isometry3<f64>, camera_in_tcp: &Isometry3<f64>) -> Isometry3<f64> {
    camera * camera_in_tcp.inverse()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_pose_and_exterior_round_trip_and_match_kuka() {
        let xyzabc = [10.0, -20.0, 600.0, 30.0, -5.0, 170.0];
        let e = Exterior::from_kuka_pose(xyzabc);
        let p = camera_pose(&e);
        let back = to_xyzabc(&p);
        for k in 0..6 {
            assert!((back[k] - xyzabc[k]).abs() < 1e-9, "{k}: {back:?}");
        }
        let e2 = exterior_of(&p);
        assert!((e2.rotation - e.rotation).abs().max() < 1e-12);
        assert!((e2.center - e.center).norm() < 1e-12);
    }

    #[test]
    fn tcp_from_camera_undoes_the_mount() {
        let tcp = from_xyzabc([100.0, 50.0, 500.0, 10.0, 0.0, 180.0]);
        let x = from_xyzabc([60.0, 0.0, -80.0, 0.0, 0.0, 180.0]);
        let camera = tcp * x;
        let back = tcp_from_camera(&camera, &x);
        assert!((back.translation.vector - tcp.translation.vector).norm() < 1e-9);
        assert!(back.rotation.angle_to(&tcp.rotation) < 1e-12);
        // The camera sits 100 mm from the TCP and looks down (its z, pointing
        // backwards, is the plate's +Z).
        assert!(((camera.translation.vector - tcp.translation.vector).norm() - 100.0).abs() < 1e-9);
        let z = camera.rotation * Vector3::z();
        assert!((z - Vector3::z()).norm() < 1e-9, "{z}");
    }
}
