//! Rotations: the paper's Cayley / Hamilton-normalised quaternion form
//! `R = (I + S)(I - S)^-1` with its analytic partial derivatives, the one
//! re-orthonormalisation of the project ([`nearest_rotation`]), and
//! conversions between matrices, quaternions (`_wxyz`: scalar first) and
//! KUKA `A, B, C`. Poses (rotation with translation) are in [`crate::pose`].

use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};

/// The Cayley rotation of the parameters `(a, b, c)`:
/// `R = (I + S)(I - S)^-1` with `S = [[0, -c, b], [c, 0, -a], [-b, a, 0]]`.
///
/// Equivalent to the rotation of the (unnormalised) quaternion `(1, a, b, c)`.
#[inline]
pub fn cayley(a: f64, b: f64, c: f64) -> Matrix3<f64> {
    let d = 1.0 + a * a + b * b + c * c;
    cayley_numerator(a, b, c) / d
}

#[inline]
fn cayley_numerator(a: f64, b: f64, c: f64) -> Matrix3<f64> {
    let (aa, bb, cc) = (a * a, b * b, c * c);
    Matrix3::new(
        1.0 + aa - bb - cc,
        2.0 * (a * b - c),
        2.0 * (a * c + b),
        2.0 * (a * b + c),
        1.0 - aa + bb - cc,
        2.0 * (b * c - a),
        2.0 * (a * c - b),
        2.0 * (b * c + a),
        1.0 - aa - bb + cc,
    )
}

/// Analytic partial derivatives `[dR/da, dR/db, dR/dc]` of [`cayley`].
#[inline]
pub fn cayley_derivatives(a: f64, b: f64, c: f64) -> [Matrix3<f64>; 3] {
    let d = 1.0 + a * a + b * b + c * c;
    let r = cayley_numerator(a, b, c) / d;
    let dna = Matrix3::new(
        2.0 * a,
        2.0 * b,
        2.0 * c,
        2.0 * b,
        -2.0 * a,
        -2.0,
        2.0 * c,
        2.0,
        -2.0 * a,
    );
    let dnb = Matrix3::new(
        -2.0 * b,
        2.0 * a,
        2.0,
        2.0 * a,
        2.0 * b,
        2.0 * c,
        -2.0,
        2.0 * c,
        -2.0 * b,
    );
    let dnc = Matrix3::new(
        -2.0 * c,
        -2.0,
        2.0 * a,
        2.0,
        -2.0 * c,
        2.0 * b,
        2.0 * a,
        2.0 * b,
        2.0 * c,
    );
    [
        (dna - r * (2.0 * a)) / d,
        (dnb - r * (2.0 * b)) / d,
        (dnc - r * (2.0 * c)) / d,
    ]
}

/// The Cayley parameters of a rotation matrix, `None` for a rotation of 180°
/// (which the form cannot express) or a matrix that is not a rotation.
pub fn cayley_from_matrix(r: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let [w, x, y, z] = quaternion_wxyz_from_matrix(r)?;
    if w.abs() < 1e-12 {
        return None;
    }
    Some(Vector3::new(x / w, y / w, z / w))
}

/// The one re-orthonormalisation of the project: the rotation nearest to `m`
/// in the Frobenius norm (polar decomposition by SVD, `U·Vᵀ` with the sign
/// of the smallest singular direction flipped if that gives a reflection).
/// Every conversion from a matrix to a rotation (isometry, quaternion) goes
/// through it. `None` if `m` has a non-finite element or the SVD does not
/// converge (never loops unbounded).
pub fn nearest_rotation(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    // nalgebra's `svd` with its default tolerance, but a bounded iteration count.
    let svd = m.try_svd(true, true, 5.0 * f64::EPSILON, 1000)?;
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        let mut u2 = u;
        u2.column_mut(2).neg_mut();
        r = u2 * vt;
    }
    r.iter().all(|v| v.is_finite()).then_some(r)
}

