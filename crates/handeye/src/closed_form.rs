//! The closed-form start of the hand-eye calibration and the
//! degenerate-motion check.
//!
//! Every pair of stations `(i, j)` gives a relative motion of the flange,
//! `A' = A_j⁻¹ A_i`, and of the camera, `B' = B_j⁻¹ B_i`, with
//! `A' X = X B'` (Z cancels). Park & Martin (1994): the rotation vectors
//! satisfy `α = R_X β`, so `R_X` is the orthogonal Procrustes solution of
//! all pairs (SVD); then `(R_A' − I) t_X = R_X t_B' − t_A'` stacked over all
//! pairs is linear in `t_X`. `Z` follows from every station,
//! `Z_i = A_i X B_i⁻¹`: the nearest rotation to the sum of the `R_Z,i` and
//! the mean translation.
//!
//! `X` is determined only if the relative rotations turn about at least two
//! different axes: the axes of all pairs (those turning by at least
//! `min_rotation_deg`) are summed as `Σ u uᵀ`, whose two largest eigenvalues
//! `λ1 ≥ λ2` give the axis spread `2 atan √(λ2/λ1)` (for two axes at angle
//! `φ`, exactly `φ`).

use crate::HandEyeError;
use nalgebra::{Isometry3, Matrix3, SymmetricEigen, Vector3};
use photopose_geometry::pose::isometry_from_matrix;
use photopose_geometry::rotation::nearest_rotation;

/// The closed-form estimate of `X = T_tcp←camera` and `Z = T_base←plate`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosedForm {
    /// Camera in the TCP frame.
    pub camera_in_tcp: Isometry3<f64>,
    /// Plate in the robot base frame.
    pub plate_in_base: Isometry3<f64>,
    /// Spread of the relative rotation axes, degrees.
    pub axis_spread_deg: f64,
}

/// Spread of the axes of the relative robot rotations (degrees), and the
/// number of station pairs that turn by at least `min_rotation_deg`.
pub fn axis_spread_deg(robot: &[Isometry3<f64>], min_rotation_deg: f64) -> (f64, usize) {
    let mut s = Matrix3::zeros();
    let mut pairs = 0;
    for j in 0..robot.len() {
        for i in 0..j {
            let rel = robot[j].rotation.inverse() * robot[i].rotation;
            let axis = rel.scaled_axis();
            let angle = axis.norm();
            if angle.to_degrees() >= min_rotation_deg {
                let u = axis / angle;
                s += u * u.transpose();
                pairs += 1;
            }
        }
    }
    if pairs == 0 {
        return (0.0, 0);
    }
    let mut ev: Vec<f64> = SymmetricEigen::new(s).eigenvalues.iter().copied().collect();
    ev.sort_by(|a, b| b.total_cmp(a));
    let ratio = (ev[1].max(0.0) / ev[0]).sqrt();
    (2.0 * ratio.atan().to_degrees(), pairs)
}

