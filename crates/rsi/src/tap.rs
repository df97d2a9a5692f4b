//! The cycle tap: what the RSI server did in each controller cycle (IPOC,
//! arrival time, `RIst`, `RSol`, the correction sent, the law's state),
//! handed to a reader on another thread (the recording) through a bounded
//! lock-free queue. The server only pushes, never waits and never
//! allocates; when the queue is full the cycle is dropped and counted.
//! The server takes a tap optionally ([`crate::server::RsiServer::spawn_tapped`]).

use crate::codec::Pose6;
use crate::law::LawStatus;
use crossbeam_queue::ArrayQueue;
use photopose_telemetry::Counter;
use std::sync::Arc;

/// One answered controller cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleRecord {
    /// The controller's interpolation counter of the cycle.
    pub ipoc: u64,
    /// When the datagram arrived, ns since the Unix epoch (host clock,
    /// UTC).
    pub arrival_utc_ns: u64,
    /// When the datagram arrived on the host's monotonic clock
    /// (`CLOCK_MONOTONIC`), ns.
    pub arrival_mono_ns: u64,
    /// `RIst`: the actual TCP pose the controller sent (X, Y, Z mm; A, B,
    /// C deg), if it sent one.
    pub rist: Option<Pose6>,
    /// `RSol`: the commanded TCP pose (mm, deg), if sent.
    pub rsol: Option<Pose6>,
    /// The controller's late-reply count (`Delay D`), if sent.
    pub delay: Option<u64>,
    /// The correction written into the reply (mm, deg).
    pub sent: Pose6,
    /// The total correction in effect after the cycle (mm, deg).
    pub total: Pose6,
    /// The law's state in the cycle.
    pub status: LawStatus,
    /// The error of the measurement used in the cycle, in the correction
    /// frame (mm, deg), when a new one was used.
    pub error: Option<Pose6>,
    /// The slew limit cut the cycle's step.
    pub slew_limited: bool,
    /// The clamp cut the total.
    pub clamped: bool,
}

/// The bounded hand-off of cycle records from the server to one reader.
#[derive(Debug)]
pub struct CycleTap {
    queue: ArrayQueue<CycleRecord>,
    pushed: Counter,
    dropped: Counter,
}

impl CycleTap {
    /// A tap holding up to `capacity` (at least 1) records not yet read.
    pub fn new(capacity: usize) -> Arc<CycleTap> {
        Arc::new(CycleTap {
            queue: ArrayQueue::new(capacity.max(1)),
            pushed: Counter::new(),
            dropped: Counter::new(),
        })
    }

    /// Hands one record over; drops it (counted) when the reader is behind.
    pub fn push(&self, record: CycleRecord) {
        if self.queue.push(record).is_ok() {
            self.pushed.inc();
        } else {
            self.dropped.inc();
        }
    }

    /// The oldest record not yet read.
    pub fn pop(&self) -> Option<CycleRecord> {
        self.queue.pop()
    }

    /// Records handed over so far.
    pub fn pushed(&self) -> u64 {
        self.pushed.get()
    }

    /// Records dropped because the queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.get()
    }
}

/// The host's monotonic clock (`CLOCK_MONOTONIC`), ns.
pub fn monotonic_ns() -> u64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::Monotonic);
    (t.tv_sec as u64)
        .saturating_mul(1_000_000_000)
        .saturating_add(t.tv_nsec as u64)
}

/// The host's UTC clock, ns since the Unix epoch.
pub fn utc_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(ipoc: u64) -> CycleRecord {
        CycleRecord {
            ipoc,
            arrival_utc_ns: 1,
            arrival_mono_ns: 2,
            rist: None,
            rsol: Some([1.0; 6]),
            delay: None,
            sent: [0.0; 6],
            total: [0.0; 6],
            status: LawStatus::MeasureOnly,
            error: None,
            slew_limited: false,
            clamped: false,
        }
    }

    #[test]
    fn a_full_tap_drops_and_counts() {
        let tap = CycleTap::new(2);
        for ipoc in 0..5 {
            tap.push(record(ipoc));
        }
        assert_eq!((tap.pushed(), tap.dropped()), (2, 3));
        assert_eq!(tap.pop().map(|r| r.ipoc), Some(0));
        assert_eq!(tap.pop().map(|r| r.ipoc), Some(1));
        assert_eq!(tap.pop(), None);
    }

    #[test]
    fn the_monotonic_clock_advances() {
        let a = monotonic_ns();
        let b = monotonic_ns();
        assert!(a > 0 && b >= a);
    }
}
