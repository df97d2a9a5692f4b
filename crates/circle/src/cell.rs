//! The simulated robot cell: a circular TCP path at constant feed and
//! orientation ([`CirclePath`]), a robot error model (an injected radial
//! deviation pattern and orientation wobble as harmonic functions of the
//! phase angle, plus seeded white jitter: [`RobotError`]), and the camera
//! mounted on the robot ([`CameraMount`]). [`Cell::samples`] gives, per
//! camera frame, the commanded and actual TCP pose and the actual camera
//! pose in the plate frame — the pose a renderer renders. [`measure`] adds
//! a pose measurement's noise (a 6×6 covariance, e.g. photopose's predicted
//! precision) for tests that skip the rendering.
//!
//! Defaults follow the reference paper's experiment: radius 149.9 mm, 10 mm/s
//! (one revolution ≈ 94 s), constant TCP orientation pointing down, camera
//! about 100 mm from the TCP looking down at the plate from ≈ 600 mm.

use crate::error::CircleError;
use nalgebra::{
    Isometry3, Matrix6, SymmetricEigen, Translation3, UnitQuaternion, Vector3, Vector6,
};
use photopose_geometry::pose::{exterior_from_camera_pose, isometry_from_xyzabc, perturbed};
use photopose_geometry::{rng::SplitMix64, Exterior};
use std::f64::consts::TAU;

/// The commanded path: a circle in a plane parallel to the plate (normal
/// `+Z`), at constant feed and constant TCP orientation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CirclePath {
    /// Centre of the TCP's circle, plate frame, mm.
    pub center_mm: [f64; 3],
    /// Radius, mm.
    pub radius_mm: f64,
    /// Feed (path speed), mm/s.
    pub feed_mm_s: f64,
    /// TCP orientation as KUKA `A, B, C`, degrees.
    pub orientation_abc_deg: [f64; 3],
    /// Phase angle of the start (from the plate's `+X`), degrees.
    pub start_deg: f64,
    /// Counter-clockwise seen from `+Z` (else clockwise).
    pub ccw: bool,
    /// Revolutions to travel.
    pub revolutions: f64,
    /// Camera frame rate, Hz (one sample per frame).
    pub rate_hz: f64,
}

impl Default for CirclePath {
    fn default() -> Self {
        CirclePath {
            // With the default mount the camera circles above the plate's
            // centre at 600 mm.
            center_mm: [-60.0, 0.0, 520.0],
            radius_mm: 149.9,
            feed_mm_s: 10.0,
            orientation_abc_deg: [0.0, 0.0, 180.0],
            start_deg: 0.0,
            ccw: true,
            revolutions: 1.0,
            rate_hz: 25.0,
        }
    }
}

impl CirclePath {
    /// Time for the whole path, s.
    pub fn duration_s(&self) -> f64 {
        TAU * self.radius_mm * self.revolutions / self.feed_mm_s
    }

    /// Number of camera samples on the path (`t = i / rate` for
    /// `t < duration`).
    pub fn n_samples(&self) -> usize {
        (self.duration_s() * self.rate_hz).ceil() as usize
    }

    /// Commanded phase angle at time `t`, radians.
    pub fn phase_at(&self, t: f64) -> f64 {
        let s = if self.ccw { 1.0 } else { -1.0 };
        self.start_deg.to_radians() + s * self.feed_mm_s * t / self.radius_mm
    }

    fn check(&self) -> Result<(), CircleError> {
        let positive = [
            ("radius_mm", self.radius_mm),
            ("feed_mm_s", self.feed_mm_s),
            ("revolutions", self.revolutions),
            ("rate_hz", self.rate_hz),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(CircleError::BadParameter {
                    name,
                    value,
                    why: "must be a positive number",
                });
            }
        }
        Ok(())
    }
}

/// One harmonic term `amplitude · cos(order · θ − phase)` of an error
/// pattern over the commanded phase angle `θ`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Harmonic {
    /// Undulations per revolution.
    pub order: u32,
    /// Amplitude (mm for radial terms, degrees for wobble terms).
    pub amplitude: f64,
    /// Phase, degrees.
    pub phase_deg: f64,
}

impl Harmonic {
    /// The term's value at `theta` (radians).
    pub fn at(&self, theta: f64) -> f64 {
        self.amplitude * (self.order as f64 * theta - self.phase_deg.to_radians()).cos()
    }
}

