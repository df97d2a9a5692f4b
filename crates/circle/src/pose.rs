//! The hand-eye step from camera to TCP. Poses are [`Isometry3`]s
//! `T_parent←child` (rotation columns: the child's axes in the parent, KUKA's
//! `M`); every conversion to and from them (KUKA `X, Y, Z, A, B, C`, the
//! camera pose of an exterior orientation) is `photopose_geometry::pose`'s.

use nalgebra::Isometry3;

/// The TCP's pose in the plate frame from the camera's and the hand-eye
/// transform `X = T_tcp←camera` (the camera in the TCP frame):
/// `T_plate←tcp = T_plate←camera · X⁻¹`.
pub fn tcp_from_camera(camera: &Isometry3<f64>, camera_in_tcp: &Isometry3<f64>) -> Isometry3<f64> {
    camera * camera_in_tcp.inverse()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use photopose_geometry::pose::isometry_from_xyzabc;

    #[test]
    fn tcp_from_camera_undoes_the_mount() {
        let tcp = isometry_from_xyzabc([100.0, 50.0, 500.0, 10.0, 0.0, 180.0]);
        let x = isometry_from_xyzabc([60.0, 0.0, -80.0, 0.0, 0.0, 180.0]);
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
