//! Poses as rigid transforms, and every conversion between their forms —
//! the one place in photopose that builds them:
//!
//! - a rotation matrix and a translation → [`Isometry3`], through the one
//!   re-orthonormalisation ([`crate::rotation::nearest_rotation`]);
//! - KUKA `X, Y, Z, A, B, C` (mm, degrees, `M = Rz(A)·Ry(B)·Rx(C)`, the
//!   gimbal-lock branch of [`crate::rotation::kuka_abc_deg_from_matrix`])
//!   ↔ isometry;
//! - exterior orientation (`R`: field → camera, projection centre) ↔ the
//!   camera's pose `T_field←camera = (Rᵀ, centre)`;
//! - covariances carried through these conversions.
//!
//! A pose `T_parent←child` maps child coordinates into the parent; its
//! rotation's columns are the child's axes in the parent (KUKA's `M`).
//!
//! Pose covariances here are of `(t, φ)`: the translation (mm) and a small
//! rotation `φ` (rad) about the *parent's* axes, `M ← exp([φ]ₓ)·M`
//! ([`perturbed`]). A resection's covariance is of `(C, ω)` with
//! `R ← R·(I + [ω]ₓ)`, i.e. `M = Rᵀ ← exp(−[ω]ₓ)·M`: [`camera_pose_covariance`]
//! turns one into the other.

use crate::exterior::Exterior;
use crate::rotation::{
    kuka_abc_deg_from_matrix, matrix_from_kuka_abc_deg, unit_quaternion_from_matrix,
};
use nalgebra::{Isometry3, Matrix3, Matrix6, Rotation3, Translation3, UnitQuaternion, Vector3};

/// The pose with rotation `m` (columns: the child's axes in the parent,
/// re-orthonormalised by [`crate::rotation::nearest_rotation`]) and
/// translation `t`. A matrix with a non-finite element gives a non-finite
/// rotation (never a panic).
pub fn isometry_from_matrix(m: &Matrix3<f64>, t: &Vector3<f64>) -> Isometry3<f64> {
    let rotation = unit_quaternion_from_matrix(m).unwrap_or_else(|| {
        // Only non-finite input gets here: let its NaNs show in the result.
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*m))
    });
    Isometry3::from_parts(Translation3::from(*t), rotation)
}

/// The pose given as KUKA `X, Y, Z, A, B, C` (mm, degrees) of a frame in its
/// parent.
pub fn isometry_from_xyzabc(xyzabc: [f64; 6]) -> Isometry3<f64> {
    let p = xyzabc;
    let m = matrix_from_kuka_abc_deg(p[3], p[4], p[5]);
    isometry_from_matrix(&m, &Vector3::new(p[0], p[1], p[2]))
}

/// KUKA `X, Y, Z, A, B, C` (mm, degrees) of a pose; at gimbal lock
/// (`|B| = 90°`) `C = 0` and `A` carries the rotation about the axis.
pub fn xyzabc_from_isometry(pose: &Isometry3<f64>) -> [f64; 6] {
    let m = pose.rotation.to_rotation_matrix().into_inner();
    let [a, b, c] = kuka_abc_deg_from_matrix(&m);
    let t = pose.translation.vector;
    [t.x, t.y, t.z, a, b, c]
}

/// The camera's pose in the field (plate) frame of an exterior orientation:
/// `T_field←camera = (Rᵀ, centre)` (the spec's `R` maps field → camera).
pub fn camera_pose(exterior: &Exterior) -> Isometry3<f64> {
    isometry_from_matrix(&exterior.rotation.transpose(), &exterior.center)
}

/// The exterior orientation (`R`, projection centre) of a camera pose
/// `T_field←camera`; the inverse of [`camera_pose`].
pub fn exterior_from_camera_pose(pose: &Isometry3<f64>) -> Exterior {
    Exterior::new(
        pose.rotation.to_rotation_matrix().into_inner().transpose(),
        pose.translation.vector,
    )
}

