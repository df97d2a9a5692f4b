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

use crate::config::Config;
use crate::result::{PoseResult, ResultStatus};
use crate::run::PipelineError;
use photopose_geometry::rotation::quaternion_wxyz_from_matrix;
use photopose_stream::{PoseMessage, PoseStatus};

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
        tcp_addr,
        tcp,
        udp,
    })
}

/// The wire message of a result (the stream's message, version 1).
pub fn message(result: &PoseResult) -> PoseMessage {
    let status = match result.status {
        ResultStatus::Ok => PoseStatus::Ok,
        ResultStatus::TooFewTargets => PoseStatus::TooFewTargets,
        ResultStatus::Error => PoseStatus::Error,
    };
    let mut m = PoseMessage::without_pose(
        result.seq,
        result.times.camera_ns,
        result.times.handover_utc_ns,
        status,
    );
    if let Some(p) = &result.pose {
        let e = &p.exterior;
        let r = e.rotation;
        m.center = Some([e.center.x, e.center.y, e.center.z]);
        m.rotation = Some([
            [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
            [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
            [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
        ]);
        m.quaternion_wxyz = quaternion_wxyz_from_matrix(&r);
        m.std_center = Some(p.std_center().into());
        m.std_rotation_deg = Some(p.std_rotation_deg().into());
        m.sigma0_px = Some(p.sigma0_px);
        m.n_targets = p.n_points as u32;
    }
    m
}

/// Puts the RSI server's state (correction state, the robot's last `RIst`)
/// into a message: the one place messages learn it.
pub fn annotate(message: &mut PoseMessage, rsi: Option<&photopose_rsi::monitor::Stats>) {
    if let Some(stats) = rsi {
        message.rsi = photopose_rsi::LawStatus::from_code(
            stats.status.load(std::sync::atomic::Ordering::Relaxed),
        )
        .map(|s| s.name());
        message.robot_xyzabc = stats.robot_pose();
    }
}
