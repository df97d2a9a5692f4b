//! The circular test of a sequence of poses (in time order): plane and
//! least-squares circle of the positions, per-sample phase angle, radial and
//! out-of-plane deviation, orientation deviation from the mean orientation,
//! and the summary figures of ISO 230-4 by their names: the circular
//! deviation `G` (radial range of the path about the least-squares circle's
//! centre) always, the radial deviation `F` (max and min of the path's
//! deviation from the nominal circle) only when the nominal circle is given.
//! One analysis is one run in one direction, so the circular hysteresis `H`
//! (between a clockwise and a counter-clockwise run) is not among them.

use crate::error::CircleError;
use crate::fit::{Circle, Plane};
use crate::harmonics::{Series, Term};
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use serde::Serialize;
use std::f64::consts::{PI, TAU};

/// Options of the analysis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnalysisOptions {
    /// Highest order (undulations per revolution) kept by the harmonic
    /// filter of the profiles; 0 disables the filter.
    pub harmonics: u32,
    /// The nominal circle the robot was programmed to follow; with it the
    /// radial deviation `F` is reported.
    pub nominal: Option<NominalCircle>,
}

impl Default for AnalysisOptions {
    fn default() -> Self {
        AnalysisOptions {
            harmonics: 15,
            nominal: None,
        }
    }
}

/// The nominal (programmed) circle of a test, in the frame of the poses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NominalCircle {
    /// Centre, mm.
    pub center_mm: [f64; 3],
    /// Radius, mm.
    pub radius_mm: f64,
}

/// ISO 230-4's radial deviation `F`: the deviation of the path from the
/// nominal circle, positive away from its centre; its largest and smallest
/// value over the samples, µm.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RadialDeviation {
    /// Largest radial deviation (`F max`), µm.
    pub max: f64,
    /// Smallest radial deviation (`F min`, negative inside the nominal circle), µm.
    pub min: f64,
}

/// Direction of travel seen from the plane normal's tip.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Counter-clockwise (phase angle increasing).
    Ccw,
    /// Clockwise (phase angle decreasing).
    Cw,
}

/// A profile along the path: summary of the samples and of the filtered
/// series. Unit: that of the profile (named by the key that holds it).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Profile {
    /// Smallest sample value.
    pub min: f64,
    /// Largest sample value.
    pub max: f64,
    /// `max − min` of the samples.
    pub span: f64,
    /// Root mean square of the samples.
    pub rms: f64,
    /// The harmonic filter's result (`null` if disabled or if the samples
    /// do not cover the circle densely enough).
    pub filtered: Option<FilteredProfile>,
}

/// The harmonically filtered profile.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FilteredProfile {
    /// Minimum of the series over the circle (0.1° grid).
    pub min: f64,
    /// Maximum of the series over the circle.
    pub max: f64,
    /// `max − min`.
    pub span: f64,
    /// Mean (order 0) of the series.
    pub mean: f64,
    /// Terms `amplitude · cos(kθ − phase)`, `k = 1..=K`.
    pub harmonics: Vec<Term>,
    /// RMS of the samples about the series (noise and higher orders).
    pub residual_rms: f64,
}

/// One sample's deviations.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SampleDeviation {
    /// Index of the pose in the input.
    pub index: usize,
    /// Phase angle in the plane from the `u` axis, degrees in `[0, 360)`.
    pub phase_deg: f64,
    /// Distance from the circle's centre minus its radius, mm.
    pub radial_mm: f64,
    /// The filtered radial profile at this angle, mm.
    pub radial_filtered_mm: Option<f64>,
    /// Signed distance from the plane along its normal, mm.
    pub out_of_plane_mm: f64,
    /// Orientation deviation: the small rotation `ω` about the field's
    /// `X, Y, Z` axes with `M = exp([ω]ₓ) M_mean`, degrees.
    pub rotation_deg: [f64; 3],
    /// The filtered orientation profiles at this angle, degrees.
    pub rotation_filtered_deg: Option<[f64; 3]>,
    /// The same small rotation about the plane's axes `u`, `v`, `normal`,
    /// degrees.
    pub rotation_plane_deg: [f64; 3],
    /// The position, field frame, mm.
    pub position_mm: [f64; 3],
}