/// Whether `m` is a proper rotation to within `tol`.
pub fn is_rotation(m: &Matrix3<f64>, tol: f64) -> bool {
    (m.transpose() * m - Matrix3::identity()).abs().max() < tol
        && (m.determinant() - 1.0).abs() < tol
}

/// The unit quaternion of the rotation nearest to `m` ([`nearest_rotation`]),
/// as nalgebra extracts it (either sign). `None` where [`nearest_rotation`]
/// gives none.
pub fn unit_quaternion_from_matrix(m: &Matrix3<f64>) -> Option<UnitQuaternion<f64>> {
    let r = nearest_rotation(m)?;
    Some(UnitQuaternion::from_rotation_matrix(
        &Rotation3::from_matrix_unchecked(r),
    ))
}

/// The Hamilton unit quaternion of a rotation matrix as `[w, x, y, z]`
/// (scalar first), sign chosen so that `w >= 0`; `None` unless `m` is a
/// rotation to within 1e-6 (it is re-orthonormalised by [`nearest_rotation`]).
/// `matrix_from_quaternion_wxyz` gives `m` back.
pub fn quaternion_wxyz_from_matrix(m: &Matrix3<f64>) -> Option<[f64; 4]> {
    if !is_rotation(m, 1e-6) {
        return None;
    }
    // A rotation to working precision (an adjustment's `R`) is read as it
    // is, so the streamed quaternion stays the same bit for bit; a looser
    // one is orthonormalised first.
    let q = if is_rotation(m, 1e-12) {
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*m))
    } else {
        unit_quaternion_from_matrix(m)?
    };
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    Some([s * q.w, s * q.i, s * q.j, s * q.k])
}

/// The rotation matrix of a quaternion `[w, x, y, z]` (scalar first;
/// normalised here, either sign gives the same matrix); `None` for a
/// non-finite or (nearly) zero quaternion.
pub fn matrix_from_quaternion_wxyz(q: [f64; 4]) -> Option<Matrix3<f64>> {
    let q = Quaternion::new(q[0], q[1], q[2], q[3]);
    let n = q.norm();
    if !(n.is_finite() && n > 1e-12) {
        return None;
    }
    Some(
        UnitQuaternion::new_normalize(q)
            .to_rotation_matrix()
            .into_inner(),
    )
}

/// KUKA `A, B, C` (degrees): `M = Rz(A) Ry(B) Rx(C)`.
pub fn matrix_from_kuka_abc_deg(a: f64, b: f64, c: f64) -> Matrix3<f64> {
    let (a, b, c) = (a.to_radians(), b.to_radians(), c.to_radians());
    let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), a);
    let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), b);
    let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), c);
    (rz * ry * rx).into_inner()
}

/// KUKA `A, B, C` (degrees) of a rotation matrix `M = Rz(A) Ry(B) Rx(C)`.
/// At gimbal lock (`|B| = 90°`) `C` is set to 0 and `A` carries the rotation.
pub fn kuka_abc_deg_from_matrix(m: &Matrix3<f64>) -> [f64; 3] {
    let cb = (m[(0, 0)] * m[(0, 0)] + m[(1, 0)] * m[(1, 0)]).sqrt();
    let b = (-m[(2, 0)]).atan2(cb);
    let (a, c) = if cb > 1e-9 {
        (m[(1, 0)].atan2(m[(0, 0)]), m[(2, 1)].atan2(m[(2, 2)]))
    } else {
        // B = ±90°: only A - C (B = +90°) or A + C (B = -90°) is defined;
        // with C = 0 both cases read A from the same two elements.
        let a = (-m[(0, 1)]).atan2(m[(1, 1)]);
        (a, 0.0)
    };
    [a.to_degrees(), b.to_degrees(), c.to_degrees()]
}

