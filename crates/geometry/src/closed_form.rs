//! Closed-form resection, two-stage as in the reference paper:
//!
//! 1. the projection centre from the plane-to-plane (projective) transform of
//!    four coplanar control points — Fischler & Bolles' perspective-4-point
//!    solution, which needs the principal distance;
//! 2. the orientation from the image rays once the centre is known — Kraus'
//!    orientation from three (or more) points, solved here as the rotation
//!    that best maps object directions onto image rays (SVD of their
//!    correlation; with three points it is Kraus' triad).
//!
//! For control points that are not coplanar, [`dlt`] gives a linear closed
//! form from six or more points.
//!
//! All inputs are ideal image coordinates (corrected, mm) and object points
//! (mm); nothing here allocates.

use crate::error::GeometryError;
use crate::exterior::Exterior;
use crate::rotation::nearest_rotation;
use nalgebra::{Matrix3, SMatrix, SVector, Vector2, Vector3};

/// The camera-frame direction of an ideal image point: the ray `(x, y, -c)`,
/// normalised.
#[inline]
pub fn ray(c: f64, image: &Vector2<f64>) -> Vector3<f64> {
    Vector3::new(image.x, image.y, -c).normalize()
}

/// Stage 2 (Kraus): the rotation `R` that maps the object-frame directions
/// from `center` to each point onto the camera-frame rays of their images.
pub fn orientation_from_center(
    c: f64,
    center: &Vector3<f64>,
    object: &[Vector3<f64>],
    image: &[Vector2<f64>],
) -> Result<Matrix3<f64>, GeometryError> {
    if object.len() < 3 || object.len() != image.len() {
        return Err(GeometryError::TooFewPoints {
            got: object.len().min(image.len()),
            need: 3,
        });
    }
    let mut corr = Matrix3::zeros();
    for (p, m) in object.iter().zip(image) {
        let d_obj = (p - center)
            .try_normalize(1e-12)
            .ok_or(GeometryError::Degenerate(
                "control point at the projection centre",
            ))?;
        corr += ray(c, m) * d_obj.transpose();
    }
    nearest_rotation(&corr).ok_or(GeometryError::Degenerate(
        "rays do not determine a rotation",
    ))
}

/// An orthonormal frame in the plane of (nearly) coplanar points: origin,
/// in-plane axes `u`, `v` and normal `n = u × v`.
#[derive(Debug, Clone, Copy)]
struct PlaneFrame {
    origin: Vector3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
    n: Vector3<f64>,
}

impl PlaneFrame {
    fn of_four(p: &[Vector3<f64>; 4]) -> Result<Self, GeometryError> {
        let origin = (p[0] + p[1] + p[2] + p[3]) / 4.0;
        // Normal from the two diagonals: robust for any convex quadrilateral.
        let d1 = p[2] - p[0];
        let d2 = p[3] - p[1];
        let mut n = d1.cross(&d2);
        let scale = d1.norm() * d2.norm();
        if n.norm() < 1e-6 * scale {
            // Diagonals parallel (a non-convex or degenerate ordering): use
            // the best of the triangle normals.
            n = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]
                .iter()
                .map(|&(a, b, c)| (p[b] - p[a]).cross(&(p[c] - p[a])))
                .max_by(|x, y| x.norm().total_cmp(&y.norm()))
                .unwrap_or_default();
        }
        let n = n
            .try_normalize(1e-9 * scale.max(1e-300))
            .ok_or(GeometryError::Degenerate("control points are collinear"))?;
        let u = (p[0] - origin)
            .try_normalize(1e-12)
            .ok_or(GeometryError::Degenerate("coincident control points"))?;
        let u = (u - n * n.dot(&u)).normalize();
        let v = n.cross(&u);
        Ok(PlaneFrame { origin, u, v, n })
    }

    #[inline]
    fn local(&self, p: &Vector3<f64>) -> Vector2<f64> {
        let d = p - self.origin;
        Vector2::new(d.dot(&self.u), d.dot(&self.v))
    }
}

