//! The pose message, version 2 (`photopose.pose.v2`): one per processed
//! frame (and one per stale interval), one JSON object on one line. It
//! names itself (schema, camera, frame ids), carries every time of the
//! frame on the clocks it is known on, the camera's pose in the field frame
//! with the adjustment's full covariance, and the robot's last reported
//! pose with its IPOC and age. `docs/streams.md` documents every key and
//! `docs/schema/pose-message.v2.json` ([`JSON_SCHEMA`]) is its JSON Schema.
//! Building and encoding a message allocates nothing once the line buffer
//! has grown (the camera id is a shared `Arc<str>`).

use serde::ser::{SerializeTuple, Serializer};
use serde::Serialize;
use std::io::Write;
use std::sync::Arc;

/// The value of the `schema` key.
pub const SCHEMA: &str = "photopose.pose.v2";

/// The JSON Schema (draft 2020-12) of the message, the repository's
/// `docs/schema/pose-message.v2.json`.
pub const JSON_SCHEMA: &str = include_str!("../../../docs/schema/pose-message.v2.json");

/// The `frame_id` of every message: the field (plate) frame the pose is
/// given in.
pub const FIELD_FRAME: &str = "field";

/// The order and units of the covariance's rows and columns: the projection
/// centre in the field frame (mm), then the adjustment's small rotations
/// `ω` (rad) with `R ← R·(I + [ω]ₓ)` — the camera turning by `−ω` about the
/// field's axes.
pub const COVARIANCE_ORDER: [&str; 6] = [
    "x_mm",
    "y_mm",
    "z_mm",
    "omega_x_rad",
    "omega_y_rad",
    "omega_z_rad",
];

/// What a message says about its frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseStatus {
    /// A pose was measured.
    Ok,
    /// Too few targets were identified for a pose.
    TooFewTargets,
    /// No fresh frame within the configured age: the message repeats the
    /// last pose and names its frame in `last_seq`.
    Stale,
    /// The frame could not be processed.
    Error,
}

/// The times of a message, ns. `null` where a clock or instant is not
/// known. Monotonic times are the host's `CLOCK_MONOTONIC`, UTC times ns
/// since the Unix epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct MessageTimes {
    /// The middle of the exposure, UTC.
    pub exposure_utc_ns: Option<u64>,
    /// The middle of the exposure, monotonic.
    pub exposure_mono_ns: Option<u64>,
    /// The standard uncertainty of the exposure instant.
    pub exposure_sigma_ns: Option<u64>,
    /// The frame's hand-over to the pipeline (reception), UTC.
    pub handover_utc_ns: Option<u64>,
    /// The frame's hand-over, monotonic.
    pub handover_mono_ns: Option<u64>,
    /// When this message was sent, UTC.
    pub sent_utc_ns: u64,
    /// When this message was sent, monotonic.
    pub sent_mono_ns: u64,
    /// The camera's own timestamp of the frame, on the camera's clock.
    pub camera_clock_ns: Option<u64>,
}

/// The camera's pose in the field frame with its precision, as the
/// adjustment (single-image resection) found it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PoseEstimate {
    /// The projection centre in the field frame, mm.
    pub position_mm: [f64; 3],
    /// Unit quaternion `(x, y, z, w)`, `w ≥ 0`, of `Rᵀ`: the camera's
    /// attitude in the field frame, so `(position_mm, quaternion_xyzw)` is
    /// the camera's pose (camera → field).
    pub quaternion_xyzw: [f64; 4],
    /// `R` of the collinearity equations (field → camera), rows: the camera
    /// axes written in the field frame.
    pub rotation_field_to_camera: [[f64; 3]; 3],
    /// The a-posteriori 6×6 covariance, row-major, the adjustment's (made
    /// exactly symmetric); rows and columns in [`COVARIANCE_ORDER`].
    #[serde(serialize_with = "flat")]
    pub covariance: [f64; 36],
    /// [`COVARIANCE_ORDER`].
    pub covariance_order: [&'static str; 6],
    /// Standard deviations of the position, mm.
    pub std_position_mm: [f64; 3],
    /// Standard deviations of the rotations about the field's axes, degrees.
    pub std_rotation_deg: [f64; 3],
    /// A-posteriori σ0 of an image coordinate, px.
    pub sigma0_px: f64,
    /// Targets used in the adjustment.
    pub n_targets: u32,
}

