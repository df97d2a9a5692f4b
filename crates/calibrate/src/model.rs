//! The observation equation of the self-calibrating bundle adjustment and
//! its analytic partials.
//!
//! The model of `docs/conventions.md` corrects *measured* coordinates: `x_corr = x' - x0 +
//! dx(x' - x0, y' - y0)` must equal the collinearity projection `-c Zx / N`.
//! The residual of one target in one image is therefore
//!
//! ```text
//! v = camera.correct(measured) - project_ideal(c, exterior, X)      (mm)
//! ```
//!
//! computed with [`photopose_geometry::Camera::correct`] and
//! [`photopose_geometry::Exterior::project_ideal`] themselves, and its
//! partials with respect to the ten camera parameters (`c, x0, y0, K1 K2 K3
//! P1 P2 b1 b2`), the six exterior increments (`Xc, Yc, Zc`, then the
//! re-based Cayley increments `a, b, c` of `R = R0 · cayley(a, b, c)`) and
//! the target's coordinates. The Cayley partial at zero increment is
//! `dZ/da_k = 2 (R0 e_k) × Z`, as in `photopose_geometry::linearised`.

use crate::params::N_PARAMS;
use nalgebra::{SMatrix, Vector2, Vector3};
use photopose_geometry::{Camera, Exterior};

/// Residual and partials of one observation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linearised {
    /// Residual `(vx, vy)`, mm.
    pub v: Vector2<f64>,
    /// `dv / d(camera parameters)`.
    pub camera: SMatrix<f64, 2, N_PARAMS>,
    /// `dv / d(Xc, Yc, Zc, a, b, c)`.
    pub exterior: SMatrix<f64, 2, 6>,
    /// `dv / d(X, Y, Z)` of the target.
    pub point: SMatrix<f64, 2, 3>,
}

/// The residual alone (`None` if the point is not in front of the camera).
pub fn residual(
    camera: &Camera,
    exterior: &Exterior,
    point: &Vector3<f64>,
    measured: &Vector2<f64>,
) -> Option<Vector2<f64>> {
    let p = exterior.project_ideal(camera.interior.c, point)?;
    Some(camera.correct(*measured) - p)
}

/// Residual and all partials (`None` if the point is not in front of the camera).
pub fn linearise(
    camera: &Camera,
    exterior: &Exterior,
    point: &Vector3<f64>,
    measured: &Vector2<f64>,
) -> Option<Linearised> {
    let c = camera.interior.c;
    let r = &exterior.rotation;
    let z = exterior.to_camera(point);
    if z.z >= 0.0 {
        return None;
    }
    let p = Vector2::new(-c * z.x / z.z, -c * z.y / z.z);
    let v = camera.correct(*measured) - p;
    // Camera parameters: the correction's partials minus the projection's.
    let x = measured.x - camera.interior.x0;
    let y = measured.y - camera.interior.y0;
    let r2 = x * x + y * y;
    let (r4, r6) = (r2 * r2, r2 * r2 * r2);
    let j = camera.distortion.corrected_jacobian(x, y);
    let cam = SMatrix::<f64, 2, N_PARAMS>::from_column_slice(&[
        -p.x / c,
        -p.y / c,
        -j[(0, 0)],
        -j[(1, 0)],
        -j[(0, 1)],
        -j[(1, 1)],
        x * r2,
        y * r2,
        x * r4,
        y * r4,
        x * r6,
        y * r6,
        2.0 * x * x + r2,
        2.0 * x * y,
        2.0 * x * y,
        2.0 * y * y + r2,
        x,
        0.0,
        y,
        0.0,
    ]);
    // dp = (-c / N) (dZxy - (Zxy / N) dN); dv = -dp.
    let f = c / z.z;
    let (gx, gy) = (z.x / z.z, z.y / z.z);
    let dv = |dz: Vector3<f64>| Vector2::new(f * (dz.x - gx * dz.z), f * (dz.y - gy * dz.z));
    let mut ext = SMatrix::<f64, 2, 6>::zeros();
    let mut pt = SMatrix::<f64, 2, 3>::zeros();
    for k in 0..3 {
        let col: Vector3<f64> = r.column(k).into();
        let d_point = dv(col);
        pt.set_column(k, &d_point);
        ext.set_column(k, &(-d_point));
        ext.set_column(3 + k, &dv(2.0 * col.cross(&z)));
    }
    Some(Linearised {
        v,
        camera: cam,
        exterior: ext,
        point: pt,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{values, with_values};
    use photopose_geometry::rotation::cayley;
    use photopose_geometry::Sensor;

    fn camera() -> Camera {
        crate::cases::strong_lens(Sensor {
            width: 1300,
            height: 1030,
            pixel_size: 0.0067,
        })
    }

    #[test]
    fn partials_match_central_differences() {
        let cam = camera();
        let e = Exterior::new(cayley(0.2, -0.15, 0.8), Vector3::new(10.0, -20.0, 900.0));
        let point = Vector3::new(120.0, 45.0, 3.0);
        let measured = Vector2::new(2.1, -1.7);
        let lin = linearise(&cam, &e, &point, &measured).unwrap();
        let base = values(&cam);
        for k in 0..N_PARAMS {
            // A step that moves the residual by about 1e-7 mm.
            let h = 1e-7 / lin.camera.column(k).norm().max(1e-3);
            let mut plus = base;
            plus[k] += h;
            let mut minus = base;
            minus[k] -= h;
            let vp = residual(&with_values(&cam, &plus), &e, &point, &measured).unwrap();
            let vm = residual(&with_values(&cam, &minus), &e, &point, &measured).unwrap();
            let fd = (vp - vm) / (2.0 * h);
            let an = lin.camera.column(k);
            assert!(
                (fd - an).norm() < 1e-6 * an.norm().max(1e-3),
                "param {k}: {fd} vs {an}"
            );
        }
        let h = 1e-6;
        for k in 0..6 {
            let step = |s: f64| {
                let mut d = [0.0; 6];
                d[k] = s;
                let ek = Exterior::new(
                    e.rotation * cayley(d[3], d[4], d[5]),
                    e.center + Vector3::new(d[0], d[1], d[2]),
                );
                residual(&cam, &ek, &point, &measured).unwrap()
            };
            let fd = (step(h) - step(-h)) / (2.0 * h);
            let an = lin.exterior.column(k);
            assert!((fd - an).norm() < 1e-6 * an.norm().max(1e-6), "ext {k}");
        }
        for k in 0..3 {
            let mut d = Vector3::zeros();
            d[k] = h;
            let fd = (residual(&cam, &e, &(point + d), &measured).unwrap()
                - residual(&cam, &e, &(point - d), &measured).unwrap())
                / (2.0 * h);
            let an = lin.point.column(k);
            assert!((fd - an).norm() < 1e-6 * an.norm().max(1e-6), "point {k}");
        }
    }

    #[test]
    fn behind_the_camera_is_none() {
        let cam = camera();
        let e = Exterior::new(cayley(0.0, 0.0, 0.0), Vector3::new(0.0, 0.0, -100.0));
        assert!(linearise(&cam, &e, &Vector3::zeros(), &Vector2::zeros()).is_none());
    }
}
