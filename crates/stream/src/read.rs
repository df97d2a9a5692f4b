//! Reading pose lines back: the messages of the pose stream (`status`) and
//! the lines of `photopose resect` (`ok`), as the tools that consume them
//! (the circular test, live hand-eye stations) need them — one reader, the
//! wire format's other half.

use serde::Deserialize;

/// The fields of one pose line that readers use; absent keys are `None`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
pub struct PoseLine {
    /// A pose message's status (`ok`, `too_few_targets`, `stale`, `error`).
    pub status: Option<String>,
    /// A resect line's outcome.
    pub ok: Option<bool>,
    /// Camera timestamp of the frame, ns.
    pub camera_time_ns: Option<u64>,
    /// Projection centre, field frame, mm.
    pub center: Option<[f64; 3]>,
    /// `R` (field → camera), rows.
    pub rotation: Option<[[f64; 3]; 3]>,
    /// σ of the centre, mm.
    pub std_center: Option<[f64; 3]>,
    /// σ of the rotations about the field axes, degrees.
    pub std_rotation_deg: Option<[f64; 3]>,
    /// The robot's `RIst` when the RSI server ran (KUKA `X … C`).
    pub robot_xyzabc: Option<[f64; 6]>,
}

impl PoseLine {
    /// Parses one line (JSON object).
    pub fn parse(line: &str) -> Result<PoseLine, serde_json::Error> {
        serde_json::from_str(line)
    }

    /// Whether the line carries a pose: `status == "ok"` for a message,
    /// `ok == true` for a resect line; `None` when it is neither kind.
    pub fn has_pose(&self) -> Option<bool> {
        match (&self.status, self.ok) {
            (Some(s), _) => Some(s == "ok"),
            (None, Some(ok)) => Some(ok),
            (None, None) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{PoseMessage, PoseStatus};

    #[test]
    fn a_written_message_reads_back() {
        let mut m = PoseMessage::without_pose(3, 1_000, 2_000, PoseStatus::Ok);
        m.center = Some([1.0, 2.0, 3.0]);
        m.robot_xyzabc = Some([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let mut buf = Vec::new();
        m.encode_line(&mut buf);
        let l = PoseLine::parse(std::str::from_utf8(&buf).unwrap().trim()).unwrap();
        assert_eq!(l.has_pose(), Some(true));
        assert_eq!(l.center, Some([1.0, 2.0, 3.0]));
        assert_eq!(l.camera_time_ns, Some(1_000));
        assert_eq!(l.robot_xyzabc, Some([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]));
        let r = PoseLine::parse(r#"{"ok":false,"error":"x"}"#).unwrap();
        assert_eq!(r.has_pose(), Some(false));
        assert_eq!(PoseLine::parse("{}").unwrap().has_pose(), None);
    }
}
