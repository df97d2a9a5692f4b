//! The RSI server's counters and histograms: reply latency (datagram
//! received → reply sent), inter-arrival times, IPOC steps, the controller's
//! `Delay`, corrections applied, clamp and slew hits, dropped datagrams by
//! reason, the controller session's restarts, frozen-invalid cycles.
//! Atomics written by the RSI thread and read from any other thread
//! (metrics, logs) without locking; one naming scheme
//! (`photopose_rsi_*`) for export.

use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};

/// Fine buckets of 1 µs below this, µs.
const FINE_US: u64 = 2_000;
/// Coarse buckets of 100 µs up to this, µs.
const COARSE_END_US: u64 = 100_000;
const COARSE_STEP: u64 = 100;
const BUCKETS: usize = FINE_US as usize + ((COARSE_END_US - FINE_US) / COARSE_STEP) as usize + 1;

/// A histogram of durations in µs: 1 µs buckets to 2 ms, 100 µs buckets to
/// 100 ms, one overflow bucket. Lock-free; allocated once.
#[derive(Debug)]
pub struct Histogram {
    buckets: Vec<AtomicU64>,
    count: AtomicU64,
    max: AtomicU64,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            buckets: (0..BUCKETS).map(|_| AtomicU64::new(0)).collect(),
            count: AtomicU64::new(0),
            max: AtomicU64::new(0),
        }
    }
}

fn bucket_of(us: u64) -> usize {
    if us < FINE_US {
        us as usize
    } else if us < COARSE_END_US {
        FINE_US as usize + ((us - FINE_US) / COARSE_STEP) as usize
    } else {
        BUCKETS - 1
    }
}

fn upper_edge(b: usize) -> u64 {
    if b < FINE_US as usize {
        b as u64 + 1
    } else if b < BUCKETS - 1 {
        FINE_US + (b as u64 - FINE_US + 1) * COARSE_STEP
    } else {
        u64::MAX
    }
}

impl Histogram {
    /// Records one duration in nanoseconds.
    pub fn record_ns(&self, ns: u64) {
        let us = ns / 1000;
        self.buckets[bucket_of(us)].fetch_add(1, Ordering::Relaxed);
        self.count.fetch_add(1, Ordering::Relaxed);
        self.max.fetch_max(ns, Ordering::Relaxed);
    }

    /// Number of recorded values.
    pub fn count(&self) -> u64 {
        self.count.load(Ordering::Relaxed)
    }

    /// Largest recorded value, ns.
    pub fn max_ns(&self) -> u64 {
        self.max.load(Ordering::Relaxed)
    }

    /// The `p` quantile (0..=1) as the upper edge of its bucket, µs
    /// (`None` when empty; the overflow bucket reports the maximum).
    pub fn quantile_us(&self, p: f64) -> Option<f64> {
        let n = self.count();
        if n == 0 {
            return None;
        }
        let rank = ((p.clamp(0.0, 1.0) * n as f64).ceil() as u64).max(1);
        let mut acc = 0;
        for (b, c) in self.buckets.iter().enumerate() {
            acc += c.load(Ordering::Relaxed);
            if acc >= rank {
                let e = upper_edge(b);
                return Some(if e == u64::MAX {
                    self.max_ns() as f64 / 1000.0
                } else {
                    e as f64
                });
            }
        }
        Some(self.max_ns() as f64 / 1000.0)
    }

    /// Number of values at or above `us` microseconds (bucket resolution).
    pub fn count_at_least_us(&self, us: u64) -> u64 {
        let from = bucket_of(us);
        self.buckets[from..]
            .iter()
            .map(|c| c.load(Ordering::Relaxed))
            .sum()
    }
}

