//! The RSI server's counters and histograms: reply latency (datagram
//! received → reply sent), inter-arrival times, IPOC steps, the controller's
//! `Delay`, corrections applied, clamp and slew hits, dropped datagrams by
//! reason, the controller session's restarts, frozen-invalid cycles.
//! Atomics and histograms of `photopose-telemetry`, written by the RSI
//! thread and read from any other thread (metrics, logs) without locking;
//! exported as `photopose_rsi_*` through its [`Collect`] implementation.

use photopose_telemetry::{Collect, Counter, Scrape};
use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::time::{Duration, Instant};

/// The daemon's one latency histogram (eight buckets per octave, 1 µs to
/// about 134 s): recording is lock-free and allocation-free.
pub use photopose_telemetry::Histogram;

/// The server's live counters.
#[derive(Debug, Default)]
pub struct Stats {
    /// Datagrams read from the socket, whatever they held.
    pub received: Counter,
    /// Controller cycles answered (new, larger IPOCs of the session).
    pub cycles: Counter,
    /// Replies sent.
    pub replies: Counter,
    /// Datagrams dropped because they did not parse (garbage, truncated,
    /// oversized).
    pub garbage: Counter,
    /// Datagrams dropped because their sender is not a configured controller.
    pub unlisted: Counter,
    /// Older queued datagrams skipped in favour of a newer one.
    pub drained: Counter,
    /// Datagrams from a listed address but not the session's port, dropped.
    pub foreign_port: Counter,
    /// Datagrams of the session with an IPOC older than the last, dropped.
    pub stale_ipoc: Counter,
    /// Datagrams of the session repeating the last IPOC (answered with the
    /// same reply, never a new step).
    pub repeated: Counter,
    /// Controller sessions opened after the first (RSI restarted).
    pub session_restarts: Counter,
    /// Cycles frozen because the correction was not finite or outside the
    /// limits (`frozen_invalid`).
    pub invalid_cycles: Counter,
    /// Replies the socket refused to send.
    pub send_errors: Counter,
    /// Last `Delay D` the controller reported.
    pub delay_last: AtomicU64,
    /// Largest `Delay D` seen.
    pub delay_max: AtomicU64,
    /// Last IPOC step (difference to the previous answered IPOC).
    pub ipoc_step_last: AtomicU64,
    /// IPOC steps that differ from the first step seen (missed cycles).
    pub ipoc_irregular: Counter,
    /// Cycles with a non-zero correction sent (relative) or a changed total
    /// (absolute).
    pub corrections_applied: Counter,
    /// Cycles where the total clamp cut the target.
    pub clamp_hits: Counter,
    /// Cycles where the slew limit cut the step.
    pub slew_hits: Counter,
    /// Cycles with a stale measurement (correction frozen).
    pub stale_cycles: Counter,
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
    /// The IPOC of the datagram that carried the last `RIst`.
    pub rist_ipoc: AtomicU64,
    /// When that datagram arrived: ns after [`epoch`].
    pub rist_arrival_ns: AtomicU64,
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

    /// Stores a cycle's `RIst` with the IPOC of its datagram and the
    /// datagram's arrival.
    pub fn record_rist(&self, ipoc: u64, arrival: Instant, pose: &[f64; 6]) {
        for (a, v) in self.rist.iter().zip(pose) {
            a.store(v.to_bits(), Ordering::Relaxed);
        }
        self.rist_ipoc.store(ipoc, Ordering::Relaxed);
        let since = arrival.saturating_duration_since(epoch()).as_nanos();
        self.rist_arrival_ns
            .store(u64::try_from(since).unwrap_or(u64::MAX), Ordering::Relaxed);
        self.rist_cycles.fetch_add(1, Ordering::Release);
    }

    /// The last `RIst` with its IPOC and age at `now`, unless none came yet
    /// or it is older than `silence` (the controller stopped sending). As
    /// with [`Stats::robot_pose`], while the robot moves the values may
    /// come from two consecutive cycles.
    pub fn robot_reading(&self, now: Instant, silence: Duration) -> Option<RobotReading> {
        if self.rist_cycles.load(Ordering::Acquire) == 0 {
            return None;
        }
        let arrival = epoch() + Duration::from_nanos(self.rist_arrival_ns.load(Ordering::Relaxed));
        let age = now.saturating_duration_since(arrival);
        (age <= silence).then(|| RobotReading {
            ipoc: self.rist_ipoc.load(Ordering::Relaxed),
            age,
            xyzabc: std::array::from_fn(|k| f64::from_bits(self.rist[k].load(Ordering::Relaxed))),
        })
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
        let us = |s: Option<f64>| s.map(|s| s * 1e6);
        StatsSnapshot {
            received: self.received.get(),
            cycles: self.cycles.get(),
            replies: self.replies.get(),
            garbage: self.garbage.get(),
            unlisted: self.unlisted.get(),
            drained: self.drained.get(),
            foreign_port: self.foreign_port.get(),
            stale_ipoc: self.stale_ipoc.get(),
            repeated: self.repeated.get(),
            session_restarts: self.session_restarts.get(),
            invalid_cycles: self.invalid_cycles.get(),
            send_errors: self.send_errors.get(),
            delay_last: g(&self.delay_last),
            delay_max: g(&self.delay_max),
            ipoc_step_last: g(&self.ipoc_step_last),
            ipoc_irregular: self.ipoc_irregular.get(),
            corrections_applied: self.corrections_applied.get(),
            clamp_hits: self.clamp_hits.get(),
            slew_hits: self.slew_hits.get(),
            stale_cycles: self.stale_cycles.get(),
            latency_p50_us: us(self.latency.quantile_seconds(0.5)),
            latency_p99_us: us(self.latency.quantile_seconds(0.99)),
            latency_p999_us: us(self.latency.quantile_seconds(0.999)),
            latency_max_us: self.latency.max_ns() as f64 / 1000.0,
            interarrival_p50_us: us(self.interarrival.quantile_seconds(0.5)),
            interarrival_p999_us: us(self.interarrival.quantile_seconds(0.999)),
            interarrival_max_us: self.interarrival.max_ns() as f64 / 1000.0,
        }
    }
}

