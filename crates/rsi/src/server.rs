//! The RSI sensor server (IO): one dedicated thread bound to the configured
//! address that only receives `<Rob>`, drains the socket and answers the
//! newest datagram to its source, reads the latest measurement from the
//! [`crate::slot`] (never waiting), runs the [`CorrectionLaw`] and writes
//! `<Sen>`. Only the controller session's new cycles move the correction
//! ([`crate::session`]); datagrams from addresses that are not configured
//! controllers, from other ports, with old IPOCs or that do not parse are
//! dropped and counted. Logs are at most one line per reason per
//! [`LOG_INTERVAL`] (with the count of the repeats), never per cycle.

use crate::codec::{parse_rob, CodecError, RobFrame, MAX_DATAGRAM};
use crate::config::RsiSettings;
use crate::law::{CorrectionLaw, CorrectionMode, HandEye, LawStatus, Measurement};
use crate::monitor::{Stats, StatsSnapshot};
use crate::session::{Session, Verdict};
use crate::slot::SlotReader;
use crate::tap::{CycleRecord, CycleTap};
use std::io;
use std::net::{IpAddr, SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use thiserror::Error;

/// How often the thread looks at its stop flag when no datagram comes.
pub const STOP_POLL: Duration = Duration::from_millis(50);

/// Why the server could not start.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ServerError {
    /// The socket could not be bound or set up.
    #[error("RSI socket {addr}: {source}")]
    Socket {
        /// The address.
        addr: SocketAddr,
        /// The OS error.
        source: io::Error,
    },
    /// The thread could not be spawned.
    #[error("RSI thread: {0}")]
    Thread(io::Error),
}

/// The one clock the server, the vision side and tests share: the host's
/// `CLOCK_MONOTONIC` in seconds — the clock the sources stamp frames on
/// (`FrameMeta::exposure_mono_ns`), so an exposure instant and a
/// controller cycle compare directly. `Instant`s (which read the same
/// clock on Linux but cannot be turned into numbers) are placed on it
/// through the pair of readings taken when the clock is made.
#[derive(Debug, Clone, Copy)]
pub struct RsiClock {
    epoch: Instant,
    epoch_ns: u64,
}

impl Default for RsiClock {
    fn default() -> Self {
        Self::new()
    }
}

impl RsiClock {
    /// The clock, with its `Instant` ↔ `CLOCK_MONOTONIC` pair read now.
    pub fn new() -> RsiClock {
        let epoch = Instant::now();
        RsiClock {
            epoch,
            epoch_ns: photopose_acquire::mono::instant_ns(epoch),
        }
    }

    /// Now, s on `CLOCK_MONOTONIC`.
    pub fn now_s(&self) -> f64 {
        Self::mono_s(photopose_acquire::mono::now_ns())
    }

    /// An instant, s on `CLOCK_MONOTONIC`.
    pub fn at(&self, t: Instant) -> f64 {
        let ns = if t >= self.epoch {
            self.epoch_ns
                .saturating_add((t - self.epoch).as_nanos() as u64)
        } else {
            self.epoch_ns
                .saturating_sub((self.epoch - t).as_nanos() as u64)
        };
        Self::mono_s(ns)
    }

    /// A `CLOCK_MONOTONIC` instant in ns (a frame's exposure), in s: the
    /// one conversion of the law's time base.
    pub fn mono_s(ns: u64) -> f64 {
        ns as f64 * 1e-9
    }
}

/// A running RSI server; stop it with [`RsiServer::stop`] (also on drop).
#[derive(Debug)]
pub struct RsiServer {
    stop: Arc<AtomicBool>,
    stats: Arc<Stats>,
    local: SocketAddr,
    handle: Option<JoinHandle<()>>,
}

impl RsiServer {
    /// Binds the socket and starts the RSI thread.
    pub fn spawn(
        settings: RsiSettings,
        hand_eye: HandEye,
        slot: SlotReader,
        clock: RsiClock,
    ) -> Result<RsiServer, ServerError> {
        let socket = UdpSocket::bind(settings.bind).map_err(|source| ServerError::Socket {
            addr: settings.bind,
            source,
        })?;
        Self::spawn_on(socket, settings, hand_eye, slot, clock)
    }

