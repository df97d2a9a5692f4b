//! The host clocks a pose message is stamped with when it is sent:
//! `CLOCK_MONOTONIC` (the clock the frame times of `FrameMeta` are on, and
//! the one `std::time::Instant` reads on Linux) and UTC (`CLOCK_REALTIME`),
//! both in ns. Reading either allocates nothing.

use rustix::time::{clock_gettime, ClockId, Timespec};

fn ns(t: Timespec) -> u64 {
    let s = u64::try_from(t.tv_sec).unwrap_or(0);
    let n = u64::try_from(t.tv_nsec).unwrap_or(0);
    s.saturating_mul(1_000_000_000).saturating_add(n)
}

/// Now on the host's monotonic clock (`CLOCK_MONOTONIC`), ns.
pub fn mono_ns() -> u64 {
    ns(clock_gettime(ClockId::Monotonic))
}

/// Now in UTC (`CLOCK_REALTIME`), ns since the Unix epoch.
pub fn utc_ns() -> u64 {
    ns(clock_gettime(ClockId::Realtime))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_monotonic_clock_is_the_one_instant_reads() {
        // Two instants on either clock, taken in turn: the differences agree
        // within the time the readings took.
        let (i0, m0) = (std::time::Instant::now(), mono_ns());
        std::thread::sleep(std::time::Duration::from_millis(20));
        let (m1, i1) = (mono_ns(), std::time::Instant::now());
        let by_instant = (i1 - i0).as_nanos() as i128;
        let by_mono = i128::from(m1 - m0);
        assert!(by_mono <= by_instant, "{by_mono} > {by_instant}");
        assert!(by_mono >= 20_000_000, "{by_mono}");
        let utc = utc_ns();
        // After 2020-01-01 and before 2100.
        assert!((1_577_836_800_000_000_000..4_102_444_800_000_000_000).contains(&utc));
    }
}