/// The robot's error along the path.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotError {
    /// Radial deviation of the TCP from the commanded circle, mm (orders
    /// ≥ 2: order 0 is a radius change and order 1 a centre shift, which the
    /// least-squares circle absorbs).
    pub radial_mm: Vec<Harmonic>,
    /// Orientation wobble: small rotation of the TCP about the plate's
    /// `X, Y, Z` axes (through the TCP), degrees; `M = exp([ω]ₓ) M_cmd`
    /// (orders ≥ 1: a constant offset is not a deviation along the path).
    pub wobble_deg: [Vec<Harmonic>; 3],
    /// Standard deviation of the robot's white position jitter per axis, mm.
    pub jitter_mm: f64,
    /// Standard deviation of its white orientation jitter per axis, degrees.
    pub jitter_deg: f64,
    /// Seed of the jitter.
    pub seed: u64,
}

impl Default for RobotError {
    /// A pattern of a size a real robot shows on such a circle: F ≈ 0.17 mm
    /// from orders 2, 3 and 4, a wobble of up to ≈ 0.014° about each axis,
    /// no jitter.
    fn default() -> Self {
        let h = |order, amplitude, phase_deg| Harmonic {
            order,
            amplitude,
            phase_deg,
        };
        RobotError {
            radial_mm: vec![h(2, 0.060, 30.0), h(3, 0.030, -50.0), h(4, 0.015, 10.0)],
            wobble_deg: [
                vec![h(1, 0.010, 0.0), h(2, 0.004, 40.0)],
                vec![h(1, 0.008, 90.0), h(3, 0.003, 0.0)],
                vec![h(2, 0.005, -20.0)],
            ],
            jitter_mm: 0.0,
            jitter_deg: 0.0,
            seed: 7,
        }
    }
}

/// Grid of the injected pattern's extremes (0.01° steps).
const DENSE_GRID: usize = 36_000;

impl RobotError {
    /// No error at all.
    pub fn none() -> Self {
        RobotError {
            radial_mm: Vec::new(),
            wobble_deg: [Vec::new(), Vec::new(), Vec::new()],
            jitter_mm: 0.0,
            jitter_deg: 0.0,
            seed: 0,
        }
    }

    /// Injected radial deviation at commanded phase `theta` (radians), mm.
    pub fn radial_at(&self, theta: f64) -> f64 {
        self.radial_mm.iter().map(|h| h.at(theta)).sum()
    }

    /// Injected wobble about the plate's axes at `theta`, degrees.
    pub fn wobble_at(&self, theta: f64) -> [f64; 3] {
        [0, 1, 2].map(|k| self.wobble_deg[k].iter().map(|h| h.at(theta)).sum())
    }

    /// `F` of the injected radial pattern: max − min of [`Self::radial_at`]
    /// over a uniform grid of 36 000 angles (0.01°). With orders ≥ 2 only,
    /// the pattern's own least-squares circle is the commanded one (to first
    /// order in the deviations), so this is the `F` a perfect measurement of
    /// the path gives (without jitter).
    pub fn radial_f_mm(&self) -> f64 {
        let (lo, hi) = (0..DENSE_GRID)
            .map(|i| self.radial_at(TAU * i as f64 / DENSE_GRID as f64))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| {
                (lo.min(y), hi.max(y))
            });
        hi - lo
    }

    fn check(&self) -> Result<(), CircleError> {
        let all = self
            .radial_mm
            .iter()
            .map(|h| (h, 2, "radial_mm order"))
            .chain(
                self.wobble_deg
                    .iter()
                    .flatten()
                    .map(|h| (h, 1, "wobble_deg order")),
            );
        for (h, min_order, name) in all {
            if h.order < min_order {
                return Err(CircleError::BadParameter {
                    name,
                    value: h.order as f64,
                    why: "radial orders start at 2, wobble orders at 1 (lower orders are absorbed by the fit)",
                });
            }
            if !(h.amplitude.is_finite() && h.phase_deg.is_finite()) {
                return Err(CircleError::BadParameter {
                    name: "harmonic amplitude or phase",
                    value: h.amplitude,
                    why: "must be finite",
                });
            }
        }
        for (name, value) in [
            ("jitter_mm", self.jitter_mm),
            ("jitter_deg", self.jitter_deg),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(CircleError::BadParameter {
                    name,
                    value,
                    why: "must be a number ≥ 0",
                });
            }
        }
        Ok(())
    }
}

