//! Keeping a device open with back-off, off the frame path: the part every
//! camera source shares (GigE Vision in [`crate::gige`], GenTL in
//! `photopose-gentl`).
//!
//! A [`Reopener`] owns the device's link state (idle, opening, waiting to
//! retry, streaming) and two helper threads: an *opener* (`<name>-open`)
//! that runs the source's opening function whenever asked, and a *reaper*
//! (`<name>-reap`) that closes devices handed to it. Opening a device that
//! is not there, or closing one that died, can block for seconds; neither
//! ever happens on the thread that asks for frames.
//!
//! Failed openings are retried after a [`Backoff`] that doubles from its
//! initial value up to its maximum and starts again from the initial value
//! after each successful opening and each loss. A loss is reported once
//! ([`SourceError::Lost`]), then [`SourceError::Unavailable`] until the
//! device is back; a device that refuses its configuration stops the
//! source ([`SourceError::Config`]). A returning device is always opened
//! afresh: a lost handle is never reused. The shared [`SourceCounters`]
//! get `opens`, `losses` and `connected` from here.
//!
//! Dropping a `Reopener` stops it (closing the device, or waiting for an
//! opening under way and closing what it gives) and joins both threads.

use crate::source::{SourceCounters, SourceError};
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long [`Reopener::stop`] waits for an opening under way (openings
/// fail or succeed within seconds).
const OPENING_GRACE: Duration = Duration::from_secs(30);

/// An open device a [`Reopener`] keeps.
pub trait Device: Send + 'static {
    /// The device's name in logs (its id).
    fn id(&self) -> &str;
    /// Stops and releases the device (on the reaper thread); `lost` says it
    /// stopped answering, so nothing should be asked of it that may block.
    fn close(self, lost: bool);
}

/// Why an opening failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OpenFailure {
    /// Not there, or not answering: tried again after the back-off.
    Absent(String),
    /// The device refuses the configuration: fatal.
    Refused {
        /// The setting (feature) concerned.
        what: String,
        /// The device's or library's word.
        reason: String,
    },
}

/// The exponential back-off between openings: `initial`, then doubled at
/// each failure, at most `max`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    initial: Duration,
    max: Duration,
    current: Duration,
}

impl Backoff {
    /// A schedule starting at `initial` and never longer than `max` (nor
    /// shorter than `initial`).
    pub fn new(initial: Duration, max: Duration) -> Self {
        Backoff {
            initial,
            max: max.max(initial),
            current: initial,
        }
    }

    /// The wait before the next attempt.
    pub fn current(&self) -> Duration {
        self.current
    }

    /// The wait before the next attempt; the one after it is doubled.
    pub fn step(&mut self) -> Duration {
        let now = self.current;
        self.current = (self.current * 2).min(self.max);
        now
    }

    /// Back to the initial wait.
    pub fn reset(&mut self) {
        self.current = self.initial;
    }
}

/// The streaming device and what the source tracks per opening.
#[derive(Debug)]
pub struct Live<D> {
    /// The open device.
    pub device: D,
    /// When the last buffer (complete or not) arrived, or the opening.
    pub last_buffer: Instant,
    /// The device's id of the last delivered frame, for counting gaps.
    pub last_frame_id: Option<u64>,
}

enum Link<D> {
    Idle,
    Opening,
    Waiting { until: Instant, reason: String },
    Streaming(Box<Live<D>>),
}

/// Where a [`Reopener`] stands.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum LinkState {
    /// Not started (or stopped, or refused).
    Idle,
    /// An opening is under way on the opener thread.
    Opening,
    /// Waiting until `until` to try again.
    Waiting {
        /// When the next opening is asked for.
        until: Instant,
        /// Why the last attempt failed (or the device was lost).
        reason: String,
    },
    /// The device is open.
    Streaming,
}

/// What [`Reopener::ready`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ready {
    /// Streaming, as before the call.
    Streaming,
    /// The device has just been opened (the source resets what depends on
    /// the opening, e.g. a camera clock map).
    Opened,
}

/// The link to one device, reopened with back-off (see the module docs).
pub struct Reopener<D: Device> {
    name: String,
    noun: &'static str,
    counters: Arc<SourceCounters>,
    link: Link<D>,
    open_tx: Option<Sender<()>>,
    opened_rx: Receiver<Result<D, OpenFailure>>,
    reap_tx: Option<Sender<(D, bool)>>,
    threads: Vec<JoinHandle<()>>,
    backoff: Backoff,
    failures_logged: bool,
}