/// The process-wide origin of the arrival instants kept as ns in [`Stats`].
pub fn epoch() -> Instant {
    static EPOCH: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

/// The robot's last reported pose, as [`Stats::robot_reading`] gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotReading {
    /// IPOC of the datagram that carried it.
    pub ipoc: u64,
    /// Time since that datagram arrived.
    pub age: Duration,
    /// KUKA `X, Y, Z` (mm), `A, B, C` (degrees).
    pub xyzabc: [f64; 6],
}

/// A copy of [`Stats`] with the histograms reduced to quantiles (µs, the
/// upper edges of their buckets: at most 9.05 % high), for reports.
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

impl Collect for Stats {
    fn collect(&self, out: &mut Scrape<'_>) -> std::fmt::Result {
        for (name, help, c) in [
            (
                "photopose_rsi_received_total",
                "Datagrams read from the RSI socket, whatever they held.",
                &self.received,
            ),
            (
                "photopose_rsi_cycles_total",
                "Controller cycles answered (new, larger IPOCs of the session).",
                &self.cycles,
            ),
            (
                "photopose_rsi_replies_total",
                "RSI replies sent.",
                &self.replies,
            ),
            (
                "photopose_rsi_garbage_dropped_total",
                "Datagrams dropped because they did not parse (garbage, truncated, oversized).",
                &self.garbage,
            ),
            (
                "photopose_rsi_unlisted_dropped_total",
                "Datagrams dropped because their sender is not a configured controller.",
                &self.unlisted,
            ),
            (
                "photopose_rsi_drained_total",
                "Older queued datagrams skipped in favour of a newer one.",
                &self.drained,
            ),
            (
                "photopose_rsi_foreign_port_dropped_total",
                "Datagrams from a listed address but not the session's port, dropped.",
                &self.foreign_port,
            ),
            (
                "photopose_rsi_stale_ipoc_dropped_total",
                "Datagrams of the session with an IPOC older than the last, dropped.",
                &self.stale_ipoc,
            ),
            (
                "photopose_rsi_repeated_ipoc_total",
                "Datagrams repeating the last IPOC (answered with the same reply).",
                &self.repeated,
            ),
            (
                "photopose_rsi_session_restarts_total",
                "Controller sessions opened after the first (RSI restarted).",
                &self.session_restarts,
            ),
            (
                "photopose_rsi_invalid_cycles_total",
                "Cycles frozen because the correction was not finite or outside the limits.",
                &self.invalid_cycles,
            ),
            (
                "photopose_rsi_send_errors_total",
                "RSI replies the socket refused to send.",
                &self.send_errors,
            ),
            (
                "photopose_rsi_ipoc_irregular_total",
                "IPOC steps that differ from the first step seen (missed cycles).",
                &self.ipoc_irregular,
            ),
            (
                "photopose_rsi_corrections_applied_total",
                "Cycles with a non-zero correction sent (relative) or a changed total (absolute).",
                &self.corrections_applied,
            ),
            (
                "photopose_rsi_clamp_hits_total",
                "Cycles where the total clamp cut the target.",
                &self.clamp_hits,
            ),
            (
                "photopose_rsi_slew_hits_total",
                "Cycles where the slew limit cut the step.",
                &self.slew_hits,
            ),
            (
                "photopose_rsi_stale_cycles_total",
                "Cycles with a stale measurement (correction frozen).",
                &self.stale_cycles,
            ),
        ] {
            out.counter(name, help, c.get())?;
        }
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        out.counter(
            "photopose_rsi_robot_pose_cycles_total",
            "Cycles whose datagram carried the robot's actual pose (RIst).",
            g(&self.rist_cycles),
        )?;
        out.counter(
            "photopose_rsi_loop_turns_total",
            "Turns of the RSI thread's loop (a datagram or a receive timeout each).",
            g(&self.loops),
        )?;
        out.gauge(
            "photopose_rsi_controller_delay",
            "Late or missing replies the controller counts now (its Delay D).",
            g(&self.delay_last) as f64,
        )?;
        out.gauge(
            "photopose_rsi_controller_delay_max",
            "Largest Delay D the controller reported.",
            g(&self.delay_max) as f64,
        )?;
        out.gauge(
            "photopose_rsi_ipoc_step",
            "Last IPOC step (difference to the previous answered IPOC, controller ticks).",
            g(&self.ipoc_step_last) as f64,
        )?;
        let code = self.status.load(Ordering::Relaxed);
        let mut states = [("waiting_for_controller", 0.0); 11];
        for (k, s) in states.iter_mut().enumerate().skip(1) {
            let st = crate::law::LawStatus::from_code(k as u8 - 1);
            *s = (
                st.map_or("unknown", |st| st.name()),
                f64::from(u8::from(code == k as u8 - 1)),
            );
        }
        states[0].1 = f64::from(u8::from(crate::law::LawStatus::from_code(code).is_none()));
        out.gauge_family(
            "photopose_rsi_state",
            "State of the correction law in the last cycle: 1 for the current state.",
            "state",
            &states,
        )?;
        out.histogram(
            "photopose_rsi_reply_latency_seconds",
            "RSI reply latency: datagram received to reply sent.",
            &self.latency,
        )?;
        out.gauge(
            "photopose_rsi_reply_latency_max_seconds",
            "Largest RSI reply latency since start.",
            self.latency.max_ns() as f64 / 1e9,
        )?;
        out.histogram(
            "photopose_rsi_interarrival_seconds",
            "Time between answered controller datagrams.",
            &self.interarrival,
        )?;
        out.gauge(
            "photopose_rsi_interarrival_max_seconds",
            "Largest time between answered controller datagrams since start.",
            self.interarrival.max_ns() as f64 / 1e9,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn snapshot_quantiles_come_from_the_histogram() {
        let s = Stats::new();
        assert_eq!(s.snapshot().latency_p50_us, None);
        for us in 1..=1000u64 {
            s.latency.record_ns(us * 1000 - 500);
        }
        let snap = s.snapshot();
        let p50 = snap.latency_p50_us.unwrap();
        let p99 = snap.latency_p99_us.unwrap();
        assert!((500.0..=500.0 * 1.0906).contains(&p50), "{p50}");
        assert!((990.0..=990.0 * 1.0906).contains(&p99), "{p99}");
        assert_eq!(snap.latency_max_us, 999.5);
    }

    #[test]
    fn the_robot_reading_has_its_ipoc_and_age_and_expires() {
        let s = Stats::new();
        let silence = Duration::from_millis(100);
        let t0 = epoch() + Duration::from_secs(1);
        assert_eq!(s.robot_reading(t0, silence), None);
        let pose = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        s.record_rist(4711, t0, &pose);
        let r = s
            .robot_reading(t0 + Duration::from_millis(30), silence)
            .unwrap();
        assert_eq!((r.ipoc, r.xyzabc), (4711, pose));
        assert_eq!(r.age, Duration::from_millis(30));
        assert_eq!(s.robot_pose(), Some(pose));
        // Silent longer than the session's timeout: no robot any more.
        assert_eq!(
            s.robot_reading(t0 + Duration::from_millis(101), silence),
            None
        );
        // An arrival the reader has not seen yet is not negative.
        let r = s
            .robot_reading(t0 - Duration::from_millis(1), silence)
            .unwrap();
        assert_eq!(r.age, Duration::ZERO);
    }

    #[test]
    fn every_metric_has_help_and_follows_the_scheme() {
        let s = Arc::new(Stats::new());
        s.cycles.inc();
        s.latency.record_ns(250_000);
        s.status.store(0, Ordering::Relaxed);
        let mut e = photopose_telemetry::Exposition::new();
        e.register(s);
        let text = e.render();
        let mut helped = std::collections::HashSet::new();
        for l in text.lines() {
            if let Some(h) = l.strip_prefix("# HELP ") {
                helped.insert(h.split(' ').next().unwrap().to_string());
            } else if !l.starts_with('#') {
                let name = l.split(['{', ' ']).next().unwrap();
                assert!(name.starts_with("photopose_rsi_"), "{l}");
                assert!(!name.contains("_us"), "{l}");
                let family = ["_bucket", "_sum", "_count"]
                    .iter()
                    .find_map(|x| name.strip_suffix(x))
                    .filter(|f| helped.contains(*f))
                    .unwrap_or(name);
                assert!(helped.contains(family), "no HELP for {l}");
            }
        }
        assert!(text.contains("photopose_rsi_cycles_total 1\n"), "{text}");
        assert!(
            text.contains("photopose_rsi_state{state=\"tracking\"} 1"),
            "{text}"
        );
        assert!(
            text.contains("photopose_rsi_state{state=\"waiting_for_controller\"} 0"),
            "{text}"
        );
        assert!(
            text.contains("photopose_rsi_reply_latency_seconds_count 1\n"),
            "{text}"
        );
    }
}
