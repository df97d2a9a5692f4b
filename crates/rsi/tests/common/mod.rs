//! Shared set-up of the loopback tests: a scene (plate in the robot base,
//! camera on the flange) and server settings.

#![allow(dead_code)]

use nalgebra::{Isometry3, Vector3};
use photopose_geometry::pose::{camera_pose, exterior_from_camera_pose};
use photopose_geometry::Exterior;
use photopose_rsi::codec::Pose6;
use photopose_rsi::law::{isometry_to_pose, pose_to_isometry};
use photopose_rsi::{HandEye, RsiConfig, RsiSettings};

/// The hand-eye pair of the tests: the camera 120 mm out on the flange,
/// the plate on the floor in front of the robot.
pub fn hand_eye() -> HandEye {
    HandEye {
        tcp_from_camera: pose_to_isometry(&[10.0, 60.0, 120.0, 90.0, 2.0, -1.0]),
        base_from_plate: pose_to_isometry(&[1400.0, -250.0, -400.0, 30.0, 0.0, 0.0]),
    }
}

/// The programmed TCP pose: the camera 800 mm above the plate centre,
/// slightly tilted.
pub fn nominal_tcp(he: &HandEye) -> Pose6 {
    let e = Exterior::look_at(
        Vector3::new(60.0, -40.0, 800.0),
        Vector3::new(0.0, 0.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
    )
    .unwrap();
    isometry_to_pose(&he.tcp_in_base(&camera_pose(&e)))
}

/// The camera's exterior orientation for a TCP pose.
pub fn exterior_of(he: &HandEye, tcp: &Isometry3<f64>) -> Exterior {
    exterior_from_camera_pose(&he.camera_in_plate(tcp))
}

/// Server settings on loopback (any port), answering 127.0.0.1.
pub fn settings(edit: impl FnOnce(&mut RsiConfig)) -> RsiSettings {
    let mut c = RsiConfig {
        enabled: true,
        bind: "127.0.0.1".into(),
        port: Some(1),
        controllers: vec!["127.0.0.1".into()],
        ..RsiConfig::default()
    };
    edit(&mut c);
    let mut s = c.settings(None).unwrap();
    s.bind.set_port(0);
    s
}

/// Cycles of the long loop: `PHOTOPOSE_RSI_CYCLES` or `default`.
pub fn cycles(default: u64) -> u64 {
    std::env::var("PHOTOPOSE_RSI_CYCLES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}
