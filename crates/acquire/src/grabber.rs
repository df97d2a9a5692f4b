//! The grabber thread: pulls frames from a [`FrameSource`] into the ring's
//! producer slot and publishes them, until a stop flag is raised or the
//! source fails for good. Logs once per change of state (connected, lost,
//! unavailable), never per frame.

use crate::ring::{Producer, Published};
use crate::source::{FrameSource, SourceError};
use photopose_telemetry::{Collect, Counter, Scrape};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long one `next_frame` call may wait, so that the stop flag is seen
/// within about this delay.
pub const POLL: Duration = Duration::from_millis(100);

/// Counters of a grabber (`photopose-telemetry` counters, shared with the
/// spawner).
#[derive(Debug, Default)]
pub struct GrabberCounters {
    /// Frames published into the ring.
    pub published: Counter,
    /// `next_frame` calls that timed out.
    pub timeouts: Counter,
    /// Losses reported by the source.
    pub losses: Counter,
    /// `next_frame` calls answered "unavailable".
    pub unavailable: Counter,
    /// Frames the source could not deliver (skipped).
    pub bad_frames: Counter,
}

impl GrabberCounters {
    /// Turns of the grabber's loop so far: every `next_frame` call ends in
    /// exactly one of the counters, so their sum advances while the thread
    /// is alive and polling, with or without a camera.
    pub fn turns(&self) -> u64 {
        self.published.get()
            + self.timeouts.get()
            + self.losses.get()
            + self.unavailable.get()
            + self.bad_frames.get()
    }
}

impl Collect for GrabberCounters {
    fn collect(&self, out: &mut Scrape<'_>) -> std::fmt::Result {
        for (name, help, c) in [
            (
                "photopose_grabber_frames_published_total",
                "Frames the grabber published into the ring.",
                &self.published,
            ),
            (
                "photopose_grabber_timeouts_total",
                "Frame requests to the source that timed out.",
                &self.timeouts,
            ),
            (
                "photopose_grabber_losses_total",
                "Camera losses the source reported to the grabber.",
                &self.losses,
            ),
            (
                "photopose_grabber_unavailable_total",
                "Frame requests answered \"camera unavailable\".",
                &self.unavailable,
            ),
            (
                "photopose_grabber_bad_frames_total",
                "Frames the source could not deliver (skipped).",
                &self.bad_frames,
            ),
        ] {
            out.counter(name, help, c.get())?;
        }
        Ok(())
    }
}

/// Why a grabber thread ended.
#[derive(Debug)]
pub enum GrabberExit {
    /// The stop flag was raised.
    Stopped,
    /// The source ran out of frames.
    Ended,
    /// The source failed for good (its error).
    Failed(SourceError),
}

/// A running grabber thread.
#[derive(Debug)]
pub struct Grabber<S> {
    handle: JoinHandle<(S, GrabberExit)>,
    counters: Arc<GrabberCounters>,
    stop: Arc<AtomicBool>,
}

impl<S> Grabber<S> {
    /// The grabber's counters.
    pub fn counters(&self) -> &GrabberCounters {
        &self.counters
    }

    /// The grabber's counters, shared (for a watchdog or metrics that
    /// outlive a borrow of the grabber).
    pub fn shared_counters(&self) -> Arc<GrabberCounters> {
        Arc::clone(&self.counters)
    }

    /// Raises the stop flag (the one given at spawn).
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Release);
    }

    /// Whether the thread has ended.
    pub fn is_finished(&self) -> bool {
        self.handle.is_finished()
    }

    /// Waits for the thread; gives the source back (stopped) and why it
    /// ended. A panic in the thread is resumed here.
    pub fn join(self) -> (S, GrabberExit) {
        match self.handle.join() {
            Ok(r) => r,
            Err(panic) => std::panic::resume_unwind(panic),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Starting,
    Streaming,
    Waiting,
    Down,
}

/// Spawns a grabber thread named `name` that runs `source` into `producer`
/// until `stop` is raised (seen within [`POLL`]) or the source fails for
/// good; the source is stopped before the thread ends.
pub fn spawn_grabber<S: FrameSource + 'static>(
    name: &str,
    source: S,
    producer: Producer,
    stop: Arc<AtomicBool>,
) -> std::io::Result<Grabber<S>> {
    spawn_grabber_with(name, source, producer, stop, |_| {})
}

/// [`spawn_grabber`] with an observer told what became of every published
/// frame (on the grabber thread, right after publishing: keep it short and
/// non-blocking). A downstream stage that restores frame order learns of
/// queued frames dropped by `drop-oldest` this way.
pub fn spawn_grabber_with<S: FrameSource + 'static>(
    name: &str,
    source: S,
    producer: Producer,
    stop: Arc<AtomicBool>,
    observer: impl FnMut(Published) + Send + 'static,
) -> std::io::Result<Grabber<S>> {
    let counters = Arc::new(GrabberCounters::default());
    spawn_grabber_counted(name, source, producer, stop, counters, observer)
}

