//! photopose-telemetry: the daemon's one counter, one gauge and one
//! latency histogram type, and their export in Prometheus' text format.
//!
//! Recording ([`Counter::inc`], [`Gauge::set`], [`Histogram::record_ns`])
//! is a handful of relaxed atomic operations on memory allocated when the
//! value is made: no lock, no allocation, so the RSI thread can record
//! every cycle and the output thread every pose.
//!
//! Export happens at scrape time only: each part of the daemon implements
//! [`Collect`] and writes its current values through a [`Scrape`], which
//! hands them to `prometheus-client`'s text encoder (HELP and TYPE lines,
//! `_total` suffix of counters, `_bucket`/`_sum`/`_count` of histograms,
//! escaping). `prometheus-client` is used only there: its own histogram
//! takes a lock to record, which the RSI thread must never do, so the
//! values live in the atomics of this crate and the encoder reads them.
//!
//! Naming scheme (held by [`Scrape`] in debug builds and by the tests):
//! `photopose_` prefix, snake_case, counters end in `_total`, durations are
//! in seconds (`_seconds`), sizes in bytes (`_bytes`).

mod export;
mod histogram;

pub use export::{Collect, Exposition, Scrape, CONTENT_TYPE};
pub use histogram::{Histogram, BUCKETS, BUCKETS_PER_OCTAVE};

use std::sync::atomic::{AtomicU64, Ordering};

/// A monotonic count (events since start). Lock-free.
#[derive(Debug, Default)]
pub struct Counter(AtomicU64);

impl Counter {
    /// A counter at zero.
    pub const fn new() -> Counter {
        Counter(AtomicU64::new(0))
    }

    /// Counts one event.
    #[inline]
    pub fn inc(&self) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }

    /// Counts `n` events.
    #[inline]
    pub fn add(&self, n: u64) {
        self.0.fetch_add(n, Ordering::Relaxed);
    }

    /// The count so far.
    #[inline]
    pub fn get(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// A value that goes up and down (a state, a last measurement). Stored as
/// the bits of an `f64`; lock-free.
#[derive(Debug)]
pub struct Gauge(AtomicU64);

impl Default for Gauge {
    fn default() -> Self {
        Gauge::new(0.0)
    }
}

impl Gauge {
    /// A gauge holding `v`.
    pub const fn new(v: f64) -> Gauge {
        Gauge(AtomicU64::new(v.to_bits()))
    }

    /// Sets the value.
    #[inline]
    pub fn set(&self, v: f64) {
        self.0.store(v.to_bits(), Ordering::Relaxed);
    }

    /// The value.
    #[inline]
    pub fn get(&self) -> f64 {
        f64::from_bits(self.0.load(Ordering::Relaxed))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counters_count_and_gauges_hold() {
        let c = Counter::new();
        c.inc();
        c.add(41);
        assert_eq!(c.get(), 42);
        let g = Gauge::default();
        assert_eq!(g.get(), 0.0);
        g.set(-1.5);
        assert_eq!(g.get(), -1.5);
    }
}
