//! photopose-stream: how poses leave the daemon.
//!
//! One [`PoseMessage`] per frame, encoded as one line of JSON
//! ([`message`]); sent as one UDP datagram to each configured destination
//! ([`udp`]) and as a JSON line to every client of a TCP server ([`tcp`]).
//! A slow TCP client has a bounded queue and is dropped with a log when it
//! overflows; nothing here ever blocks the caller. Once warm, publishing a
//! pose allocates nothing (encoding goes into reused buffers).
//!
//! The formats are documented in `docs/streams.md`.

pub mod message;
pub mod tcp;
pub mod udp;

pub use message::{PoseMessage, PoseStatus};
pub use tcp::{TcpServer, TcpStats};
pub use udp::UdpSender;

use thiserror::Error;

/// Why a stream could not be set up.
#[derive(Debug, Error)]
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
}