/// The projective transform (homography) `H` with `w ~ H (s, t, 1)ᵀ` from four
/// plane points to four image points, normalised so that `H[2,2] = 1`.
fn homography4(plane: &[Vector2<f64>; 4], w: &[Vector2<f64>; 4]) -> Option<Matrix3<f64>> {
    let mut a = SMatrix::<f64, 8, 8>::zeros();
    let mut b = SVector::<f64, 8>::zeros();
    for k in 0..4 {
        let (s, t) = (plane[k].x, plane[k].y);
        let (x, y) = (w[k].x, w[k].y);
        let r = 2 * k;
        a[(r, 0)] = s;
        a[(r, 1)] = t;
        a[(r, 2)] = 1.0;
        a[(r, 6)] = -x * s;
        a[(r, 7)] = -x * t;
        b[r] = x;
        a[(r + 1, 3)] = s;
        a[(r + 1, 4)] = t;
        a[(r + 1, 5)] = 1.0;
        a[(r + 1, 6)] = -y * s;
        a[(r + 1, 7)] = -y * t;
        b[r + 1] = y;
    }
    let h = a.lu().solve(&b)?;
    let m = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], 1.0);
    m.iter().all(|v| v.is_finite()).then_some(m)
}

/// Stage 1 (Fischler & Bolles P4P): the projection centre from four coplanar
/// control points and their ideal images, through the plane-to-plane
/// transformation. Also returns the rotation implied by the transform, which
/// stage 2 replaces.
pub fn center_from_four_coplanar(
    c: f64,
    object: &[Vector3<f64>; 4],
    image: &[Vector2<f64>; 4],
) -> Result<(Vector3<f64>, Matrix3<f64>), GeometryError> {
    for (i, p) in object.iter().enumerate() {
        if !p.iter().chain(image[i].iter()).all(|v| v.is_finite()) {
            return Err(GeometryError::NonFinite { index: i });
        }
    }
    let frame = PlaneFrame::of_four(object)?;
    let plane = [
        frame.local(&object[0]),
        frame.local(&object[1]),
        frame.local(&object[2]),
        frame.local(&object[3]),
    ];
    // Reject three collinear points: every triangle must have some area.
    let extent = plane.iter().map(|p| p.norm()).fold(0.0, f64::max);
    for (a, b, d) in [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)] {
        let e1 = plane[b] - plane[a];
        let e2 = plane[d] - plane[a];
        if (e1.x * e2.y - e1.y * e2.x).abs() < 1e-6 * extent * extent {
            return Err(GeometryError::Degenerate(
                "three of the four control points are collinear",
            ));
        }
    }
    // Image rays as (Zx/N, Zy/N) = (-x/c, -y/c).
    let w = [-image[0] / c, -image[1] / c, -image[2] / c, -image[3] / c];
    let h = homography4(&plane, &w).ok_or(GeometryError::Degenerate(
        "plane-to-plane transform is singular",
    ))?;
    let h1 = h.column(0).into_owned();
    let h2 = h.column(1).into_owned();
    let h3 = h.column(2).into_owned();
    let norm = 0.5 * (h1.norm() + h2.norm());
    if !(norm.is_finite() && norm > 1e-15) {
        return Err(GeometryError::Degenerate(
            "plane-to-plane transform is singular",
        ));
    }
    // The plane origin must lie in front of the camera: its camera-frame z
    // (scale * h33 = scale) is negative.
    let k = -1.0 / norm;
    let r1 = h1 * k;
    let r2 = h2 * k;
    let t = h3 * k;
    let r3 = r1.cross(&r2);
    let cam = Matrix3::from_columns(&[r1, r2, r3]);
    let obj = Matrix3::from_columns(&[frame.u, frame.v, frame.n]);
    let rot = nearest_rotation(&(cam * obj.transpose())).ok_or(GeometryError::Degenerate(
        "plane-to-plane transform gives no rotation",
    ))?;
    let center = frame.origin - rot.transpose() * t;
    Ok((center, rot))
}

/// The full two-stage closed form from four coplanar points: centre by
/// Fischler & Bolles, orientation by Kraus.
pub fn resect_four_coplanar(
    c: f64,
    object: &[Vector3<f64>; 4],
    image: &[Vector2<f64>; 4],
) -> Result<Exterior, GeometryError> {
    let (center, _) = center_from_four_coplanar(c, object, image)?;
    let rotation = orientation_from_center(c, &center, object, image)?;
    Ok(Exterior { rotation, center })
}