/// How the camera sits on the robot: `X = T_tcp←camera`, the camera's pose
/// in the TCP frame (its axes those of `docs/conventions.md`: `z`
/// points backwards, away from the scene).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraMount {
    /// `T_tcp←camera`.
    pub camera_in_tcp: Isometry3<f64>,
}

impl CameraMount {
    /// The default mount as KUKA `X, Y, Z, A, B, C` in the TCP frame.
    pub const DEFAULT_XYZABC: [f64; 6] = [60.0, 0.0, -80.0, 0.0, 0.0, 180.0];
}

impl Default for CameraMount {
    /// 100 mm from the TCP (60 mm along the tool's `x`, 80 mm back up its
    /// `z`), looking along the tool's `z`: with the default TCP orientation
    /// (`C = 180°`, tool pointing down) the camera looks straight down.
    fn default() -> Self {
        CameraMount {
            camera_in_tcp: isometry_from_xyzabc(Self::DEFAULT_XYZABC),
        }
    }
}

/// One camera frame of the cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellSample {
    /// Time since the start of the path, s.
    pub time_s: f64,
    /// Commanded phase angle, radians (unwrapped).
    pub phase: f64,
    /// Commanded TCP pose in the plate frame.
    pub commanded_tcp: Isometry3<f64>,
    /// Actual TCP pose (commanded plus the robot's error).
    pub actual_tcp: Isometry3<f64>,
    /// Actual camera pose in the plate frame, `T_plate←camera`.
    pub camera: Isometry3<f64>,
}

impl CellSample {
    /// The camera's exterior orientation (what the renderer renders).
    pub fn exterior(&self) -> Exterior {
        exterior_from_camera_pose(&self.camera)
    }
}

/// The simulated cell.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Cell {
    /// The commanded path.
    pub path: CirclePath,
    /// The robot's error.
    pub error: RobotError,
    /// The camera on the robot.
    pub mount: CameraMount,
}

impl Cell {
    /// Every camera frame of the path, in time order. Deterministic: the
    /// jitter comes from `error.seed`.
    pub fn samples(&self) -> Result<Vec<CellSample>, CircleError> {
        self.path.check()?;
        self.error.check()?;
        let p = &self.path;
        let [a, b, c] = p.orientation_abc_deg;
        let m_cmd = isometry_from_xyzabc([0.0, 0.0, 0.0, a, b, c]).rotation;
        let centre = Vector3::from(p.center_mm);
        let mut rng = SplitMix64::new(self.error.seed);
        let n = p.n_samples();
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let t = i as f64 / p.rate_hz;
            let theta = p.phase_at(t);
            let dir = Vector3::new(theta.cos(), theta.sin(), 0.0);
            let commanded =
                Isometry3::from_parts(Translation3::from(centre + dir * p.radius_mm), m_cmd);
            let mut jitter = |s: f64| Vector3::new(rng.normal(), rng.normal(), rng.normal()) * s;
            let dp = jitter(self.error.jitter_mm);
            let dw = jitter(self.error.jitter_deg.to_radians());
            let w = Vector3::from(self.error.wobble_at(theta).map(f64::to_radians)) + dw;
            let actual = Isometry3::from_parts(
                Translation3::from(centre + dir * (p.radius_mm + self.error.radial_at(theta)) + dp),
                UnitQuaternion::from_scaled_axis(w) * m_cmd,
            );
            out.push(CellSample {
                time_s: t,
                phase: theta,
                commanded_tcp: commanded,
                actual_tcp: actual,
                camera: actual * self.mount.camera_in_tcp,
            });
        }
        Ok(out)
    }
}