/// The robot's state when the message was sent (KUKA RSI).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RobotState {
    /// The IPOC of the controller datagram that carried the pose.
    pub ipoc: u64,
    /// Time from that datagram's arrival to this message, ms.
    pub age_ms: f64,
    /// The robot's actual TCP pose (`RIst`) in its base frame, KUKA
    /// `X, Y, Z` (mm), `A, B, C` (degrees).
    pub xyzabc_mm_deg: [f64; 6],
    /// The correction law's state (`tracking`, `measure_only`, `stale_…`,
    /// `frozen_invalid`); `null` before its first cycle.
    pub correction: Option<&'static str>,
}

/// One pose message.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PoseMessage {
    /// Always [`SCHEMA`].
    pub schema: &'static str,
    /// The `[camera] id`.
    #[serde(serialize_with = "text")]
    pub camera: Arc<str>,
    /// The frame's sequence number; `None` (null) on a stale message.
    pub seq: Option<u64>,
    /// On a stale message: the sequence number of the frame whose pose it
    /// repeats (absent otherwise, null when no frame has been seen).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_seq: Option<Option<u64>>,
    /// What the message says.
    pub status: PoseStatus,
    /// The frame the pose is given in: [`FIELD_FRAME`].
    pub frame_id: &'static str,
    /// The frame whose pose is given: the camera's, named by its id.
    #[serde(serialize_with = "text")]
    pub child_frame_id: Arc<str>,
    /// The times.
    pub time: MessageTimes,
    /// The pose; `None` (null) without one.
    pub pose: Option<PoseEstimate>,
    /// The robot; absent without RSI, before the first `RIst` and once the
    /// controller has been silent longer than its session timeout.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub robot: Option<RobotState>,
}

fn text<S: Serializer>(s: &Arc<str>, ser: S) -> Result<S::Ok, S::Error> {
    ser.serialize_str(s)
}

// serde implements arrays up to 32 elements only.
fn flat<S: Serializer>(v: &[f64; 36], ser: S) -> Result<S::Ok, S::Error> {
    let mut t = ser.serialize_tuple(v.len())?;
    for x in v {
        t.serialize_element(x)?;
    }
    t.end()
}

impl PoseMessage {
    /// A message of camera `camera` for frame `seq`, without a pose, its
    /// times unknown.
    pub fn new(camera: &Arc<str>, seq: u64, status: PoseStatus) -> Self {
        PoseMessage {
            schema: SCHEMA,
            camera: Arc::clone(camera),
            seq: Some(seq),
            last_seq: None,
            status,
            frame_id: FIELD_FRAME,
            child_frame_id: Arc::clone(camera),
            time: MessageTimes::default(),
            pose: None,
            robot: None,
        }
    }

    /// The stale message that follows `last` (the last message sent, if
    /// any, else none of `camera`): no frame of its own (`seq` null), the
    /// last frame's pose and times kept, `last_seq` naming that frame.
    pub fn stale(camera: &Arc<str>, last: Option<&PoseMessage>) -> Self {
        let mut m = match last {
            Some(l) => l.clone(),
            None => PoseMessage::new(camera, 0, PoseStatus::Stale),
        };
        m.last_seq = Some(last.and_then(|l| l.seq.or(l.last_seq.flatten())));
        m.seq = None;
        m.status = PoseStatus::Stale;
        m.robot = None;
        m
    }

