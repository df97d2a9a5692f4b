//! photopose-stream: how poses leave the daemon.
//!
//! One [`PoseMessage`] per frame (`photopose.pose.v2`), encoded as one
//! line of JSON ([`message`], stamped with the host clocks of [`clock`]); sent as one UDP datagram to each configured destination
//! ([`udp`]) and as a JSON line to every client of a TCP server ([`tcp`]).
//! The TCP server, like every network edge that serves people and other
//! programs (also the metrics endpoint, [`http`], and the Foxglove live
//! view, [`live`]), runs on the one tokio runtime of [`edge`]; the pipeline's threads hand lines to it without
//! waiting. A slow TCP client has a bounded queue and is dropped with a log
//! when it overflows; nothing here ever blocks the caller. Once warm,
//! publishing a pose allocates nothing (encoding goes into reused buffers).
//!
//! The formats are documented in `docs/streams.md`.

pub mod clock;
pub mod edge;
pub mod http;
pub mod live;
pub mod live_front;
pub mod message;
pub mod read;
pub mod tcp;
pub mod udp;

pub use edge::{Edge, EdgeHandle};
pub use http::{HttpLimits, HttpStats, TextEndpoint};
pub use live::{LiveOptions, LiveSender, LiveServer};
pub use message::{MessageTimes, PoseEstimate, PoseMessage, PoseStatus, RobotState};
pub use read::{LinePose, LineRobot, LineTimes, PoseLine};
pub use tcp::{TcpLimits, TcpServer, TcpStats};
pub use udp::{DestinationStats, UdpSender, UdpStats};

use thiserror::Error;

/// Why a stream could not be set up.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum StreamError {
    /// Binding or configuring a socket failed.
    #[error("{what} {addr}: {source}")]
    Socket {
        /// What was being set up.
        what: &'static str,
        /// The address.
        addr: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// The edge runtime (tokio) could not start.
    #[error("cannot start the edge runtime: {source}")]
    Runtime {
        /// The OS error.
        source: std::io::Error,
    },
}