    /// [`RsiServer::spawn`] handing a record of every answered cycle to
    /// `tap` (never waiting: a full tap drops the record and counts it).
    pub fn spawn_tapped(
        settings: RsiSettings,
        hand_eye: HandEye,
        slot: SlotReader,
        clock: RsiClock,
        tap: Arc<CycleTap>,
    ) -> Result<RsiServer, ServerError> {
        let socket = UdpSocket::bind(settings.bind).map_err(|source| ServerError::Socket {
            addr: settings.bind,
            source,
        })?;
        Self::spawn_inner(socket, settings, hand_eye, slot, clock, Some(tap))
    }

    /// Starts the RSI thread on an already bound socket (`settings.bind` is
    /// then not used; e.g. a socket handed over by the service manager).
    pub fn spawn_on(
        socket: UdpSocket,
        settings: RsiSettings,
        hand_eye: HandEye,
        slot: SlotReader,
        clock: RsiClock,
    ) -> Result<RsiServer, ServerError> {
        Self::spawn_inner(socket, settings, hand_eye, slot, clock, None)
    }

    fn spawn_inner(
        socket: UdpSocket,
        settings: RsiSettings,
        hand_eye: HandEye,
        slot: SlotReader,
        clock: RsiClock,
        tap: Option<Arc<CycleTap>>,
    ) -> Result<RsiServer, ServerError> {
        let sock_err = |source| ServerError::Socket {
            addr: settings.bind,
            source,
        };
        socket.set_read_timeout(Some(STOP_POLL)).map_err(sock_err)?;
        let local = socket.local_addr().map_err(sock_err)?;
        for w in &settings.warnings {
            tracing::warn!(target: "photopose::rsi", "{w}");
        }
        let stop = Arc::new(AtomicBool::new(false));
        let stats = Arc::new(Stats::new());
        let (s2, st2) = (stop.clone(), stats.clone());
        let handle = std::thread::Builder::new()
            .name("rsi".into())
            .spawn(move || {
                setup_thread(&settings);
                let mut w = Worker::new(settings, hand_eye, slot, clock, socket, st2);
                w.tap = tap;
                w.run(&s2);
            })
            .map_err(ServerError::Thread)?;
        tracing::info!(target: "photopose::rsi", "RSI server listening on {local}");
        Ok(RsiServer {
            stop,
            stats,
            local,
            handle: Some(handle),
        })
    }

    /// The bound address (useful with port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// The live counters.
    pub fn stats(&self) -> &Arc<Stats> {
        &self.stats
    }

    /// The law's status of the last cycle (`None` before the first cycle),
    /// for the pose stream's status flag.
    pub fn status(&self) -> Option<LawStatus> {
        LawStatus::from_code(self.stats.status.load(Ordering::Relaxed))
    }

    /// Stops the thread, waits for it and returns the final counters.
    pub fn stop(mut self) -> StatsSnapshot {
        self.shutdown();
        self.stats.snapshot()
    }

    fn shutdown(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            if h.join().is_err() {
                tracing::error!(target: "photopose::rsi", "RSI thread panicked");
            }
        }
    }
}