/// The least-squares plane as reported.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PlaneReport {
    /// Centroid of the positions, mm.
    pub point_mm: [f64; 3],
    /// Unit normal (towards the field's `+Z`).
    pub normal: [f64; 3],
    /// In-plane axis `u` (phase angle 0): the field's `X` projected.
    pub axis_u: [f64; 3],
    /// In-plane axis `v` (phase angle 90°), `normal × u`.
    pub axis_v: [f64; 3],
}

/// The result of a circular test.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CircleTest {
    /// Poses analysed.
    pub n_samples: usize,
    /// The least-squares plane.
    pub plane: PlaneReport,
    /// Centre of the least-squares circle, field frame, mm.
    pub center_mm: [f64; 3],
    /// Radius of the least-squares circle, mm.
    pub radius_mm: f64,
    /// A-posteriori standard deviations of the centre along `u`, `v`, mm.
    pub std_center_mm: [f64; 2],
    /// A-posteriori standard deviation of the radius, mm.
    pub std_radius_mm: f64,
    /// Gauss–Newton iterations of the circle fit.
    pub iterations: usize,
    /// Direction of travel seen from the normal's tip.
    pub direction: Direction,
    /// Net angle swept by the samples in time order, degrees.
    pub coverage_deg: f64,
    /// Highest harmonic order of the filter (0: no filter).
    pub harmonics_upr: u32,
    /// Circular deviation `G` (ISO 230-4): the radial separation of the two
    /// circles about the least-squares circle's centre that enclose the
    /// samples (max − min radial deviation from the least-squares circle), µm.
    pub g_um: f64,
    /// `G` of the harmonic-filtered radial profile, µm.
    pub g_filtered_um: Option<f64>,
    /// The nominal circle, when given.
    pub nominal: Option<NominalCircle>,
    /// Radial deviation `F` (ISO 230-4) from the nominal circle, measured
    /// in the least-squares plane from the nominal centre projected into
    /// it; only with a nominal circle.
    pub f_um: Option<RadialDeviation>,
    /// Radial deviations, mm.
    pub radial_mm: Profile,
    /// Out-of-plane deviations, mm.
    pub out_of_plane_mm: Profile,
    /// Mean orientation as KUKA `A, B, C`, degrees.
    pub mean_orientation_abc_deg: [f64; 3],
    /// Orientation deviations about the field's `X` axis, degrees.
    pub rotation_x_deg: Profile,
    /// About `Y`, degrees.
    pub rotation_y_deg: Profile,
    /// About `Z`, degrees.
    pub rotation_z_deg: Profile,
    /// Largest rotation angle of a sample from the mean orientation, degrees.
    pub rotation_max_angle_deg: f64,
    /// Every sample, in input order.
    pub samples: Vec<SampleDeviation>,
}

impl CircleTest {
    /// The filtered series of the radial profile, if any (re-fitted from the
    /// samples, for plotting).
    pub fn radial_series(&self) -> Option<Series> {
        self.series(|s| s.radial_mm)
    }

    /// The filtered series of the orientation deviation about field axis
    /// `axis` (0, 1, 2), degrees.
    pub fn rotation_series(&self, axis: usize) -> Option<Series> {
        self.series(|s| s.rotation_deg[axis])
    }

    fn series(&self, value: impl Fn(&SampleDeviation) -> f64) -> Option<Series> {
        if self.harmonics_upr == 0 {
            return None;
        }
        let angles: Vec<f64> = self
            .samples
            .iter()
            .map(|s| s.phase_deg.to_radians())
            .collect();
        let values: Vec<f64> = self.samples.iter().map(value).collect();
        Series::fit(&angles, &values, self.harmonics_upr)
    }
}

