//! Poses as KUKA `X, Y, Z, A, B, C` (mm, degrees; `M = Rz(A) Ry(B) Rx(C)`,
//! `docs/conventions.md`) and back, and the standard deviations of `X … C` from a
//! covariance of translation and small rotations about the parent's axes.

use nalgebra::{Isometry3, Matrix3, Matrix6, Rotation3, Translation3, UnitQuaternion, Vector3};
use photopose_geometry::rotation::{kuka_abc_deg_from_matrix, matrix_from_kuka_abc_deg};

/// The frame given as KUKA `X, Y, Z, A, B, C` (mm, degrees) in its parent.
pub fn isometry_from_xyzabc(p: [f64; 6]) -> Isometry3<f64> {
    let m = matrix_from_kuka_abc_deg(p[3], p[4], p[5]);
    isometry(&m, &Vector3::new(p[0], p[1], p[2]))
}

/// KUKA `X, Y, Z, A, B, C` (mm, degrees) of a frame in its parent.
pub fn xyzabc_from_isometry(t: &Isometry3<f64>) -> [f64; 6] {
    let m = t.rotation.to_rotation_matrix().into_inner();
    let [a, b, c] = kuka_abc_deg_from_matrix(&m);
    let v = t.translation.vector;
    [v.x, v.y, v.z, a, b, c]
}

/// An isometry from a rotation matrix (re-orthonormalised by nalgebra's
/// quaternion extraction) and a translation.
pub fn isometry(m: &Matrix3<f64>, t: &Vector3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(*t),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*m)),
    )
}

/// The frame turned by the small rotation `omega` (rad) about the parent's
/// axes and shifted by `dt` (mm): `R ← exp(ω) R`, `t ← t + dt`.
pub fn perturbed(t: &Isometry3<f64>, dt: &Vector3<f64>, omega: &Vector3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(t.translation.vector + dt),
        UnitQuaternion::from_scaled_axis(*omega) * t.rotation,
    )
}

/// Standard deviations of `X, Y, Z` (mm) and `A, B, C` (degrees) of `pose`
/// from the covariance of `(tx, ty, tz, ωx, ωy, ωz)` (mm², rad²; `ω` small
/// rotations about the parent's axes, `R ← exp(ω) R`). `A, B, C` by
/// propagation through the derivatives of the angles (central differences);
/// near `|B| = 90°` their standard deviations grow without bound, as the
/// angles themselves do.
pub fn xyzabc_std(pose: &Isometry3<f64>, covariance: &Matrix6<f64>) -> [f64; 6] {
    let h = 1e-7;
    let mut j = Matrix3::zeros();
    for k in 0..3 {
        let mut w = Vector3::zeros();
        w[k] = h;
        let plus = xyzabc_from_isometry(&perturbed(pose, &Vector3::zeros(), &w));
        let minus = xyzabc_from_isometry(&perturbed(pose, &Vector3::zeros(), &-w));
        for r in 0..3 {
            // Angles wrap at ±180°: difference on the circle.
            let d = wrap_deg(plus[3 + r] - minus[3 + r]);
            j[(r, k)] = d / (2.0 * h);
        }
    }
    let cw = covariance.fixed_view::<3, 3>(3, 3).into_owned();
    let ca = j * cw * j.transpose();
    [
        covariance[(0, 0)].max(0.0).sqrt(),
        covariance[(1, 1)].max(0.0).sqrt(),
        covariance[(2, 2)].max(0.0).sqrt(),
        ca[(0, 0)].max(0.0).sqrt(),
        ca[(1, 1)].max(0.0).sqrt(),
        ca[(2, 2)].max(0.0).sqrt(),
    ]
}

/// An angle difference in degrees brought into `(-180, 180]`.
pub fn wrap_deg(d: f64) -> f64 {
    let r = d.rem_euclid(360.0);
    if r > 180.0 {
        r - 360.0
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xyzabc_round_trips() {
        let p = [12.5, -300.0, 845.0, 170.0, -35.0, 20.0];
        let q = xyzabc_from_isometry(&isometry_from_xyzabc(p));
        for k in 0..6 {
            assert!((p[k] - q[k]).abs() < 1e-9, "{k}: {} vs {}", p[k], q[k]);
        }
    }

    #[test]
    fn abc_std_of_a_rotation_about_the_parent_z_is_a() {
        // With B = C = 0, a small rotation about the parent's Z changes A only.
        let pose = isometry_from_xyzabc([0.0, 0.0, 0.0, 30.0, 0.0, 0.0]);
        let mut cov = Matrix6::zeros();
        cov[(5, 5)] = 0.01f64.to_radians().powi(2);
        cov[(0, 0)] = 0.04;
        let s = xyzabc_std(&pose, &cov);
        assert!((s[0] - 0.2).abs() < 1e-12);
        assert!((s[3] - 0.01).abs() < 1e-6, "{s:?}");
        assert!(s[4] < 1e-9 && s[5] < 1e-9, "{s:?}");
    }

    #[test]
    fn wrap_brings_angles_near_180_together() {
        assert!((wrap_deg(359.0) + 1.0).abs() < 1e-12);
        assert!((wrap_deg(-359.0) - 1.0).abs() < 1e-12);
    }
}