/// The pose turned by the small rotation `omega` (rad) about the parent's
/// axes and shifted by `dt` (mm): `M ← exp([ω]ₓ)·M`, `t ← t + dt` — the
/// perturbation the pose covariances of this module describe.
pub fn perturbed(pose: &Isometry3<f64>, dt: &Vector3<f64>, omega: &Vector3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(pose.translation.vector + dt),
        UnitQuaternion::from_scaled_axis(*omega) * pose.rotation,
    )
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

/// The covariance of the camera pose `(t, φ)` (mm², rad²; `φ` about the
/// field's axes, `M ← exp([φ]ₓ)·M`) from a resection's covariance of
/// `(Xc, Yc, Zc, ωX, ωY, ωZ)` (`R ← R·(I + [ω]ₓ)`): `t = C` and `φ = −ω`, so
/// the centre–rotation blocks change sign. Its own inverse.
pub fn camera_pose_covariance(exterior_covariance: &Matrix6<f64>) -> Matrix6<f64> {
    let mut c = *exterior_covariance;
    for i in 0..3 {
        for j in 3..6 {
            c[(i, j)] = -c[(i, j)];
            c[(j, i)] = -c[(j, i)];
        }
    }
    c
}

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// `∂r/∂φ` of the rotation vector `r = log(M)` (axis × angle, rad) under
/// `M ← exp([φ]ₓ)·M`: the inverse left Jacobian of SO(3),
/// `I − ½[r]ₓ + (1/θ² − (1 + cos θ)/(2θ sin θ))·[r]ₓ²`, `θ = |r|`. It grows
/// without bound as `θ → π`, where the rotation vector jumps.
pub fn rotation_vector_jacobian(pose: &Isometry3<f64>) -> Matrix3<f64> {
    let r = pose.rotation.scaled_axis();
    let theta = r.norm();
    let k = skew(&r);
    let coefficient = if theta < 1e-4 {
        // Series of the coefficient: 1/12 + θ²/720 + …
        1.0 / 12.0 + theta * theta / 720.0
    } else {
        1.0 / (theta * theta) - (1.0 + theta.cos()) / (2.0 * theta * theta.sin())
    };
    Matrix3::identity() - k * 0.5 + k * k * coefficient
}

/// The covariance of `(t, r)` — translation and rotation vector
/// `r = log(M)` — from a pose covariance of `(t, φ)` (see the module doc),
/// by first-order propagation through [`rotation_vector_jacobian`].
pub fn rotation_vector_covariance(
    pose: &Isometry3<f64>,
    covariance: &Matrix6<f64>,
) -> Matrix6<f64> {
    let mut j = Matrix6::identity();
    j.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&rotation_vector_jacobian(pose));
    j * covariance * j.transpose()
}

/// Where `cos B` is below this, the KUKA angles are at gimbal lock
/// ([`kuka_abc_deg_from_matrix`]'s branch) and their derivatives are
/// evaluated as if `cos B` were this.
const LOCK_COS_B: f64 = 1e-9;

/// `∂(A, B, C)/∂φ` (degrees per radian) of the KUKA angles of `m` under
/// `M ← exp([φ]ₓ)·M`, analytic: with `φ = Ȧ·z + Ḃ·Rz(A)·y + Ċ·Rz(A)Ry(B)·x`
/// inverted,
///
/// ```text
/// dA = tan B (cos A φx + sin A φy) + φz
/// dB = −sin A φx + cos A φy
/// dC = (cos A φx + sin A φy) / cos B
/// ```
///
/// `A` and `C` grow without bound as `|B| → 90°`; at the lock itself `cos B`
/// is taken as 1e-9 (huge, finite derivatives).
pub fn abc_jacobian_deg(m: &Matrix3<f64>) -> Matrix3<f64> {
    let [a, b, _] = kuka_abc_deg_from_matrix(m);
    let (sa, ca) = a.to_radians().sin_cos();
    let sb = b.to_radians().sin();
    let cb = b.to_radians().cos().max(LOCK_COS_B);
    let j = Matrix3::new(
        ca * sb / cb,
        sa * sb / cb,
        1.0,
        -sa,
        ca,
        0.0,
        ca / cb,
        sa / cb,
        0.0,
    );
    j * 1f64.to_degrees()
}

