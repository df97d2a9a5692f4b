//! The camera model of `docs/conventions.md`: sensor, interior orientation and the
//! Brown/Fraser correction of measured image coordinates, with its inverse.
//!
//! Measured (distorted) image coordinates `(x', y')` are corrected into ideal
//! coordinates `(x_corr, y_corr)` that obey the collinearity equations; the
//! inverse, used to project object points into the image, is solved by
//! Newton's method on the correction.

use crate::error::GeometryError;
use nalgebra::{Matrix2, Vector2};
use wide::{f64x2, CmpEq};

/// The image sensor: size in pixels and pixel pitch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensor {
    /// Width in pixels (columns).
    pub width: u32,
    /// Height in pixels (rows).
    pub height: u32,
    /// Pixel pitch in mm (square pixels).
    pub pixel_size: f64,
}

/// Interior orientation: principal distance and principal point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interior {
    /// Principal distance `c`, mm.
    pub c: f64,
    /// Principal point offset from the image centre, mm (`x'` right).
    pub x0: f64,
    /// Principal point offset from the image centre, mm (`y'` up).
    pub y0: f64,
}

/// Brown/Fraser additional parameters, applied to measured coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Distortion {
    /// Radial, `r^2` term.
    pub k1: f64,
    /// Radial, `r^4` term.
    pub k2: f64,
    /// Radial, `r^6` term.
    pub k3: f64,
    /// Decentring.
    pub p1: f64,
    /// Decentring.
    pub p2: f64,
    /// Affinity (scale difference).
    pub b1: f64,
    /// Shear.
    pub b2: f64,
}

/// Where [`Camera::distort_seeded`] found the inverse of the correction
/// for a point: the start for a point nearby (a target's next frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DistortSeed {
    /// The ideal coordinates inverted, mm.
    ideal: Vector2<f64>,
    /// Their inverse, principal point not added, mm.
    point: Vector2<f64>,
    /// The inverse Jacobian of the correction near it.
    j_inv: Matrix2<f64>,
}

/// A calibrated camera: sensor, interior orientation and distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// The sensor.
    pub sensor: Sensor,
    /// Interior orientation.
    pub interior: Interior,
    /// Additional parameters.
    pub distortion: Distortion,
}

/// Iterations allowed when inverting the correction.
const INVERSE_MAX_ITER: usize = 20;
/// Convergence of the inverse correction, mm.
const INVERSE_TOL: f64 = 1e-12;
/// Steps allowed in [`Camera::distort_seeded`] before it falls back.
const CHORD_MAX_ITER: usize = 8;
/// Square of the distance, mm, up to which [`Camera::distort_seeded`]
/// starts from its seed (0.1 mm: 15 px; a tracked target moves a
/// fraction of a pixel per frame).
const SEED_REACH_SQ: f64 = 1e-2;
/// Square of the error, mm, at which [`Camera::distort_seeded`] stops.
const CHORD_TOL_SQ: f64 = 1e-28;

/// Whether both coordinates are finite, as `is_finite` of each says it, in
/// fewer instructions: `0 · x` is zero for a finite `x` and NaN for an
/// infinity or NaN.
#[inline(always)]
fn finite(p: Vector2<f64>) -> bool {
    let zero = f64x2::ZERO;
    (f64x2::new([p.x, p.y]) * zero).cmp_eq(zero).move_mask() == 3
}

impl Distortion {
    /// Whether all parameters are zero (an ideal lens).
    #[inline]
    pub fn is_zero(&self) -> bool {
        *self == Distortion::default()
    }

    /// The correction `(dx, dy)` at principal-point-reduced coordinates `(x, y)`.
    #[inline]
    pub fn correction(&self, x: f64, y: f64) -> Vector2<f64> {
        let r2 = x * x + y * y;
        let radial = r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let dx = x * radial
            + (2.0 * x * x + r2) * self.p1
            + 2.0 * self.p2 * x * y
            + self.b1 * x
            + self.b2 * y;
        let dy = y * radial + 2.0 * self.p1 * x * y + (2.0 * y * y + r2) * self.p2;
        Vector2::new(dx, dy)
    }

