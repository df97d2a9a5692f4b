//! Gathering stations live: from a stream of (robot pose, camera pose)
//! samples — the daemon's pose stream with `RIst` from the RSI server —
//! [`Gatherer`] takes a station each time the robot has stood still for a
//! while, and only after it has moved away from the previous station.
//! Pure: time comes with each sample.
//!
//! A station's robot pose is the newest `RIst` of the still phase (the
//! robot reports the same pose while it stands); its camera pose is the
//! mean of the phase's camera poses (centre averaged, rotation by the
//! normalised mean of sign-aligned quaternions); its standard deviations
//! are the mean of the per-frame ones, not divided by √n, because the
//! frames of one station share their systematic errors.

use crate::stations::{CameraSource, StationRow};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use photopose_geometry::pose::{isometry_from_xyzabc, xyzabc_from_isometry};

/// When the robot counts as standing, and as moved on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GatherSettings {
    /// How long the robot must stand still, s.
    pub still_s: f64,
    /// Largest change of the robot's position while still, mm.
    pub still_mm: f64,
    /// Largest change of the robot's orientation while still, degrees.
    pub still_deg: f64,
    /// Distance from the previous station that arms the next one, mm.
    pub move_mm: f64,
    /// Rotation from the previous station that arms the next one, degrees.
    pub move_deg: f64,
    /// Camera poses a station needs at least.
    pub min_poses: usize,
}

impl Default for GatherSettings {
    fn default() -> Self {
        GatherSettings {
            still_s: 1.0,
            still_mm: 0.01,
            still_deg: 0.002,
            move_mm: 5.0,
            move_deg: 2.0,
            min_poses: 5,
        }
    }
}

/// One sample of the stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// When the frame was taken, s (any monotonic origin).
    pub time_s: f64,
    /// The robot's TCP in its base (`RIst`), KUKA `X … C`, mm and degrees.
    pub robot_xyzabc: [f64; 6],
    /// The camera in the plate frame, `T_plate←camera`.
    pub camera: Isometry3<f64>,
    /// Standard deviations of the camera's centre (mm) and of its rotations
    /// about the plate's axes (degrees).
    pub camera_std: [f64; 6],
}

/// Takes stations from a stream of samples.
#[derive(Debug, Clone)]
pub struct Gatherer {
    settings: GatherSettings,
    window: Vec<Sample>,
    last_station: Option<[f64; 6]>,
    taken: usize,
    moved: Option<(f64, f64)>,
}

/// Why the gatherer is waiting, for a live display: how long the robot has
/// stood still so far, and (until it has moved far enough) how far it has
/// moved from the previous station.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GatherProgress {
    /// Time the robot has stood still in the current phase, s.
    pub still_s: f64,
    /// Translation (mm) and rotation (degrees) from the previous station
    /// while the next one is not armed yet; `None`: armed.
    pub moved: Option<(f64, f64)>,
    /// Stations taken so far.
    pub taken: usize,
}

/// Translation (mm) and rotation (degrees) between two KUKA poses.
fn distance(a: &[f64; 6], b: &[f64; 6]) -> (f64, f64) {
    let (ta, tb) = (isometry_from_xyzabc(*a), isometry_from_xyzabc(*b));
    let d = ta.inverse() * tb;
    (
        (Vector3::new(a[0], a[1], a[2]) - Vector3::new(b[0], b[1], b[2])).norm(),
        d.rotation.angle().to_degrees(),
    )
}

impl Gatherer {
    /// A gatherer; the first still phase gives the first station.
    pub fn new(settings: GatherSettings) -> Self {
        Gatherer {
            settings,
            window: Vec::new(),
            last_station: None,
            taken: 0,
            moved: None,
        }
    }

    /// The settings.
    pub fn settings(&self) -> &GatherSettings {
        &self.settings
    }

    /// Stations taken so far.
    pub fn taken(&self) -> usize {
        self.taken
    }

    /// Whether the robot has moved far enough from the previous station for
    /// the next still phase to count.
    pub fn armed(&self) -> bool {
        self.last_station.is_none()
    }

