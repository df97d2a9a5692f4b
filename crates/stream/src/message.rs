//! The pose message: one per processed frame, one JSON object on one line.

use serde::Serialize;
use std::io::Write;

/// What a message says about its frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseStatus {
    /// A pose was measured.
    Ok,
    /// Too few targets were identified for a pose.
    TooFewTargets,
    /// The pose is older than allowed (no fresh frame).
    Stale,
    /// The frame could not be processed.
    Error,
}

/// One pose, as streamed. Lengths in mm, angles in degrees where the key
/// says `_deg`, times in ns or µs as the key says.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PoseMessage {
    /// Frame sequence number of the source.
    pub seq: u64,
    /// Camera timestamp of the frame, ns (source clock).
    pub camera_time_ns: u64,
    /// Host time at which the frame was received, ns since the Unix epoch.
    pub host_time_ns: u64,
    /// Time from frame hand-over to this message, µs.
    pub latency_us: f64,
    /// What the message says.
    pub status: PoseStatus,
    /// Projection centre in the field frame, mm (null without a pose).
    pub center: Option<[f64; 3]>,
    /// `R` of `docs/conventions.md` (field → camera), rows.
    pub rotation: Option<[[f64; 3]; 3]>,
    /// Unit quaternion `(w, x, y, z)` of `R`.
    pub quaternion_wxyz: Option<[f64; 4]>,
    /// Standard deviations of the centre, mm.
    pub std_center: Option<[f64; 3]>,
    /// Standard deviations of the rotations about the field axes, degrees.
    pub std_rotation_deg: Option<[f64; 3]>,
    /// A-posteriori σ0 of an image coordinate, px.
    pub sigma0_px: Option<f64>,
    /// Targets used in the pose.
    pub n_targets: u32,
    /// State of the robot correction (KUKA RSI) when it runs: `tracking`,
    /// `measure_only` or `stale_…` (the correction is frozen); absent
    /// without RSI.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rsi: Option<&'static str>,
    /// The robot's actual TCP pose (`RIst`, KUKA `X, Y, Z, A, B, C` in mm
    /// and degrees) last reported to the RSI server when this message was
    /// sent; absent without RSI or before the first `RIst`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub robot_xyzabc: Option<[f64; 6]>,
}

impl PoseMessage {
    /// A message without a pose.
    pub fn without_pose(
        seq: u64,
        camera_time_ns: u64,
        host_time_ns: u64,
        status: PoseStatus,
    ) -> Self {
        PoseMessage {
            seq,
            camera_time_ns,
            host_time_ns,
            latency_us: 0.0,
            status,
            center: None,
            rotation: None,
            quaternion_wxyz: None,
            std_center: None,
            std_rotation_deg: None,
            sigma0_px: None,
            n_targets: 0,
            rsi: None,
            robot_xyzabc: None,
        }
    }

    /// Writes the message as one JSON line (with `\n`) into `buf`, which is
    /// cleared first; no allocation once `buf` has grown to a line's size.
    pub fn encode_line(&self, buf: &mut Vec<u8>) {
        buf.clear();
        // Serialising plain numbers and fixed keys into a Vec cannot fail.
        let _ = serde_json::to_writer(&mut *buf, self);
        let _ = buf.write_all(b"\n");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_message_is_one_json_line_with_the_documented_keys() {
        let mut m = PoseMessage::without_pose(7, 1_000, 2_000, PoseStatus::Ok);
        m.center = Some([1.0, 2.0, 1000.5]);
        m.n_targets = 230;
        let mut buf = Vec::new();
        m.encode_line(&mut buf);
        let line = std::str::from_utf8(&buf).unwrap();
        assert!(line.ends_with('\n') && line.matches('\n').count() == 1);
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        for key in [
            "seq",
            "camera_time_ns",
            "host_time_ns",
            "latency_us",
            "status",
            "center",
            "rotation",
            "quaternion_wxyz",
            "std_center",
            "std_rotation_deg",
            "sigma0_px",
            "n_targets",
        ] {
            assert!(v.get(key).is_some(), "{key}");
        }
        assert_eq!(v["status"], "ok");
        assert_eq!(v["rotation"], serde_json::Value::Null);
        let s = PoseMessage::without_pose(1, 0, 0, PoseStatus::TooFewTargets);
        s.encode_line(&mut buf);
        assert!(std::str::from_utf8(&buf)
            .unwrap()
            .contains("\"too_few_targets\""));
    }
}