    /// Jacobian of `(x + dx, y + dy)` with respect to `(x, y)`.
    #[inline]
    pub fn corrected_jacobian(&self, x: f64, y: f64) -> Matrix2<f64> {
        let r2 = x * x + y * y;
        let f = r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let fp = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3);
        let dxdx = f + 2.0 * x * x * fp + 6.0 * x * self.p1 + 2.0 * self.p2 * y + self.b1;
        let dxdy = 2.0 * x * y * fp + 2.0 * y * self.p1 + 2.0 * self.p2 * x + self.b2;
        let dydx = 2.0 * x * y * fp + 2.0 * self.p1 * y + 2.0 * x * self.p2;
        let dydy = f + 2.0 * y * y * fp + 2.0 * self.p1 * x + 6.0 * y * self.p2;
        Matrix2::new(1.0 + dxdx, dxdy, dydx, 1.0 + dydy)
    }
}

impl Camera {
    /// The reference camera: a 1300 × 1030 px sensor of 6.7 µm pixels
    /// behind a 12 mm lens, with the principal point and distortion of the
    /// shipped `config/camera.toml` (the camera of the examples, benchmarks
    /// and tests).
    pub fn reference() -> Camera {
        Camera {
            distortion: Distortion {
                k1: -1.2e-4,
                k2: 3.0e-7,
                p1: 5.0e-6,
                p2: -3.0e-6,
                ..Distortion::default()
            },
            interior: Interior {
                c: 12.0,
                x0: 0.021,
                y0: -0.014,
            },
            ..Camera::reference_ideal()
        }
    }

    /// The reference camera's sensor and lens, ideal: the principal point
    /// in the image centre, no distortion.
    pub fn reference_ideal() -> Camera {
        Camera {
            sensor: Sensor {
                width: 1300,
                height: 1030,
                pixel_size: 0.0067,
            },
            interior: Interior {
                c: 12.0,
                x0: 0.0,
                y0: 0.0,
            },
            distortion: Distortion::default(),
        }
    }

    /// Builds a camera, checking every parameter (the key names are those of
    /// the camera file).
    pub fn new(
        sensor: Sensor,
        interior: Interior,
        distortion: Distortion,
    ) -> Result<Self, GeometryError> {
        let bad = |key, value: f64, why| Err(GeometryError::InvalidCamera { key, value, why });
        if sensor.width < 2 || sensor.width > 65_536 {
            return bad(
                "sensor.width",
                sensor.width as f64,
                "must be 2..=65536 pixels",
            );
        }
        if sensor.height < 2 || sensor.height > 65_536 {
            return bad(
                "sensor.height",
                sensor.height as f64,
                "must be 2..=65536 pixels",
            );
        }
        if !(sensor.pixel_size.is_finite() && sensor.pixel_size > 0.0 && sensor.pixel_size < 1.0) {
            return bad(
                "sensor.pixel_size",
                sensor.pixel_size,
                "must be a positive size in mm below 1",
            );
        }
        if !(interior.c.is_finite() && interior.c > 0.0) {
            return bad("interior.c", interior.c, "must be a positive length in mm");
        }
        let half_w = sensor.width as f64 * sensor.pixel_size / 2.0;
        let half_h = sensor.height as f64 * sensor.pixel_size / 2.0;
        if !(interior.x0.is_finite() && interior.x0.abs() < half_w) {
            return bad("interior.x0", interior.x0, "must lie on the sensor");
        }
        if !(interior.y0.is_finite() && interior.y0.abs() < half_h) {
            return bad("interior.y0", interior.y0, "must lie on the sensor");
        }
        let d = &distortion;
        for (key, v) in [
            ("distortion.k1", d.k1),
            ("distortion.k2", d.k2),
            ("distortion.k3", d.k3),
            ("distortion.p1", d.p1),
            ("distortion.p2", d.p2),
            ("distortion.b1", d.b1),
            ("distortion.b2", d.b2),
        ] {
            if !v.is_finite() {
                return bad(key, v, "must be a finite number");
            }
        }
        Ok(Camera {
            sensor,
            interior,
            distortion,
        })
    }

    /// Principal distance, mm.
    #[inline]
    pub fn c(&self) -> f64 {
        self.interior.c
    }

