//! Reading pose lines back: the messages of the pose stream
//! (`photopose.pose.v2`, with `status`) and the lines of `photopose
//! resect` (with `ok`), which share the `pose` object, as the tools that
//! consume them (the circular test, live hand-eye stations) need them —
//! one reader, the wire format's other half.

use serde::Deserialize;

/// The `pose` object of a line (see [`crate::message::PoseEstimate`]).
#[derive(Debug, Clone, Deserialize, PartialEq)]
pub struct LinePose {
    /// Projection centre in the field frame, mm.
    pub position_mm: [f64; 3],
    /// `R` (field → camera), rows.
    pub rotation_field_to_camera: [[f64; 3]; 3],
    /// Quaternion `(x, y, z, w)` of `Rᵀ`.
    pub quaternion_xyzw: Option<[f64; 4]>,
    /// The 6×6 covariance, row-major (36 numbers).
    #[serde(default)]
    pub covariance: Vec<f64>,
    /// σ of the position, mm.
    pub std_position_mm: Option<[f64; 3]>,
    /// σ of the rotations about the field axes, degrees.
    pub std_rotation_deg: Option<[f64; 3]>,
    /// A-posteriori σ0, px.
    pub sigma0_px: Option<f64>,
    /// Targets used.
    pub n_targets: Option<u32>,
}

/// The `time` object of a message; absent keys and nulls are `None`.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
pub struct LineTimes {
    /// Middle of the exposure, UTC ns.
    pub exposure_utc_ns: Option<u64>,
    /// Hand-over of the frame, UTC ns.
    pub handover_utc_ns: Option<u64>,
    /// The camera's own timestamp, ns.
    pub camera_clock_ns: Option<u64>,
}

/// The `robot` object of a message.
#[derive(Debug, Clone, Deserialize, PartialEq)]
pub struct LineRobot {
    /// IPOC of the datagram that carried the robot's pose.
    pub ipoc: u64,
    /// Age of that datagram when the message was sent, ms.
    pub age_ms: f64,
    /// The robot's `RIst`: KUKA `X, Y, Z` mm, `A, B, C` degrees.
    pub xyzabc_mm_deg: [f64; 6],
}

/// The fields of one pose line that readers use; absent keys are `None`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
pub struct PoseLine {
    /// A message's schema (`photopose.pose.v2`).
    pub schema: Option<String>,
    /// A pose message's status (`ok`, `too_few_targets`, `stale`, `error`).
    pub status: Option<String>,
    /// A resect line's outcome.
    pub ok: Option<bool>,
    /// The frame's sequence number (null on stale messages).
    pub seq: Option<u64>,
    /// A message's times.
    pub time: Option<LineTimes>,
    /// The camera's pose.
    pub pose: Option<LinePose>,
    /// The robot's pose, when the message carries one.
    pub robot: Option<LineRobot>,
}

impl PoseLine {
    /// Parses one line (JSON object).
    pub fn parse(line: &str) -> Result<PoseLine, serde_json::Error> {
        serde_json::from_str(line)
    }

    /// Whether the line carries a fresh pose: `status == "ok"` for a
    /// message, `ok == true` for a resect line; `None` when it is neither
    /// kind.
    pub fn has_pose(&self) -> Option<bool> {
        match (&self.status, self.ok) {
            (Some(s), _) => Some(s == "ok"),
            (None, Some(ok)) => Some(ok),
            (None, None) => None,
        }
    }

    /// The instant the pose belongs to, UTC ns: the middle of the exposure
    /// when known, else the frame's hand-over.
    pub fn time_utc_ns(&self) -> Option<u64> {
        let t = self.time.as_ref()?;
        t.exposure_utc_ns.or(t.handover_utc_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::message::{PoseEstimate, RobotState, COVARIANCE_ORDER};
    use crate::{PoseMessage, PoseStatus};

    #[test]
    fn a_written_message_reads_back() {
        let camera: std::sync::Arc<str> = std::sync::Arc::from("camera");
        let mut m = PoseMessage::new(&camera, 3, PoseStatus::Ok);
        m.time.handover_utc_ns = Some(2_000);
        m.pose = Some(PoseEstimate {
            position_mm: [1.0, 2.0, 3.0],
            quaternion_xyzw: [0.0, 0.0, 0.0, 1.0],
            rotation_field_to_camera: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            covariance: [0.5; 36],
            covariance_order: COVARIANCE_ORDER,
            std_position_mm: [0.1; 3],
            std_rotation_deg: [0.01; 3],
            sigma0_px: 0.02,
            n_targets: 9,
        });
        m.robot = Some(RobotState {
            ipoc: 11,
            age_ms: 2.0,
            xyzabc_mm_deg: [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            correction: None,
        });
        let mut buf = Vec::new();
        m.encode_line(&mut buf);
        let l = PoseLine::parse(std::str::from_utf8(&buf).unwrap().trim()).unwrap();
        assert_eq!(l.has_pose(), Some(true));
        assert_eq!(l.schema.as_deref(), Some("photopose.pose.v2"));
        let p = l.pose.as_ref().unwrap();
        assert_eq!(p.position_mm, [1.0, 2.0, 3.0]);
        assert_eq!(p.covariance, vec![0.5; 36]);
        assert_eq!(l.time_utc_ns(), Some(2_000));
        let r = l.robot.as_ref().unwrap();
        assert_eq!(
            (r.ipoc, r.xyzabc_mm_deg),
            (11, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
        );
        let stale = PoseMessage::stale(&camera, Some(&m));
        stale.encode_line(&mut buf);
        let l = PoseLine::parse(std::str::from_utf8(&buf).unwrap().trim()).unwrap();
        assert_eq!((l.has_pose(), l.seq), (Some(false), None));
        let r = PoseLine::parse(r#"{"ok":false,"error":"x"}"#).unwrap();
        assert_eq!(r.has_pose(), Some(false));
        assert_eq!(PoseLine::parse("{}").unwrap().has_pose(), None);
    }
}