/// A measured camera pose: `pose` disturbed by a draw from the covariance
/// `cov` of `(Xc, Yc, Zc, ωX, ωY, ωZ)` (mm², rad²) in the resection's
/// parameters — the centre moves by `(dXc, dYc, dZc)` and `R` of `docs/conventions.md`
/// becomes `R · exp([ω]ₓ)`, as in `photopose-geometry`'s covariance.
pub fn perturb(pose: &Isometry3<f64>, cov: &Matrix6<f64>, rng: &mut SplitMix64) -> Isometry3<f64> {
    let eig = SymmetricEigen::new(*cov);
    let z = Vector6::from_fn(|_, _| rng.normal());
    let d = eig.eigenvectors * Vector6::from_fn(|k, _| eig.eigenvalues[k].max(0.0).sqrt() * z[k]);
    let w = Vector3::new(d[3], d[4], d[5]);
    // M = Rᵀ, so R·exp([ω]) gives M' = exp(−[ω]) M.
    perturbed(pose, &Vector3::new(d[0], d[1], d[2]), &-w)
}

/// The camera poses of `samples` as a pose measurement would give them:
/// each disturbed ([`perturb`]) by the covariance `cov(sample)` returns.
pub fn measure(
    samples: &[CellSample],
    cov: impl Fn(&CellSample) -> Matrix6<f64>,
    seed: u64,
) -> Vec<Isometry3<f64>> {
    let mut rng = SplitMix64::new(seed);
    samples
        .iter()
        .map(|s| perturb(&s.camera, &cov(s), &mut rng))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_path_is_the_papers() {
        let p = CirclePath::default();
        assert!((p.duration_s() - 94.18).abs() < 0.01, "{}", p.duration_s());
        assert_eq!(p.n_samples(), 2355);
        let cell = Cell::default();
        let s = cell.samples().unwrap();
        assert_eq!(s.len(), 2355);
        // The camera circles above the plate's centre at ≈ 600 mm, looking down.
        let c = s[0].camera.translation.vector;
        assert!((c - Vector3::new(149.9, 0.0, 600.0)).norm() < 0.1, "{c}");
        let e = s[0].exterior();
        assert!((e.rotation.row(2).transpose() - Vector3::z()).norm() < 1e-3);
        // Commanded and actual differ by the injected radial error.
        let d = s[0].actual_tcp.translation.vector - s[0].commanded_tcp.translation.vector;
        assert!((d.x - cell.error.radial_at(0.0)).abs() < 1e-12 && d.y.abs() < 1e-12);
    }

    #[test]
    fn the_injected_f_is_the_span_of_the_pattern() {
        let e = RobotError {
            radial_mm: vec![Harmonic {
                order: 2,
                amplitude: 0.01,
                phase_deg: 0.0,
            }],
            ..RobotError::none()
        };
        assert!((e.radial_f_mm() - 0.02).abs() < 1e-12);
        let bad = RobotError {
            radial_mm: vec![Harmonic {
                order: 1,
                amplitude: 0.01,
                phase_deg: 0.0,
            }],
            ..RobotError::none()
        };
        let cell = Cell {
            error: bad,
            ..Cell::default()
        };
        assert!(matches!(
            cell.samples(),
            Err(CircleError::BadParameter {
                name: "radial_mm order",
                ..
            })
        ));
    }

    #[test]
    fn perturbation_follows_the_covariance() {
        let mut cov = Matrix6::zeros();
        cov[(0, 0)] = 0.01f64.powi(2);
        cov[(4, 4)] = 1e-5f64.powi(2);
        cov[(0, 4)] = 0.8 * 0.01 * 1e-5;
        cov[(4, 0)] = cov[(0, 4)];
        let pose = isometry_from_xyzabc([0.0, 0.0, 600.0, 0.0, 0.0, 0.0]);
        let mut rng = SplitMix64::new(3);
        let (mut sxx, mut sww, mut sxw) = (0.0, 0.0, 0.0);
        let n = 20_000;
        for _ in 0..n {
            let p = perturb(&pose, &cov, &mut rng);
            let dx = p.translation.vector.x;
            // R' = R exp([ω]) with R = I: ω = −(rotation of M').
            let w = -p.rotation.scaled_axis().y;
            sxx += dx * dx;
            sww += w * w;
            sxw += dx * w;
        }
        let n = n as f64;
        assert!(((sxx / n).sqrt() / 0.01 - 1.0).abs() < 0.03);
        assert!(((sww / n).sqrt() / 1e-5 - 1.0).abs() < 0.03);
        let corr = sxw / (sxx * sww).sqrt();
        assert!((corr - 0.8).abs() < 0.02, "{corr}");
    }
}
