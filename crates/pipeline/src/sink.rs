//! The sink seam: every output of the daemon implements [`PoseSink`] and
//! receives, in frame order on the output thread, each [`PoseResult`] with
//! its wire message already encoded once (a JSON line), plus the stale
//! messages sent while no frame comes. A sink never blocks and never
//! allocates per pose once warm: it hands off to its socket, its slot or
//! its bounded queue, and counts what it had to drop.
//!
//! Adding an output: one module under `sink/` implementing [`PoseSink`]
//! from its own configuration, and one line in [`build`].

pub mod live;
pub mod record;
pub mod rsi;
pub mod tcp;
pub mod udp;
#[cfg(feature = "zenoh")]
pub mod zenoh;

use crate::config::Config;
use crate::result::{PoseResult, ResultStatus};
use crate::run::PipelineError;
use photopose_geometry::rotation::quaternion_wxyz_from_matrix;
use photopose_geometry::ResectionReport;
use photopose_stream::message::COVARIANCE_ORDER;
use photopose_stream::{MessageTimes, PoseEstimate, PoseMessage, PoseStatus, RobotState};

/// What the output stage hands every sink for one message.
#[derive(Debug, Clone, Copy)]
pub struct Outgoing<'a> {
    /// The frame's result; `None` for a stale message (no fresh frame).
    pub result: Option<&'a PoseResult>,
    /// The wire message.
    pub message: &'a PoseMessage,
    /// The message as one JSON line, `\n` included.
    pub line: &'a [u8],
}

/// An output of the daemon.
pub trait PoseSink: Send {
    /// The sink's name in logs (`udp`, `tcp`, `rsi` …).
    fn name(&self) -> &'static str;

    /// One message, in frame order. Never blocks; drops are the sink's to
    /// count.
    fn publish(&mut self, out: &Outgoing<'_>);

    /// The pipeline is stopping: flush and close (may block briefly).
    fn finish(&mut self) {}
}

/// The sinks of a configuration, in the order they receive each message,
/// and what the output stage reads back from them for the messages (the
/// RSI server's state).
pub struct Sinks {
    /// The sinks.
    pub sinks: Vec<Box<dyn PoseSink>>,
    /// The RSI server's counters when it runs (correction state and the
    /// robot's pose go into every message).
    pub rsi: Option<std::sync::Arc<photopose_rsi::monitor::Stats>>,
    /// The controller's session timeout (`[rsi] session_idle_ms`): a robot
    /// pose older than this is not put into messages.
    pub rsi_silence: std::time::Duration,
    /// The TCP stream's address, when it runs.
    pub tcp_addr: Option<std::net::SocketAddr>,
    /// The TCP stream's counters, when it runs.
    pub tcp: Option<std::sync::Arc<photopose_stream::TcpStats>>,
    /// The UDP destinations' counters, when there are any.
    pub udp: Option<std::sync::Arc<photopose_stream::UdpStats>>,
}

impl std::fmt::Debug for Sinks {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list()
            .entries(self.sinks.iter().map(|s| s.name()))
            .finish()
    }
}

/// The sinks `config` asks for: the RSI slot (when `rsi` is given: the
/// server the pipeline started), UDP datagrams, the TCP stream (on `edge`,
/// the runtime of the network edges).
pub fn build(
    config: &Config,
    rsi: Option<rsi::RsiSink>,
    edge: Option<&photopose_stream::EdgeHandle>,
) -> Result<Sinks, PipelineError> {
    let mut sinks: Vec<Box<dyn PoseSink>> = Vec::new();
    let stats = rsi.as_ref().map(|r| r.stats());
    if let Some(r) = rsi {
        sinks.push(Box::new(r));
    }
    let mut udp = None;
    if let Some(u) = udp::UdpSink::from_config(config)? {
        udp = Some(u.stats());
        sinks.push(Box::new(u));
    }
    if let Some(r) = record::RecordSink::from_config(config)? {
        sinks.push(Box::new(r));
    }
    let (mut tcp_addr, mut tcp) = (None, None);
    if let Some(t) = tcp::TcpSink::from_config(config, edge)? {
        (tcp_addr, tcp) = (t.local_addr(), t.stats());
        sinks.push(Box::new(t));
    }
    Ok(Sinks {
        sinks,
        rsi: stats,
        rsi_silence: config
            .rsi
            .as_ref()
            .map_or(std::time::Duration::ZERO, |r| r.settings.session_idle),
        tcp_addr,
        tcp,
        udp,
    })
}

