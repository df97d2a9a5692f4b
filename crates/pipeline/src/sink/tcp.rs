//! The TCP sink: JSON lines to every client of the pose stream
//! (`[output] tcp_listen`), through the stream's bounded hand-off.

use super::{Outgoing, PoseSink};
use crate::config::Config;
use crate::run::PipelineError;
use photopose_stream::{EdgeHandle, TcpLimits, TcpServer};
use std::net::SocketAddr;
use std::sync::Arc;

/// The TCP pose stream.
#[derive(Debug)]
pub struct TcpSink(Option<TcpServer>);

impl TcpSink {
    /// The sink of `[output] tcp_listen`, if set, served on `edge`.
    pub fn from_config(
        config: &Config,
        edge: Option<&EdgeHandle>,
    ) -> Result<Option<TcpSink>, PipelineError> {
        match (config.tcp_listen, edge) {
            (Some(a), Some(edge)) => Ok(Some(TcpSink(Some(TcpServer::bind(
                edge,
                a,
                TcpLimits {
                    max_clients: config.tcp_max_clients,
                    client_queue: config.tcp_client_queue,
                },
            )?)))),
            _ => Ok(None),
        }
    }

    /// The address clients connect to.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.0.as_ref().map(|t| t.local_addr())
    }

    /// The stream's counters (clients).
    pub fn stats(&self) -> Option<Arc<photopose_stream::TcpStats>> {
        self.0.as_ref().map(|t| t.shared_stats())
    }
}

impl PoseSink for TcpSink {
    fn name(&self) -> &'static str {
        "tcp"
    }

    fn publish(&mut self, out: &Outgoing<'_>) {
        if let Some(t) = self.0.as_mut() {
            t.publish(out.line);
        }
    }

    fn finish(&mut self) {
        if let Some(t) = self.0.take() {
            t.shutdown();
        }
    }
}