/// The rotation angle of `m` in radians (0..=π).
pub fn angle_of(m: &Matrix3<f64>) -> f64 {
    ((m.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos()
}

/// The angle in radians between two rotations.
pub fn angle_between(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    // Robust for tiny angles: use the skew part of a^T b.
    let d = a.transpose() * b;
    let s = Vector3::new(
        d[(2, 1)] - d[(1, 2)],
        d[(0, 2)] - d[(2, 0)],
        d[(1, 0)] - d[(0, 1)],
    )
    .norm()
        / 2.0;
    let c = (d.trace() - 1.0) / 2.0;
    s.atan2(c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn skew(a: f64, b: f64, c: f64) -> Matrix3<f64> {
        Matrix3::new(0.0, -c, b, c, 0.0, -a, -b, a, 0.0)
    }

    #[test]
    fn cayley_is_the_matrix_definition() {
        let (a, b, c) = (0.3, -0.7, 1.9);
        let s = skew(a, b, c);
        let i = Matrix3::identity();
        let r = (i + s) * (i - s).try_inverse().unwrap();
        assert!((r - cayley(a, b, c)).abs().max() < 1e-14);
        assert!(is_rotation(&cayley(a, b, c), 1e-12));
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, rng_seed: proptest::test_runner::RngSeed::Fixed(7), ..ProptestConfig::default() })]

        #[test]
        fn derivatives_match_central_differences(a in -3.0..3.0f64, b in -3.0..3.0f64, c in -3.0..3.0f64) {
            let d = cayley_derivatives(a, b, c);
            let h = 1e-6;
            let fd = [
                (cayley(a + h, b, c) - cayley(a - h, b, c)) / (2.0 * h),
                (cayley(a, b + h, c) - cayley(a, b - h, c)) / (2.0 * h),
                (cayley(a, b, c + h) - cayley(a, b, c - h)) / (2.0 * h),
            ];
            for k in 0..3 {
                prop_assert!((d[k] - fd[k]).abs().max() < 1e-8, "k={} {}", k, (d[k] - fd[k]).abs().max());
            }
        }

        #[test]
        fn cayley_round_trips(a in -50.0..50.0f64, b in -50.0..50.0f64, c in -50.0..50.0f64) {
            let r = cayley(a, b, c);
            let p = cayley_from_matrix(&r).unwrap();
            prop_assert!((cayley(p.x, p.y, p.z) - r).abs().max() < 1e-9);
        }

        #[test]
        fn quaternion_round_trips(w in -1.0..1.0f64, x in -1.0..1.0f64, y in -1.0..1.0f64, z in -1.0..1.0f64) {
            prop_assume!((w * w + x * x + y * y + z * z) > 1e-3);
            let m = matrix_from_quaternion_wxyz([w, x, y, z]).unwrap();
            prop_assert!(is_rotation(&m, 1e-12));
            let q = quaternion_wxyz_from_matrix(&m).unwrap();
            let m2 = matrix_from_quaternion_wxyz(q).unwrap();
            prop_assert!((m - m2).abs().max() < 1e-12);
            // Sign convention: w >= 0, so the quaternion is the input's
            // (normalised) or its negative, whichever has w >= 0.
            prop_assert!(q[0] >= 0.0);
            let n = (w * w + x * x + y * y + z * z).sqrt();
            let s = if w < 0.0 { -1.0 / n } else { 1.0 / n };
            if w.abs() > 1e-6 {
                for (k, v) in [w, x, y, z].into_iter().enumerate() {
                    prop_assert!((q[k] - s * v).abs() < 1e-12, "{:?} vs {:?}", q, [w, x, y, z]);
                }
            }
        }

        #[test]
        fn nearest_rotation_undoes_a_small_disturbance(a in -3.0..3.0f64, b in -3.0..3.0f64, c in -3.0..3.0f64, e in prop::array::uniform9(-1e-6..1e-6f64)) {
            let r = cayley(a, b, c);
            let m = r + Matrix3::from_column_slice(&e);
            let n = nearest_rotation(&m).unwrap();
            prop_assert!(is_rotation(&n, 1e-14));
            // Within the disturbance of the exact rotation, and a fixed point.
            prop_assert!((n - r).abs().max() < 1e-5);
            prop_assert!((nearest_rotation(&r).unwrap() - r).abs().max() < 1e-14);
        }

        #[test]
        fn kuka_abc_round_trips(a in -179.9..179.9f64, b in -89.9..89.9f64, c in -179.9..179.9f64) {
            let m = matrix_from_kuka_abc_deg(a, b, c);
            let [a2, b2, c2] = kuka_abc_deg_from_matrix(&m);
            prop_assert!((a - a2).abs() < 1e-7 && (b - b2).abs() < 1e-7 && (c - c2).abs() < 1e-7,
                "{} {} {} -> {} {} {}", a, b, c, a2, b2, c2);
        }

        #[test]
        fn kuka_abc_matrix_round_trips_through_gimbal_lock(a in -179.9..179.9f64, b in prop::sample::select(vec![-90.0, 90.0]), c in -179.9..179.9f64) {
            let m = matrix_from_kuka_abc_deg(a, b, c);
            let [a2, b2, c2] = kuka_abc_deg_from_matrix(&m);
            let m2 = matrix_from_kuka_abc_deg(a2, b2, c2);
            prop_assert!((m - m2).abs().max() < 1e-7);
        }
    }

    #[test]
    fn kuka_abc_is_z_then_y_then_x() {
        // A = 90: x axis of the frame points along parent y.
        let m = matrix_from_kuka_abc_deg(90.0, 0.0, 0.0);
        assert!((m.column(0) - Vector3::y()).norm() < 1e-12);
        // B = 90 about the new y: x axis points along parent -z.
        let m = matrix_from_kuka_abc_deg(0.0, 90.0, 0.0);
        assert!((m.column(0) + Vector3::z()).norm() < 1e-12);
        // The spec's example pose A=180, B=0, C=180: tool z points down.
        let m = matrix_from_kuka_abc_deg(180.0, 0.0, 180.0);
        assert!((m.column(2) + Vector3::z()).norm() < 1e-12);
    }

    #[test]
    fn quaternion_wxyz_names_the_scalar_first() {
        // 90° about z: w = cos 45°, z = sin 45°.
        let m = matrix_from_kuka_abc_deg(90.0, 0.0, 0.0);
        let q = quaternion_wxyz_from_matrix(&m).unwrap();
        let h = 0.5f64.sqrt();
        assert!(
            (q[0] - h).abs() < 1e-15 && (q[3] - h).abs() < 1e-15,
            "{q:?}"
        );
        assert!(q[1].abs() < 1e-15 && q[2].abs() < 1e-15);
        assert!(quaternion_wxyz_from_matrix(&(m * 1.1)).is_none());
    }

    #[test]
    fn nearest_rotation_refuses_bad_matrices() {
        let mut m = Matrix3::identity();
        m[(1, 2)] = f64::NAN;
        assert!(nearest_rotation(&m).is_none());
        m[(1, 2)] = f64::INFINITY;
        assert!(nearest_rotation(&m).is_none());
        // A reflection becomes the nearest proper rotation.
        let r = nearest_rotation(&Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0))).unwrap();
        assert!(is_rotation(&r, 1e-12));
    }

    #[test]
    fn cayley_cannot_express_half_turn() {
        let m = matrix_from_kuka_abc_deg(180.0, 0.0, 0.0);
        assert!(cayley_from_matrix(&m).is_none());
    }

    #[test]
    fn angle_between_is_accurate_for_tiny_angles() {
        let a = cayley(0.1, 0.2, 0.3);
        let b = cayley(1e-10, 0.0, 0.0) * a;
        assert!((angle_between(&a, &b) - 2e-10).abs() < 1e-16);
    }
}