    /// Where the gatherer stands (see [`GatherProgress`]).
    pub fn progress(&self) -> GatherProgress {
        let still_s = match (self.window.first(), self.window.last()) {
            (Some(a), Some(b)) if self.last_station.is_none() => b.time_s - a.time_s,
            _ => 0.0,
        };
        GatherProgress {
            still_s,
            moved: self.last_station.map(|_| self.moved.unwrap_or((0.0, 0.0))),
            taken: self.taken,
        }
    }

    /// Feeds one sample; returns a station (named `live1`, `live2`, …) when
    /// a still phase completes.
    pub fn push(&mut self, s: Sample) -> Option<StationRow> {
        let g = self.settings;
        if let Some(last) = &self.last_station {
            let (mm, deg) = distance(last, &s.robot_xyzabc);
            self.moved = Some((mm, deg));
            if mm < g.move_mm && deg < g.move_deg {
                return None;
            }
            self.last_station = None;
            self.moved = None;
        }
        let moved = self.window.first().is_some_and(|first| {
            let (mm, deg) = distance(&first.robot_xyzabc, &s.robot_xyzabc);
            mm > g.still_mm || deg > g.still_deg
        });
        if moved || self.window.last().is_some_and(|l| s.time_s < l.time_s) {
            self.window.clear();
        }
        self.window.push(s);
        let span = s.time_s - self.window[0].time_s;
        if span < g.still_s || self.window.len() < g.min_poses {
            return None;
        }
        let station = self.station(&s);
        self.last_station = Some(s.robot_xyzabc);
        self.moved = Some((0.0, 0.0));
        self.window.clear();
        Some(station)
    }

