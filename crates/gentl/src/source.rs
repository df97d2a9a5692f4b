//! [`GentlSource`]: a GenTL device as a `photopose-acquire` frame source.
//!
//! The producer is loaded and initialised when the source is built (a
//! missing or invalid `.cti` is an error then, naming the file); the device
//! is opened on an *opener* thread and closed on a *reaper* thread, so the
//! grabber never waits on discovery or on a dead device. Each frame is one
//! `EventGetData` (NEW_BUFFER), a few `DSGetBufferInfo` queries, one pass
//! converting the payload into the caller's slot (see [`crate::pixel`]) and
//! the buffer queued again: no allocation once the slot has the frame's size.
//!
//! A device counts as lost when no buffer arrived for
//! [`GentlConfig::timeout`] or the stream fails; it is reported once
//! ([`SourceError::Lost`]), then [`SourceError::Unavailable`] while it is
//! reopened with exponential back-off. Gaps in the device's frame ids are
//! counted as missing frames and advance `seq`; incomplete buffers are
//! counted and not delivered.
//!
//! Times: `camera_time_ns` is the producer's buffer timestamp (ns, or ticks
//! converted with the device's timestamp frequency; 0 when the producer gives
//! none, as some software producers do); `host_time_ns` and `host_mono_ns`
//! are the reception instant on the host's real-time and monotonic clocks.

use crate::config::GentlConfig;
use crate::error::GentlError;
use crate::ffi::monotonic_ns;
use crate::pixel::{convert, ConvertError, Layout, PixelFormat};
use crate::system::{Delivered, Opened, System, WaitError};
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use photopose_acquire::source::{Clock, SystemClock};
use photopose_acquire::{FrameSource, Slot, SourceCounters, SourceError, SourceStats};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

struct Live {
    opened: Opened,
    last_buffer: Instant,
    last_frame_id: Option<u64>,
}

enum Link {
    /// Not started.
    Idle,
    /// An opening is under way on the opener thread.
    Opening,
    /// Waiting to try again.
    Waiting { until: Instant, reason: String },
    /// Frames flowing.
    Streaming(Box<Live>),
}

/// A GenTL device as a [`FrameSource`] (see the module docs).
pub struct GentlSource {
    name: String,
    config: GentlConfig,
    system: Arc<System>,
    clock: Box<dyn Clock>,
    counters: Arc<SourceCounters>,
    link: Link,
    open_tx: Option<Sender<()>>,
    opened_rx: Receiver<Result<Opened, GentlError>>,
    reap_tx: Option<Sender<Opened>>,
    threads: Vec<JoinHandle<()>>,
    backoff: Duration,
    next_seq: u64,
    failures_logged: bool,
    resized_logged: bool,
}

impl std::fmt::Debug for GentlSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GentlSource")
            .field("name", &self.name)
            .field("config", &self.config)
            .field("stats", &self.counters.snapshot())
            .finish()
    }
}

/// What became of one delivered buffer.
enum Took {
    Frame { resized: bool },
    Incomplete,
    Refused(String),
}

impl GentlSource {
    /// A source for the device in `config`, with helper threads named after
    /// `name` (`<name>-open`, `<name>-reap`). Loads and initialises the
    /// producer now (its errors name the file); opens no device yet (see
    /// [`FrameSource::start`]).
    pub fn new(name: &str, config: GentlConfig) -> Result<Self, GentlError> {
        Self::with_clock(name, config, Box::new(SystemClock))
    }

    /// As [`GentlSource::new`], with host times from `clock`.
    pub fn with_clock(
        name: &str,
        config: GentlConfig,
        clock: Box<dyn Clock>,
    ) -> Result<Self, GentlError> {
        let system = System::open(&config.producer)?;
        let thread_err = |e: std::io::Error| GentlError::InvalidProducer {
            path: config.producer.clone(),
            reason: format!("cannot start a helper thread: {e}"),
        };
        let (open_tx, open_rx) = crossbeam_channel::unbounded::<()>();
        let (opened_tx, opened_rx) = crossbeam_channel::unbounded();
        let (reap_tx, reap_rx) = crossbeam_channel::unbounded::<Opened>();
        let (sys, cfg) = (Arc::clone(&system), config.clone());
        let opener = std::thread::Builder::new()
            .name(format!("{name}-open"))
            .spawn(move || {
                for () in open_rx {
                    let r = sys.open_device(
                        cfg.device.as_deref(),
                        cfg.buffers,
                        cfg.payload_size,
                        cfg.timeout,
                    );
                    if opened_tx.send(r).is_err() {
                        break;
                    }
                }
            })
            .map_err(thread_err)?;
        let reaper = std::thread::Builder::new()
            .name(format!("{name}-reap"))
            .spawn(move || {
                for o in reap_rx {
                    o.close();
                }
            })
            .map_err(thread_err)?;
        Ok(GentlSource {
            name: name.to_string(),
            backoff: config.backoff_initial,
            config,
            system,
            clock,
            counters: Arc::new(SourceCounters::default()),
            link: Link::Idle,
            open_tx: Some(open_tx),
            opened_rx,
            reap_tx: Some(reap_tx),
            threads: vec![opener, reaper],
            next_seq: 0,
            failures_logged: false,
            resized_logged: false,
        })
    }