impl Drop for RsiServer {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// Real-time priority and CPU pinning: failures are warnings.
fn setup_thread(s: &RsiSettings) {
    if let Some(cpu) = s.cpu {
        let ok = core_affinity::get_core_ids()
            .and_then(|ids| ids.into_iter().find(|c| c.id == cpu))
            .is_some_and(core_affinity::set_for_current);
        if ok {
            tracing::info!(target: "photopose::rsi", "RSI thread pinned to CPU {cpu}");
        } else {
            tracing::warn!(target: "photopose::rsi", "could not pin the RSI thread to CPU {cpu}; running unpinned");
        }
    }
    if let Some(p) = s.realtime_priority {
        match set_fifo(p) {
            Ok(()) => {
                tracing::info!(target: "photopose::rsi", "RSI thread runs SCHED_FIFO priority {p}")
            }
            Err(e) => tracing::warn!(
                target: "photopose::rsi",
                "could not get SCHED_FIFO priority {p} ({e}); running with normal priority (grant CAP_SYS_NICE or an rtprio limit)"
            ),
        }
    }
}

/// Gives the calling thread SCHED_FIFO priority `p` (1–99).
pub fn set_realtime_priority(p: u8) -> Result<(), String> {
    set_fifo(p)
}

#[cfg(unix)]
fn set_fifo(p: u8) -> Result<(), String> {
    use thread_priority::unix::{
        set_thread_priority_and_policy, thread_native_id, RealtimeThreadSchedulePolicy,
        ThreadSchedulePolicy,
    };
    use thread_priority::{ThreadPriority, ThreadPriorityValue};
    let value = ThreadPriorityValue::try_from(p).map_err(|e| e.to_string())?;
    set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .map_err(|e| e.to_string())
}

#[cfg(not(unix))]
fn set_fifo(_p: u8) -> Result<(), String> {
    Err("SCHED_FIFO is only available on unix".into())
}

/// How often one reason of a recurring event (a dropped datagram, a failed
/// send) is logged at most; the repeats in between are counted in the next
/// line and in the counters.
pub const LOG_INTERVAL: Duration = Duration::from_secs(10);

/// Reasons tracked by one [`RateLog`] (more share the last entry).
const LOG_REASONS: usize = 32;

/// One log line per reason per [`LOG_INTERVAL`], with the count of the
/// repeats since the last line. Fixed-size, allocation-free bookkeeping;
/// time passed in.
#[derive(Debug)]
pub struct RateLog {
    reasons: [(&'static str, Option<Instant>, u64); LOG_REASONS],
    used: usize,
    interval: Duration,
}

impl RateLog {
    /// An empty log limiting each reason to one line per `interval`.
    pub fn new(interval: Duration) -> RateLog {
        RateLog {
            reasons: [("", None, 0); LOG_REASONS],
            used: 0,
            interval,
        }
    }

    /// An event of `reason` at `now`: `Some(repeats suppressed since the
    /// last line)` when a line is due, `None` when it is only counted.
    pub fn due(&mut self, reason: &'static str, now: Instant) -> Option<u64> {
        let k = match self.reasons[..self.used].iter().position(|r| r.0 == reason) {
            Some(k) => k,
            None if self.used < LOG_REASONS => {
                self.used += 1;
                self.reasons[self.used - 1] = (reason, None, 0);
                self.used - 1
            }
            None => LOG_REASONS - 1,
        };
        let entry = &mut self.reasons[k];
        match entry.1 {
            Some(last) if now.saturating_duration_since(last) < self.interval => {
                entry.2 += 1;
                None
            }
            _ => {
                entry.1 = Some(now);
                Some(std::mem::take(&mut entry.2))
            }
        }
    }

    /// Logs a warning for `reason` if one is due.
    fn warn(&mut self, reason: &'static str, now: Instant, line: impl FnOnce() -> String) {
        if let Some(more) = self.due(reason, now) {
            if more > 0 {
                tracing::warn!(target: "photopose::rsi", "{} ({more} more {reason} since the last report)", line());
            } else {
                tracing::warn!(target: "photopose::rsi", "{}", line());
            }
        }
    }
}

/// The datagram chosen to be answered after a drain.
#[derive(Debug, Clone, Copy)]
struct Pending {
    frame: RobFrame,
    /// The sender as received (the reply goes there).
    to: SocketAddr,
    t_rx: Instant,
    /// It restarted the session: the law starts again from zero.
    restart: bool,
}

/// Most datagrams read in one drain before the newest cycle is answered:
/// a flood cannot hold the reply back for longer than this many reads.
pub const DRAIN_MAX: usize = 256;

struct Worker {
    settings: RsiSettings,
    law: CorrectionLaw,
    slot: SlotReader,
    clock: RsiClock,
    socket: UdpSocket,
    stats: Arc<Stats>,
    rx: Vec<u8>,
    tx: Vec<u8>,
    /// Length of the last reply in `tx` and where it went.
    last_reply: Option<(usize, SocketAddr)>,
    session: Session,
    latest: Option<Measurement>,
    log: RateLog,
    last_status: Option<LawStatus>,
    last_rx: Option<Instant>,
    last_ipoc: Option<u64>,
    first_step: Option<u64>,
    /// Where a record of each answered cycle goes, if anywhere.
    tap: Option<Arc<CycleTap>>,
}

impl Worker {
    fn new(
        settings: RsiSettings,
        hand_eye: HandEye,
        slot: SlotReader,
        clock: RsiClock,
        socket: UdpSocket,
        stats: Arc<Stats>,
    ) -> Worker {
        let tx = vec![0; settings.reply_capacity()];
        Worker {
            law: CorrectionLaw::new(settings.law, hand_eye),
            session: Session::new(settings.session_idle.as_secs_f64()),
            settings,
            slot,
            clock,
            socket,
            stats,
            // One byte more than the limit, so an oversized datagram shows.
            rx: vec![0; MAX_DATAGRAM + 1],
            tx,
            last_reply: None,
            latest: None,
            log: RateLog::new(LOG_INTERVAL),
            last_status: None,
            last_rx: None,
            last_ipoc: None,
            first_step: None,
            tap: None,
        }
    }

    fn allowed(&self, ip: IpAddr) -> bool {
        // An IPv4-mapped sender (a dual-stack socket) is its IPv4 address.
        self.settings.controllers.contains(&ip.to_canonical())
    }

    /// Sorts one received datagram: counts and drops what is not from the
    /// session or does not parse, keeps the newest cycle in `pending`, and
    /// notes a repeat of the last answered IPOC.
    fn sort(
        &mut self,
        n: usize,
        from: SocketAddr,
        t: Instant,
        pending: &mut Option<Pending>,
        repeat: &mut bool,
    ) {
        let s = &self.stats;
        s.received.inc();
        if !self.allowed(from.ip()) {
            s.unlisted.inc();
            self.log.warn("unlisted", t, || {
                format!("dropped a datagram from {from}: not a configured controller")
            });
            return;
        }
        let now_s = self.clock.at(t);
        if self.session.is_foreign(from, now_s) {
            s.foreign_port.inc();
            let peer = self.session.peer();
            self.log.warn("foreign_port", t, || {
                format!(
                    "dropped a datagram from {from}: the controller session is {}",
                    peer.map_or_else(|| "-".to_string(), |p| p.to_string())
                )
            });
            return;
        }
        let frame = if n > MAX_DATAGRAM {
            Err(CodecError::Oversize { len: n })
        } else {
            parse_rob(&self.rx[..n])
        };
        let frame = match frame {
            Ok(f) => f,
            Err(e) => {
                s.garbage.inc();
                self.log.warn(e.kind(), t, || {
                    format!("dropped a datagram of {n} bytes from {from}: {e}")
                });
                return;
            }
        };
        let ipoc = frame.ipoc.value();
        let verdict = self.session.classify(from, ipoc, now_s);
        match verdict {
            Verdict::Open | Verdict::Advance | Verdict::Restart => {
                if pending.is_some() {
                    s.drained.inc();
                }
                // A restart earlier in this drain still applies.
                let restart =
                    verdict == Verdict::Restart || pending.as_ref().is_some_and(|p| p.restart);
                if verdict == Verdict::Restart {
                    let old = self.session.peer();
                    tracing::warn!(
                        target: "photopose::rsi",
                        "controller session restarts at {from} IPOC {ipoc} (was {}, silent for the idle time): correction back to zero",
                        old.map_or_else(|| "-".to_string(), |p| p.to_string())
                    );
                } else if verdict == Verdict::Open {
                    tracing::info!(target: "photopose::rsi", "controller session opened by {from} at IPOC {ipoc}");
                }
                self.session.commit(from, ipoc, now_s);
                *pending = Some(Pending {
                    frame,
                    to: from,
                    t_rx: t,
                    restart,
                });
                *repeat = false;
            }
            Verdict::Repeat => {
                s.repeated.inc();
                if pending.is_none() {
                    *repeat = true;
                }
            }
            Verdict::Older => {
                s.stale_ipoc.inc();
                self.log.warn("stale_ipoc", t, || {
                    format!("dropped a datagram from {from}: IPOC {ipoc} is older than the session's last")
                });
            }
            Verdict::Foreign => {
                s.foreign_port.inc();
            }
        }
    }

    fn run(&mut self, stop: &AtomicBool) {
        while !stop.load(Ordering::Relaxed) {
            self.stats.loops.fetch_add(1, Ordering::Relaxed);
            let (n, from) = match self.socket.recv_from(&mut self.rx) {
                Ok(x) => x,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock
                            | io::ErrorKind::TimedOut
                            | io::ErrorKind::Interrupted
                    ) =>
                {
                    continue
                }
                Err(e) => {
                    // E.g. ICMP port unreachable from an earlier reply.
                    tracing::debug!(target: "photopose::rsi", "recv: {e}");
                    continue;
                }
            };
            let mut pending = None;
            let mut repeat = false;
            self.sort(n, from, Instant::now(), &mut pending, &mut repeat);
            // Drain: only the newest queued cycle is still answerable. A
            // flood is read at most DRAIN_MAX datagrams deep before the
            // newest cycle found is answered.
            if self.socket.set_nonblocking(true).is_ok() {
                for _ in 1..DRAIN_MAX {
                    let Ok((n, from)) = self.socket.recv_from(&mut self.rx) else {
                        break;
                    };
                    self.sort(n, from, Instant::now(), &mut pending, &mut repeat);
                }
                if let Err(e) = self.socket.set_nonblocking(false) {
                    tracing::error!(target: "photopose::rsi", "socket mode: {e}");
                }
            }
            if let Some(p) = pending {
                self.answer(&p);
            } else if repeat {
                self.repeat_reply();
            }
        }
        tracing::info!(target: "photopose::rsi", "RSI server stopped after {} cycles", self.stats.cycles.get());
    }

    /// The session's last IPOC came again: the same reply, unchanged.
    fn repeat_reply(&mut self) {
        if let Some((n, to)) = self.last_reply {
            if let Err(e) = self.socket.send_to(&self.tx[..n], to) {
                self.stats.send_errors.inc();
                self.log.warn("send_error", Instant::now(), || {
                    format!("reply to {to}: {e}")
                });
            }
        }
    }

    fn answer(&mut self, p: &Pending) {
        let (frame, to, t_rx) = (&p.frame, p.to, p.t_rx);
        if p.restart {
            self.stats.session_restarts.inc();
            self.law.reset();
            self.last_ipoc = None;
            self.first_step = None;
        }
        if let Some(r) = &frame.rist {
            self.stats.record_rist(frame.ipoc.value(), t_rx, r);
        }
        if let Some(m) = self.slot.read() {
            self.latest = Some(m);
        }
        let now = self.clock.at(t_rx);
        let before = self.law.total();
        let mut out = self
            .law
            .cycle_at(now, frame.ipoc.value(), frame.rsol, self.latest.as_ref());
        // The last check before the numbers are written: finite and inside
        // the clamp / slew limit, else the held value.
        if !self.law.admissible(&out.send) {
            out.status = LawStatus::FrozenInvalid;
            out.send = self.law.hold();
        }
        let written = self
            .settings
            .sen
            .write(&out.send, &frame.ipoc, &mut self.tx);
        let n = match written {
            Ok(n) => n,
            Err(e) => {
                self.last_reply = None;
                self.log.warn("write_error", t_rx, || {
                    format!("cannot write the reply: {e}")
                });
                return;
            }
        };
        self.last_reply = Some((n, to));
        let sent = self.socket.send_to(&self.tx[..n], to);
        let t_tx = Instant::now();
        let s = &self.stats;
        match sent {
            Ok(_) => {
                s.replies.inc();
                s.latency.record_ns((t_tx - t_rx).as_nanos() as u64);
            }
            Err(e) => {
                s.send_errors.inc();
                self.log
                    .warn("send_error", t_tx, || format!("reply to {to}: {e}"));
            }
        }
        s.cycles.inc();
        if let Some(prev) = self.last_rx.replace(t_rx) {
            s.interarrival.record_ns((t_rx - prev).as_nanos() as u64);
        }
        self.bookkeeping(frame, &out, &before);
        if let Some(tap) = &self.tap {
            // The arrival instant on both host clocks: now, less the time
            // since the datagram came.
            let back = t_rx.elapsed().as_nanos() as u64;
            tap.push(CycleRecord {
                ipoc: frame.ipoc.value(),
                arrival_utc_ns: crate::tap::utc_ns().saturating_sub(back),
                arrival_mono_ns: crate::tap::monotonic_ns().saturating_sub(back),
                rist: frame.rist,
                rsol: frame.rsol,
                delay: frame.delay,
                sent: out.send,
                total: out.total,
                status: out.status,
                error: out.error,
                slew_limited: out.slew_limited,
                clamped: out.clamped,
            });
        }
    }

    fn bookkeeping(
        &mut self,
        frame: &RobFrame,
        out: &crate::law::CycleOutput,
        before: &crate::codec::Pose6,
    ) {
        let s = &self.stats;
        let ipoc = frame.ipoc.value();
        if let Some(prev) = self.last_ipoc.replace(ipoc) {
            let step = ipoc.wrapping_sub(prev);
            s.ipoc_step_last.store(step, Ordering::Relaxed);
            match self.first_step {
                None => self.first_step = Some(step),
                Some(f) if f != step => {
                    s.ipoc_irregular.inc();
                }
                Some(_) => {}
            }
        }
        if let Some(d) = frame.delay {
            let prev = s.delay_last.swap(d, Ordering::Relaxed);
            s.delay_max.fetch_max(d, Ordering::Relaxed);
            if d != prev && d > 0 {
                tracing::warn!(target: "photopose::rsi", "controller Delay is {d} (late replies counted by the controller; it stops at its Timeout)");
            } else if d == 0 && prev > 0 {
                tracing::info!(target: "photopose::rsi", "controller Delay back to 0");
            }
        }
        let applied = match self.settings.law.mode {
            CorrectionMode::Relative => out.send.iter().any(|v| *v != 0.0),
            CorrectionMode::Absolute => out.total != *before,
        };
        if applied {
            s.corrections_applied.inc();
        }
        if out.clamped {
            s.clamp_hits.inc();
        }
        if out.slew_limited {
            s.slew_hits.inc();
        }
        if matches!(out.status, LawStatus::Stale(_)) {
            s.stale_cycles.inc();
        }
        if out.status == LawStatus::FrozenInvalid {
            s.invalid_cycles.inc();
        }
        s.status.store(out.status.code(), Ordering::Relaxed);
        if self.last_status != Some(out.status) {
            match out.status {
                LawStatus::Stale(_) | LawStatus::FrozenInvalid => {
                    tracing::warn!(target: "photopose::rsi", "correction frozen: {}", out.status.name())
                }
                _ => {
                    tracing::info!(target: "photopose::rsi", "correction state: {}", out.status.name())
                }
            }
            self.last_status = Some(out.status);
        }
        if out.clamped {
            tracing::debug!(target: "photopose::rsi", "total correction clamped");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_line_per_reason_per_interval() {
        let mut log = RateLog::new(Duration::from_secs(10));
        let t0 = Instant::now();
        let mut lines = Vec::new();
        for k in 0..30_000u64 {
            let t = t0 + Duration::from_millis(k);
            for reason in ["unlisted", "syntax", "bad_ipoc"] {
                if let Some(more) = log.due(reason, t) {
                    lines.push((reason, k, more));
                }
            }
        }
        // At 0, 10 and 20 s, each with the repeats since the last line.
        assert_eq!(lines.len(), 9, "{lines:?}");
        assert_eq!(lines[0], ("unlisted", 0, 0));
        assert_eq!(lines[3], ("unlisted", 10_000, 9_999));
        assert_eq!(lines[8], ("bad_ipoc", 20_000, 9_999));
        // More reasons than the table holds share its last entry.
        let mut log = RateLog::new(Duration::from_secs(10));
        let names: Vec<&'static str> = (0..40)
            .map(|k| &*Box::leak(format!("r{k}").into_boxed_str()))
            .collect();
        let due = names.iter().filter(|n| log.due(n, t0).is_some()).count();
        assert_eq!(due, LOG_REASONS);
    }
}
