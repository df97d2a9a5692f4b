//! The RSI sensor server (IO): one dedicated thread bound to the configured
//! address that only receives `<Rob>`, drains the socket and answers the
//! newest datagram to its source, reads the latest measurement from the
//! [`crate::slot`] (never waiting), runs the [`CorrectionLaw`] and writes
//! `<Sen>`. Datagrams from addresses that are not configured controllers,
//! and datagrams that do not parse, are dropped with a log line and a
//! counter. Logs are one line per change of event kind, never per cycle.

use crate::codec::{parse_rob, CodecError, RobFrame, MAX_DATAGRAM};
use crate::config::RsiSettings;
use crate::law::{CorrectionLaw, CorrectionMode, HandEye, LawStatus, Measurement};
use crate::monitor::{Stats, StatsSnapshot};
use crate::slot::SlotReader;
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

/// The one clock the server, the vision side and tests share: seconds
/// since an epoch, from a monotonic [`Instant`].
#[derive(Debug, Clone, Copy)]
pub struct RsiClock {
    epoch: Instant,
}

impl Default for RsiClock {
    fn default() -> Self {
        Self::new()
    }
}

impl RsiClock {
    /// A clock whose epoch is now.
    pub fn new() -> RsiClock {
        RsiClock {
            epoch: Instant::now(),
        }
    }

    /// Seconds since the epoch.
    pub fn now_s(&self) -> f64 {
        self.at(Instant::now())
    }