    /// Stamps the sending instant (`time.sent_*`) from the host's clocks.
    pub fn stamp_sent(&mut self) {
        self.time.sent_mono_ns = crate::clock::mono_ns();
        self.time.sent_utc_ns = crate::clock::utc_ns();
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

    fn camera() -> Arc<str> {
        Arc::from("cam-left")
    }

    /// A message with every optional part filled.
    pub(crate) fn full_message() -> PoseMessage {
        let mut m = PoseMessage::new(&camera(), 7, PoseStatus::Ok);
        m.time = MessageTimes {
            exposure_utc_ns: Some(1_763_820_000_000_000_000),
            exposure_mono_ns: Some(5_000_000),
            exposure_sigma_ns: Some(20_000),
            handover_utc_ns: Some(1_763_820_000_002_000_000),
            handover_mono_ns: Some(7_000_000),
            sent_utc_ns: 1_763_820_000_003_000_000,
            sent_mono_ns: 8_000_000,
            camera_clock_ns: Some(123_456_789),
        };
        let mut cov = [0.0; 36];
        for k in 0..6 {
            cov[k * 6 + k] = 1e-4 * (k + 1) as f64;
        }
        cov[1] = 2e-5;
        cov[6] = 2e-5;
        let r = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
        m.pose = Some(PoseEstimate {
            position_mm: [1.0, 2.0, 1000.5],
            quaternion_xyzw: [1.0, 0.0, 0.0, 0.0],
            rotation_field_to_camera: r,
            covariance: cov,
            covariance_order: COVARIANCE_ORDER,
            std_position_mm: [0.01, 0.014, 0.017],
            std_rotation_deg: [0.001, 0.0012, 0.0013],
            sigma0_px: 0.02,
            n_targets: 230,
        });
        m.robot = Some(RobotState {
            ipoc: 4_000_123,
            age_ms: 1.5,
            xyzabc_mm_deg: [500.0, 0.0, 900.0, 0.0, 90.0, 0.0],
            correction: Some("tracking"),
        });
        m
    }

    fn json(m: &PoseMessage) -> serde_json::Value {
        let mut buf = Vec::new();
        m.encode_line(&mut buf);
        let line = std::str::from_utf8(&buf).unwrap();
        assert!(line.ends_with('\n') && line.matches('\n').count() == 1);
        serde_json::from_str(line).unwrap()
    }

    fn validator() -> jsonschema::Validator {
        let schema: serde_json::Value = serde_json::from_str(JSON_SCHEMA).unwrap();
        jsonschema::draft202012::new(&schema).unwrap()
    }

    fn assert_valid(v: &serde_json::Value) {
        let errors: Vec<String> = validator()
            .iter_errors(v)
            .map(|e| format!("{} at {}", e, e.instance_path()))
            .collect();
        assert!(errors.is_empty(), "{errors:?}\n{v}");
    }

    #[test]
    fn a_message_is_one_json_line_with_the_documented_keys() {
        let v = json(&full_message());
        assert_eq!(v["schema"], "photopose.pose.v2");
        assert_eq!(v["camera"], "cam-left");
        assert_eq!(v["child_frame_id"], "cam-left");
        assert_eq!(v["frame_id"], "field");
        assert_eq!(v["seq"], 7);
        assert!(v.get("last_seq").is_none());
        assert_eq!(v["status"], "ok");
        assert_eq!(v["pose"]["covariance"].as_array().unwrap().len(), 36);
        assert_eq!(v["pose"]["covariance"][1], 2e-5);
        assert_eq!(v["pose"]["covariance_order"][5], "omega_z_rad");
        assert_eq!(v["robot"]["ipoc"], 4_000_123);
        assert_eq!(v["time"]["camera_clock_ns"], 123_456_789);
        assert_valid(&v);
    }

    #[test]
    fn every_kind_of_message_validates_against_the_schema() {
        let full = full_message();
        let mut bare = PoseMessage::new(&camera(), 3, PoseStatus::TooFewTargets);
        bare.stamp_sent();
        let v = json(&bare);
        assert_eq!(v["pose"], serde_json::Value::Null);
        assert_eq!(v["time"]["exposure_utc_ns"], serde_json::Value::Null);
        assert!(v.get("robot").is_none());
        assert_valid(&v);
        let stale = PoseMessage::stale(&camera(), Some(&full));
        let v = json(&stale);
        assert_eq!(v["seq"], serde_json::Value::Null);
        assert_eq!(v["last_seq"], 7);
        assert_eq!(v["status"], "stale");
        assert_eq!(v["pose"]["position_mm"][2], 1000.5);
        assert_valid(&v);
        // A stale message after a stale message still names the frame.
        let again = PoseMessage::stale(&camera(), Some(&stale));
        assert_eq!(json(&again)["last_seq"], 7);
        let first = PoseMessage::stale(&camera(), None);
        let v = json(&first);
        assert_eq!(v["last_seq"], serde_json::Value::Null);
        assert_valid(&v);
        let mut error = PoseMessage::new(&camera(), 9, PoseStatus::Error);
        error.robot = full.robot;
        error.robot.as_mut().unwrap().correction = None;
        assert_valid(&json(&error));
    }

    #[test]
    fn the_schema_refuses_what_the_message_never_is() {
        let v = json(&full_message());
        let bad = |edit: &dyn Fn(&mut serde_json::Value)| {
            let mut b = v.clone();
            edit(&mut b);
            assert!(!validator().is_valid(&b), "accepted {b}");
        };
        bad(&|b| b["schema"] = "photopose.pose.v1".into());
        bad(&|b| b["status"] = "fine".into());
        bad(&|b| {
            b["pose"]["covariance"].as_array_mut().unwrap().pop();
        });
        bad(&|b| b["pose"]["center"] = serde_json::json!([0, 0, 0]));
        bad(&|b| {
            b.as_object_mut().unwrap().remove("time");
        });
        bad(&|b| b["robot"]["age_ms"] = "1 ms".into());
        // A frame's message without its seq, a stale one with one.
        bad(&|b| b["seq"] = serde_json::Value::Null);
        bad(&|b| b["status"] = "stale".into());
    }
}
