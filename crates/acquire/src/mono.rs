//! The host's monotonic clock (`CLOCK_MONOTONIC`) in nanoseconds: the one
//! time base of the daemon's instants (frame reception, exposure, the RSI
//! controller's cycles). Rust's `Instant` reads the same clock on Linux but
//! cannot be turned into a number; [`now_ns`] can, and [`instant_ns`]
//! places an `Instant` on it. Read through `rustix`'s safe
//! `clock_gettime` (the workspace denies `unsafe`).

use rustix::time::{clock_gettime, ClockId};
use std::time::Instant;

/// Now on `CLOCK_MONOTONIC`, ns.
pub fn now_ns() -> u64 {
    let ts = clock_gettime(ClockId::Monotonic);
    (ts.tv_sec.max(0) as u64)
        .saturating_mul(1_000_000_000)
        .saturating_add(ts.tv_nsec.max(0) as u64)
}

/// An `Instant` on `CLOCK_MONOTONIC`, ns: now minus how long ago it was
/// (or plus how far ahead it is). Exact up to the few tens of ns between
/// the two clock reads.
pub fn instant_ns(t: Instant) -> u64 {
    let (now, mono) = (Instant::now(), now_ns());
    if t <= now {
        mono.saturating_sub((now - t).as_nanos() as u64)
    } else {
        mono.saturating_add((t - now).as_nanos() as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn agrees_with_instant_and_never_goes_back() {
        let a = now_ns();
        let t = Instant::now();
        let b = now_ns();
        assert!(a > 0 && b >= a);
        let n = instant_ns(t);
        // Within the reads around it (plus slack for a loaded machine).
        assert!(n + 1_000_000 >= a && n <= b + 1_000_000, "{a} {n} {b}");
        let later = instant_ns(t + Duration::from_millis(5));
        assert!(later.abs_diff(n + 5_000_000) < 1_000_000);
        let mut last = now_ns();
        for _ in 0..1000 {
            let x = now_ns();
            assert!(x >= last);
            last = x;
        }
    }
}
