//! Liveness of the daemon's own threads and the systemd watchdog.
//!
//! Every dedicated thread (grabber, detection workers, output, RSI) shows
//! that it is alive and turning by advancing a counter on every turn of its
//! loop, including the turns where nothing arrived (a camera away, a quiet
//! controller). The `watchdog` thread looks at all of them once per tick:
//! when every one advanced since the last tick it sends `WATCHDOG=1`; when
//! one did not, it names it once in the log and stops pinging, so systemd
//! restarts a daemon that is really stuck — and only then. A camera that is
//! away is a reported state (`STATUS=`, metrics, stale messages), not a hang.
//!
//! The tick is half of `WATCHDOG_USEC` (systemd's own advice), or
//! [`STATUS_EVERY`] when no watchdog is asked for (then only `STATUS=` lines
//! are sent).

use crate::notify::Notifier;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How often `STATUS=` is sent when systemd asks for no watchdog.
pub const STATUS_EVERY: Duration = Duration::from_secs(5);

/// A counter a thread advances on every turn of its loop.
#[derive(Debug, Default)]
pub struct Heartbeat(AtomicU64);

impl Heartbeat {
    /// One more turn.
    #[inline]
    pub fn beat(&self) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }

    /// Turns so far.
    pub fn turns(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// How the watchdog reads one thread's turns.
pub type TurnReader = Box<dyn Fn() -> u64 + Send>;

/// The threads the watchdog looks after, by role name (`grabber`,
/// `detect-0`, `output`, `rsi` …).
#[derive(Default)]
pub struct Threads {
    watched: Vec<(String, TurnReader)>,
}

impl std::fmt::Debug for Threads {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list()
            .entries(self.watched.iter().map(|(n, _)| n))
            .finish()
    }
}

impl Threads {
    /// Watches the thread `role` through `turns`.
    pub fn watch(&mut self, role: impl Into<String>, turns: impl Fn() -> u64 + Send + 'static) {
        self.watched.push((role.into(), Box::new(turns)));
    }

    /// Watches the thread `role` through its heartbeat.
    pub fn watch_heartbeat(&mut self, role: impl Into<String>, beat: &Arc<Heartbeat>) {
        let beat = Arc::clone(beat);
        self.watch(role, move || beat.turns());
    }

    /// The roles watched.
    pub fn roles(&self) -> impl Iterator<Item = &str> {
        self.watched.iter().map(|(n, _)| n.as_str())
    }
}

/// What the watchdog found in one tick.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Verdict {
    /// Every watched thread turned since the last tick.
    Alive,
    /// These threads did not turn since the last tick.
    Stuck(Vec<String>),
}

/// Compares the turns of every watched thread with the previous tick.
#[derive(Debug)]
pub struct Liveness {
    threads: Threads,
    last: Vec<u64>,
}

impl Liveness {
    /// Starts from the threads' current turns.
    pub fn new(threads: Threads) -> Liveness {
        let last = threads.watched.iter().map(|(_, t)| t()).collect();
        Liveness { threads, last }
    }

    /// One tick: which threads advanced since the previous one.
    pub fn check(&mut self) -> Verdict {
        let mut stuck = Vec::new();
        for ((role, turns), last) in self.threads.watched.iter().zip(self.last.iter_mut()) {
            let now = turns();
            if now == *last {
                stuck.push(role.clone());
            }
            *last = now;
        }
        if stuck.is_empty() {
            Verdict::Alive
        } else {
            Verdict::Stuck(stuck)
        }
    }
}

/// The watchdog thread: liveness ticks, `WATCHDOG=1` while every thread
/// turns, a `STATUS=` line each tick.
pub struct Watchdog {
    handle: Option<JoinHandle<()>>,
    stop: Arc<AtomicBool>,
}

impl std::fmt::Debug for Watchdog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Watchdog").finish_non_exhaustive()
    }
}