/// Checks the motion and computes the closed form from `robot` (`A_i`) and
/// `camera` (`B_i`) poses of the same stations.
pub fn closed_form(
    robot: &[Isometry3<f64>],
    camera: &[Isometry3<f64>],
    min_rotation_deg: f64,
    min_axis_spread_deg: f64,
) -> Result<ClosedForm, HandEyeError> {
    assert_eq!(robot.len(), camera.len());
    let n = robot.len();
    if n < 3 {
        return Err(HandEyeError::TooFewStations { got: n, need: 3 });
    }
    let (spread, pairs) = axis_spread_deg(robot, min_rotation_deg);
    if pairs < 2 {
        return Err(HandEyeError::DegenerateMotion {
            what: format!(
                "{pairs} station pairs differ in orientation by {min_rotation_deg}° or more, \
                 at least 2 are needed"
            ),
        });
    }
    if spread < min_axis_spread_deg {
        return Err(HandEyeError::DegenerateMotion {
            what: format!(
                "the robot's rotations between stations are about parallel axes \
                 (axis spread {spread:.2}° < {min_axis_spread_deg}°)"
            ),
        });
    }
    // Rotation: Procrustes on the rotation vectors of all pairs.
    let mut h = Matrix3::zeros();
    let mut rel = Vec::with_capacity(n * (n - 1) / 2);
    for j in 0..n {
        for i in 0..j {
            let a = robot[j].inverse() * robot[i];
            let b = camera[j].inverse() * camera[i];
            h += b.rotation.scaled_axis() * a.rotation.scaled_axis().transpose();
            rel.push((a, b));
        }
    }
    // R_X maximises Σ a·(R_X b), i.e. tr(R_X H): the rotation nearest to Hᵀ.
    let rx = nearest_rotation(&h.transpose()).ok_or_else(|| HandEyeError::DegenerateMotion {
        what: "the rotation vectors of the station pairs do not determine R_X".into(),
    })?;
    // Translation: stacked (R_A' − I) t_X = R_X t_B' − t_A'.
    let mut nmat = Matrix3::zeros();
    let mut rhs = Vector3::zeros();
    for (a, b) in &rel {
        let c = a.rotation.to_rotation_matrix().into_inner() - Matrix3::identity();
        let r = rx * b.translation.vector - a.translation.vector;
        nmat += c.transpose() * c;
        rhs += c.transpose() * r;
    }
    let tx = nmat
        .try_inverse()
        .ok_or_else(|| HandEyeError::DegenerateMotion {
            what: "the relative rotations do not determine the camera's position on the flange"
                .into(),
        })?
        * rhs;
    let x = isometry_from_matrix(&rx, &tx);
    // Z from every station.
    let mut rz_sum = Matrix3::zeros();
    let mut tz_sum = Vector3::zeros();
    for (a, b) in robot.iter().zip(camera) {
        let z = a * x * b.inverse();
        rz_sum += z.rotation.to_rotation_matrix().into_inner();
        tz_sum += z.translation.vector;
    }
    let rz = nearest_rotation(&rz_sum).ok_or_else(|| HandEyeError::DegenerateMotion {
        what: "the stations disagree on the plate's orientation".into(),
    })?;
    let z = isometry_from_matrix(&rz, &(tz_sum / n as f64));
    Ok(ClosedForm {
        camera_in_tcp: x,
        plate_in_base: z,
        axis_spread_deg: spread,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use photopose_geometry::pose::isometry_from_xyzabc;

    #[test]
    fn exact_stations_give_the_exact_transforms() {
        let x = isometry_from_xyzabc([40.0, -75.0, 130.0, 88.0, 3.0, -2.0]);
        let z = isometry_from_xyzabc([1200.0, 150.0, -20.0, 30.0, 1.0, -0.5]);
        let poses = [
            [0.0, 0.0, 600.0, 0.0, 0.0, 0.0],
            [80.0, -40.0, 580.0, 40.0, 15.0, -10.0],
            [-60.0, 50.0, 620.0, -70.0, -20.0, 12.0],
            [30.0, 90.0, 550.0, 120.0, 5.0, 25.0],
        ];
        let camera: Vec<_> = poses
            .iter()
            .map(|p| isometry_from_xyzabc([p[0], p[1], p[2], p[3], p[4], 180.0 + p[5]]))
            .collect();
        let robot: Vec<_> = camera.iter().map(|b| z * b * x.inverse()).collect();
        let cf = closed_form(&robot, &camera, 2.0, 5.0).unwrap();
        let ex = cf.camera_in_tcp.inverse() * x;
        let ez = cf.plate_in_base.inverse() * z;
        assert!(ex.translation.vector.norm() < 1e-8, "{ex:?}");
        assert!(ex.rotation.angle() < 1e-10);
        assert!(ez.translation.vector.norm() < 1e-8, "{ez:?}");
        assert!(ez.rotation.angle() < 1e-10);
        assert!(cf.axis_spread_deg > 20.0);
    }

    #[test]
    fn axis_spread_of_two_axes_is_their_angle() {
        let robot = [
            Isometry3::identity(),
            isometry_from_xyzabc([0.0, 0.0, 0.0, 0.0, 0.0, 30.0]),
            isometry_from_xyzabc([0.0, 0.0, 0.0, 0.0, 30.0, 0.0]),
        ];
        // Pairs: (0,1) about x, (0,2) about y, (1,2) about a tilted axis.
        let (spread, pairs) = axis_spread_deg(&robot, 1.0);
        assert_eq!(pairs, 3);
        assert!(spread > 60.0, "{spread}");
        let robot = [
            Isometry3::identity(),
            isometry_from_xyzabc([0.0, 0.0, 0.0, 20.0, 0.0, 0.0]),
            isometry_from_xyzabc([100.0, 0.0, 0.0, -35.0, 0.0, 0.0]),
        ];
        let (spread, _) = axis_spread_deg(&robot, 1.0);
        assert!(spread < 1e-6, "{spread}");
    }
}
