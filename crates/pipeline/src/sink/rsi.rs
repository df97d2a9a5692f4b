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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::result::FrameTimes;
    use std::time::{Duration, Instant};

    /// The law gets the exposure instant when the source knew it (on the
    /// same monotonic clock as the controller's cycles), the hand-over
    /// otherwise — never the hand-over of a frame with a known exposure.
    #[test]
    fn the_measurement_time_is_the_exposure_when_known() {
        let clock = RsiClock::new();
        let handover = Instant::now();
        let mut times = FrameTimes {
            camera_ns: 0,
            handover_utc_ns: 0,
            handover,
            handover_mono_ns: 0,
            exposure_mono_ns: 0,
            exposure_utc_ns: None,
            exposure_sigma_ns: 0,
            processed: handover,
        };
        let at_handover = measurement_time_s(&clock, &times);
        assert!((at_handover - clock.at(handover)).abs() < 1e-12);
        // The same instant through both paths agrees within a few µs.
        let mono = photopose_acquire::mono::instant_ns(handover);
        assert!((RsiClock::mono_s(mono) - at_handover).abs() < 1e-3);
        // 13 ms before the hand-over: that is what the law gets.
        times.exposure_mono_ns = mono - 13_000_000;
        let at_exposure = measurement_time_s(&clock, &times);
        assert!((at_handover - at_exposure - 0.013).abs() < 1e-3);
        let later = clock.at(handover + Duration::from_millis(5));
        assert!((later - at_handover - 0.005).abs() < 1e-9);
    }
}
