//! [`GentlSource`]: a GenTL device as a `photopose-acquire` frame source.
//!
//! The producer is loaded and initialised when the source is built (a
//! missing or invalid `.cti` is an error then, naming the file); the device
//! is opened on an *opener* thread and closed on a *reaper* thread (the
//! shared [`Reopener`] of `photopose-acquire`), so the
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
use photopose_acquire::reopen::{Backoff, Device, OpenFailure, Ready, Reopener};
use photopose_acquire::source::{Clock, SystemClock};
use photopose_acquire::{FrameSource, Slot, SourceCounters, SourceError, SourceStats};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A GenTL device as a [`FrameSource`] (see the module docs).
pub struct GentlSource {
    name: String,
    config: GentlConfig,
    system: Arc<System>,
    clock: Box<dyn Clock>,
    counters: Arc<SourceCounters>,
    link: Reopener<Opened>,
    next_seq: u64,
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

impl Device for Opened {
    fn id(&self) -> &str {
        &self.info().id
    }
    fn close(self, _lost: bool) {
        Opened::close(self);
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
        let counters = Arc::new(SourceCounters::default());
        let (sys, cfg) = (Arc::clone(&system), config.clone());
        let link = Reopener::spawn(
            name,
            "GenTL device",
            Backoff::new(config.backoff_initial, config.backoff_max),
            Arc::clone(&counters),
            move || {
                sys.open_device(
                    cfg.device.as_deref(),
                    cfg.buffers,
                    cfg.payload_size,
                    cfg.timeout,
                )
                .map_err(|e| match e {
                    GentlError::Stream { .. } => OpenFailure::Refused {
                        what: "GenTL data stream".into(),
                        reason: e.to_string(),
                    },
                    e => OpenFailure::Absent(e.to_string()),
                })
            },
        )
        .map_err(|e| GentlError::InvalidProducer {
            path: config.producer.clone(),
            reason: format!("cannot start a helper thread: {e}"),
        })?;
        Ok(GentlSource {
            name: name.to_string(),
            config,
            system,
            clock,
            counters,
            link,
            next_seq: 0,
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
        self.link.live().map(|live| &live.device)
    }

    fn on_opened(&self) {
        if let Some(opened) = self.opened() {
            tracing::info!(source = %self.name, device = %opened.info().id,
                model = opened.info().model.as_deref().unwrap_or("?"),
                buffers = opened.buffer_count(), "GenTL device opened, streaming");
        }
    }

    fn grab(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        let Some(live) = self.link.live_mut() else {
            return Err(SourceError::Unavailable {
                reason: "not streaming".into(),
            });
        };
        let image = slot.image_mut();
        let took = live
            .device
            .next(timeout, |d: &Delivered, bytes: &[u8]| take(d, bytes, image));
        let host_mono_ns = monotonic_ns();
        let host_time_ns = self.clock.now_ns();
        let (took, d) = match took {
            Ok(t) => t,
            Err(WaitError::Timeout) => {
                let silent = live.last_buffer.elapsed();
                if silent >= self.config.timeout {
                    return Err(self
                        .link
                        .lose(format!("no frame for {:.1} s", silent.as_secs_f64())));
                }
                return Err(SourceError::Timeout(timeout));
            }
            Err(WaitError::Failed(e)) => return Err(self.link.lose(e.to_string())),
        };
        live.last_buffer = Instant::now();
        match took {
            Took::Frame { resized } => {
                if resized && !self.resized_logged {
                    tracing::warn!(source = %self.name, width = slot.image().width(), height = slot.image().height(),
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
                reason: format!("GenTL device {}: {reason}", live.device.info().id),
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
        self.link.start()
    }

    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        let (ready, left) = self.link.ready(timeout)?;
        if ready == Ready::Opened {
            self.on_opened();
        }
        self.grab(slot, left)
    }

    fn stop(&mut self) {
        self.link.stop();
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