/// The pose object of the wire message (and of `photopose resect`'s lines)
/// of an adjustment: the camera's pose in the field frame, `R`, the
/// adjustment's full covariance (made exactly symmetric), σ, σ0, targets
/// used.
pub fn pose_estimate(report: &ResectionReport) -> PoseEstimate {
    let e = &report.exterior;
    let r = e.rotation;
    let rows = |m: &photopose_geometry::Matrix3<f64>| {
        [
            [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
            [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
            [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
        ]
    };
    // The camera's attitude in the field frame is Rᵀ.
    let [w, x, y, z] = quaternion_wxyz_from_matrix(&r.transpose()).unwrap_or([f64::NAN; 4]);
    let c = &report.covariance;
    PoseEstimate {
        position_mm: [e.center.x, e.center.y, e.center.z],
        quaternion_xyzw: [x, y, z, w],
        rotation_field_to_camera: rows(&r),
        // The adjustment's σ0²·N⁻¹ is symmetric up to rounding (its
        // off-diagonal pairs differ in the last digits): the message's is
        // exactly symmetric, the mean of each pair.
        covariance: std::array::from_fn(|k| {
            let (i, j) = (k / 6, k % 6);
            0.5 * (c[(i, j)] + c[(j, i)])
        }),
        covariance_order: COVARIANCE_ORDER,
        std_position_mm: report.std_center().into(),
        std_rotation_deg: report.std_rotation_deg().into(),
        sigma0_px: report.sigma0_px,
        n_targets: u32::try_from(report.n_points).unwrap_or(u32::MAX),
    }
}

/// The wire message of a result (`photopose.pose.v2`), its sending time
/// not yet stamped.
pub fn message(result: &PoseResult) -> PoseMessage {
    let status = match result.status {
        ResultStatus::Ok => PoseStatus::Ok,
        ResultStatus::TooFewTargets => PoseStatus::TooFewTargets,
        ResultStatus::Error => PoseStatus::Error,
    };
    let mut m = PoseMessage::new(&result.camera, result.seq, status);
    let t = &result.times;
    let known = |ns: u64| (ns != 0).then_some(ns);
    m.time = MessageTimes {
        exposure_utc_ns: t.exposure_utc_ns,
        exposure_mono_ns: known(t.exposure_mono_ns),
        exposure_sigma_ns: known(t.exposure_sigma_ns),
        handover_utc_ns: known(t.handover_utc_ns),
        handover_mono_ns: known(t.handover_mono_ns),
        sent_utc_ns: 0,
        sent_mono_ns: 0,
        camera_clock_ns: known(t.camera_ns),
    };
    m.pose = result.pose.as_ref().map(pose_estimate);
    m
}

/// Puts the robot's state into a message — the last `RIst` with its IPOC
/// and age and the correction's state, unless the controller has been
/// silent longer than `silence` — and stamps the sending time: the one
/// place messages learn them, just before they are encoded.
pub fn annotate(
    message: &mut PoseMessage,
    rsi: Option<&photopose_rsi::monitor::Stats>,
    silence: std::time::Duration,
) {
    message.robot = rsi.and_then(|stats| {
        let r = stats.robot_reading(std::time::Instant::now(), silence)?;
        Some(RobotState {
            ipoc: r.ipoc,
            age_ms: r.age.as_secs_f64() * 1e3,
            xyzabc_mm_deg: r.xyzabc,
            correction: photopose_rsi::LawStatus::from_code(
                stats.status.load(std::sync::atomic::Ordering::Relaxed),
            )
            .map(|s| s.name()),
        })
    });
    message.stamp_sent();
}

#[cfg(test)]
mod tests {
    use super::*;
    use photopose_geometry::{Exterior, Matrix6};
    use std::sync::Arc;
    use std::time::Instant;

    fn result(report: Option<ResectionReport>) -> PoseResult {
        let camera: crate::result::CameraId = Arc::from("left");
        let meta = photopose_frame::FrameMeta {
            seq: 12,
            camera_time_ns: 77,
            host_time_ns: 1_000_000,
            host_mono_ns: 5_000,
            exposure_mono_ns: 3_000,
            exposure_sigma_ns: 0,
            ..Default::default()
        };
        let status = if report.is_some() {
            photopose_locate::PoseStatus::Ok
        } else {
            photopose_locate::PoseStatus::TooFewTargets { coded: 2 }
        };
        PoseResult::from_location(
            &camera,
            &meta,
            Instant::now(),
            Some((&status, report.as_ref())),
        )
    }

    fn report() -> ResectionReport {
        // A full, symmetric positive definite covariance (A Aᵀ + diag).
        let a = Matrix6::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 * 1e-3 - 2e-3);
        let covariance = a * a.transpose() + Matrix6::from_diagonal_element(1e-6);
        ResectionReport {
            exterior: Exterior::from_kuka_pose([30.0, -20.0, 800.0, 25.0, 8.0, 170.0]),
            covariance,
            sigma0: 1e-4,
            sigma0_px: 0.015,
            rms_px: 0.014,
            n_points: 212,
            n_rejected: 1,
            iterations: 3,
            hypotheses: 1,
        }
    }

    #[test]
    fn the_message_carries_the_adjustments_covariance_and_the_cameras_pose() {
        let r = report();
        let m = message(&result(Some(r)));
        let p = m.pose.expect("a pose");
        for i in 0..6 {
            for j in 0..6 {
                assert_eq!(p.covariance[i * 6 + j], r.covariance[(i, j)], "({i}, {j})");
            }
        }
        assert_eq!(p.covariance_order[3], "omega_x_rad");
        assert_eq!(p.n_targets, 212);
        assert_eq!(p.position_mm, [30.0, -20.0, 800.0]);
        // The quaternion is of Rᵀ: the camera's attitude in the field,
        // the same as KUKA's M of the camera pose.
        let [x, y, z, w] = p.quaternion_xyzw;
        assert!(w >= 0.0);
        let q = photopose_geometry::rotation::matrix_from_quaternion_wxyz([w, x, y, z]).unwrap();
        let rt = r.exterior.rotation.transpose();
        assert!((q - rt).abs().max() < 1e-12, "{q} vs {rt}");
        let row = p.rotation_field_to_camera;
        assert_eq!(row[0][2], r.exterior.rotation[(0, 2)]);
        // Times: known ones as given, unknown ones null.
        assert_eq!(m.seq, Some(12));
        assert_eq!(&*m.camera, "left");
        assert_eq!(&*m.child_frame_id, "left");
        assert_eq!(m.time.camera_clock_ns, Some(77));
        assert_eq!(m.time.handover_mono_ns, Some(5_000));
        assert_eq!(m.time.exposure_mono_ns, Some(3_000));
        assert_eq!(m.time.exposure_utc_ns, Some(998_000));
        assert_eq!(m.time.exposure_sigma_ns, None);
    }

    #[test]
    fn without_a_pose_the_message_has_none_and_annotate_stamps_the_sending() {
        let mut m = message(&result(None));
        assert_eq!(m.status, PoseStatus::TooFewTargets);
        assert!(m.pose.is_none());
        let stats = photopose_rsi::monitor::Stats::new();
        annotate(&mut m, Some(&stats), std::time::Duration::from_millis(100));
        assert!(m.robot.is_none(), "no RIst yet");
        assert!(m.time.sent_mono_ns > 0 && m.time.sent_utc_ns > 0);
        stats.record_rist(99, Instant::now(), &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        annotate(&mut m, Some(&stats), std::time::Duration::from_millis(100));
        let robot = m.robot.expect("the robot");
        assert_eq!((robot.ipoc, robot.xyzabc_mm_deg[5]), (99, 6.0));
        assert!(robot.age_ms >= 0.0 && robot.age_ms < 100.0);
        std::thread::sleep(std::time::Duration::from_millis(2));
        annotate(&mut m, Some(&stats), std::time::Duration::from_millis(1));
        assert!(m.robot.is_none(), "older than the session timeout");
    }
}