    /// Pixel `(col, row)` to measured image coordinates `(x', y')` in mm.
    #[inline]
    pub fn pixel_to_image(&self, col: f64, row: f64) -> Vector2<f64> {
        let s = &self.sensor;
        Vector2::new(
            (col - (s.width as f64 - 1.0) / 2.0) * s.pixel_size,
            ((s.height as f64 - 1.0) / 2.0 - row) * s.pixel_size,
        )
    }

    /// Measured image coordinates `(x', y')` in mm to pixel `(col, row)`.
    #[inline]
    pub fn image_to_pixel(&self, image: Vector2<f64>) -> Vector2<f64> {
        let s = &self.sensor;
        Vector2::new(
            image.x / s.pixel_size + (s.width as f64 - 1.0) / 2.0,
            (s.height as f64 - 1.0) / 2.0 - image.y / s.pixel_size,
        )
    }

    /// Corrects measured image coordinates `(x', y')` into ideal coordinates
    /// `(x_corr, y_corr)` (principal point removed, distortion applied).
    #[inline]
    pub fn correct(&self, measured: Vector2<f64>) -> Vector2<f64> {
        let x = measured.x - self.interior.x0;
        let y = measured.y - self.interior.y0;
        Vector2::new(x, y) + self.distortion.correction(x, y)
    }

    /// Corrects a pixel position straight into ideal image coordinates.
    #[inline]
    pub fn correct_pixel(&self, col: f64, row: f64) -> Vector2<f64> {
        self.correct(self.pixel_to_image(col, row))
    }

    /// The inverse of [`Camera::correct`]: the measured coordinates `(x', y')`
    /// whose correction gives `ideal`. Newton's method on the correction;
    /// returns `None` if it does not settle (a point far outside the field of
    /// view of a strongly distorted lens).
    pub fn distort(&self, ideal: Vector2<f64>) -> Option<Vector2<f64>> {
        if self.distortion.is_zero() {
            return Some(ideal + Vector2::new(self.interior.x0, self.interior.y0));
        }
        let mut p = ideal;
        for _ in 0..INVERSE_MAX_ITER {
            let f = p + self.distortion.correction(p.x, p.y) - ideal;
            let j = self.distortion.corrected_jacobian(p.x, p.y);
            let step = j.try_inverse()? * f;
            p -= step;
            if !(p.x.is_finite() && p.y.is_finite()) {
                return None;
            }
            if step.norm() < INVERSE_TOL {
                return Some(p + Vector2::new(self.interior.x0, self.interior.y0));
            }
        }
        let f = p + self.distortion.correction(p.x, p.y) - ideal;
        (f.norm() < 1e-9).then(|| p + Vector2::new(self.interior.x0, self.interior.y0))
    }

    /// [`Camera::distort`] in fewer operations, for predictions that place
    /// windows and gates (tracking): the chord method — Newton's method
    /// with one Jacobian kept — from `seed`, the inverse found for a point
    /// nearby (a target's in the previous frame), moved by its inverse
    /// Jacobian; without a seed, from the first-order inverse
    /// `ideal − correction(ideal)` and its Jacobian. It stops once the
    /// error left after a step, estimated as `|step|² / |previous step|`
    /// (the steps shrink geometrically), is below 1e-14 mm, and leaves the
    /// seed for the next call (its Jacobian renewed when the steps shrank
    /// slowly). On the reference lens two cheap steps instead of three full
    /// Newton steps, within 1e-12 px of [`Camera::distort`] (tracking:
    /// 5.01 M → 3.49 M instructions per 50 frames without seeds, → 2.44 M with
    /// them). Falls back to [`Camera::distort`] (and forgets the seed) when
    /// the chord does not settle.
    // Inline (and `is_zero` with it): called per projected target from
    // another crate (tracking: 0.18 M of 2.44 M instructions).
    #[inline]
    pub fn distort_seeded(
        &self,
        ideal: Vector2<f64>,
        seed: &mut Option<DistortSeed>,
    ) -> Option<Vector2<f64>> {
        let d = &self.distortion;
        if d.is_zero() {
            return self.distort(ideal);
        }
        let start = match seed {
            Some(s) if (ideal - s.ideal).norm_squared() < SEED_REACH_SQ => {
                Some((s.point + s.j_inv * (ideal - s.ideal), s.j_inv))
            }
            _ => {
                let p = ideal - d.correction(ideal.x, ideal.y);
                d.corrected_jacobian(p.x, p.y).try_inverse().map(|j| (p, j))
            }
        };
        if let Some((mut p, j_inv)) = start {
            let mut previous = 0.0;
            for n in 0..CHORD_MAX_ITER {
                let step = j_inv * (p + d.correction(p.x, p.y) - ideal);
                p -= step;
                // Squared lengths: |s|² / |s_prev| < 1e-14 mm ⇔
                // |s|⁴ < 1e-28 mm² · |s_prev|² (no square root).
                let s2 = step.norm_squared();
                if s2 * s2 < CHORD_TOL_SQ * previous || s2 < CHORD_TOL_SQ {
                    if !finite(p) {
                        break;
                    }
                    let j_inv = if n < 2 {
                        j_inv
                    } else {
                        d.corrected_jacobian(p.x, p.y)
                            .try_inverse()
                            .unwrap_or(j_inv)
                    };
                    *seed = Some(DistortSeed {
                        ideal,
                        point: p,
                        j_inv,
                    });
                    return Some(p + Vector2::new(self.interior.x0, self.interior.y0));
                }
                previous = s2;
            }
        }
        *seed = None;
        self.distort(ideal)
    }