    /// Seconds since the epoch of an instant.
    pub fn at(&self, t: Instant) -> f64 {
        t.saturating_duration_since(self.epoch).as_secs_f64()
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

    /// Starts the RSI thread on an already bound socket (`settings.bind` is
    /// then not used; e.g. a socket handed over by the service manager).
    pub fn spawn_on(
        socket: UdpSocket,
        settings: RsiSettings,
        hand_eye: HandEye,
        slot: SlotReader,
        clock: RsiClock,
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
    .map_err(|e| format!("{e:?}"))
}

#[cfg(not(unix))]
fn set_fifo(_p: u8) -> Result<(), String> {
    Err("SCHED_FIFO is only available on unix".into())
}

/// Logs one line when the kind of a recurring event changes, counting the
/// repeats in between instead of logging each.
#[derive(Debug, Default)]
struct EventLog {
    last: Option<&'static str>,
    repeats: u64,
}

impl EventLog {
    fn event(&mut self, kind: &'static str, line: impl FnOnce() -> String) {
        if self.last == Some(kind) {
            self.repeats += 1;
            return;
        }
        let rep = std::mem::take(&mut self.repeats);
        if rep > 0 {
            tracing::warn!(target: "photopose::rsi", "{} more {} datagram(s) dropped", rep, self.last.unwrap_or("?"));
        }
        self.last = Some(kind);
        tracing::warn!(target: "photopose::rsi", "{}", line());
    }
}

struct Worker {
    settings: RsiSettings,
    law: CorrectionLaw,
    slot: SlotReader,
    clock: RsiClock,
    socket: UdpSocket,
    stats: Arc<Stats>,
    rx: Vec<u8>,
    tx: Vec<u8>,
    latest: Option<Measurement>,
    drops: EventLog,
    last_status: Option<LawStatus>,
    last_rx: Option<Instant>,
    last_ipoc: Option<u64>,
    first_step: Option<u64>,
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
        Worker {
            law: CorrectionLaw::new(settings.law, hand_eye),
            settings,
            slot,
            clock,
            socket,
            stats,
            // One byte more than the limit, so an oversized datagram shows.
            rx: vec![0; MAX_DATAGRAM + 1],
            tx: vec![0; 4096],
            latest: None,
            drops: EventLog::default(),
            last_status: None,
            last_rx: None,
            last_ipoc: None,
            first_step: None,
        }
    }

    fn allowed(&self, ip: IpAddr) -> bool {
        self.settings.controllers.contains(&ip)
    }

    /// Parses a received datagram, dropping (with a log) what is not an
    /// answerable `<Rob>` from a configured controller.
    fn accept(&mut self, n: usize, from: SocketAddr) -> Option<RobFrame> {
        if !self.allowed(from.ip()) {
            self.stats.unlisted.fetch_add(1, Ordering::Relaxed);
            self.drops.event("unlisted", || {
                format!("dropped a datagram from {from}: not a configured controller")
            });
            return None;
        }
        let r = if n > MAX_DATAGRAM {
            Err(CodecError::Oversize { len: n })
        } else {
            parse_rob(&self.rx[..n])
        };
        match r {
            Ok(f) => Some(f),
            Err(e) => {
                self.stats.garbage.fetch_add(1, Ordering::Relaxed);
                self.drops.event(e.kind(), || {
                    format!("dropped a datagram of {n} bytes from {from}: {e}")
                });
                None
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
            let mut t_rx = Instant::now();
            let mut newest = self.accept(n, from).map(|f| (f, from));
            // Drain: only the newest queued datagram is still answerable.
            if self.socket.set_nonblocking(true).is_ok() {
                while let Ok((n, from)) = self.socket.recv_from(&mut self.rx) {
                    let t = Instant::now();
                    if let Some(f) = self.accept(n, from) {
                        if newest.is_some() {
                            self.stats.drained.fetch_add(1, Ordering::Relaxed);
                        }
                        newest = Some((f, from));
                        t_rx = t;
                    }
                }
                if let Err(e) = self.socket.set_nonblocking(false) {
                    tracing::error!(target: "photopose::rsi", "socket mode: {e}");
                }
            }
            if let Some((frame, from)) = newest {
                self.answer(&frame, from, t_rx);
            }
        }
        tracing::info!(target: "photopose::rsi", "RSI server stopped after {} cycles", self.stats.cycles.load(Ordering::Relaxed));
    }

    fn answer(&mut self, frame: &RobFrame, to: SocketAddr, t_rx: Instant) {
        if let Some(p) = &frame.rist {
            self.stats.record_rist(p);
        }
        if let Some(m) = self.slot.read() {
            self.latest = Some(m);
        }
        let now = self.clock.at(t_rx);
        let before = self.law.total();
        let out = self.law.cycle(now, frame.rsol, self.latest.as_ref());
        let n = match self
            .settings
            .sen
            .write(&out.send, &frame.ipoc, &mut self.tx)
        {
            Ok(n) => n,
            Err(e) => {
                tracing::error!(target: "photopose::rsi", "cannot write the reply: {e}");
                return;
            }
        };
        let sent = self.socket.send_to(&self.tx[..n], to);
        let t_tx = Instant::now();
        let s = &self.stats;
        match sent {
            Ok(_) => {
                s.replies.fetch_add(1, Ordering::Relaxed);
                s.latency.record_ns((t_tx - t_rx).as_nanos() as u64);
            }
            Err(e) => {
                s.send_errors.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(target: "photopose::rsi", "reply to {to}: {e}");
            }
        }
        s.cycles.fetch_add(1, Ordering::Relaxed);
        if let Some(prev) = self.last_rx.replace(t_rx) {
            s.interarrival.record_ns((t_rx - prev).as_nanos() as u64);
        }
        self.bookkeeping(frame, &out, &before);
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
                    s.ipoc_irregular.fetch_add(1, Ordering::Relaxed);
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
            s.corrections_applied.fetch_add(1, Ordering::Relaxed);
        }
        if out.clamped {
            s.clamp_hits.fetch_add(1, Ordering::Relaxed);
        }
        if out.slew_limited {
            s.slew_hits.fetch_add(1, Ordering::Relaxed);
        }
        if matches!(out.status, LawStatus::Stale(_)) {
            s.stale_cycles.fetch_add(1, Ordering::Relaxed);
        }
        s.status.store(out.status.code(), Ordering::Relaxed);
        if self.last_status != Some(out.status) {
            match out.status {
                LawStatus::Stale(_) => {
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
