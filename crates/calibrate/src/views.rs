//! A set of camera stations for calibration images of a plate: tilted
//! 0–40° towards it from all sides, rolled in steps of 90°, at varied
//! distances — the geometry that separates the principal distance from the
//! distances and the principal point from the rotations. For the robot
//! that takes the pictures, the renderer that simulates them, and tests.

use nalgebra::{Matrix3, Vector3};
use photopose_geometry::Exterior;

/// `n` stations looking at `centre` (a plate facing `+Z`) from distances in
/// `[near, far]` mm. Deterministic.
pub fn stations(n: usize, centre: Vector3<f64>, near: f64, far: f64) -> Vec<Exterior> {
    const TILTS_DEG: [f64; 4] = [8.0, 22.0, 32.0, 40.0];
    (0..n)
        .map(|k| {
            let tilt = TILTS_DEG[k % 4].to_radians();
            // Golden-angle azimuths spread the tilt directions evenly.
            let azimuth = (k as f64 * 137.507_764).to_radians();
            let roll = ((k / 2 % 4) as f64 * 90.0).to_radians();
            let share = if n > 1 {
                ((k * 7) % n) as f64 / (n - 1) as f64
            } else {
                0.5
            };
            let distance = near + (far - near) * share;
            let dir = Vector3::new(
                tilt.sin() * azimuth.cos(),
                tilt.sin() * azimuth.sin(),
                tilt.cos(),
            );
            let aim = centre + Vector3::new(20.0 * azimuth.sin(), -15.0 * azimuth.cos(), 0.0);
            let e = Exterior::look_at(aim + distance * dir, aim, Vector3::y())
                .expect("the view direction is never along +Y");
            let (s, c) = roll.sin_cos();
            let turn = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
            Exterior::new(turn * e.rotation, e.center)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stations_look_at_the_plate_from_varied_tilts_and_rolls() {
        let st = stations(20, Vector3::zeros(), 650.0, 950.0);
        assert_eq!(st.len(), 20);
        let mut tilts = Vec::new();
        for e in &st {
            assert!(photopose_geometry::rotation::is_rotation(
                &e.rotation,
                1e-12
            ));
            // The plate centre is in front of the camera.
            assert!(e.to_camera(&Vector3::zeros()).z < 0.0);
            let axis: Vector3<f64> = e.rotation.row(2).transpose();
            tilts.push(axis.z.acos().to_degrees());
            let d = e.center.norm();
            assert!((640.0..=960.0).contains(&d), "{d}");
        }
        let max = tilts.iter().cloned().fold(0.0, f64::max);
        assert!(max > 35.0 && tilts.iter().any(|&t| t < 10.0), "{tilts:?}");
    }
}
