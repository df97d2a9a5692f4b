//! The RSI sink: every measured pose into the RSI server's lock-free
//! latest-measurement slot, stamped on the server's clock (`CLOCK_MONOTONIC`
//! seconds) with the frame's mid-exposure instant when the source knows it,
//! else its hand-over instant. The RSI thread reads the slot each
//! controller cycle and never waits on vision.

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

/// The instant a pose belongs to on the law's clock: the middle of the
/// exposure when the source stamped it, the hand-over otherwise.
pub fn measurement_time_s(clock: &RsiClock, times: &crate::result::FrameTimes) -> f64 {
    if times.exposure_mono_ns != 0 {
        RsiClock::mono_s(times.exposure_mono_ns)
    } else {
        clock.at(times.handover)
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
                    measurement_time_s(&self.clock, &result.times),
                    result.seq,
                ));
            }
        }
    }
}