impl Watchdog {
    /// Spawns the watchdog thread. `interval` is systemd's watchdog
    /// interval (`WATCHDOG_USEC`), if it asks for one; `status` makes the
    /// `STATUS=` text (rate, camera, RSI) each tick.
    pub fn spawn(
        notifier: Notifier,
        interval: Option<Duration>,
        threads: Threads,
        mut status: impl FnMut() -> String + Send + 'static,
    ) -> std::io::Result<Watchdog> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let tick = interval.map_or(STATUS_EVERY, |i| (i / 2).max(Duration::from_millis(10)));
        let watched: Vec<&str> = threads.roles().collect();
        tracing::debug!(tick_ms = tick.as_millis() as u64, threads = %watched.join(", "), "watchdog started");
        let handle = std::thread::Builder::new()
            .name("watchdog".into())
            .spawn(move || {
                let mut liveness = Liveness::new(threads);
                let mut reported: Option<Vec<String>> = None;
                let mut next = Instant::now() + tick;
                while !flag.load(Ordering::Acquire) {
                    let now = Instant::now();
                    if now < next {
                        std::thread::sleep((next - now).min(Duration::from_millis(50)));
                        continue;
                    }
                    next += tick;
                    match liveness.check() {
                        Verdict::Alive => {
                            if interval.is_some() {
                                notifier.notify("WATCHDOG=1");
                            }
                            if reported.take().is_some() {
                                tracing::info!("every thread turns again; watchdog pings resumed");
                            }
                        }
                        Verdict::Stuck(roles) => {
                            if reported.as_ref() != Some(&roles) {
                                tracing::error!(
                                    threads = %roles.join(", "),
                                    "thread(s) not turning: watchdog pings withheld (systemd restarts the daemon if this lasts)"
                                );
                                reported = Some(roles);
                            }
                        }
                    }
                    if notifier.enabled() {
                        notifier.notify(&format!("STATUS={}", status()));
                    }
                }
            })?;
        Ok(Watchdog {
            handle: Some(handle),
            stop,
        })
    }

    /// Stops and joins the thread.
    pub fn stop(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

impl Drop for Watchdog {
    fn drop(&mut self) {
        self.shutdown();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thread_that_stops_turning_is_named() {
        let (a, b) = (
            Arc::new(Heartbeat::default()),
            Arc::new(Heartbeat::default()),
        );
        let mut threads = Threads::default();
        threads.watch_heartbeat("output", &a);
        threads.watch_heartbeat("detect-0", &b);
        let mut l = Liveness::new(threads);
        a.beat();
        b.beat();
        assert_eq!(l.check(), Verdict::Alive);
        a.beat();
        assert_eq!(l.check(), Verdict::Stuck(vec!["detect-0".into()]));
        assert_eq!(
            l.check(),
            Verdict::Stuck(vec!["output".into(), "detect-0".into()])
        );
        b.beat();
        a.beat();
        assert_eq!(l.check(), Verdict::Alive);
    }

    #[test]
    fn pings_follow_liveness_on_a_real_notify_socket() {
        use std::os::unix::net::UnixDatagram;
        let dir = std::env::temp_dir().join(format!("pp-wd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("notify.sock");
        let _ = std::fs::remove_file(&path);
        let sock = UnixDatagram::bind(&path).unwrap();
        sock.set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        let beat = Arc::new(Heartbeat::default());
        let alive = Arc::new(AtomicBool::new(true));
        let mut threads = Threads::default();
        threads.watch_heartbeat("output", &beat);
        let wd = Watchdog::spawn(
            Notifier::to_path(&path),
            Some(Duration::from_millis(40)),
            threads,
            || "test".into(),
        )
        .unwrap();
        // A beating thread: pings come.
        let (b, a) = (Arc::clone(&beat), Arc::clone(&alive));
        let beater = std::thread::spawn(move || {
            while a.load(Ordering::Relaxed) {
                b.beat();
                std::thread::sleep(Duration::from_millis(2));
            }
        });
        let count = |for_: Duration| {
            let end = Instant::now() + for_;
            let (mut pings, mut status) = (0, 0);
            let mut buf = [0u8; 256];
            while Instant::now() < end {
                if let Ok(n) = sock.recv(&mut buf) {
                    match &buf[..n] {
                        b"WATCHDOG=1" => pings += 1,
                        m if m.starts_with(b"STATUS=") => status += 1,
                        _ => {}
                    }
                }
            }
            (pings, status)
        };
        let (pings, status) = count(Duration::from_millis(400));
        assert!(pings >= 5, "{pings} pings while the thread turns");
        assert!(status >= 5);
        // The thread stops turning: no more pings, STATUS goes on.
        alive.store(false, Ordering::Relaxed);
        beater.join().unwrap();
        let _ = count(Duration::from_millis(60));
        let (pings, status) = count(Duration::from_millis(400));
        assert_eq!(pings, 0, "pings while the thread is stuck");
        assert!(status >= 5);
        wd.stop();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
