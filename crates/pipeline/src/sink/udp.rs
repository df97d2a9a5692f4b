//! The UDP sink: one datagram per message to each configured destination
//! (`[output] udp`), from connected non-blocking sockets.

use super::{Outgoing, PoseSink};
use crate::config::Config;
use crate::run::PipelineError;
use photopose_stream::UdpSender;

/// Datagrams to the configured destinations.
#[derive(Debug)]
pub struct UdpSink(UdpSender);

impl UdpSink {
    /// The sink of `[output] udp`, if it names any destination.
    pub fn from_config(config: &Config) -> Result<Option<UdpSink>, PipelineError> {
        if config.udp.is_empty() {
            return Ok(None);
        }
        let any = "0.0.0.0:0".parse().expect("literal address");
        Ok(Some(UdpSink(UdpSender::new(any, &config.udp)?)))
    }
}

impl UdpSink {
    /// The counters of the destinations.
    pub fn stats(&self) -> std::sync::Arc<photopose_stream::UdpStats> {
        self.0.shared_stats()
    }
}

impl PoseSink for UdpSink {
    fn name(&self) -> &'static str {
        "udp"
    }

    fn publish(&mut self, out: &Outgoing<'_>) {
        self.0.send(out.line);
    }
}