impl<D: Device> std::fmt::Debug for Reopener<D> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Reopener")
            .field("name", &self.name)
            .field("state", &self.state())
            .field("backoff", &self.backoff)
            .finish()
    }
}

impl<D: Device> Reopener<D> {
    /// Starts the helper threads of source `name` (named `<name>-open` and
    /// `<name>-reap`); `noun` names the device in logs ("camera", "GenTL
    /// device"); `open` is run on the opener thread for each attempt.
    /// Opens nothing yet: see [`Reopener::start`].
    pub fn spawn<F>(
        name: &str,
        noun: &'static str,
        backoff: Backoff,
        counters: Arc<SourceCounters>,
        mut open: F,
    ) -> std::io::Result<Self>
    where
        F: FnMut() -> Result<D, OpenFailure> + Send + 'static,
    {
        let (open_tx, open_rx) = crossbeam_channel::unbounded::<()>();
        let (opened_tx, opened_rx) = crossbeam_channel::unbounded();
        let (reap_tx, reap_rx) = crossbeam_channel::unbounded::<(D, bool)>();
        let opener = std::thread::Builder::new()
            .name(format!("{name}-open"))
            .spawn(move || {
                for () in open_rx {
                    if opened_tx.send(open()).is_err() {
                        break;
                    }
                }
            })?;
        let reaper = std::thread::Builder::new()
            .name(format!("{name}-reap"))
            .spawn(move || {
                for (device, lost) in reap_rx {
                    device.close(lost);
                }
            })?;
        Ok(Reopener {
            name: name.to_string(),
            noun,
            counters,
            link: Link::Idle,
            open_tx: Some(open_tx),
            opened_rx,
            reap_tx: Some(reap_tx),
            threads: vec![opener, reaper],
            backoff,
            failures_logged: false,
        })
    }

    /// Where the link stands.
    pub fn state(&self) -> LinkState {
        match &self.link {
            Link::Idle => LinkState::Idle,
            Link::Opening => LinkState::Opening,
            Link::Waiting { until, reason } => LinkState::Waiting {
                until: *until,
                reason: reason.clone(),
            },
            Link::Streaming(_) => LinkState::Streaming,
        }
    }

    /// The streaming device.
    pub fn live(&self) -> Option<&Live<D>> {
        match &self.link {
            Link::Streaming(live) => Some(live),
            _ => None,
        }
    }

    /// The streaming device, to take a frame from.
    pub fn live_mut(&mut self) -> Option<&mut Live<D>> {
        match &mut self.link {
            Link::Streaming(live) => Some(live),
            _ => None,
        }
    }

    /// Asks for an opening unless already started.
    pub fn start(&mut self) -> Result<(), SourceError> {
        if matches!(self.link, Link::Idle) {
            self.backoff.reset();
            self.request_open()?;
        }
        Ok(())
    }

    /// Gets the link to streaming if it can within `timeout`: `Ok` with the
    /// time left for taking a frame (at least 1 ms when an opening just
    /// completed), or why there is no device now (not started, still
    /// opening, waiting for the back-off, refused). Never blocks longer than
    /// about `timeout`; allocates nothing while streaming.
    pub fn ready(&mut self, timeout: Duration) -> Result<(Ready, Duration), SourceError> {
        let deadline = Instant::now() + timeout;
        match &self.link {
            Link::Streaming(_) => Ok((Ready::Streaming, timeout)),
            Link::Idle => Err(SourceError::Unavailable {
                reason: "not started".into(),
            }),
            Link::Opening => match self.opened_rx.recv_timeout(timeout) {
                Ok(result) => {
                    self.on_opened(result)?;
                    let left = deadline.saturating_duration_since(Instant::now());
                    Ok((Ready::Opened, left.max(Duration::from_millis(1))))
                }
                // The opener is at work: alive, no frame yet.
                Err(RecvTimeoutError::Timeout) => Err(SourceError::Timeout(timeout)),
                Err(RecvTimeoutError::Disconnected) => Err(opener_gone()),
            },
            Link::Waiting { until, reason } => {
                let (until, reason) = (*until, reason.clone());
                let now = Instant::now();
                if now < until {
                    std::thread::sleep((until - now).min(timeout));
                }
                if Instant::now() >= until {
                    self.request_open()?;
                }
                Err(SourceError::Unavailable { reason })
            }
        }
    }