/// [`spawn_grabber_with`] counting into `counters` (made before the thread,
/// e.g. to be registered for metrics first).
pub fn spawn_grabber_counted<S: FrameSource + 'static>(
    name: &str,
    mut source: S,
    mut producer: Producer,
    stop: Arc<AtomicBool>,
    counters: Arc<GrabberCounters>,
    mut observer: impl FnMut(Published) + Send + 'static,
) -> std::io::Result<Grabber<S>> {
    let c = Arc::clone(&counters);
    let flag = Arc::clone(&stop);
    let thread_name = name.to_string();
    let handle = std::thread::Builder::new()
        .name(name.to_string())
        .spawn(move || {
            let exit = run(
                &thread_name,
                &mut source,
                &mut producer,
                &flag,
                &c,
                &mut observer,
            );
            source.stop();
            let why = match &exit {
                GrabberExit::Stopped => "stopped".to_string(),
                GrabberExit::Ended => "source ended".to_string(),
                GrabberExit::Failed(e) => format!("failed: {e}"),
            };
            let published = c.published.get();
            if source.shared_counters().is_some() {
                // A camera keeps its own counts of what the link lost.
                let st = source.stats();
                tracing::info!(
                    grabber = %thread_name,
                    exit = %why,
                    frames = published,
                    missing = st.missing,
                    incomplete = st.incomplete,
                    losses = st.losses,
                    opens = st.opens,
                    "grabber stopped"
                );
            } else {
                tracing::info!(grabber = %thread_name, exit = %why, frames = published, "grabber stopped");
            }
            (source, exit)
        })?;
    Ok(Grabber {
        handle,
        counters,
        stop,
    })
}

fn run<S: FrameSource>(
    name: &str,
    source: &mut S,
    producer: &mut Producer,
    stop: &AtomicBool,
    c: &GrabberCounters,
    observer: &mut impl FnMut(Published),
) -> GrabberExit {
    if let Err(e) = source.start() {
        tracing::error!(grabber = %name, error = %e, "source did not start");
        return GrabberExit::Failed(e);
    }
    tracing::info!(grabber = %name, source = %source.describe(), "grabber started");
    let mut state = State::Starting;
    let mut drops_logged = 0u64;
    while !stop.load(Ordering::Acquire) {
        match source.next_frame(producer.slot_mut(), POLL) {
            Ok(()) => {
                if state != State::Streaming {
                    tracing::info!(grabber = %name, seq = producer.slot().meta.seq, "frames arriving");
                    state = State::Streaming;
                }
                producer.slot_mut().received = Instant::now();
                let published = producer.publish();
                observer(published);
                if published != Published::Queued {
                    // Log the first drop and then every power of two.
                    let dropped = producer.counters().snapshot().dropped;
                    if dropped >= drops_logged.saturating_mul(2).max(1) {
                        tracing::warn!(grabber = %name, dropped, policy = producer.policy().name(), "ring full: frames dropped");
                        drops_logged = dropped;
                    }
                }
                c.published.inc();
            }
            Err(SourceError::Timeout(_)) => {
                c.timeouts.inc();
            }
            Err(SourceError::Lost { reason }) => {
                c.losses.inc();
                tracing::warn!(grabber = %name, %reason, "camera lost; reconnecting");
                state = State::Down;
            }
            Err(SourceError::Unavailable { reason }) => {
                c.unavailable.inc();
                if state != State::Waiting && state != State::Down {
                    tracing::warn!(grabber = %name, %reason, "camera unavailable; retrying");
                }
                if state != State::Down {
                    state = State::Waiting;
                }
            }
            Err(SourceError::Frame { reason }) => {
                // One bad frame: skipped, counted, logged; the next may be fine.
                c.bad_frames.inc();
                let n = c.bad_frames.get();
                if n.is_power_of_two() {
                    tracing::warn!(grabber = %name, %reason, bad_frames = n, "frame skipped");
                }
            }
            Err(SourceError::Ended) => return GrabberExit::Ended,
            Err(e @ SourceError::Config { .. }) => {
                tracing::error!(grabber = %name, error = %e, "grabber gives up");
                return GrabberExit::Failed(e);
            }
        }
    }
    GrabberExit::Stopped
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ring::{Overflow, Ring};
    use crate::source::{CountingSource, SystemClock};
    use photopose_frame::Image;

    #[test]
    fn grabber_runs_a_finite_source_to_the_end() {
        let (p, c) = Ring::build(4, Overflow::DropNewest, || Image::new_mono8(16, 4));
        let src = CountingSource::new(16, 4, Some(1000), None, SystemClock);
        let stop = Arc::new(AtomicBool::new(false));
        let g = spawn_grabber("grab-test", src, p, stop).unwrap();
        let mut seen = 0u64;
        let mut last = None;
        while let Ok(h) = c.recv_timeout(Duration::from_secs(5)) {
            assert_eq!(
                CountingSource::<SystemClock>::seq_of(h.image()),
                Some(h.meta.seq)
            );
            assert!(last.is_none_or(|l| h.meta.seq > l));
            last = Some(h.meta.seq);
            seen += 1;
        }
        let (_src, exit) = g.join();
        assert!(matches!(exit, GrabberExit::Ended));
        let st = c.counters().snapshot();
        assert_eq!(st.frames_in, 1000);
        assert_eq!(st.delivered + st.dropped, 1000);
        assert_eq!(st.delivered, seen);
    }

    #[test]
    fn grabber_stops_on_the_flag() {
        let (p, c) = Ring::build(2, Overflow::DropOldest, || Image::new_mono8(8, 1));
        let src = CountingSource::new(8, 1, None, Some(200.0), SystemClock);
        let stop = Arc::new(AtomicBool::new(false));
        let g = spawn_grabber("grab-stop", src, p, Arc::clone(&stop)).unwrap();
        let h = c.recv_timeout(Duration::from_secs(5)).unwrap();
        drop(h);
        stop.store(true, Ordering::Release);
        let t = std::time::Instant::now();
        let (_src, exit) = g.join();
        assert!(matches!(exit, GrabberExit::Stopped));
        assert!(t.elapsed() < Duration::from_secs(2));
    }
}