/// The covariance of `X, Y, Z, A, B, C` (mm², degrees², mm·degrees) of
/// `pose` from its covariance of `(t, φ)` (mm², rad²; see the module doc),
/// first order through [`abc_jacobian_deg`].
pub fn xyzabc_covariance(pose: &Isometry3<f64>, covariance: &Matrix6<f64>) -> Matrix6<f64> {
    let m = pose.rotation.to_rotation_matrix().into_inner();
    let mut j = Matrix6::identity();
    j.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&abc_jacobian_deg(&m));
    j * covariance * j.transpose()
}

/// Standard deviations of `X, Y, Z` (mm) and `A, B, C` (degrees) of `pose`
/// from its covariance of `(t, φ)` (mm², rad²; see the module doc): the
/// diagonal of [`xyzabc_covariance`]. Near `|B| = 90°` those of `A` and `C`
/// grow without bound, as the angles themselves do.
pub fn xyzabc_std(pose: &Isometry3<f64>, covariance: &Matrix6<f64>) -> [f64; 6] {
    let c = xyzabc_covariance(pose, covariance);
    std::array::from_fn(|k| c[(k, k)].max(0.0).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::rotation::{cayley, is_rotation};
    use proptest::prelude::*;
    use proptest::test_runner::RngSeed;

    fn config(cases: u32, seed: u64) -> ProptestConfig {
        ProptestConfig {
            cases,
            rng_seed: RngSeed::Fixed(seed),
            ..ProptestConfig::default()
        }
    }

    /// A 6×6 covariance with strong centre–rotation correlation, as a
    /// narrow-angle resection gives (shift sideways ≈ turn back).
    fn correlated_covariance() -> Matrix6<f64> {
        let l = Matrix6::new(
            0.05, 0.0, 0.0, 0.0, 0.0, 0.0, //
            0.01, 0.04, 0.0, 0.0, 0.0, 0.0, //
            0.0, 0.005, 0.02, 0.0, 0.0, 0.0, //
            1e-5, 8e-5, 0.0, 2e-5, 0.0, 0.0, //
            -9e-5, 1e-5, 0.0, 3e-6, 2e-5, 0.0, //
            0.0, 0.0, 1e-5, 1e-6, 2e-6, 3e-5,
        );
        l * l.transpose()
    }

    /// The old `handeye::kuka::xyzabc_std`: central differences of the
    /// angles, kept here as the reference the analytic form must reproduce.
    fn xyzabc_std_by_differences(pose: &Isometry3<f64>, covariance: &Matrix6<f64>) -> [f64; 6] {
        let h = 1e-7;
        let mut j = Matrix3::zeros();
        for k in 0..3 {
            let mut w = Vector3::zeros();
            w[k] = h;
            let plus = xyzabc_from_isometry(&perturbed(pose, &Vector3::zeros(), &w));
            let minus = xyzabc_from_isometry(&perturbed(pose, &Vector3::zeros(), &-w));
            for r in 0..3 {
                j[(r, k)] = wrap_deg(plus[3 + r] - minus[3 + r]) / (2.0 * h);
            }
        }
        let ca = j * covariance.fixed_view::<3, 3>(3, 3) * j.transpose();
        [
            covariance[(0, 0)].sqrt(),
            covariance[(1, 1)].sqrt(),
            covariance[(2, 2)].sqrt(),
            ca[(0, 0)].sqrt(),
            ca[(1, 1)].sqrt(),
            ca[(2, 2)].sqrt(),
        ]
    }

    /// `(t − t0, log(M M0ᵀ))` of `pose` against `base`: its `(t, φ)` offset.
    fn offset(pose: &Isometry3<f64>, base: &Isometry3<f64>) -> [f64; 6] {
        let dt = pose.translation.vector - base.translation.vector;
        let phi = (pose.rotation * base.rotation.inverse()).scaled_axis();
        [dt.x, dt.y, dt.z, phi.x, phi.y, phi.z]
    }

    proptest! {
        #![proptest_config(config(256, 11))]

        /// Away from gimbal lock: angles back to 1e-7°, positions exactly.
        #[test]
        fn xyzabc_round_trips_away_from_gimbal_lock(
            t in prop::array::uniform3(-2000.0..2000.0f64),
            a in -179.9..179.9f64, b in -89.9..89.9f64, c in -179.9..179.9f64,
        ) {
            let p = [t[0], t[1], t[2], a, b, c];
            let q = xyzabc_from_isometry(&isometry_from_xyzabc(p));
            for k in 0..6 {
                prop_assert!((p[k] - q[k]).abs() < 1e-7, "{:?} -> {:?}", p, q);
            }
        }

        /// At gimbal lock the angles are another triple of the same rotation:
        /// the matrices agree to 1e-12.
        #[test]
        fn xyzabc_at_gimbal_lock_gives_the_same_matrix(
            a in -180.0..180.0f64, b in prop::sample::select(vec![-90.0, 90.0]), c in -180.0..180.0f64,
        ) {
            let pose = isometry_from_xyzabc([1.0, 2.0, 3.0, a, b, c]);
            let q = xyzabc_from_isometry(&pose);
            prop_assert!(q[5] == 0.0 && (q[4] - b).abs() < 1e-6, "{:?}", q);
            let m = matrix_from_kuka_abc_deg(a, b, c);
            let m2 = matrix_from_kuka_abc_deg(q[3], q[4], q[5]);
            prop_assert!((m - m2).abs().max() < 1e-12, "{} vs {}", m, m2);
            prop_assert!((pose.rotation.to_rotation_matrix().into_inner() - m).abs().max() < 1e-12);
        }

        /// Isometry → xyzabc → isometry: the same pose (rotation to 1e-12
        /// rad, translation exactly), for any rotation.
        #[test]
        fn isometry_round_trips_through_xyzabc(
            t in prop::array::uniform3(-2000.0..2000.0f64),
            w in prop::array::uniform3(-3.1..3.1f64),
        ) {
            let pose = Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), UnitQuaternion::from_scaled_axis(Vector3::from(w)));
            let back = isometry_from_xyzabc(xyzabc_from_isometry(&pose));
            prop_assert!(back.rotation.angle_to(&pose.rotation) < 1e-12);
            prop_assert_eq!(back.translation, pose.translation);
        }

        /// The one orthonormalisation gives the rotations the former
        /// per-crate extractions gave: nalgebra's quaternion of the unchecked
        /// matrix (handeye, formats, circle) to 1e-12 for KUKA matrices; for
        /// products of rotations the exact product to 1e-14, where the
        /// iterative `from_matrix_eps` (rsi, stopping at 1e-12) was within
        /// 1e-11.
        #[test]
        fn isometry_from_matrix_equals_the_former_extractions(
            p in prop::array::uniform3(-180.0..180.0f64),
            q in prop::array::uniform3(-180.0..180.0f64),
        ) {
            let m = matrix_from_kuka_abc_deg(p[0], p[1], p[2]);
            let t = Vector3::new(1.0, 2.0, 3.0);
            let new = isometry_from_matrix(&m, &t).rotation.to_rotation_matrix().into_inner();
            let old = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
            prop_assert!((new - old.to_rotation_matrix().into_inner()).abs().max() < 1e-12);
            let product = m * matrix_from_kuka_abc_deg(q[0], q[1], q[2]);
            let new = isometry_from_matrix(&product, &t).rotation.to_rotation_matrix().into_inner();
            let old = UnitQuaternion::from_matrix_eps(&product, 1e-12, 100, UnitQuaternion::identity());
            prop_assert!((new - product).abs().max() < 1e-14);
            prop_assert!((new - old.to_rotation_matrix().into_inner()).abs().max() < 1e-11);
        }

        /// Exterior → camera pose → exterior: `R` to 1e-12, the centre
        /// exactly; and the camera pose's `M` is `Rᵀ`.
        #[test]
        fn camera_pose_round_trips_with_the_exterior(
            r in prop::array::uniform3(-20.0..20.0f64),
            centre in prop::array::uniform3(-2000.0..2000.0f64),
        ) {
            let e = Exterior::new(cayley(r[0], r[1], r[2]), Vector3::from(centre));
            let pose = camera_pose(&e);
            let m = pose.rotation.to_rotation_matrix().into_inner();
            prop_assert!((m - e.rotation.transpose()).abs().max() < 1e-12);
            prop_assert_eq!(pose.translation.vector, e.center);
            let back = exterior_from_camera_pose(&pose);
            prop_assert!((back.rotation - e.rotation).abs().max() < 1e-12);
            prop_assert!(is_rotation(&back.rotation, 1e-12));
            prop_assert_eq!(back.center, e.center);
        }

        /// The camera pose of `Exterior::from_kuka_pose(p)` is `p`.
        #[test]
        fn camera_pose_agrees_with_the_kuka_exterior(
            t in prop::array::uniform3(-2000.0..2000.0f64),
            a in -179.9..179.9f64, b in -89.9..89.9f64, c in -179.9..179.9f64,
        ) {
            let p = [t[0], t[1], t[2], a, b, c];
            let e = Exterior::from_kuka_pose(p);
            let q = xyzabc_from_isometry(&camera_pose(&e));
            let k = e.to_kuka_pose();
            for i in 0..6 {
                prop_assert!((p[i] - q[i]).abs() < 1e-7 && (q[i] - k[i]).abs() < 1e-7, "{:?} {:?} {:?}", p, q, k);
            }
        }

        /// Analytic `∂r/∂φ` against central differences (1e-6 relative),
        /// rotations up to 3 rad.
        #[test]
        fn rotation_vector_jacobian_matches_differences(w in prop::array::uniform3(-1.7..1.7f64)) {
            let pose = Isometry3::from_parts(Translation3::identity(), UnitQuaternion::from_scaled_axis(Vector3::from(w)));
            let j = rotation_vector_jacobian(&pose);
            let h = 1e-6;
            for k in 0..3 {
                let mut d = Vector3::zeros();
                d[k] = h;
                let plus = perturbed(&pose, &Vector3::zeros(), &d).rotation.scaled_axis();
                let minus = perturbed(&pose, &Vector3::zeros(), &-d).rotation.scaled_axis();
                let fd = (plus - minus) / (2.0 * h);
                prop_assert!((fd - j.column(k)).norm() < 1e-6 * fd.norm().max(1.0), "k={} {} vs {}", k, fd, j.column(k));
            }
        }

        /// Analytic `∂(A, B, C)/∂φ` against central differences of the
        /// angles (1e-6 relative), `|B| ≤ 80°`.
        #[test]
        fn abc_jacobian_matches_differences(
            a in -179.0..179.0f64, b in -80.0..80.0f64, c in -179.0..179.0f64,
        ) {
            let pose = isometry_from_xyzabc([0.0, 0.0, 0.0, a, b, c]);
            let j = abc_jacobian_deg(&pose.rotation.to_rotation_matrix().into_inner());
            let h = 1e-7;
            for k in 0..3 {
                let mut d = Vector3::zeros();
                d[k] = h;
                let plus = xyzabc_from_isometry(&perturbed(&pose, &Vector3::zeros(), &d));
                let minus = xyzabc_from_isometry(&perturbed(&pose, &Vector3::zeros(), &-d));
                for r in 0..3 {
                    let fd = wrap_deg(plus[3 + r] - minus[3 + r]) / (2.0 * h);
                    prop_assert!((fd - j[(r, k)]).abs() < 1e-6 * fd.abs().max(1.0), "({},{}) {} vs {}", r, k, fd, j[(r, k)]);
                }
            }
        }

        /// The analytic σ of `X … C` equals the former central-difference
        /// ones (`handeye::kuka::xyzabc_std`) to 1e-6 relative.
        #[test]
        fn xyzabc_std_equals_the_difference_version(
            a in -179.0..179.0f64, b in -85.0..85.0f64, c in -179.0..179.0f64,
        ) {
            let pose = isometry_from_xyzabc([100.0, -50.0, 700.0, a, b, c]);
            let cov = correlated_covariance();
            let s = xyzabc_std(&pose, &cov);
            let old = xyzabc_std_by_differences(&pose, &cov);
            for k in 0..6 {
                prop_assert!((s[k] - old[k]).abs() <= 1e-6 * old[k], "{}: {:?} vs {:?}", k, s, old);
            }
        }
    }

    #[test]
    fn xyzabc_std_of_a_rotation_about_the_parent_z_is_a() {
        // With B = C = 0, a small rotation about the parent's Z changes A only.
        let pose = isometry_from_xyzabc([0.0, 0.0, 0.0, 30.0, 0.0, 0.0]);
        let mut cov = Matrix6::zeros();
        cov[(5, 5)] = 0.01f64.to_radians().powi(2);
        cov[(0, 0)] = 0.04;
        let s = xyzabc_std(&pose, &cov);
        assert!((s[0] - 0.2).abs() < 1e-12);
        assert!((s[3] - 0.01).abs() < 1e-12, "{s:?}");
        assert!(s[4] < 1e-12 && s[5] < 1e-12, "{s:?}");
    }

    #[test]
    fn xyzabc_std_at_gimbal_lock_is_huge_but_finite() {
        let pose = isometry_from_xyzabc([0.0, 0.0, 0.0, 20.0, 90.0, 0.0]);
        let cov = Matrix6::identity() * 1e-8;
        let s = xyzabc_std(&pose, &cov);
        assert!(s.iter().all(|v| v.is_finite()), "{s:?}");
        assert!(s[3] > 1e3 && s[5] > 1e3 && s[4] < 0.01, "{s:?}");
    }

    #[test]
    fn wrap_brings_angles_near_180_together() {
        assert!((wrap_deg(359.0) + 1.0).abs() < 1e-12);
        assert!((wrap_deg(-359.0) - 1.0).abs() < 1e-12);
        assert_eq!(wrap_deg(180.0), 180.0);
    }

    #[test]
    fn non_finite_matrices_give_non_finite_poses_without_panicking() {
        let mut m = Matrix3::identity();
        m[(0, 1)] = f64::NAN;
        let pose = isometry_from_matrix(&m, &Vector3::zeros());
        assert!(pose.rotation.coords.iter().any(|v| v.is_nan()));
        let p = xyzabc_from_isometry(&isometry_from_xyzabc([0.0, 0.0, 0.0, f64::NAN, 0.0, 0.0]));
        assert!(p[3].is_nan() || p[4].is_nan() || p[5].is_nan(), "{p:?}");
    }

    /// The camera pose's `(t, φ)` as a function of the resection's `(C, ω)`
    /// has the Jacobian `diag(I, −I)` (central differences, 1e-8), which
    /// [`camera_pose_covariance`] applies.
    #[test]
    fn camera_pose_covariance_uses_the_numeric_jacobian() {
        let e0 = Exterior::from_kuka_pose([30.0, -20.0, 800.0, 25.0, 8.0, 170.0]);
        let p0 = camera_pose(&e0);
        let h = 1e-6;
        let at = |d: &[f64; 6]| {
            let e = Exterior::new(
                e0.rotation * cayley(d[3] / 2.0, d[4] / 2.0, d[5] / 2.0),
                e0.center + Vector3::new(d[0], d[1], d[2]),
            );
            offset(&camera_pose(&e), &p0)
        };
        let mut j = Matrix6::zeros();
        for k in 0..6 {
            let mut d = [0.0; 6];
            d[k] = h;
            let plus = at(&d);
            d[k] = -h;
            let minus = at(&d);
            for r in 0..6 {
                j[(r, k)] = (plus[r] - minus[r]) / (2.0 * h);
            }
        }
        let cov = correlated_covariance();
        let numeric = j * cov * j.transpose();
        let analytic = camera_pose_covariance(&cov);
        let scale = cov.abs().max();
        assert!(
            (numeric - analytic).abs().max() < 1e-8 * scale,
            "{numeric} vs {analytic}"
        );
        // The cross terms really change sign (the covariance has some).
        assert!(cov[(0, 4)].abs() > 1e-7);
        assert_eq!(analytic[(0, 4)], -cov[(0, 4)]);
        assert_eq!(camera_pose_covariance(&analytic), cov);
    }

    /// Sample covariances of the camera pose's `(t, φ)`, of its rotation
    /// vector and of its `X … C`, from draws of a resection's `(C, ω)`,
    /// against the propagated ones (20000 seeded draws; within 3% of the
    /// larger standard deviation of each pair).
    #[test]
    fn propagated_covariances_match_monte_carlo() {
        let e0 = Exterior::from_kuka_pose([30.0, -20.0, 800.0, 25.0, 38.0, 170.0]);
        let p0 = camera_pose(&e0);
        let cov = correlated_covariance();
        let l = cov.cholesky().unwrap().l();
        let mut rng = SplitMix64::new(21);
        let n = 20_000;
        let x0 = xyzabc_from_isometry(&p0);
        let r0 = p0.rotation.scaled_axis();
        let (mut s_pose, mut s_rv, mut s_abc) =
            (Matrix6::zeros(), Matrix6::zeros(), Matrix6::zeros());
        for _ in 0..n {
            let d = l * nalgebra::Vector6::from_fn(|_, _| rng.normal());
            let e = Exterior::new(
                e0.rotation * cayley(d[3] / 2.0, d[4] / 2.0, d[5] / 2.0),
                e0.center + Vector3::new(d[0], d[1], d[2]),
            );
            let p = camera_pose(&e);
            let o = nalgebra::Vector6::from(offset(&p, &p0));
            s_pose += o * o.transpose();
            let dr = p.rotation.scaled_axis() - r0;
            let v = nalgebra::Vector6::new(o[0], o[1], o[2], dr.x, dr.y, dr.z);
            s_rv += v * v.transpose();
            let x = xyzabc_from_isometry(&p);
            let v = nalgebra::Vector6::from_fn(|k, _| {
                if k < 3 {
                    x[k] - x0[k]
                } else {
                    wrap_deg(x[k] - x0[k])
                }
            });
            s_abc += v * v.transpose();
        }
        let pose_cov = camera_pose_covariance(&cov);
        for (sample, want) in [
            (s_pose / n as f64, pose_cov),
            (s_rv / n as f64, rotation_vector_covariance(&p0, &pose_cov)),
            (s_abc / n as f64, xyzabc_covariance(&p0, &pose_cov)),
        ] {
            // Each element's error in units of the σ product of its pair.
            let s = Matrix6::from_diagonal(&want.diagonal().map(|v| 1.0 / v.sqrt()));
            let worst = (s * (sample - want) * s).abs().max();
            assert!(worst < 0.03, "{worst}: {sample} vs {want}");
        }
    }
}
