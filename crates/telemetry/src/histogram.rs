//! The one latency histogram: log-spaced buckets, eight per octave (an
//! upper bucket edge is at most 2^(1/8) − 1 ≈ 9.05 % above any value in
//! the bucket), from 1 µs to about 134 s, plus an overflow bucket; the sum
//! and the largest value kept exactly. Hand-written on atomics because it
//! is recorded on the RSI thread every cycle (no lock, no allocation).

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Buckets per doubling of the value.
pub const BUCKETS_PER_OCTAVE: usize = 8;
/// Octaves covered above the first edge (1 µs · 2^27 ≈ 134 s).
const OCTAVES: usize = 27;
/// Upper edge of the first bucket, ns.
const BASE_NS: f64 = 1_000.0;
/// Buckets with a finite upper edge, then one overflow bucket.
pub const BUCKETS: usize = OCTAVES * BUCKETS_PER_OCTAVE + 2;
const OVERFLOW: usize = BUCKETS - 1;

/// A histogram of durations. Bucket `k < BUCKETS - 1` counts values in
/// `(edge(k-1), edge(k)]` with `edge(k) = 1 µs · 2^(k/8)`; the last bucket
/// counts what is above `edge(BUCKETS - 2)`.
#[derive(Debug)]
pub struct Histogram {
    buckets: [AtomicU64; BUCKETS],
    sum_ns: AtomicU64,
    max_ns: AtomicU64,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            buckets: std::array::from_fn(|_| AtomicU64::new(0)),
            sum_ns: AtomicU64::new(0),
            max_ns: AtomicU64::new(0),
        }
    }
}

/// The bucket of a value, ns.
fn bucket_of(ns: u64) -> usize {
    let x = ns as f64 / BASE_NS;
    if x <= 1.0 {
        return 0;
    }
    let k = (BUCKETS_PER_OCTAVE as f64 * x.log2()).ceil();
    if k >= OVERFLOW as f64 {
        OVERFLOW
    } else {
        k as usize
    }
}

/// Upper edge of bucket `k`, seconds (infinite for the overflow bucket).
pub(crate) fn upper_edge_seconds(k: usize) -> f64 {
    if k >= OVERFLOW {
        f64::INFINITY
    } else {
        BASE_NS * 1e-9 * 2f64.powf(k as f64 / BUCKETS_PER_OCTAVE as f64)
    }
}

impl Histogram {
    /// Records one duration, ns. Lock-free, allocation-free.
    #[inline]
    pub fn record_ns(&self, ns: u64) {
        self.buckets[bucket_of(ns)].fetch_add(1, Ordering::Relaxed);
        self.sum_ns.fetch_add(ns, Ordering::Relaxed);
        self.max_ns.fetch_max(ns, Ordering::Relaxed);
    }

    /// Records one duration.
    #[inline]
    pub fn record(&self, d: Duration) {
        self.record_ns(u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
    }

    /// Number of recorded values.
    pub fn count(&self) -> u64 {
        self.buckets.iter().map(|b| b.load(Ordering::Relaxed)).sum()
    }

    /// Sum of the recorded values, seconds.
    pub fn sum_seconds(&self) -> f64 {
        self.sum_ns.load(Ordering::Relaxed) as f64 / 1e9
    }

    /// Largest recorded value, ns (0 when empty).
    pub fn max_ns(&self) -> u64 {
        self.max_ns.load(Ordering::Relaxed)
    }

    /// The value below which a share `q` (0..=1) of the recorded values
    /// lie, seconds: the upper edge of its bucket (at most 9.05 % high),
    /// never more than the largest value recorded; `None` when empty.
    pub fn quantile_seconds(&self, q: f64) -> Option<f64> {
        let counts = self.counts();
        let n: u64 = counts.iter().sum();
        if n == 0 {
            return None;
        }
        let rank = ((q.clamp(0.0, 1.0) * n as f64).ceil() as u64).max(1);
        let max = self.max_ns() as f64 / 1e9;
        let mut seen = 0;
        for (k, c) in counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return Some(upper_edge_seconds(k).min(max));
            }
        }
        Some(max)
    }

    /// The bucket counts (non-cumulative), read once each.
    pub fn counts(&self) -> [u64; BUCKETS] {
        std::array::from_fn(|k| self.buckets[k].load(Ordering::Relaxed))
    }

    /// `(upper edge in seconds, count)` of every non-empty bucket, in
    /// order (the overflow bucket's edge is infinite).
    pub fn nonempty_buckets(&self) -> impl Iterator<Item = (f64, u64)> {
        let counts = self.counts();
        (0..BUCKETS)
            .filter(move |&k| counts[k] > 0)
            .map(move |k| (upper_edge_seconds(k), counts[k]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_value_lands_in_a_bucket_whose_edge_is_within_nine_percent() {
        for ns in (1_001..50_000_000u64).step_by(997) {
            let k = bucket_of(ns);
            let (lo, hi) = (
                if k == 0 {
                    0.0
                } else {
                    upper_edge_seconds(k - 1)
                },
                upper_edge_seconds(k),
            );
            let s = ns as f64 * 1e-9;
            assert!(lo < s * (1.0 + 1e-12) && s <= hi * (1.0 + 1e-12), "{ns}");
            assert!(hi / s <= 1.0906, "{ns}: edge {hi}");
        }
        assert_eq!(bucket_of(0), 0);
        assert_eq!(bucket_of(1_000), 0);
        assert_eq!(bucket_of(u64::MAX), OVERFLOW);
        assert!(upper_edge_seconds(OVERFLOW - 1) > 130.0);
    }

    #[test]
    fn quantiles_of_a_known_histogram() {
        let h = Histogram::default();
        assert_eq!(h.quantile_seconds(0.5), None);
        // 10 µs … 10 ms in 10 µs steps.
        for k in 1..=1000u64 {
            h.record_ns(k * 10_000);
        }
        assert_eq!(h.count(), 1000);
        for (q, exact) in [(0.5, 5e-3), (0.99, 9.9e-3), (0.999, 9.99e-3)] {
            let v = h.quantile_seconds(q).unwrap();
            assert!(v >= exact && v <= exact * 1.0906, "p{q}: {v} vs {exact}");
        }
        assert_eq!(h.quantile_seconds(1.0), Some(10e-3));
        assert!((h.sum_seconds() - 5.005).abs() < 1e-9);
        assert_eq!(h.max_ns(), 10_000_000);
        h.record(Duration::from_secs(1000));
        assert_eq!(h.quantile_seconds(1.0), Some(1000.0), "overflow: the max");
        assert_eq!(h.nonempty_buckets().last().unwrap().0, f64::INFINITY);
    }
}