    /// Projects a point given in camera coordinates (camera frame of
    /// `docs/conventions.md`: `z` backwards) into measured image coordinates. `None` if the
    /// point is not in front of the camera.
    #[inline]
    pub fn project_camera_point(&self, p: &nalgebra::Vector3<f64>) -> Option<Vector2<f64>> {
        if p.z >= 0.0 {
            return None;
        }
        let c = self.interior.c;
        self.distort(Vector2::new(-c * p.x / p.z, -c * p.y / p.z))
    }

    /// Whether a pixel position lies on the sensor, `margin` pixels inside its edge.
    #[inline]
    pub fn contains_pixel(&self, px: Vector2<f64>, margin: f64) -> bool {
        px.x >= -0.5 + margin
            && px.y >= -0.5 + margin
            && px.x <= self.sensor.width as f64 - 0.5 - margin
            && px.y <= self.sensor.height as f64 - 0.5 - margin
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn strong_lens() -> Camera {
        Camera::new(
            Sensor {
                width: 1300,
                height: 1030,
                pixel_size: 0.0067,
            },
            Interior {
                c: 12.0,
                x0: 0.05,
                y0: -0.03,
            },
            Distortion {
                k1: -2.5e-3,
                k2: 2.0e-5,
                k3: -1.0e-7,
                p1: 3.0e-5,
                p2: -2.0e-5,
                b1: 1.0e-4,
                b2: -5.0e-5,
            },
        )
        .unwrap()
    }

    #[test]
    fn pixel_image_round_trip_and_centre() {
        let cam = strong_lens();
        let centre = cam.pixel_to_image(649.5, 514.5);
        assert!(centre.norm() < 1e-15);
        let tl = cam.pixel_to_image(0.0, 0.0);
        assert!(tl.x < 0.0 && tl.y > 0.0, "top-left pixel is left and up");
        let back = cam.image_to_pixel(cam.pixel_to_image(12.25, 1000.75));
        assert!((back - Vector2::new(12.25, 1000.75)).norm() < 1e-9);
    }

    #[test]
    fn projection_then_correction_round_trips_over_the_whole_sensor() {
        let cam = strong_lens();
        // Check that the lens really is strong: tens of pixels at the corner.
        let corner = cam.pixel_to_image(0.0, 0.0);
        let d = cam.correct(corner) - (corner - Vector2::new(0.05, -0.03));
        assert!(
            d.norm() / 0.0067 > 20.0,
            "distortion at corner {} px",
            d.norm() / 0.0067
        );
        let mut worst: f64 = 0.0;
        for row in (0..=1030).step_by(10) {
            for col in (0..=1300).step_by(10) {
                let measured = cam.pixel_to_image(col as f64 - 0.5, row as f64 - 0.5);
                let ideal = cam.correct(measured);
                let again = cam.distort(ideal).expect("inverse converges");
                worst = worst.max((again - measured).norm());
                let ideal_again = cam.correct(again);
                worst = worst.max((ideal_again - ideal).norm());
            }
        }
        assert!(worst < 1e-9, "worst round-trip error {worst} mm");
    }

    #[test]
    fn fast_inverse_agrees_with_newton() {
        for cam in [
            Camera::reference(),
            strong_lens(),
            Camera::reference_ideal(),
        ] {
            let mut worst: f64 = 0.0;
            for row in (-20..=1050).step_by(5) {
                for col in (-20..=1320).step_by(5) {
                    let measured = cam.pixel_to_image(col as f64 + 0.3, row as f64 - 0.1);
                    let ideal = cam.correct(measured);
                    let want = cam.distort(ideal).expect("Newton converges");
                    let got = cam
                        .distort_seeded(ideal, &mut None)
                        .expect("chord converges");
                    worst = worst.max((got - want).norm() / cam.sensor.pixel_size);
                }
            }
            assert!(worst < 1e-11, "worst difference {worst:e} px");
        }
        // Far outside the field of view of the strong lens neither settles.
        let cam = strong_lens();
        let far = Vector2::new(40.0, 30.0);
        assert_eq!(cam.distort_seeded(far, &mut None), cam.distort(far));
    }

    #[test]
    fn seeded_inverse_agrees_with_newton_along_a_path_and_after_jumps() {
        for cam in [Camera::reference(), strong_lens()] {
            let mut seed = None;
            let mut worst: f64 = 0.0;
            // A point moving 0.3 px per call along a line, then jumps
            // across the sensor.
            let path = (0..400).map(|k| (20.0 + 3.1 * k as f64 * 0.1, 15.0 + 2.4 * k as f64 * 0.1));
            let jumps = [
                (1280.0, 1010.0),
                (5.0, 1000.0),
                (650.0, 515.0),
                (1299.0, 2.0),
            ];
            for (col, row) in path.chain(jumps) {
                let ideal = cam.correct(cam.pixel_to_image(col, row));
                let want = cam.distort(ideal).expect("Newton converges");
                let got = cam
                    .distort_seeded(ideal, &mut seed)
                    .expect("chord converges");
                assert!(seed.is_some());
                worst = worst.max((got - want).norm() / cam.sensor.pixel_size);
            }
            assert!(worst < 1e-11, "worst difference {worst:e} px");
        }
        // Far outside the field of view of the strong lens: the seed goes.
        let cam = strong_lens();
        let mut seed = None;
        let ok = cam.correct(cam.pixel_to_image(600.0, 500.0));
        cam.distort_seeded(ok, &mut seed);
        let far = Vector2::new(40.0, 30.0);
        assert_eq!(cam.distort_seeded(far, &mut seed), cam.distort(far));
        assert_eq!(seed, None);
    }

    #[test]
    fn finite_is_is_finite_of_both() {
        let values = [
            0.0,
            -0.0,
            1.5,
            -1e308,
            f64::MAX,
            f64::MIN_POSITIVE / 4.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        for &x in &values {
            for &y in &values {
                let want = x.is_finite() && y.is_finite();
                assert_eq!(finite(Vector2::new(x, y)), want, "{x} {y}");
            }
        }
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let d = strong_lens().distortion;
        let (x, y) = (3.1, -2.4);
        let j = d.corrected_jacobian(x, y);
        let h = 1e-6;
        let f = |x: f64, y: f64| Vector2::new(x, y) + d.correction(x, y);
        let cx = (f(x + h, y) - f(x - h, y)) / (2.0 * h);
        let cy = (f(x, y + h) - f(x, y - h)) / (2.0 * h);
        assert!((j.column(0) - cx).norm() < 1e-8);
        assert!((j.column(1) - cy).norm() < 1e-8);
    }

    #[test]
    fn the_reference_cameras_are_valid() {
        for cam in [Camera::reference(), Camera::reference_ideal()] {
            assert_eq!(
                Camera::new(cam.sensor, cam.interior, cam.distortion).unwrap(),
                cam
            );
        }
        assert!(Camera::reference_ideal().distortion.is_zero());
        assert!(!Camera::reference().distortion.is_zero());
    }

    #[test]
    fn invalid_parameters_are_named() {
        let s = Sensor {
            width: 1300,
            height: 1030,
            pixel_size: -0.0067,
        };
        let e = Camera::new(
            s,
            Interior {
                c: 12.0,
                x0: 0.0,
                y0: 0.0,
            },
            Distortion::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("sensor.pixel_size"), "{e}");
    }
}