/// The server's live counters.
#[derive(Debug, Default)]
pub struct Stats {
    /// Datagrams read from the socket, whatever they held.
    pub received: AtomicU64,
    /// Controller cycles answered (new, larger IPOCs of the session).
    pub cycles: AtomicU64,
    /// Replies sent.
    pub replies: AtomicU64,
    /// Datagrams dropped because they did not parse (garbage, truncated,
    /// oversized).
    pub garbage: AtomicU64,
    /// Datagrams dropped because their sender is not a configured controller.
    pub unlisted: AtomicU64,
    /// Older queued datagrams skipped in favour of a newer one.
    pub drained: AtomicU64,
    /// Datagrams from a listed address but not the session's port, dropped.
    pub foreign_port: AtomicU64,
    /// Datagrams of the session with an IPOC older than the last, dropped.
    pub stale_ipoc: AtomicU64,
    /// Datagrams of the session repeating the last IPOC (answered with the
    /// same reply, never a new step).
    pub repeated: AtomicU64,
    /// Controller sessions opened after the first (RSI restarted).
    pub session_restarts: AtomicU64,
    /// Cycles frozen because the correction was not finite or outside the
    /// limits (`frozen_invalid`).
    pub invalid_cycles: AtomicU64,
    /// Replies the socket refused to send.
    pub send_errors: AtomicU64,
    /// Last `Delay D` the controller reported.
    pub delay_last: AtomicU64,
    /// Largest `Delay D` seen.
    pub delay_max: AtomicU64,
    /// Last IPOC step (difference to the previous answered IPOC).
    pub ipoc_step_last: AtomicU64,
    /// IPOC steps that differ from the first step seen (missed cycles).
    pub ipoc_irregular: AtomicU64,
    /// Cycles with a non-zero correction sent (relative) or a changed total
    /// (absolute).
    pub corrections_applied: AtomicU64,
    /// Cycles where the total clamp cut the target.
    pub clamp_hits: AtomicU64,
    /// Cycles where the slew limit cut the step.
    pub slew_hits: AtomicU64,
    /// Cycles with a stale measurement (correction frozen).
    pub stale_cycles: AtomicU64,
    /// [`crate::law::LawStatus::code`] of the last cycle (255 before the first).
    pub status: AtomicU8,
    /// Reply latency: datagram received → reply sent.
    pub latency: Histogram,
    /// Inter-arrival times of answered datagrams.
    pub interarrival: Histogram,
    /// The last `RIst` (actual TCP pose, KUKA `X … C`) as `f64` bits, for
    /// the pose stream and hand-eye stations; see [`Stats::robot_pose`].
    pub rist: [AtomicU64; 6],
    /// Cycles that carried `RIst` (0: none yet).
    pub rist_cycles: AtomicU64,
    /// Turns of the server thread's loop (a datagram or a receive timeout
    /// each): the daemon's watchdog checks that it keeps advancing.
    pub loops: AtomicU64,
}

impl Stats {
    /// New, zeroed counters.
    pub fn new() -> Stats {
        let s = Stats::default();
        s.status.store(255, Ordering::Relaxed);
        s
    }

    /// Stores a cycle's `RIst`.
    pub fn record_rist(&self, pose: &[f64; 6]) {
        for (a, v) in self.rist.iter().zip(pose) {
            a.store(v.to_bits(), Ordering::Relaxed);
        }
        self.rist_cycles.fetch_add(1, Ordering::Release);
    }

    /// The last `RIst` the controller sent, if any. The six values are read
    /// one by one: while the robot moves, they may come from two
    /// consecutive cycles (one interpolation cycle apart); while it stands
    /// still they are exact.
    pub fn robot_pose(&self) -> Option<[f64; 6]> {
        (self.rist_cycles.load(Ordering::Acquire) > 0)
            .then(|| std::array::from_fn(|k| f64::from_bits(self.rist[k].load(Ordering::Relaxed))))
    }

    /// A plain copy for reports and metrics.
    pub fn snapshot(&self) -> StatsSnapshot {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        StatsSnapshot {
            received: g(&self.received),
            cycles: g(&self.cycles),
            replies: g(&self.replies),
            garbage: g(&self.garbage),
            unlisted: g(&self.unlisted),
            drained: g(&self.drained),
            foreign_port: g(&self.foreign_port),
            stale_ipoc: g(&self.stale_ipoc),
            repeated: g(&self.repeated),
            session_restarts: g(&self.session_restarts),
            invalid_cycles: g(&self.invalid_cycles),
            send_errors: g(&self.send_errors),
            delay_last: g(&self.delay_last),
            delay_max: g(&self.delay_max),
            ipoc_step_last: g(&self.ipoc_step_last),
            ipoc_irregular: g(&self.ipoc_irregular),
            corrections_applied: g(&self.corrections_applied),
            clamp_hits: g(&self.clamp_hits),
            slew_hits: g(&self.slew_hits),
            stale_cycles: g(&self.stale_cycles),
            latency_p50_us: self.latency.quantile_us(0.5),
            latency_p99_us: self.latency.quantile_us(0.99),
            latency_p999_us: self.latency.quantile_us(0.999),
            latency_max_us: self.latency.max_ns() as f64 / 1000.0,
            interarrival_p50_us: self.interarrival.quantile_us(0.5),
            interarrival_p999_us: self.interarrival.quantile_us(0.999),
            interarrival_max_us: self.interarrival.max_ns() as f64 / 1000.0,
        }
    }
}

