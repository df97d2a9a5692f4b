//! The RSI sink: every measured pose into the RSI server's lock-free
//! latest-measurement slot, stamped on the server's clock with the frame's
//! hand-over instant. The RSI thread reads the slot each controller cycle
//! and never waits on vision.

use super::{Outgoing, PoseSink};
use photopose_rsi::server::RsiClock;
use photopose_rsi::{Measurement, SlotPublisher};
use std::sync::Arc;

/// The publishing side of the RSI server's slot.
pub struct RsiSink {
    publisher: SlotPublisher,
    clock: RsiClock,
    stats: Arc<photopose_rsi::monitor::Stats>,
}

impl std::fmt::Debug for RsiSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RsiSink").finish_non_exhaustive()
    }
}

impl RsiSink {
    /// Publishes into `publisher` on `clock` (the server's); `stats` are
    /// the server's counters.
    pub fn new(
        publisher: SlotPublisher,
        clock: RsiClock,
        stats: Arc<photopose_rsi::monitor::Stats>,
    ) -> RsiSink {
        RsiSink {
            publisher,
            clock,
            stats,
        }
    }

    /// The server's counters.
    pub fn stats(&self) -> Arc<photopose_rsi::monitor::Stats> {
        Arc::clone(&self.stats)
    }
}

impl PoseSink for RsiSink {
    fn name(&self) -> &'static str {
        "rsi"
    }

    fn publish(&mut self, out: &Outgoing<'_>) {
        if let Some(result) = out.result {
            if let Some(report) = &result.pose {
                self.publisher.publish(&Measurement::from_report(
                    report,
                    self.clock.at(result.times.handover),
                    result.seq,
                ));
            }
        }
    }
}