    /// The streaming device is lost (`reason` says how it showed): hands it
    /// to the reaper, counts the loss, waits the initial back-off before
    /// reopening; the error to report this once.
    pub fn lose(&mut self, reason: String) -> SourceError {
        if let Link::Streaming(live) = std::mem::replace(&mut self.link, Link::Idle) {
            tracing::warn!(source = %self.name, device = %live.device.id(), %reason,
                "{} lost", self.noun);
            self.reap(live.device, true);
        }
        self.counters.losses.inc();
        self.backoff.reset();
        self.failures_logged = false;
        self.link = Link::Waiting {
            until: Instant::now() + self.backoff.current(),
            reason: reason.clone(),
        };
        SourceError::Lost { reason }
    }

    /// Closes the device (on the reaper) or, while an opening is under way,
    /// waits for it and closes what it gives; the link is idle afterwards.
    pub fn stop(&mut self) {
        match std::mem::replace(&mut self.link, Link::Idle) {
            Link::Streaming(live) => self.reap(live.device, false),
            Link::Opening => {
                if let Ok(Ok(device)) = self.opened_rx.recv_timeout(OPENING_GRACE) {
                    self.reap(device, false);
                }
            }
            Link::Idle | Link::Waiting { .. } => {}
        }
        self.counters.connected.store(false, Ordering::Relaxed);
    }

    fn request_open(&mut self) -> Result<(), SourceError> {
        match self.open_tx.as_ref().map(|tx| tx.send(())) {
            Some(Ok(())) => {
                self.link = Link::Opening;
                Ok(())
            }
            _ => Err(opener_gone()),
        }
    }

    fn reap(&mut self, device: D, lost: bool) {
        self.counters.connected.store(false, Ordering::Relaxed);
        if let Some(tx) = &self.reap_tx {
            if let Err(e) = tx.send((device, lost)) {
                // Reaper gone (cannot happen before drop): close here.
                let (device, lost) = e.into_inner();
                device.close(lost);
            }
        }
    }

    fn on_opened(&mut self, result: Result<D, OpenFailure>) -> Result<(), SourceError> {
        match result {
            Ok(device) => {
                self.counters.opens.inc();
                self.counters.connected.store(true, Ordering::Relaxed);
                self.backoff.reset();
                self.failures_logged = false;
                self.link = Link::Streaming(Box::new(Live {
                    device,
                    last_buffer: Instant::now(),
                    last_frame_id: None,
                }));
                Ok(())
            }
            Err(OpenFailure::Refused { what, reason }) => {
                tracing::error!(source = %self.name, %what, %reason,
                    "{} refuses the configuration", self.noun);
                self.link = Link::Idle;
                Err(SourceError::Config { what, reason })
            }
            Err(OpenFailure::Absent(reason)) => {
                let wait = self.backoff.step();
                if !self.failures_logged {
                    tracing::warn!(source = %self.name, %reason,
                        "{} not available; retrying with back-off", self.noun);
                    self.failures_logged = true;
                } else {
                    tracing::debug!(source = %self.name, %reason, backoff_ms = wait.as_millis() as u64,
                        "{} open failed", self.noun);
                }
                self.link = Link::Waiting {
                    until: Instant::now() + wait,
                    reason: reason.clone(),
                };
                Err(SourceError::Unavailable { reason })
            }
        }
    }
}

fn opener_gone() -> SourceError {
    SourceError::Config {
        what: "opener thread".into(),
        reason: "gone".into(),
    }
}