/// A copy of [`Stats`] with the histograms reduced to quantiles.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[allow(missing_docs)] // the fields mirror [`Stats`]
pub struct StatsSnapshot {
    pub received: u64,
    pub cycles: u64,
    pub replies: u64,
    pub garbage: u64,
    pub unlisted: u64,
    pub drained: u64,
    pub foreign_port: u64,
    pub stale_ipoc: u64,
    pub repeated: u64,
    pub session_restarts: u64,
    pub invalid_cycles: u64,
    pub send_errors: u64,
    pub delay_last: u64,
    pub delay_max: u64,
    pub ipoc_step_last: u64,
    pub ipoc_irregular: u64,
    pub corrections_applied: u64,
    pub clamp_hits: u64,
    pub slew_hits: u64,
    pub stale_cycles: u64,
    pub latency_p50_us: Option<f64>,
    pub latency_p99_us: Option<f64>,
    pub latency_p999_us: Option<f64>,
    pub latency_max_us: f64,
    pub interarrival_p50_us: Option<f64>,
    pub interarrival_p999_us: Option<f64>,
    pub interarrival_max_us: f64,
}

impl StatsSnapshot {
    /// `(metric name, value)` pairs named `photopose_rsi_*` (counters end
    /// in `_total`), for the daemon's metrics endpoint.
    pub fn metrics(&self) -> Vec<(&'static str, f64)> {
        let mut m = vec![
            ("photopose_rsi_cycles_total", self.cycles as f64),
            ("photopose_rsi_replies_total", self.replies as f64),
            ("photopose_rsi_garbage_dropped_total", self.garbage as f64),
            ("photopose_rsi_unlisted_dropped_total", self.unlisted as f64),
            ("photopose_rsi_received_total", self.received as f64),
            ("photopose_rsi_drained_total", self.drained as f64),
            (
                "photopose_rsi_foreign_port_dropped_total",
                self.foreign_port as f64,
            ),
            (
                "photopose_rsi_stale_ipoc_dropped_total",
                self.stale_ipoc as f64,
            ),
            ("photopose_rsi_repeated_ipoc_total", self.repeated as f64),
            (
                "photopose_rsi_session_restarts_total",
                self.session_restarts as f64,
            ),
            (
                "photopose_rsi_invalid_cycles_total",
                self.invalid_cycles as f64,
            ),
            ("photopose_rsi_send_errors_total", self.send_errors as f64),
            ("photopose_rsi_controller_delay", self.delay_last as f64),
            ("photopose_rsi_controller_delay_max", self.delay_max as f64),
            ("photopose_rsi_ipoc_step", self.ipoc_step_last as f64),
            (
                "photopose_rsi_ipoc_irregular_total",
                self.ipoc_irregular as f64,
            ),
            (
                "photopose_rsi_corrections_applied_total",
                self.corrections_applied as f64,
            ),
            ("photopose_rsi_clamp_hits_total", self.clamp_hits as f64),
            ("photopose_rsi_slew_hits_total", self.slew_hits as f64),
            ("photopose_rsi_stale_cycles_total", self.stale_cycles as f64),
            ("photopose_rsi_reply_latency_max_us", self.latency_max_us),
            (
                "photopose_rsi_interarrival_max_us",
                self.interarrival_max_us,
            ),
        ];
        for (name, v) in [
            ("photopose_rsi_reply_latency_p50_us", self.latency_p50_us),
            ("photopose_rsi_reply_latency_p99_us", self.latency_p99_us),
            ("photopose_rsi_reply_latency_p999_us", self.latency_p999_us),
            (
                "photopose_rsi_interarrival_p50_us",
                self.interarrival_p50_us,
            ),
            (
                "photopose_rsi_interarrival_p999_us",
                self.interarrival_p999_us,
            ),
        ] {
            if let Some(v) = v {
                m.push((name, v));
            }
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_of_a_known_histogram() {
        let h = Histogram::default();
        assert_eq!(h.quantile_us(0.5), None);
        for us in 1..=1000u64 {
            h.record_ns(us * 1000 - 500);
        }
        h.record_ns(50_000_000);
        h.record_ns(500_000_000);
        assert_eq!(h.count(), 1002);
        assert_eq!(h.quantile_us(0.5), Some(501.0));
        assert_eq!(h.quantile_us(0.99), Some(992.0));
        assert_eq!(h.quantile_us(0.9985), Some(50_100.0));
        assert_eq!(h.quantile_us(1.0), Some(500_000.0));
        assert_eq!(h.count_at_least_us(1000), 2);
        assert_eq!(h.max_ns(), 500_000_000);
    }

    #[test]
    fn metric_names_follow_the_scheme() {
        let s = Stats::new();
        s.latency.record_ns(10_000);
        for (name, _) in s.snapshot().metrics() {
            assert!(name.starts_with("photopose_rsi_"), "{name}");
        }
    }
}