    /// The live counters (shareable with a metrics thread).
    pub fn counters(&self) -> Arc<SourceCounters> {
        Arc::clone(&self.counters)
    }

    /// The producer's system (for listing its devices).
    pub fn system(&self) -> &Arc<System> {
        &self.system
    }

    /// The open device, while streaming.
    pub fn opened(&self) -> Option<&Opened> {
        match &self.link {
            Link::Streaming(live) => Some(&live.opened),
            _ => None,
        }
    }

    fn request_open(&mut self) -> Result<(), SourceError> {
        match self.open_tx.as_ref().map(|tx| tx.send(())) {
            Some(Ok(())) => {
                self.link = Link::Opening;
                Ok(())
            }
            _ => Err(SourceError::Config {
                what: "opener thread".into(),
                reason: "gone".into(),
            }),
        }
    }

    fn reap(&mut self, o: Opened) {
        self.counters.connected.store(false, Ordering::Relaxed);
        if let Some(tx) = &self.reap_tx {
            if let Err(e) = tx.send(o) {
                e.into_inner().close();
            }
        }
    }

    fn lose(&mut self, reason: String) -> SourceError {
        if let Link::Streaming(live) = std::mem::replace(&mut self.link, Link::Idle) {
            tracing::warn!(source = %self.name, device = %live.opened.info().id, %reason, "GenTL device lost");
            self.reap(live.opened);
        }
        self.counters.losses.inc();
        self.backoff = self.config.backoff_initial;
        self.failures_logged = false;
        self.link = Link::Waiting {
            until: Instant::now() + self.backoff,
            reason: reason.clone(),
        };
        SourceError::Lost { reason }
    }

    fn on_opened(&mut self, result: Result<Opened, GentlError>) -> Result<(), SourceError> {
        match result {
            Ok(opened) => {
                tracing::info!(source = %self.name, device = %opened.info().id,
                    model = opened.info().model.as_deref().unwrap_or("?"),
                    buffers = opened.buffer_count(), "GenTL device opened, streaming");
                self.counters.opens.inc();
                self.counters.connected.store(true, Ordering::Relaxed);
                self.backoff = self.config.backoff_initial;
                self.failures_logged = false;
                self.link = Link::Streaming(Box::new(Live {
                    opened,
                    last_buffer: Instant::now(),
                    last_frame_id: None,
                }));
                Ok(())
            }
            Err(e @ GentlError::Stream { .. }) => {
                tracing::error!(source = %self.name, error = %e, "GenTL device cannot stream");
                self.link = Link::Idle;
                Err(SourceError::Config {
                    what: "GenTL data stream".into(),
                    reason: e.to_string(),
                })
            }
            Err(e) => {
                let reason = e.to_string();
                if !self.failures_logged {
                    tracing::warn!(source = %self.name, %reason, "GenTL device not available; retrying with back-off");
                    self.failures_logged = true;
                } else {
                    tracing::debug!(source = %self.name, %reason, backoff_ms = self.backoff.as_millis() as u64, "GenTL open failed");
                }
                self.link = Link::Waiting {
                    until: Instant::now() + self.backoff,
                    reason: reason.clone(),
                };
                self.backoff = (self.backoff * 2).min(self.config.backoff_max);
                Err(SourceError::Unavailable { reason })
            }
        }
    }

