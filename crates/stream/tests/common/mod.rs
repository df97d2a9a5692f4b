//! Set-up shared by the stream crate's end-to-end tests: a pose and its
//! encoded line.

// Each test binary uses its own part of this module.
#![allow(dead_code)]

use photopose_stream::{PoseMessage, PoseStatus};

/// A pose at `x` mm along the field's X axis, as a message carries it.
pub fn pose(x: f64) -> photopose_stream::PoseEstimate {
    let mut covariance = [0.0; 36];
    for k in 0..6 {
        covariance[k * 7] = 1e-4;
    }
    photopose_stream::PoseEstimate {
        position_mm: [x, 0.0, 1000.0],
        quaternion_xyzw: [1.0, 0.0, 0.0, 0.0],
        rotation_field_to_camera: [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
        covariance,
        covariance_order: photopose_stream::message::COVARIANCE_ORDER,
        std_position_mm: [0.01; 3],
        std_rotation_deg: [0.001; 3],
        sigma0_px: 0.02,
        n_targets: 230,
    }
}

/// The line of pose number `seq` (at `seq` mm) of camera "camera", into `buf`.
pub fn line(seq: u64, buf: &mut Vec<u8>) {
    let mut m = PoseMessage::new(&std::sync::Arc::from("camera"), seq, PoseStatus::Ok);
    m.pose = Some(pose(seq as f64));
    m.encode_line(buf);
}