impl<D: Device> Drop for Reopener<D> {
    fn drop(&mut self) {
        self.stop();
        self.open_tx = None;
        self.reap_tx = None;
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// What happened to fake devices: (id, lost, closing thread's name).
    type Closed = Arc<Mutex<Vec<(String, bool, String)>>>;
    /// What the opener answers next: a device whose close takes this long,
    /// or absent for this reason.
    type Script = Sender<Result<Duration, String>>;
    /// The names of the threads openings ran on.
    type OpenedOn = Arc<Mutex<Vec<String>>>;

    struct Fake {
        id: String,
        closed: Closed,
        close_takes: Duration,
    }

    impl Device for Fake {
        fn id(&self) -> &str {
            &self.id
        }
        fn close(self, lost: bool) {
            std::thread::sleep(self.close_takes);
            let thread = std::thread::current().name().unwrap_or("").to_string();
            self.closed.lock().unwrap().push((self.id, lost, thread));
        }
    }

    /// A reopener whose opener answers, in turn, what `script` sends (an
    /// `Err(reason)` fails as absent), recording each opening's thread.
    fn scripted(initial_ms: u64, max_ms: u64) -> (Reopener<Fake>, Script, Closed, OpenedOn) {
        let (script_tx, script_rx) = crossbeam_channel::unbounded::<Result<Duration, String>>();
        let closed: Closed = Arc::default();
        let opened_on: OpenedOn = Arc::default();
        let (c, o) = (Arc::clone(&closed), Arc::clone(&opened_on));
        let mut n = 0;
        let reopener = Reopener::spawn(
            "t",
            "fake device",
            Backoff::new(
                Duration::from_millis(initial_ms),
                Duration::from_millis(max_ms),
            ),
            Arc::new(SourceCounters::default()),
            move || {
                let thread = std::thread::current().name().unwrap_or("").to_string();
                o.lock().unwrap().push(thread);
                match script_rx.recv_timeout(Duration::from_secs(10)) {
                    Ok(Ok(close_takes)) => {
                        n += 1;
                        Ok(Fake {
                            id: format!("dev{n}"),
                            closed: Arc::clone(&c),
                            close_takes,
                        })
                    }
                    Ok(Err(reason)) => Err(OpenFailure::Absent(reason)),
                    Err(_) => Err(OpenFailure::Absent("script ended".into())),
                }
            },
        )
        .unwrap();
        (reopener, script_tx, closed, opened_on)
    }

    fn wait_for(r: &mut Reopener<Fake>) -> Result<(Ready, Duration), SourceError> {
        let t0 = Instant::now();
        loop {
            match r.ready(Duration::from_millis(50)) {
                Err(SourceError::Timeout(_)) if t0.elapsed() < Duration::from_secs(10) => {}
                other => return other,
            }
        }
    }

    #[test]
    fn backoff_doubles_up_to_its_maximum_and_resets() {
        let mut b = Backoff::new(Duration::from_millis(100), Duration::from_millis(1000));
        let waits: Vec<u64> = (0..6).map(|_| b.step().as_millis() as u64).collect();
        assert_eq!(waits, [100, 200, 400, 800, 1000, 1000]);
        b.reset();
        assert_eq!(b.current(), Duration::from_millis(100));
        // A maximum below the initial wait does not shorten it.
        let mut b = Backoff::new(Duration::from_millis(300), Duration::from_millis(10));
        assert_eq!(b.step(), Duration::from_millis(300));
        assert_eq!(b.step(), Duration::from_millis(300));
    }

    #[test]
    fn failed_openings_wait_the_back_off_schedule() {
        let (mut r, script, _closed, _) = scripted(40, 100);
        assert_eq!(r.state(), LinkState::Idle);
        assert!(matches!(
            r.ready(Duration::from_millis(1)),
            Err(SourceError::Unavailable { .. })
        ));
        r.start().unwrap();
        assert_eq!(r.state(), LinkState::Opening);
        // Each failure waits the next step: 40, 80, 100, 100 ms.
        for want_ms in [40, 80, 100, 100] {
            script.send(Err("absent".into())).unwrap();
            let before = Instant::now();
            let e = wait_for(&mut r).unwrap_err();
            let after = Instant::now();
            assert!(matches!(e, SourceError::Unavailable { ref reason } if reason == "absent"));
            let LinkState::Waiting { until, reason } = r.state() else {
                panic!("not waiting: {:?}", r.state());
            };
            assert_eq!(reason, "absent");
            let want = Duration::from_millis(want_ms);
            assert!(
                until >= before + want && until <= after + want,
                "wait {want_ms} ms"
            );
            // Waiting reports unavailable until the wait is over, then asks again.
            while r.state() != LinkState::Opening {
                assert!(matches!(
                    r.ready(Duration::from_millis(500)),
                    Err(SourceError::Unavailable { .. })
                ));
                assert!(Instant::now() < after + Duration::from_secs(5));
            }
        }
        // Success: streaming, schedule back to the start.
        script.send(Ok(Duration::ZERO)).unwrap();
        assert_eq!(wait_for(&mut r).unwrap().0, Ready::Opened);
        assert_eq!(r.state(), LinkState::Streaming);
        assert_eq!(
            r.ready(Duration::from_millis(7)).unwrap(),
            (Ready::Streaming, Duration::from_millis(7))
        );
        assert_eq!(r.counters.opens.get(), 1);
        assert!(r.counters.connected.load(Ordering::Relaxed));
        // A loss waits the initial back-off again and is reported once.
        let before = Instant::now();
        assert!(matches!(r.lose("gone".into()), SourceError::Lost { .. }));
        let LinkState::Waiting { until, .. } = r.state() else {
            panic!("not waiting after a loss");
        };
        assert!(until >= before + Duration::from_millis(40));
        assert!(until <= Instant::now() + Duration::from_millis(40));
        assert_eq!(r.counters.losses.get(), 1);
        assert!(!r.counters.connected.load(Ordering::Relaxed));
    }

    #[test]
    fn refused_configuration_stops_the_source() {
        let counters = Arc::new(SourceCounters::default());
        let mut r = Reopener::<Fake>::spawn(
            "t",
            "fake device",
            Backoff::new(Duration::from_millis(10), Duration::from_millis(10)),
            counters,
            || {
                Err(OpenFailure::Refused {
                    what: "PixelFormat".into(),
                    reason: "no".into(),
                })
            },
        )
        .unwrap();
        r.start().unwrap();
        let e = r.ready(Duration::from_secs(10)).unwrap_err();
        assert!(matches!(e, SourceError::Config { ref what, .. } if what == "PixelFormat"));
        assert!(e.is_fatal());
        assert_eq!(r.state(), LinkState::Idle);
    }

    #[test]
    fn opening_and_closing_stay_off_the_frame_path() {
        let (mut r, script, closed, opened_on) = scripted(10, 10);
        r.start().unwrap();
        // An opening that takes long: the caller gets a timeout in its own
        // time, not the opening's.
        let t0 = Instant::now();
        assert!(matches!(
            r.ready(Duration::from_millis(20)),
            Err(SourceError::Timeout(_))
        ));
        assert!(t0.elapsed() < Duration::from_secs(1));
        script.send(Ok(Duration::from_millis(1500))).unwrap();
        assert_eq!(wait_for(&mut r).unwrap().0, Ready::Opened);
        assert_eq!(r.live().unwrap().device.id(), "dev1");
        // A lost device whose close blocks: losing it returns at once.
        let t0 = Instant::now();
        r.lose("silent".into());
        assert!(t0.elapsed() < Duration::from_millis(500));
        drop(r);
        assert_eq!(*opened_on.lock().unwrap(), ["t-open"]);
        assert_eq!(
            *closed.lock().unwrap(),
            [("dev1".to_string(), true, "t-reap".to_string())]
        );
    }

    #[test]
    fn stop_while_reopening() {
        // Stopped while waiting for the back-off: nothing to close, no
        // opening asked for later.
        let (mut r, script, closed, opened_on) = scripted(20, 20);
        r.start().unwrap();
        script.send(Err("absent".into())).unwrap();
        assert!(wait_for(&mut r).is_err());
        assert!(matches!(r.state(), LinkState::Waiting { .. }));
        r.stop();
        assert_eq!(r.state(), LinkState::Idle);
        std::thread::sleep(Duration::from_millis(40));
        assert!(matches!(
            r.ready(Duration::from_millis(40)),
            Err(SourceError::Unavailable { ref reason }) if reason == "not started"
        ));
        assert_eq!(opened_on.lock().unwrap().len(), 1);
        // Stopped while an opening is under way: waits for it and closes
        // the device it gives (not lost) on the reaper.
        r.start().unwrap();
        assert_eq!(r.state(), LinkState::Opening);
        let late = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(50));
            script.send(Ok(Duration::ZERO)).unwrap();
        });
        r.stop();
        late.join().unwrap();
        assert_eq!(r.state(), LinkState::Idle);
        drop(r);
        assert_eq!(
            *closed.lock().unwrap(),
            [("dev1".to_string(), false, "t-reap".to_string())]
        );
    }

    #[test]
    fn a_streaming_device_is_closed_on_drop() {
        let (mut r, script, closed, _) = scripted(10, 10);
        r.start().unwrap();
        script.send(Ok(Duration::ZERO)).unwrap();
        assert_eq!(wait_for(&mut r).unwrap().0, Ready::Opened);
        r.live_mut().unwrap().last_frame_id = Some(3);
        drop(r);
        assert_eq!(
            *closed.lock().unwrap(),
            [("dev1".to_string(), false, "t-reap".to_string())]
        );
    }
}