    fn station(&mut self, newest: &Sample) -> StationRow {
        let n = self.window.len() as f64;
        let centre = self
            .window
            .iter()
            .fold(Vector3::zeros(), |acc, w| acc + w.camera.translation.vector)
            / n;
        let q0 = *self.window[0].camera.rotation.quaternion();
        let sum = self
            .window
            .iter()
            .fold(Quaternion::new(0.0, 0.0, 0.0, 0.0), |acc, w| {
                let q = *w.camera.rotation.quaternion();
                if q.dot(&q0) < 0.0 {
                    acc - q
                } else {
                    acc + q
                }
            });
        let rotation = UnitQuaternion::from_quaternion(sum);
        let mut std = [0.0; 6];
        for w in &self.window {
            for (s, v) in std.iter_mut().zip(w.camera_std) {
                *s += v / n;
            }
        }
        let xyzabc =
            xyzabc_from_isometry(&Isometry3::from_parts(Translation3::from(centre), rotation));
        self.taken += 1;
        StationRow {
            line: 0,
            name: format!("live{}", self.taken),
            robot_xyzabc: newest.robot_xyzabc,
            camera: CameraSource::Pose {
                xyzabc,
                std: Some(std),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t: f64, robot: [f64; 6], cam_x: f64) -> Sample {
        Sample {
            time_s: t,
            robot_xyzabc: robot,
            camera: isometry_from_xyzabc([cam_x, 20.0, 600.0, 10.0, 0.0, 180.0]),
            camera_std: [0.005, 0.005, 0.002, 0.001, 0.001, 0.0005],
        }
    }

    #[test]
    fn a_station_per_still_phase_and_none_before_the_robot_moves_on() {
        let mut g = Gatherer::new(GatherSettings::default());
        let p1 = [400.0, 0.0, 600.0, 0.0, 90.0, 0.0];
        let p2 = [420.0, 10.0, 600.0, 15.0, 80.0, 5.0];
        let mut t = 0.0;
        let mut stations = Vec::new();
        // Still at p1 for 2 s at 25 Hz (camera noise ±0.004 mm).
        for k in 0..50 {
            if let Some(s) = g.push(sample(t, p1, 100.0 + 0.004 * (k % 3) as f64)) {
                stations.push((t, s));
            }
            t += 0.04;
        }
        assert_eq!(stations.len(), 1, "one station for one still phase");
        assert!((stations[0].0 - 1.0).abs() < 0.05, "after 1 s still");
        assert!(!g.armed());
        // Moving to p2: samples along the way never make a station.
        for k in 1..25 {
            let f = k as f64 / 25.0;
            let p: [f64; 6] = std::array::from_fn(|i| p1[i] + f * (p2[i] - p1[i]));
            assert!(g.push(sample(t, p, 100.0)).is_none());
            t += 0.04;
        }
        // Still at p2.
        for _ in 0..30 {
            if let Some(s) = g.push(sample(t, p2, 130.0)) {
                stations.push((t, s));
            }
            t += 0.04;
        }
        assert_eq!(stations.len(), 2);
        let s = &stations[1].1;
        assert_eq!(s.name, "live2");
        assert_eq!(s.robot_xyzabc, p2);
        let CameraSource::Pose { xyzabc, std } = &s.camera else {
            panic!("pose columns expected")
        };
        let mean = isometry_from_xyzabc(*xyzabc);
        let want = sample(0.0, p2, 130.0).camera;
        assert!((mean.translation.vector - want.translation.vector).norm() < 1e-9);
        assert!(mean.rotation.angle_to(&want.rotation) < 1e-9);
        assert!((std.unwrap()[0] - 0.005).abs() < 1e-12);
        // The row writes as a line of the station file.
        assert!(s.csv_line().unwrap().starts_with("live2,420,"));
    }

    #[test]
    fn progress_says_how_long_still_and_how_far_moved() {
        let mut g = Gatherer::new(GatherSettings::default());
        let p1 = [400.0, 0.0, 600.0, 0.0, 90.0, 0.0];
        assert_eq!(g.progress().moved, None);
        for k in 0..10 {
            g.push(sample(0.04 * k as f64, p1, 100.0));
        }
        let p = g.progress();
        assert!((p.still_s - 0.36).abs() < 1e-9, "{p:?}");
        assert_eq!((p.moved, p.taken), (None, 0));
        let mut t = 0.4;
        while g.taken() == 0 {
            g.push(sample(t, p1, 100.0));
            t += 0.04;
        }
        assert_eq!(g.progress().moved, Some((0.0, 0.0)));
        let p2 = [403.0, 0.0, 600.0, 0.0, 90.0, 0.0];
        g.push(sample(t, p2, 100.0));
        let p = g.progress();
        let (mm, deg) = p.moved.unwrap();
        assert!((mm - 3.0).abs() < 1e-9 && deg.abs() < 1e-9, "{p:?}");
        assert_eq!((p.still_s, p.taken), (0.0, 1));
    }

    #[test]
    fn a_creeping_robot_never_counts_as_still() {
        let mut g = Gatherer::new(GatherSettings::default());
        for k in 0..200 {
            let t = k as f64 * 0.04;
            // 0.5 mm/s: 0.02 mm per frame, over the 0.01 mm stillness.
            let p = [400.0 + 0.5 * t, 0.0, 600.0, 0.0, 90.0, 0.0];
            assert!(g.push(sample(t, p, 100.0)).is_none(), "at {t} s");
        }
        assert_eq!(g.taken(), 0);
    }

    #[test]
    fn the_mean_rotation_is_taken_across_the_quaternion_sign() {
        let mut g = Gatherer::new(GatherSettings {
            min_poses: 2,
            ..GatherSettings::default()
        });
        let robot = [0.0; 6];
        let mut a = sample(0.0, robot, 0.0);
        let mut b = sample(1.0, robot, 0.0);
        let r = UnitQuaternion::from_euler_angles(0.1, -0.2, 3.0);
        a.camera.rotation = r;
        // The same rotation written with the opposite sign.
        b.camera.rotation = UnitQuaternion::new_unchecked(-*r.quaternion());
        assert!(g.push(a).is_none());
        let s = g.push(b).expect("a station");
        let CameraSource::Pose { xyzabc, .. } = s.camera else {
            panic!()
        };
        let back = isometry_from_xyzabc(xyzabc);
        assert!(back.rotation.angle_to(&r) < 1e-9);
    }
}
