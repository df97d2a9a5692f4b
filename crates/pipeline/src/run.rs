//! The running pipeline: grabber thread, ring, detection workers, ordered
//! output, and its counters. See the crate documentation for the picture.

use crate::config::{Config, Overflow};
use crate::health::{Heartbeat, Threads, Watchdog};
use crate::notify::Notifier;
use crate::result::{CameraId, PoseResult, ResultStatus, TargetPool};
use crate::sink::{Outgoing, Sinks};
use crossbeam_channel::{bounded, Receiver, RecvTimeoutError, Sender};
use photopose_acquire::ring::RecvError;
use photopose_acquire::{spawn_grabber_counted, FrameSource, Published, Ring, Slot};
use photopose_field::Field;
use photopose_geometry::Camera;
use photopose_locate::Locator;
use photopose_stream::{Edge, PoseMessage};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use thiserror::Error;

/// Why the pipeline could not start.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum PipelineError {
    /// A pose stream could not be opened.
    #[error(transparent)]
    Stream(#[from] photopose_stream::StreamError),
    /// The frame locator could not be built.
    #[error("frame locator: {0}")]
    Locate(#[from] photopose_locate::LocateError),
    /// The hand-eye file of the RSI server cannot be used.
    #[error("rsi.hand_eye: {0}")]
    HandEye(#[from] photopose_formats::FormatError),
    /// The RSI server could not start.
    #[error("RSI server: {0}")]
    Rsi(#[from] photopose_rsi::server::ServerError),
    /// The Zenoh session could not be opened or declared (`[zenoh]`).
    #[error("zenoh: {why}")]
    Zenoh {
        /// What failed, with Zenoh's word.
        why: String,
    },
    /// A thread could not be started.
    #[error("cannot start thread {name}: {source}")]
    Thread {
        /// Thread name.
        name: String,
        /// The OS error.
        source: std::io::Error,
    },
}

pub use crate::metrics::Counters;

/// One worker result, or the notice that an admitted frame was dropped.
// Moved by value through a bounded channel: boxing the large variant would
// allocate per frame.
#[allow(clippy::large_enum_variant)]
enum Outcome {
    Message { order: u64, result: PoseResult },
    Skipped { order: u64 },
}

/// How the pipeline reports to the service manager: where notifications
/// go, the watchdog interval systemd asks for, and a fault to inject
/// (tests of the watchdog only).
#[derive(Debug)]
pub struct Supervision {
    /// Where `WATCHDOG=1` and `STATUS=` go.
    pub notifier: Notifier,
    /// systemd's watchdog interval (`WATCHDOG_USEC`); `None`: no pings.
    pub watchdog: Option<Duration>,
    /// A thread to wedge after its first frame (fault injection for the
    /// watchdog's tests; `None` in service).
    #[doc(hidden)]
    pub wedge: Option<Wedge>,
}

impl Supervision {
    /// From the environment systemd gives a service (`NOTIFY_SOCKET`,
    /// `WATCHDOG_USEC`, `WATCHDOG_PID`).
    pub fn from_env() -> Supervision {
        Supervision {
            notifier: Notifier::from_env(),
            watchdog: crate::notify::watchdog_interval(),
            wedge: None,
        }
    }

    /// No notifications, no watchdog.
    pub fn none() -> Supervision {
        Supervision {
            notifier: Notifier::disabled(),
            watchdog: None,
            wedge: None,
        }
    }
}

/// A thread that stops turning after its first frame, to prove that the
/// watchdog notices (fault injection for tests).
#[doc(hidden)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wedge {
    /// The ordered output thread.
    Output,
    /// The first detection worker.
    Worker,
}

impl Wedge {
    /// `output` or `worker`.
    pub fn parse(s: &str) -> Option<Wedge> {
        match s {
            "output" => Some(Wedge::Output),
            "worker" => Some(Wedge::Worker),
            _ => None,
        }
    }
}

/// Holds a wedged thread until the pipeline stops: it neither works nor
/// turns (its heartbeat stands still).
fn hold_wedged(stop: &AtomicBool, role: &str) {
    tracing::warn!(thread = role, "fault injection: thread wedged");
    while !stop.load(Ordering::Acquire) {
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A running pipeline.
pub struct Pipeline {
    rsi: Option<photopose_rsi::server::RsiServer>,
    rsi_addr: Option<SocketAddr>,
    grabber: Option<photopose_acquire::Grabber<Box<dyn FrameSource>>>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
    threads: Vec<JoinHandle<()>>,
    tcp_addr: Option<SocketAddr>,
    metrics: Option<crate::metrics::MetricsServer>,
    metrics_addr: Option<SocketAddr>,
    watchdog: Option<Watchdog>,
    /// The tokio runtime of the TCP stream and the metrics endpoint.
    edge: Option<Edge>,
    /// The live view's address, when it runs.
    live_addr: Option<SocketAddr>,
}

/// Worker threads of the edge runtime: the network edges are light.
const EDGE_THREADS: usize = 1;

impl std::fmt::Debug for Pipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pipeline")
            .field("threads", &self.threads.len())
            .finish()
    }
}

fn spawn(name: &str, f: impl FnOnce() + Send + 'static) -> Result<JoinHandle<()>, PipelineError> {
    std::thread::Builder::new()
        .name(name.to_string())
        .spawn(f)
        .map_err(|source| PipelineError::Thread {
            name: name.to_string(),
            source,
        })
}

impl Pipeline {
    /// Starts the threads: grabber on `source`, `config.workers` detection
    /// workers, the ordered output, and the watchdog as systemd's
    /// environment asks ([`Supervision::from_env`]).
    pub fn start(
        config: &Config,
        camera: Camera,
        field: Field,
        source: Box<dyn FrameSource>,
    ) -> Result<Self, PipelineError> {
        Self::start_supervised(config, camera, field, source, Supervision::from_env())
    }

    /// [`Pipeline::start`] reporting to `supervision`.
    pub fn start_supervised(
        config: &Config,
        camera: Camera,
        field: Field,
        source: Box<dyn FrameSource>,
        supervision: Supervision,
    ) -> Result<Self, PipelineError> {
        let stop = Arc::new(AtomicBool::new(false));
        let mut watched = Threads::default();
        let wedge = supervision.wedge;
        let slots = config.slots;
        let (producer, consumer) = Ring::build(
            slots,
            match config.overflow {
                Overflow::DropNewest => photopose_acquire::Overflow::DropNewest,
                Overflow::DropOldest => photopose_acquire::Overflow::DropOldest,
                Overflow::Block => photopose_acquire::Overflow::Block,
            },
            || photopose_frame::Image::new_mono8(camera.sensor.width, camera.sensor.height),
        );
        let (out_tx, out_rx) = bounded::<Outcome>(slots * 2 + config.workers);
        // The network edges (TCP stream, metrics) run on one tokio runtime
        // of their own; the pipeline's threads never await.
        let edge = if config.tcp_listen.is_some()
            || config.metrics_listen.is_some()
            || config.live.enabled
            || config.zenoh.enabled
        {
            Some(Edge::start(EDGE_THREADS)?)
        } else {
            None
        };
        // The RSI server reads the latest pose from a lock-free slot the
        // output stage publishes into; it never waits on vision.
        let (rsi, rsi_link) = match &config.rsi {
            Some(r) => {
                let file = photopose_formats::hand_eye::load_hand_eye(&r.hand_eye)?;
                let hand_eye = photopose_rsi::HandEye {
                    tcp_from_camera: file.camera_in_tcp.isometry(),
                    base_from_plate: file.plate_in_base.isometry(),
                };
                let (publisher, reader) = photopose_rsi::latest_slot();
                let clock = photopose_rsi::server::RsiClock::new();
                // The recording's tap, when it records the RSI cycles.
                let tap = config.record.link.as_ref().and_then(|l| l.rsi_tap());
                let server = match tap {
                    Some(tap) => photopose_rsi::server::RsiServer::spawn_tapped(
                        r.settings.clone(),
                        hand_eye,
                        reader,
                        clock,
                        tap,
                    )?,
                    None => photopose_rsi::server::RsiServer::spawn(
                        r.settings.clone(),
                        hand_eye,
                        reader,
                        clock,
                    )?,
                };
                let stats = Arc::clone(server.stats());
                (
                    Some(server),
                    Some(crate::sink::rsi::RsiSink::new(publisher, clock, stats)),
                )
            }
            None => (None, None),
        };
        let rsi_addr = rsi.as_ref().map(|s| s.local_addr());
        let mut sinks = crate::sink::build(config, rsi_link, edge.as_ref().map(|e| e.handle()))?;
        // The live view (Foxglove WebSocket, on the edge): a frame tap on
        // the source and a sink of the results.
        let (source, live_addr) = match (&edge, config.live.enabled) {
            (Some(edge), true) => {
                let live = crate::sink::live::LiveLink::start(
                    &config.live,
                    edge.handle(),
                    &camera,
                    &field,
                )?;
                sinks.sinks.push(Box::new(live.sink(sinks.rsi.clone())));
                (live.tap(source), Some(live.local_addr()))
            }
            _ => (source, None),
        };
        let tcp_addr = sinks.tcp_addr;
        // The camera's exposure, and the link its control loop is fed by.
        let exposure = source.exposure_link();
        let counters = Arc::new(Counters {
            source: source.shared_counters(),
            exposure: exposure.clone(),
            tcp: sinks.tcp.clone(),
            udp: sinks.udp.clone(),
            rsi: sinks.rsi.clone(),
            ring: Some(consumer.shared_counters()),
            zenoh: config
                .zenoh
                .enabled
                .then(|| Arc::new(crate::metrics::ZenohStats::default())),
            ..Counters::default()
        });
        // The Zenoh publisher (on the edge), before any frame is taken: it
        // may wait for a subscriber (`zenoh.wait_for_subscriber_ms`).
        #[cfg(feature = "zenoh")]
        if let (Some(stats), Some(edge)) = (&counters.zenoh, &edge) {
            sinks
                .sinks
                .push(Box::new(crate::sink::zenoh::ZenohSink::start(
                    config,
                    edge.handle(),
                    Arc::clone(stats),
                    Arc::clone(&counters),
                )?));
        }
        let metrics = match (config.metrics_listen, &edge) {
            (Some(a), Some(edge)) => Some(crate::metrics::MetricsServer::start(
                edge.handle(),
                a,
                counters.clone(),
            )?),
            _ => None,
        };
        let metrics_addr = metrics.as_ref().map(|m| m.local_addr());
        let mut threads = Vec::new();
        let camera_id: CameraId = Arc::from(config.camera_id.as_str());
        // Target lists for the results in flight: in the channel to the
        // output, in its re-ordering window, one in each worker's hands
        // and the one being sent.
        let targets = TargetPool::counted(
            2 * (slots * 2 + config.workers) + config.workers + 2,
            field.len(),
            Arc::clone(&counters.results_without_targets),
        );
        // `[record] frames = "on_change"`: the workers record a frame whose
        // status differs from the one before.
        let on_change = config
            .record
            .link
            .clone()
            .filter(|_| config.record.frames == crate::config::RecordFrames::OnChange);
        // Workers: take frames from the ring, hand each result to the output
        // stage; dropping the frame handle returns its slot to the ring.
        let track_slot = crate::track::TrackSlot::default();
        for k in 0..config.workers {
            let mut locator = crate::track::locator(camera, field.clone(), &config.tracking)?;
            let tracker = crate::track::Tracker::new(config.tracking, track_slot.clone());
            let (consumer, out_tx) = (consumer.clone(), out_tx.clone());
            let counters = counters.clone();
            let camera_id = camera_id.clone();
            let (targets, on_change) = (targets.clone(), on_change.clone());
            // With the exposure control loop on: each frame's peak offered
            // to the source (a scratch list per worker, no allocation).
            let mut peaks = exposure
                .clone()
                .filter(|l| l.steering())
                .map(|l| (l, Vec::with_capacity(field.len())));
            let name = format!("detect-{k}");
            let beat = Arc::new(Heartbeat::default());
            watched.watch_heartbeat(name.clone(), &beat);
            let wedged = (k == 0 && wedge == Some(Wedge::Worker)).then(|| stop.clone());
            threads.push(spawn(&name, move || loop {
                beat.beat();
                let frame = match consumer.recv_timeout(Duration::from_millis(100)) {
                    Ok(f) => f,
                    Err(RecvError::Timeout) => continue,
                    Err(RecvError::Disconnected) => return,
                };
                if let Some(stop) = &wedged {
                    drop(frame);
                    hold_wedged(stop, "detect-0");
                    return;
                }
                let result = locate(
                    &mut locator,
                    &tracker,
                    &counters,
                    &camera_id,
                    &frame,
                    &targets,
                );
                if let Some(link) = &on_change {
                    link.frame_on_change(&frame, result.status);
                }
                if let Some((link, scratch)) = &mut peaks {
                    offer_peak(link, scratch, &frame, locator.identified());
                }
                counters.frames_processed.inc();
                let outcome = Outcome::Message {
                    order: frame.order,
                    result,
                };
                drop(frame);
                if out_tx.send(outcome).is_err() {
                    return;
                }
            })?);
        }
        drop(consumer);
        // Grabber: the source into the ring (photopose-acquire's thread; it
        // logs connection changes and applies the overflow policy).
        let grabber = {
            let (counters, out_tx) = (counters.clone(), out_tx.clone());
            spawn_grabber_counted(
                "grabber",
                source,
                producer,
                stop.clone(),
                Arc::clone(&counters.grabber),
                move |published| observe(published, &counters, &out_tx),
            )
            .map_err(|source| PipelineError::Thread {
                name: "grabber".into(),
                source,
            })?
        };
        drop(out_tx);
        {
            let g = grabber.shared_counters();
            watched.watch("grabber", move || g.turns());
        }
        if let Some(stats) = &counters.rsi {
            let s = Arc::clone(stats);
            watched.watch("rsi", move || s.loops.load(Ordering::Relaxed));
        }
        // Output.
        {
            let (stop_out, counters) = (stop.clone(), counters.clone());
            let max_age = Duration::from_secs_f64(config.max_age_ms / 1000.0);
            let window = slots * 2 + config.workers;
            let beat = Arc::new(Heartbeat::default());
            watched.watch_heartbeat("output", &beat);
            let wedged = wedge == Some(Wedge::Output);
            threads.push(spawn("output", move || {
                output_loop(
                    out_rx, sinks, counters, max_age, window, stop_out, beat, wedged,
                );
            })?);
        }
        let watchdog = Watchdog::spawn(
            supervision.notifier,
            supervision.watchdog,
            watched,
            status_line(Arc::clone(&counters)),
        )
        .map_err(|source| PipelineError::Thread {
            name: "watchdog".into(),
            source,
        })?;
        Ok(Pipeline {
            rsi,
            rsi_addr,
            grabber: Some(grabber),
            stop,
            counters,
            threads,
            tcp_addr,
            metrics,
            metrics_addr,
            watchdog: Some(watchdog),
            edge,
            live_addr,
        })
    }

    /// The live view's address (`ws://ADDR`), if it runs.
    pub fn live_addr(&self) -> Option<SocketAddr> {
        self.live_addr
    }

    /// The TCP stream's address, if one is configured.
    pub fn tcp_addr(&self) -> Option<SocketAddr> {
        self.tcp_addr
    }

    /// The RSI server's address, if it runs.
    pub fn rsi_addr(&self) -> Option<SocketAddr> {
        self.rsi_addr
    }

    /// The metrics endpoint's address, if one is configured.
    pub fn metrics_addr(&self) -> Option<SocketAddr> {
        self.metrics_addr
    }

    /// The counters.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Asks the pipeline to stop: the grabber stops, queued frames are
    /// finished, outputs flushed.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Release);
    }

    /// Whether every pipeline thread has ended (the source ended and
    /// everything was processed and sent).
    pub fn finished(&self) -> bool {
        self.grabber.as_ref().is_none_or(|g| g.is_finished())
            && self.threads.iter().all(|t| t.is_finished())
    }

    /// A flag that stops the pipeline when set (for signal handlers).
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// Waits for every thread to end (after [`Pipeline::stop`] or the end of
    /// the source).
    pub fn join(mut self) -> Arc<Counters> {
        if let Some(w) = self.watchdog.take() {
            w.stop();
        }
        if let Some(g) = self.grabber.take() {
            // Ending the grabber drops the ring's producer: the workers
            // finish the queued frames, then the output drains.
            let (_source, exit) = g.join();
            let why = match &exit {
                photopose_acquire::GrabberExit::Stopped => "stopped".to_string(),
                photopose_acquire::GrabberExit::Ended => "the source ended".to_string(),
                photopose_acquire::GrabberExit::Failed(e) => e.to_string(),
            };
            tracing::debug!(exit = %why, "grabber joined");
        }
        for t in self.threads {
            let _ = t.join();
        }
        if let Some(server) = self.rsi.take() {
            // The robot keeps being answered until the poses have stopped.
            // The server logs its own stop; the figures are in the summary.
            server.stop();
        }
        if let Some(m) = self.metrics.take() {
            m.stop();
        }
        if let Some(edge) = self.edge.take() {
            // The output thread has closed the TCP stream: its clients get
            // what is queued, then the runtime's threads are joined.
            edge.stop();
        }
        self.counters
    }
}

/// Counts what became of a published frame; a queued frame evicted by
/// `drop-oldest` is announced to the output stage so it does not wait for it.
fn observe(published: Published, counters: &Counters, out_tx: &Sender<Outcome>) {
    counters.record_frame_in();
    match published {
        Published::Queued => {}
        Published::DroppedNewest => {
            counters.frames_dropped.inc();
        }
        Published::QueuedDroppedOldest { dropped_order } => {
            counters.frames_dropped.inc();
            let _ = out_tx.send(Outcome::Skipped {
                order: dropped_order,
            });
        }
    }
}

/// Locates one frame (tracked from the latest pose when it may be) into
/// its result, with its identified targets in a list from `targets`.
fn locate(
    locator: &mut Locator,
    tracker: &crate::track::Tracker,
    counters: &Counters,
    camera: &CameraId,
    frame: &Slot,
    targets: &TargetPool,
) -> PoseResult {
    let located = tracker
        .locate(locator, frame.meta.seq, frame.image().view())
        .ok();
    if let Some((crate::track::Mode::Tracked, _, _)) = located {
        counters.frames_tracked.inc();
    }
    let result = PoseResult::from_location(
        camera,
        &frame.meta,
        frame.received,
        located.map(|(_, status, pose)| (status, pose)),
    );
    match located {
        Some(_) => result.with_targets(targets.take(), locator.identified()),
        None => result,
    }
}

/// Offers the frame's peak (`photopose_acquire::exposure::frame_peak` of
/// its identified targets' peaks as shares of full scale — each the
/// brightest pixel of the target's blob, as the detector found it; clipped
/// ones counted above it) to the exposure control loop; a frame without
/// identified targets offers nothing. Allocates nothing: `scratch` has
/// room for the field's targets.
fn offer_peak(
    link: &photopose_acquire::ExposureLink,
    scratch: &mut Vec<f32>,
    frame: &Slot,
    identified: &[photopose_locate::Identified],
) {
    use photopose_acquire::exposure::{frame_peak, SATURATED_PEAK};
    scratch.clear();
    let full = f32::from(frame.image().max_value().max(1));
    for t in identified {
        if scratch.len() == scratch.capacity() {
            break;
        }
        scratch.push(if t.saturated {
            SATURATED_PEAK
        } else {
            t.peak as f32 / full
        });
    }
    if let Some(peak) = frame_peak(scratch) {
        link.offer(frame.meta.seq, peak);
    }
}

/// The `STATUS=` text the watchdog sends each tick: pose rate since the
/// last tick, camera state, RSI state.
fn status_line(counters: Arc<Counters>) -> impl FnMut() -> String + Send + 'static {
    let mut last = (Instant::now(), 0u64, 0u64);
    move || {
        let now = Instant::now();
        let poses = counters.poses_ok.get();
        let frames = counters.frames_in.get();
        let secs = now.duration_since(last.0).as_secs_f64().max(1e-3);
        let rate = (poses - last.1) as f64 / secs;
        let camera = match &counters.source {
            Some(s) if s.connected.load(Ordering::Relaxed) => "connected",
            Some(_) => "absent",
            None if frames > last.2 => "frames arriving",
            None => "no frames",
        };
        last = (now, poses, frames);
        let rsi = match &counters.rsi {
            None => "off",
            Some(s) => photopose_rsi::LawStatus::from_code(s.status.load(Ordering::Relaxed))
                .map_or("waiting for the controller", |st| st.name()),
        };
        format!("{rate:.1} poses/s; camera {camera}; rsi {rsi}")
    }
}