    fn grab(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        let Link::Streaming(live) = &mut self.link else {
            return Err(SourceError::Unavailable {
                reason: "not streaming".into(),
            });
        };
        let image = &mut slot.image;
        let took = live
            .opened
            .next(timeout, |d: &Delivered, bytes: &[u8]| take(d, bytes, image));
        let host_mono_ns = monotonic_ns();
        let host_time_ns = self.clock.now_ns();
        let (took, d) = match took {
            Ok(t) => t,
            Err(WaitError::Timeout) => {
                let silent = live.last_buffer.elapsed();
                if silent >= self.config.timeout {
                    return Err(self.lose(format!("no frame for {:.1} s", silent.as_secs_f64())));
                }
                return Err(SourceError::Timeout(timeout));
            }
            Err(WaitError::Failed(e)) => return Err(self.lose(e.to_string())),
        };
        live.last_buffer = Instant::now();
        match took {
            Took::Frame { resized } => {
                if resized && !self.resized_logged {
                    tracing::warn!(source = %self.name, width = slot.image.width(), height = slot.image.height(),
                        "frame size differs from the ring's slots: slot reallocated (size the ring from the camera)");
                    self.resized_logged = true;
                }
                if let (Some(last), Some(id)) = (live.last_frame_id, d.frame_id) {
                    if id > last + 1 {
                        let gap = id - last - 1;
                        self.counters.missing.add(gap);
                        self.next_seq += gap;
                    }
                }
                live.last_frame_id = d.frame_id.or(live.last_frame_id);
                slot.meta.seq = self.next_seq;
                slot.meta.camera_frame_id = d.frame_id.unwrap_or(0);
                slot.meta.camera_time_ns = d.timestamp_ns.unwrap_or(0);
                slot.meta.host_time_ns = host_time_ns;
                slot.meta.host_mono_ns = host_mono_ns;
                slot.meta.exposure_mono_ns = 0;
                slot.meta.exposure_sigma_ns = 0;
                slot.meta.exposure_ns = 0;
                self.next_seq += 1;
                self.counters.frames.inc();
                Ok(())
            }
            Took::Incomplete => {
                self.counters.incomplete.inc();
                Err(SourceError::Timeout(timeout))
            }
            Took::Refused(reason) => Err(SourceError::Config {
                what: "pixel format".into(),
                reason: format!("GenTL device {}: {reason}", live.opened.info().id),
            }),
        }
    }
}

/// One delivered buffer into the slot's image.
fn take(d: &Delivered, bytes: &[u8], image: &mut photopose_frame::Image) -> (Took, Delivered) {
    if d.incomplete {
        return (Took::Incomplete, *d);
    }
    // PFNC values, or GigE Vision ones (the same numbers for these formats);
    // 0 = not said: taken as PFNC.
    let pfnc_like = matches!(
        d.namespace,
        crate::abi::PIXELFORMAT_NAMESPACE_UNKNOWN
            | crate::abi::PIXELFORMAT_NAMESPACE_GEV
            | crate::abi::PIXELFORMAT_NAMESPACE_PFNC_16BIT
            | crate::abi::PIXELFORMAT_NAMESPACE_PFNC_32BIT
    );
    let Some(format) = PixelFormat::from_pfnc(d.pfnc).filter(|_| pfnc_like) else {
        let e = ConvertError::Unsupported { pfnc: d.pfnc };
        return (
            Took::Refused(format!("{e} (namespace {})", d.namespace)),
            *d,
        );
    };
    let layout = Layout {
        width: d.width,
        height: d.height,
        x_padding: d.x_padding,
    };
    match convert(format, layout, bytes, image) {
        Ok(resized) => (Took::Frame { resized }, *d),
        Err(ConvertError::Unsupported { pfnc }) => (
            Took::Refused(ConvertError::Unsupported { pfnc }.to_string()),
            *d,
        ),
        Err(_) => (Took::Incomplete, *d),
    }
}

impl FrameSource for GentlSource {
    fn start(&mut self) -> Result<(), SourceError> {
        if matches!(self.link, Link::Idle) {
            self.backoff = self.config.backoff_initial;
            self.request_open()?;
        }
        Ok(())
    }

    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        let deadline = Instant::now() + timeout;
        match &self.link {
            Link::Idle => Err(SourceError::Unavailable {
                reason: "not started".into(),
            }),
            Link::Opening => match self.opened_rx.recv_timeout(timeout) {
                Ok(result) => {
                    self.on_opened(result)?;
                    let left = deadline.saturating_duration_since(Instant::now());
                    self.grab(slot, left.max(Duration::from_millis(1)))
                }
                Err(RecvTimeoutError::Timeout) => Err(SourceError::Timeout(timeout)),
                Err(RecvTimeoutError::Disconnected) => Err(SourceError::Config {
                    what: "opener thread".into(),
                    reason: "gone".into(),
                }),
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
            Link::Streaming(_) => self.grab(slot, timeout),
        }
    }

    fn stop(&mut self) {
        match std::mem::replace(&mut self.link, Link::Idle) {
            Link::Streaming(live) => self.reap(live.opened),
            Link::Opening => {
                if let Ok(Ok(o)) = self.opened_rx.recv_timeout(Duration::from_secs(30)) {
                    self.reap(o);
                }
            }
            Link::Idle | Link::Waiting { .. } => {}
        }
        self.counters.connected.store(false, Ordering::Relaxed);
    }

    fn describe(&self) -> String {
        format!(
            "GenTL device {} through {}",
            self.config.device.as_deref().unwrap_or("(first found)"),
            self.config.producer.display()
        )
    }

    fn stats(&self) -> SourceStats {
        self.counters.snapshot()
    }

    fn shared_counters(&self) -> Option<Arc<SourceCounters>> {
        Some(self.counters())
    }
}

impl Drop for GentlSource {
    fn drop(&mut self) {
        self.stop();
        self.open_tx = None;
        self.reap_tx = None;
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}