/// The circular test of `poses` (time order) in the field frame.
pub fn analyse(
    poses: &[Isometry3<f64>],
    options: &AnalysisOptions,
) -> Result<CircleTest, CircleError> {
    if options.harmonics > 180 {
        return Err(CircleError::BadParameter {
            name: "harmonics",
            value: options.harmonics as f64,
            why: "at most 180 undulations per revolution",
        });
    }
    for (index, p) in poses.iter().enumerate() {
        if !p.translation.vector.iter().all(|x| x.is_finite()) {
            return Err(CircleError::NotFinite {
                index,
                what: "position",
            });
        }
        if !p.rotation.coords.iter().all(|x| x.is_finite()) {
            return Err(CircleError::NotFinite {
                index,
                what: "rotation",
            });
        }
    }
    if let Some(n) = &options.nominal {
        if let Some(&v) = n.center_mm.iter().find(|v| !v.is_finite()) {
            return Err(CircleError::BadParameter {
                name: "nominal centre",
                value: v,
                why: "must be finite (mm)",
            });
        }
        if !(n.radius_mm.is_finite() && n.radius_mm > 0.0) {
            return Err(CircleError::BadParameter {
                name: "nominal radius",
                value: n.radius_mm,
                why: "must be a positive length (mm)",
            });
        }
    }
    let positions: Vec<Vector3<f64>> = poses.iter().map(|p| p.translation.vector).collect();
    let plane = Plane::fit(&positions)?;
    let in_plane: Vec<_> = positions.iter().map(|p| plane.to_plane(p)).collect();
    let circle = Circle::fit(&in_plane)?;
    let f_um = options.nominal.map(|n| {
        let c = plane.to_plane(&Vector3::from(n.center_mm));
        let (mut max, mut min) = (f64::NEG_INFINITY, f64::INFINITY);
        for q in &in_plane {
            let f = (q - c).norm() - n.radius_mm;
            max = max.max(f);
            min = min.min(f);
        }
        RadialDeviation {
            max: max * 1e3,
            min: min * 1e3,
        }
    });

    let mut phases = Vec::with_capacity(poses.len());
    let mut radial = Vec::with_capacity(poses.len());
    let mut out_of_plane = Vec::with_capacity(poses.len());
    for (q, p) in in_plane.iter().zip(&positions) {
        let d = q - circle.center;
        phases.push(d.y.atan2(d.x).rem_euclid(TAU));
        radial.push(d.norm() - circle.radius);
        out_of_plane.push(plane.distance(p));
    }
    let swept: f64 = phases
        .windows(2)
        .map(|w| {
            let d = w[1] - w[0];
            if d > PI {
                d - TAU
            } else if d < -PI {
                d + TAU
            } else {
                d
            }
        })
        .sum();
    let direction = if swept >= 0.0 {
        Direction::Ccw
    } else {
        Direction::Cw
    };

    let rotations: Vec<UnitQuaternion<f64>> = poses.iter().map(|p| p.rotation).collect();
    let mean = mean_rotation(&rotations);
    let omegas: Vec<Vector3<f64>> = rotations
        .iter()
        .map(|r| log(&(r * mean.inverse())))
        .collect();
    let rotation_max_angle_deg = omegas
        .iter()
        .map(|w| w.norm().to_degrees())
        .fold(0.0, f64::max);
    let rot_axis = |k: usize| -> Vec<f64> { omegas.iter().map(|w| w[k].to_degrees()).collect() };
    let (rx, ry, rz) = (rot_axis(0), rot_axis(1), rot_axis(2));

    let order = options.harmonics;
    let (radial_mm, radial_series) = profile(&phases, &radial, order);
    let (out_of_plane_mm, _) = profile(&phases, &out_of_plane, order);
    let (rotation_x_deg, sx) = profile(&phases, &rx, order);
    let (rotation_y_deg, sy) = profile(&phases, &ry, order);
    let (rotation_z_deg, sz) = profile(&phases, &rz, order);

    let samples = (0..poses.len())
        .map(|i| {
            let t = phases[i];
            let rot_f = match (&sx, &sy, &sz) {
                (Some(a), Some(b), Some(c)) => Some([a.eval(t), b.eval(t), c.eval(t)]),
                _ => None,
            };
            SampleDeviation {
                index: i,
                phase_deg: t.to_degrees(),
                radial_mm: radial[i],
                radial_filtered_mm: radial_series.as_ref().map(|s| s.eval(t)),
                out_of_plane_mm: out_of_plane[i],
                rotation_deg: [rx[i], ry[i], rz[i]],
                rotation_filtered_deg: rot_f,
                rotation_plane_deg: [plane.u, plane.v, plane.normal]
                    .map(|a| a.dot(&omegas[i]).to_degrees()),
                position_mm: positions[i].into(),
            }
        })
        .collect();
    let center = plane.to_space(&circle.center);
    let m = mean.to_rotation_matrix().into_inner();
    Ok(CircleTest {
        n_samples: poses.len(),
        plane: PlaneReport {
            point_mm: plane.point.into(),
            normal: plane.normal.into(),
            axis_u: plane.u.into(),
            axis_v: plane.v.into(),
        },
        center_mm: center.into(),
        radius_mm: circle.radius,
        std_center_mm: [circle.std[0], circle.std[1]],
        std_radius_mm: circle.std[2],
        iterations: circle.iterations,
        direction,
        coverage_deg: swept.abs().to_degrees(),
        harmonics_upr: order,
        g_um: radial_mm.span * 1e3,
        g_filtered_um: radial_mm.filtered.as_ref().map(|f| f.span * 1e3),
        nominal: options.nominal,
        f_um,
        radial_mm,
        out_of_plane_mm,
        mean_orientation_abc_deg: photopose_geometry::rotation::kuka_abc_deg_from_matrix(&m),
        rotation_x_deg,
        rotation_y_deg,
        rotation_z_deg,
        rotation_max_angle_deg,
        samples,
    })
}