/// Linear closed form for non-coplanar control points (direct linear
/// transformation of the calibrated camera, Hartley-normalised), from six
/// points. The points must not be coplanar.
pub fn dlt(
    c: f64,
    object: &[Vector3<f64>; 6],
    image: &[Vector2<f64>; 6],
) -> Result<Exterior, GeometryError> {
    let mut centroid = Vector3::zeros();
    for (i, p) in object.iter().enumerate() {
        if !p.iter().chain(image[i].iter()).all(|v| v.is_finite()) {
            return Err(GeometryError::NonFinite { index: i });
        }
        centroid += p;
    }
    centroid /= 6.0;
    let spread = (object
        .iter()
        .map(|p| (p - centroid).norm_squared())
        .sum::<f64>()
        / 6.0)
        .sqrt();
    if spread < 1e-9 {
        return Err(GeometryError::Degenerate("coincident control points"));
    }
    let s = 1.0 / spread;
    let mut a = SMatrix::<f64, 12, 12>::zeros();
    for k in 0..6 {
        let p = (object[k] - centroid) * s;
        let w = -image[k] / c; // (Zx/N, Zy/N)
        let hp = [p.x, p.y, p.z, 1.0];
        let r = 2 * k;
        for j in 0..4 {
            a[(r, j)] = hp[j];
            a[(r, 8 + j)] = -w.x * hp[j];
            a[(r + 1, 4 + j)] = hp[j];
            a[(r + 1, 8 + j)] = -w.y * hp[j];
        }
    }
    let svd = a.svd(false, true);
    let vt = svd
        .v_t
        .ok_or(GeometryError::Degenerate("DLT system has no solution"))?;
    // Smallest singular value: nalgebra does not sort them, find it.
    let (imin, _) = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|x, y| x.1.total_cmp(y.1))
        .ok_or(GeometryError::Degenerate("DLT system has no solution"))?;
    let sv = &svd.singular_values;
    let mut sorted = [0.0; 12];
    sorted.copy_from_slice(sv.as_slice());
    sorted.sort_by(f64::total_cmp);
    if sorted[1] < 1e-9 * sorted[11] {
        return Err(GeometryError::Degenerate(
            "control points are coplanar or too few for the non-coplanar closed form",
        ));
    }
    let h = vt.row(imin);
    let mut m = Matrix3::new(h[0], h[1], h[2], h[4], h[5], h[6], h[8], h[9], h[10]);
    let mut t = Vector3::new(h[3], h[7], h[11]);
    let det = m.determinant();
    if !(det.is_finite() && det.abs() > 1e-300) {
        return Err(GeometryError::Degenerate("DLT matrix is singular"));
    }
    // Scale so that M is a rotation (det +1); camera-frame z of the
    // centroid is t.z and must be negative (in front).
    let scale = det.abs().cbrt();
    m /= scale;
    t /= scale;
    if m.determinant() < 0.0 {
        m = -m;
        t = -t;
    }
    if t.z > 0.0 {
        return Err(GeometryError::BehindCamera { count: 6 });
    }
    let rot = nearest_rotation(&m).ok_or(GeometryError::Degenerate("DLT gives no rotation"))?;
    // t = R (centroid_n - C_n) with the normalised frame; C_n = -Rᵀ t.
    let center_n = -(rot.transpose() * t);
    let center = centroid + center_n / s;
    Ok(Exterior {
        rotation: rot,
        center,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotation::{angle_between, cayley};

    fn project(e: &Exterior, c: f64, p: &Vector3<f64>) -> Vector2<f64> {
        e.project_ideal(c, p).unwrap()
    }

    /// A camera about 1 m from the origin, looking at it obliquely.
    fn oblique_view() -> Exterior {
        Exterior::look_at(
            Vector3::new(-300.0, 200.0, 900.0),
            Vector3::zeros(),
            Vector3::y(),
        )
        .unwrap()
    }

    #[test]
    fn four_coplanar_points_give_the_exact_pose() {
        let c = 12.0;
        let truth = Exterior::new(cayley(0.1, -0.2, 0.7), Vector3::new(30.0, -40.0, 1000.0));
        let obj = [
            Vector3::new(-200.0, -150.0, 0.0),
            Vector3::new(210.0, -140.0, 0.0),
            Vector3::new(190.0, 160.0, 0.0),
            Vector3::new(-220.0, 150.0, 0.0),
        ];
        // Orient so the plate is in front.
        let truth = Exterior::look_at(
            truth.center,
            Vector3::new(10.0, 5.0, 0.0),
            Vector3::new(0.3, 1.0, 0.0),
        )
        .unwrap();
        let img = obj.map(|p| project(&truth, c, &p));
        let e = resect_four_coplanar(c, &obj, &img).unwrap();
        assert!(
            (e.center - truth.center).norm() < 1e-8,
            "{}",
            (e.center - truth.center).norm()
        );
        assert!(angle_between(&e.rotation, &truth.rotation) < 1e-11);
    }

    #[test]
    fn tilted_plane_and_oblique_view() {
        let c = 12.0;
        let tilt = cayley(0.3, 0.1, -0.4);
        let obj = [
            tilt * Vector3::new(-200.0, -150.0, 0.0) + Vector3::new(5.0, 6.0, 7.0),
            tilt * Vector3::new(210.0, -140.0, 0.0) + Vector3::new(5.0, 6.0, 7.0),
            tilt * Vector3::new(190.0, 160.0, 0.0) + Vector3::new(5.0, 6.0, 7.0),
            tilt * Vector3::new(-220.0, 150.0, 0.0) + Vector3::new(5.0, 6.0, 7.0),
        ];
        let eye = tilt * Vector3::new(600.0, 0.0, 800.0);
        let truth =
            Exterior::look_at(eye, Vector3::new(0.0, 0.0, 0.0), tilt * Vector3::z()).unwrap();
        let img = obj.map(|p| project(&truth, c, &p));
        let e = resect_four_coplanar(c, &obj, &img).unwrap();
        assert!((e.center - truth.center).norm() < 1e-7);
        assert!(angle_between(&e.rotation, &truth.rotation) < 1e-10);
    }

    #[test]
    fn collinear_points_are_degenerate() {
        let obj = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(10.0, 0.0, 0.0),
            Vector3::new(20.0, 0.0, 0.0),
            Vector3::new(30.0, 0.0, 0.0),
        ];
        let img = [
            Vector2::new(0.0, 0.0),
            Vector2::new(1.0, 0.0),
            Vector2::new(2.0, 0.0),
            Vector2::new(3.0, 0.0),
        ];
        assert!(matches!(
            resect_four_coplanar(12.0, &obj, &img),
            Err(GeometryError::Degenerate(_))
        ));
    }

    #[test]
    fn dlt_recovers_a_pose_from_non_coplanar_points() {
        let c = 12.0;
        let truth = oblique_view();
        let obj = [
            Vector3::new(-200.0, -150.0, 0.0),
            Vector3::new(210.0, -140.0, 50.0),
            Vector3::new(190.0, 160.0, -30.0),
            Vector3::new(-220.0, 150.0, 80.0),
            Vector3::new(0.0, 10.0, 120.0),
            Vector3::new(50.0, -60.0, -70.0),
        ];
        let img = obj.map(|p| project(&truth, c, &p));
        let e = dlt(c, &obj, &img).unwrap();
        assert!(
            (e.center - truth.center).norm() < 1e-6,
            "{}",
            (e.center - truth.center).norm()
        );
        assert!(angle_between(&e.rotation, &truth.rotation) < 1e-9);
    }

    #[test]
    fn dlt_rejects_coplanar_points() {
        let c = 12.0;
        let truth = oblique_view();
        let obj = [
            Vector3::new(-200.0, -150.0, 0.0),
            Vector3::new(210.0, -140.0, 0.0),
            Vector3::new(190.0, 160.0, 0.0),
            Vector3::new(-220.0, 150.0, 0.0),
            Vector3::new(0.0, 10.0, 0.0),
            Vector3::new(50.0, -60.0, 0.0),
        ];
        let img = obj.map(|p| project(&truth, c, &p));
        assert!(dlt(c, &obj, &img).is_err());
    }
}