#[allow(clippy::too_many_arguments)]
fn output_loop(
    rx: Receiver<Outcome>,
    mut sinks: Sinks,
    counters: Arc<Counters>,
    max_age: Duration,
    window: usize,
    stop: Arc<AtomicBool>,
    beat: Arc<Heartbeat>,
    wedged: bool,
) {
    // Re-ordering window indexed by admission order.
    let mut pending: Vec<Option<Outcome>> = (0..window).map(|_| None).collect();
    let mut next = 0u64;
    let mut line = Vec::with_capacity(1024);
    let mut last_sent = Instant::now();
    let mut last_message: Option<PoseMessage> = None;
    // Encodes a message once and hands it to every sink.
    let mut emit = |result: Option<&PoseResult>, m: &PoseMessage, sinks: &mut Sinks| {
        m.encode_line(&mut line);
        let out = Outgoing {
            result,
            message: m,
            line: &line,
        };
        for s in sinks.sinks.iter_mut() {
            s.publish(&out);
        }
    };
    loop {
        beat.beat();
        match rx.recv_timeout(max_age.min(Duration::from_millis(100))) {
            Ok(_) if wedged => {
                hold_wedged(&stop, "output");
                break;
            }
            Ok(o) => {
                let order = match &o {
                    Outcome::Message { order, .. } | Outcome::Skipped { order } => *order,
                };
                let idx = (order % window as u64) as usize;
                pending[idx] = Some(o);
                // Emit everything that is now in order.
                loop {
                    let idx = (next % window as u64) as usize;
                    let Some(o) = pending[idx].take() else { break };
                    next += 1;
                    if let Outcome::Message { result, .. } = o {
                        let mut message = crate::sink::message(&result);
                        crate::sink::annotate(
                            &mut message,
                            sinks.rsi.as_deref(),
                            sinks.rsi_silence,
                        );
                        let latency = result.times.handover.elapsed();
                        counters.latency.record(latency);
                        if result.status == ResultStatus::Ok {
                            counters.poses_ok.inc();
                        } else {
                            counters.poses_failed.inc();
                        }
                        let pose = message.pose.as_ref();
                        counters.record_pose(
                            pose.map(|p| p.sigma0_px),
                            pose.map_or(0, |p| p.n_targets),
                            pose.map(|p| p.std_position_mm),
                        );
                        emit(Some(&result), &message, &mut sinks);
                        last_message = Some(message);
                        last_sent = Instant::now();
                    }
                }
            }
            Err(RecvTimeoutError::Timeout) => {
                if let Some(m) = last_message.as_ref() {
                    if last_sent.elapsed() >= max_age && !stop.load(Ordering::Acquire) {
                        // No fresh pose: say so, without a frame of its own
                        // (seq null), the last frame's pose and times kept
                        // and named by last_seq.
                        let mut s = PoseMessage::stale(&m.camera, Some(m));
                        crate::sink::annotate(&mut s, sinks.rsi.as_deref(), sinks.rsi_silence);
                        emit(None, &s, &mut sinks);
                        counters.stale.inc();
                        last_sent = Instant::now();
                        tracing::debug!("no fresh pose: stale message sent");
                    }
                }
            }
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    for s in sinks.sinks.iter_mut() {
        s.finish();
    }
    tracing::info!(
        poses_ok = counters.poses_ok.get(),
        poses_failed = counters.poses_failed.get(),
        dropped = counters.frames_dropped.get(),
        "pose output stopped"
    );
}