/// The summary of one profile and its filtered series.
fn profile(angles: &[f64], values: &[f64], order: u32) -> (Profile, Option<Series>) {
    let min = values.iter().copied().fold(f64::INFINITY, f64::min);
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let rms = (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt();
    let series = if order > 0 {
        Series::fit(angles, values, order)
    } else {
        None
    };
    let filtered = series.as_ref().map(|s| {
        let (lo, hi) = s.extremes();
        let residual = angles
            .iter()
            .zip(values)
            .map(|(&t, &y)| (y - s.eval(t)).powi(2))
            .sum::<f64>()
            / values.len() as f64;
        FilteredProfile {
            min: lo,
            max: hi,
            span: hi - lo,
            mean: s.mean,
            harmonics: s.terms(),
            residual_rms: residual.sqrt(),
        }
    });
    (
        Profile {
            min,
            max,
            span: max - min,
            rms,
            filtered,
        },
        series,
    )
}

/// The rotation vector (axis × angle, radians) of a unit quaternion,
/// accurate for tiny angles: `2 atan2(|v|, w) · v / |v|`.
pub fn log(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (w, v) = (q.w, q.imag());
    let (w, v) = if w < 0.0 { (-w, -v) } else { (w, v) };
    let s = v.norm();
    if s < 1e-300 {
        return Vector3::zeros();
    }
    v * (2.0 * s.atan2(w) / s)
}

/// The mean rotation (Karcher mean on SO(3), started at the chordal mean).
pub fn mean_rotation(rotations: &[UnitQuaternion<f64>]) -> UnitQuaternion<f64> {
    if rotations.is_empty() {
        return UnitQuaternion::identity();
    }
    let sum: nalgebra::Matrix3<f64> = rotations
        .iter()
        .map(|r| r.to_rotation_matrix().into_inner())
        .sum();
    let mut mean =
        photopose_geometry::rotation::unit_quaternion_from_matrix(&sum).unwrap_or(rotations[0]);
    for _ in 0..20 {
        let step: Vector3<f64> = rotations
            .iter()
            .map(|r| log(&(r * mean.inverse())))
            .sum::<Vector3<f64>>()
            / rotations.len() as f64;
        mean = UnitQuaternion::from_scaled_axis(step) * mean;
        if step.norm() < 1e-15 {
            break;
        }
    }
    mean
}

#[cfg(test)]
mod tests {
    use super::*;
    use photopose_geometry::pose::isometry_from_xyzabc as from_xyzabc;

    #[test]
    fn an_exact_circle_has_no_deviation() {
        let poses: Vec<_> = (0..720)
            .map(|i| {
                let t = (i as f64 * 0.5).to_radians();
                from_xyzabc([
                    10.0 + 149.9 * t.cos(),
                    -5.0 + 149.9 * t.sin(),
                    600.0,
                    0.0,
                    0.0,
                    180.0,
                ])
            })
            .collect();
        let r = analyse(&poses, &AnalysisOptions::default()).unwrap();
        assert!((r.radius_mm - 149.9).abs() < 1e-9);
        assert!((r.center_mm[0] - 10.0).abs() < 1e-9 && (r.center_mm[1] + 5.0).abs() < 1e-9);
        assert!((r.center_mm[2] - 600.0).abs() < 1e-9);
        assert!(r.g_um < 1e-6 && r.g_filtered_um.unwrap() < 1e-6);
        assert_eq!((r.nominal, r.f_um), (None, None));
        assert!(r.rotation_max_angle_deg < 1e-9);
        assert_eq!(r.direction, Direction::Ccw);
        assert!((r.coverage_deg - 359.5).abs() < 1e-6);
        assert!((r.samples[90].phase_deg - 45.0).abs() < 1e-9);
        assert_eq!(r.plane.normal, [0.0, 0.0, 1.0]);
    }

    /// A circle of radius 100.02 mm about (0.01, 0, 600) with a 10 µm
    /// two-lobe radial error: G is the 20 µm range about the least-squares
    /// centre whatever the nominal circle; F is measured from the nominal
    /// circle and follows its centre and radius.
    #[test]
    fn g_is_about_the_least_squares_centre_and_f_about_the_nominal_circle() {
        let poses: Vec<_> = (0..720)
            .map(|i| {
                let t = (i as f64 * 0.5).to_radians();
                let r = 100.02 + 0.010 * (2.0 * t).cos();
                from_xyzabc([0.01 + r * t.cos(), r * t.sin(), 600.0, 0.0, 0.0, 180.0])
            })
            .collect();
        let plain = analyse(&poses, &AnalysisOptions::default()).unwrap();
        assert!((plain.g_um - 20.0).abs() < 1e-3, "{}", plain.g_um);
        assert_eq!(plain.f_um, None);
        let nominal = NominalCircle {
            center_mm: [0.0, 0.0, 600.0],
            radius_mm: 100.0,
        };
        let options = AnalysisOptions {
            nominal: Some(nominal),
            ..AnalysisOptions::default()
        };
        let r = analyse(&poses, &options).unwrap();
        assert_eq!(r.g_um, plain.g_um);
        assert_eq!(r.nominal, Some(nominal));
        let f = r.f_um.unwrap();
        // F(θ) = 20 + 10 cos 2θ + 10 cos θ µm (radius, lobes, the 10 µm
        // centre offset along X): largest 40 µm at θ = 0, smallest
        // 8.75 µm at cos θ = −1/4.
        assert!((f.max - 40.0).abs() < 0.01, "{f:?}");
        assert!((f.min - 8.75).abs() < 0.01, "{f:?}");
        let bad = AnalysisOptions {
            nominal: Some(NominalCircle {
                radius_mm: -1.0,
                ..nominal
            }),
            ..AnalysisOptions::default()
        };
        let e = analyse(&poses, &bad).unwrap_err().to_string();
        assert!(e.contains("nominal radius") && e.contains("-1"), "{e}");
    }

    #[test]
    fn a_tilted_circle_reports_rotations_about_its_plane_axes() {
        // Plane tilted 30° about X; the pose turns about the plane normal by
        // 0.01° sin θ.
        let tilt = UnitQuaternion::from_scaled_axis(Vector3::x() * 30f64.to_radians());
        let normal = tilt * Vector3::z();
        let base = UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3);
        let poses: Vec<_> = (0..720)
            .map(|i| {
                let t = (i as f64 * 0.5).to_radians();
                let p = tilt * Vector3::new(100.0 * t.cos(), 100.0 * t.sin(), 0.0);
                let q = UnitQuaternion::from_scaled_axis(normal * (0.01f64.to_radians() * t.sin()))
                    * base;
                Isometry3::from_parts(p.into(), q)
            })
            .collect();
        let r = analyse(&poses, &AnalysisOptions::default()).unwrap();
        assert!((Vector3::from(r.plane.normal) - normal).norm() < 1e-9);
        for s in &r.samples {
            let t = s.phase_deg.to_radians();
            assert!(
                (s.rotation_plane_deg[2] - 0.01 * t.sin()).abs() < 1e-9,
                "{s:?}"
            );
            assert!(s.rotation_plane_deg[0].abs() < 1e-9 && s.rotation_plane_deg[1].abs() < 1e-9);
        }
        assert!((r.rotation_x_deg.span - 0.0).abs() < 1e-9);
    }

    #[test]
    fn the_mean_rotation_is_the_centre_of_symmetric_deviations() {
        let base = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0);
        let rs: Vec<_> = [1.0, -1.0]
            .iter()
            .flat_map(|s| {
                [Vector3::x(), Vector3::y(), Vector3::z()]
                    .map(|a| UnitQuaternion::from_scaled_axis(a * (0.01 * *s)) * base)
            })
            .collect();
        let m = mean_rotation(&rs);
        let d = log(&(m * base.inverse())).norm();
        assert!(
            (log(&UnitQuaternion::from_scaled_axis(Vector3::new(
                1e-9, -2e-9, 0.5
            ))) - Vector3::new(1e-9, -2e-9, 0.5))
            .norm()
                < 1e-15
        );
        assert!(d < 1e-7, "{d} {m}");
    }
}
