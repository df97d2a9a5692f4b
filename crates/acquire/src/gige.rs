//! The GigE Vision source over aravis (libaravis 0.8).
//!
//! [`GigeSource`] opens a camera by device id or serial number (or the
//! first one found), configures it (pixel format, exposure, gain, frame
//! rate, ROI, packet size, packet socket, buffer count) and copies each
//! complete frame into the caller's ring slot with one `memcpy` (Mono8) or
//! one widening pass (Mono16, little-endian on the wire), pushing the aravis
//! buffer straight back.
//!
//! # Losing the camera
//! A camera counts as lost when no buffer at all arrived for
//! [`GigeConfig::lost_after`] or aravis signals "control lost". Every
//! register access to a dead camera blocks about 2.5 s, so the source never
//! touches a lost camera on the acquisition path: the camera and its stream
//! are handed to a *reaper* thread that stops and drops them, and opening
//! (which fails only after about 1 s while the camera is absent) happens on
//! an *opener* thread. The source retries with exponential back-off and
//! reports [`SourceError::Lost`] once, then [`SourceError::Unavailable`]
//! until frames flow again. A stale handle is never reused: a returning
//! camera is always opened afresh.
//!
//! Dropping a `GigeSource` joins its helper threads, so it waits for a lost
//! camera's close still under way (measured: about 6.7 s after the loss).
//!
//! Opening touches aravis' global device list, so openings of every
//! `GigeSource` in the process are serialised by one lock (off the frame
//! path).
//!
//! # Missing frames
//! Gaps in the camera's frame (block) ids between delivered frames are
//! counted in [`SourceStats::missing`](crate::source::SourceStats) and
//! advance [`FrameMeta::seq`](photopose_frame::FrameMeta), so a consumer
//! sees a missed frame as a gap in `seq`. The first frame after each start
//! usually arrives incomplete and is counted in `incomplete`, not delivered.

use crate::ffi;
use crate::ring::Slot;
use crate::source::{Clock, FrameSource, SourceCounters, SourceError, SourceStats, SystemClock};
use aravis::prelude::*;
use aravis::{AcquisitionMode, Buffer, BufferStatus, Camera, DeviceError, PixelFormat, Stream};
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use glib::prelude::Cast;
use photopose_frame::{Image, Pixels};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Aravis' device discovery is global state: one opening at a time.
static OPEN_LOCK: Mutex<()> = Mutex::new(());

/// Pixel depth asked of the camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PixelDepth {
    /// 8-bit grey (`Mono8`).
    #[default]
    Mono8,
    /// 16-bit grey (`Mono16`).
    Mono16,
}

/// A region of interest on the sensor, in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Roi {
    /// Left column.
    pub x: u32,
    /// Top row.
    pub y: u32,
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
}

/// How to open and run a GigE Vision camera.
#[derive(Debug, Clone, PartialEq)]
pub struct GigeConfig {
    /// Device id (as `arv-tool-0.8` lists it, e.g. `Aravis-Fake-GV01`),
    /// address, or serial number; `None` takes the first camera found.
    pub camera: Option<String>,
    /// Pixel format asked of the camera.
    pub pixel: PixelDepth,
    /// Exposure time, µs (`None`: leave the camera's).
    pub exposure_us: Option<f64>,
    /// Gain (`None`: leave the camera's).
    pub gain: Option<f64>,
    /// Frame rate, frames/s (`None`: leave the camera's).
    pub frame_rate: Option<f64>,
    /// Region of interest (`None`: leave the camera's).
    pub roi: Option<Roi>,
    /// GigE stream packet size, bytes (`None`: leave the camera's).
    pub packet_size: Option<u32>,
    /// Use the packet socket (faster on a real NIC when root; delivers no
    /// frames at all on loopback). Default `false`.
    pub packet_socket: bool,
    /// Buffers queued on the aravis stream (≥ 2), allocated at each opening.
    pub buffers: usize,
    /// No buffer at all for this long means the camera is lost (raised to
    /// three frame periods at a slow `frame_rate`).
    pub lost_after: Duration,
    /// First wait before reopening a lost camera; doubles per failure.
    pub backoff_initial: Duration,
    /// Longest wait between reopening attempts.
    pub backoff_max: Duration,
}

impl Default for GigeConfig {
    fn default() -> Self {
        GigeConfig {
            camera: None,
            pixel: PixelDepth::Mono8,
            exposure_us: None,
            gain: None,
            frame_rate: None,
            roi: None,
            packet_size: None,
            packet_socket: false,
            buffers: 8,
            lost_after: Duration::from_secs(2),
            backoff_initial: Duration::from_millis(100),
            backoff_max: Duration::from_secs(5),
        }
    }
}

impl GigeConfig {
    /// `lost_after`, but never less than three frame periods.
    pub fn effective_lost_after(&self) -> Duration {
        match self.frame_rate {
            Some(fps) if fps > 0.0 && fps.is_finite() => self
                .lost_after
                .max(Duration::from_secs_f64((3.0 / fps).min(3600.0))),
            _ => self.lost_after,
        }
    }

    fn validate(&self) -> Result<(), SourceError> {
        let bad = |what: &str, reason: String| {
            Err(SourceError::Config {
                what: what.into(),
                reason,
            })
        };
        if self.buffers < 2 {
            return bad("buffers", format!("{} < 2", self.buffers));
        }
        for (what, v) in [
            ("exposure_us", self.exposure_us),
            ("frame_rate", self.frame_rate),
        ] {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    return bad(what, format!("{v} is not positive"));
                }
            }
        }
        if let Some(g) = self.gain {
            if !g.is_finite() {
                return bad("gain", format!("{g} is not finite"));
            }
        }
        if let Some(r) = self.roi {
            if r.width == 0
                || r.height == 0
                || r.x.max(r.y).max(r.width).max(r.height) > i32::MAX as u32
            {
                return bad("roi", format!("{r:?} is empty or too large"));
            }
        }
        if self.lost_after.is_zero() || self.backoff_initial.is_zero() {
            return bad("lost_after/backoff_initial", "must be positive".into());
        }
        Ok(())
    }
}

/// An opened, streaming camera.
struct Opened {
    camera: Camera,
    stream: Stream,
    control_lost: Arc<AtomicBool>,
    id: String,
    took: Duration,
}

enum OpenError {
    /// Not there (or not answering): try again later.
    Absent(String),
    /// The camera refuses the configuration: fatal.
    Config { what: String, reason: String },
}

fn transient(e: &glib::Error) -> bool {
    matches!(
        e.kind::<DeviceError>(),
        Some(
            DeviceError::Timeout
                | DeviceError::TransferError
                | DeviceError::NotConnected
                | DeviceError::NotFound
                | DeviceError::ProtocolError
        )
    )
}

fn setting(what: &str) -> impl Fn(glib::Error) -> OpenError + '_ {
    move |e| {
        if transient(&e) {
            OpenError::Absent(format!("{what}: {e}"))
        } else {
            OpenError::Config {
                what: what.into(),
                reason: e.to_string(),
            }
        }
    }
}

fn open(config: &GigeConfig, resolved: &mut Option<String>) -> Result<Opened, OpenError> {
    let t0 = Instant::now();
    let guard = OPEN_LOCK.lock().unwrap_or_else(PoisonError::into_inner);
    // A serial number is resolved to its device id by one discovery (about
    // 1 s); the id found is kept, so reopening the same camera is fast.
    let t_find = Instant::now();
    let name = match (resolved.clone(), config.camera.as_deref()) {
        (Some(id), _) => Some(id),
        (None, Some(want)) => {
            Some(ffi::device_id_of_serial(want).unwrap_or_else(|| want.to_string()))
        }
        (None, None) => None,
    };
    let find_ms = t_find.elapsed().as_millis() as u64;
    let camera = Camera::new(name.as_deref()).map_err(|e| {
        OpenError::Absent(format!(
            "opening {}: {e}",
            name.as_deref().unwrap_or("the first camera")
        ))
    })?;
    if config.camera.is_some() {
        resolved.clone_from(&name);
    }
    tracing::debug!(
        ?name,
        find_ms,
        open_ms = t0.elapsed().as_millis() as u64,
        "camera found"
    );
    drop(guard);
    let id = camera
        .device_id()
        .map(|s| s.to_string())
        .unwrap_or_else(|_| config.camera.clone().unwrap_or_default());

    let format = match config.pixel {
        PixelDepth::Mono8 => PixelFormat::MONO_8,
        PixelDepth::Mono16 => PixelFormat::MONO_16,
    };
    camera
        .set_pixel_format(format)
        .map_err(setting("pixel format"))?;
    if let Some(r) = config.roi {
        camera
            .set_region(r.x as i32, r.y as i32, r.width as i32, r.height as i32)
            .map_err(setting("roi"))?;
    }
    if let Some(us) = config.exposure_us {
        camera.set_exposure_time(us).map_err(setting("exposure"))?;
    }
    if let Some(g) = config.gain {
        camera.set_gain(g).map_err(setting("gain"))?;
    }
    if let Some(fps) = config.frame_rate {
        camera.set_frame_rate(fps).map_err(setting("frame rate"))?;
    }
    if camera.is_gv_device() {
        if let Some(p) = config.packet_size {
            camera
                .gv_set_packet_size(p as i32)
                .map_err(setting("packet size"))?;
        }
        if !config.packet_socket {
            // Must precede create_stream.
            camera.gv_set_stream_options(aravis::GvStreamOption::PACKET_SOCKET_DISABLED);
        }
    }
    camera
        .set_acquisition_mode(AcquisitionMode::Continuous)
        .map_err(setting("acquisition mode"))?;
    let payload = camera.payload().map_err(setting("payload"))? as usize;

    let stream = camera.create_stream().map_err(setting("stream"))?;
    if let Some(gv) = stream.downcast_ref::<aravis::GvStream>() {
        gv.set_socket_buffer(aravis::GvStreamSocketBuffer::Auto);
    }
    for _ in 0..config.buffers {
        stream.push_buffer(Buffer::new_allocate(payload));
    }

    let control_lost = Arc::new(AtomicBool::new(false));
    if let Some(device) = camera.device() {
        let flag = Arc::clone(&control_lost);
        device.connect_control_lost(move |_| flag.store(true, Ordering::Release));
    }
    camera.start_acquisition().map_err(setting("start"))?;
    Ok(Opened {
        camera,
        stream,
        control_lost,
        id,
        took: t0.elapsed(),
    })
}

/// Stops (unless `lost`) and drops a camera: slow if the camera is dead,
/// so never on the acquisition path. A lost camera gets no "stop": its
/// address may already serve a restarted camera, which a stale handle
/// would talk to.
fn close(o: Opened, lost: bool) {
    let t0 = Instant::now();
    if !lost {
        let _ = o.camera.stop_acquisition();
    }
    drop(o.stream);
    drop(o.camera);
    tracing::debug!(camera = %o.id, lost, took_ms = t0.elapsed().as_millis() as u64, "camera closed");
}

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

/// A GigE Vision camera as a [`FrameSource`] (see the module docs).
pub struct GigeSource {
    name: String,
    config: GigeConfig,
    clock: Box<dyn Clock>,
    counters: Arc<SourceCounters>,
    link: Link,
    open_tx: Option<Sender<()>>,
    opened_rx: Receiver<Result<Opened, OpenError>>,
    reap_tx: Option<Sender<(Opened, bool)>>,
    threads: Vec<JoinHandle<()>>,
    backoff: Duration,
    lost_after: Duration,
    next_seq: u64,
    failures_logged: bool,
    resized_logged: bool,
}

impl std::fmt::Debug for GigeSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GigeSource")
            .field("name", &self.name)
            .field("config", &self.config)
            .field("stats", &self.counters.snapshot())
            .finish()
    }
}

impl GigeSource {
    /// A source for the camera in `config`, with helper threads named after
    /// `name` (`<name>-open`, `<name>-reap`). Opens nothing yet: see
    /// [`FrameSource::start`]. Host times come from the system clock.
    pub fn new(name: &str, config: GigeConfig) -> Result<Self, SourceError> {
        Self::with_clock(name, config, Box::new(SystemClock))
    }

    /// As [`GigeSource::new`], with host times from `clock` when aravis
    /// gives no reception time.
    pub fn with_clock(
        name: &str,
        config: GigeConfig,
        clock: Box<dyn Clock>,
    ) -> Result<Self, SourceError> {
        config.validate()?;
        let spawn_err = |e: std::io::Error| SourceError::Config {
            what: "thread".into(),
            reason: e.to_string(),
        };
        let (open_tx, open_rx) = crossbeam_channel::unbounded::<()>();
        let (opened_tx, opened_rx) = crossbeam_channel::unbounded();
        let (reap_tx, reap_rx) = crossbeam_channel::unbounded::<(Opened, bool)>();
        let cfg = config.clone();
        let opener = std::thread::Builder::new()
            .name(format!("{name}-open"))
            .spawn(move || {
                let mut resolved = None;
                for () in open_rx {
                    if opened_tx.send(open(&cfg, &mut resolved)).is_err() {
                        break;
                    }
                }
            })
            .map_err(spawn_err)?;
        let reaper = std::thread::Builder::new()
            .name(format!("{name}-reap"))
            .spawn(move || {
                for (o, lost) in reap_rx {
                    close(o, lost);
                }
            })
            .map_err(spawn_err)?;
        Ok(GigeSource {
            name: name.to_string(),
            backoff: config.backoff_initial,
            lost_after: config.effective_lost_after(),
            config,
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

    fn reap(&mut self, o: Opened, lost: bool) {
        self.counters.connected.store(false, Ordering::Relaxed);
        if let Some(tx) = &self.reap_tx {
            if let Err(e) = tx.send((o, lost)) {
                // Reaper gone (cannot happen before drop): close here.
                let (o, lost) = e.into_inner();
                close(o, lost);
            }
        }
    }

    fn lose(&mut self, reason: String) -> SourceError {
        if let Link::Streaming(live) = std::mem::replace(&mut self.link, Link::Idle) {
            tracing::warn!(source = %self.name, camera = %live.opened.id, %reason, "camera lost");
            self.reap(live.opened, true);
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

    fn on_opened(&mut self, result: Result<Opened, OpenError>) -> Result<(), SourceError> {
        match result {
            Ok(opened) => {
                tracing::info!(source = %self.name, camera = %opened.id,
                    took_ms = opened.took.as_millis() as u64, "camera opened, streaming");
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
            Err(OpenError::Config { what, reason }) => {
                tracing::error!(source = %self.name, %what, %reason, "camera refuses the configuration");
                self.link = Link::Idle;
                Err(SourceError::Config { what, reason })
            }
            Err(OpenError::Absent(reason)) => {
                if !self.failures_logged {
                    tracing::warn!(source = %self.name, %reason, "camera not available; retrying with back-off");
                    self.failures_logged = true;
                } else {
                    tracing::debug!(source = %self.name, %reason, backoff_ms = self.backoff.as_millis() as u64, "open failed");
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
        if live.opened.control_lost.load(Ordering::Acquire) {
            return Err(self.lose("control lost".into()));
        }
        let timeout_us = timeout.as_micros().clamp(1, u64::MAX as u128) as u64;
        let Some(buffer) = live.opened.stream.timeout_pop_buffer(timeout_us) else {
            let silent = live.last_buffer.elapsed();
            if silent >= self.lost_after {
                return Err(self.lose(format!("no frame for {:.1} s", silent.as_secs_f64())));
            }
            return Err(SourceError::Timeout(timeout));
        };
        live.last_buffer = Instant::now();
        let copied = if buffer.status() == BufferStatus::Success {
            copy_frame(&buffer, slot)
        } else {
            Err(Copy::Incomplete)
        };
        let frame_id = buffer.frame_id();
        let camera_time_ns = buffer.timestamp();
        let host_time_ns = match buffer.system_timestamp() {
            0 => self.clock.now_ns(),
            t => t,
        };
        live.opened.stream.push_buffer(buffer);
        match copied {
            Ok(resized) => {
                if resized && !self.resized_logged {
                    tracing::warn!(source = %self.name, width = slot.image.width(), height = slot.image.height(),
                        "frame size differs from the ring's slots: slot reallocated (size the ring from the camera)");
                    self.resized_logged = true;
                }
                if let Some(last) = live.last_frame_id {
                    let gap = id_gap(last, frame_id);
                    if gap > 0 {
                        self.counters.missing.add(gap);
                        self.next_seq += gap;
                    }
                }
                live.last_frame_id = Some(frame_id);
                slot.meta.seq = self.next_seq;
                slot.meta.camera_frame_id = frame_id;
                slot.meta.camera_time_ns = camera_time_ns;
                slot.meta.host_time_ns = host_time_ns;
                self.next_seq += 1;
                self.counters.frames.inc();
                Ok(())
            }
            Err(Copy::Incomplete) => {
                self.counters.incomplete.inc();
                Err(SourceError::Timeout(timeout))
            }
            Err(Copy::Format(raw)) => Err(SourceError::Config {
                what: "pixel format".into(),
                reason: format!("camera sends pixel format {raw:#010x}, not Mono8/Mono16"),
            }),
        }
    }
}

/// Frames missed between camera frame ids `last` and `id`. GigE Vision 1.x
/// block ids are 16-bit and skip 0 on wrap; a smaller id that is not a wrap
/// (a camera that restarted counting) counts as no gap.
pub fn id_gap(last: u64, id: u64) -> u64 {
    if id > last {
        id - last - 1
    } else if last > 0xFF00 && last <= 0xFFFF && id < 0x100 {
        // 16-bit wrap: ids run ..., 0xFFFF, 1, 2, ...
        (0xFFFF - last) + id.saturating_sub(1)
    } else {
        0
    }
}

enum Copy {
    Incomplete,
    Format(u32),
}

/// Copies a complete buffer's pixels into `slot` (reallocating its image
/// only if the size or depth differ); returns whether it reallocated.
fn copy_frame(buffer: &Buffer, slot: &mut Slot) -> Result<bool, Copy> {
    let width = buffer.image_width().max(0) as u32;
    let height = buffer.image_height().max(0) as u32;
    let format = buffer.image_pixel_format();
    let wide = if format == PixelFormat::MONO_8 {
        false
    } else if format == PixelFormat::MONO_16 {
        true
    } else {
        return Err(Copy::Format(format.raw()));
    };
    let pixels = width as usize * height as usize;
    let bytes = ffi::payload(buffer);
    let need = pixels * if wide { 2 } else { 1 };
    if pixels == 0 || bytes.len() < need {
        return Err(Copy::Incomplete);
    }
    let fits = slot.image.width() == width
        && slot.image.height() == height
        && matches!(
            (slot.image.pixels(), wide),
            (Pixels::Mono8(_), false) | (Pixels::Mono16(_), true)
        );
    if !fits {
        slot.image = if wide {
            Image::new_mono16(width, height, u16::MAX)
        } else {
            Image::new_mono8(width, height)
        };
    }
    match slot.image.pixels_mut() {
        Pixels::Mono8(dst) => dst.copy_from_slice(&bytes[..need]),
        Pixels::Mono16(dst) => {
            for (d, s) in dst.iter_mut().zip(bytes[..need].chunks_exact(2)) {
                *d = u16::from_le_bytes([s[0], s[1]]);
            }
        }
    }
    Ok(!fits)
}

impl FrameSource for GigeSource {
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
                // The opener is at work: alive, no frame yet.
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
            Link::Streaming(live) => self.reap(live.opened, false),
            Link::Opening => {
                // Opening fails or succeeds within seconds; close what it gives.
                if let Ok(Ok(o)) = self.opened_rx.recv_timeout(Duration::from_secs(30)) {
                    self.reap(o, false);
                }
            }
            Link::Idle | Link::Waiting { .. } => {}
        }
        self.counters.connected.store(false, Ordering::Relaxed);
    }

    fn describe(&self) -> String {
        format!(
            "GigE Vision camera {} ({:?})",
            self.config.camera.as_deref().unwrap_or("(first found)"),
            self.config.pixel
        )
    }

    fn stats(&self) -> SourceStats {
        self.counters.snapshot()
    }

    fn shared_counters(&self) -> Option<Arc<SourceCounters>> {
        Some(self.counters())
    }
}

impl Drop for GigeSource {
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

    #[test]
    fn id_gaps() {
        assert_eq!(id_gap(5, 6), 0);
        assert_eq!(id_gap(5, 8), 2);
        assert_eq!(id_gap(0xFFFF, 1), 0);
        assert_eq!(id_gap(0xFFFE, 1), 1);
        assert_eq!(id_gap(0xFFFF, 3), 2);
        assert_eq!(id_gap(100, 3), 0);
    }

    #[test]
    fn config_is_checked() {
        let bad = GigeConfig {
            buffers: 1,
            ..GigeConfig::default()
        };
        assert!(matches!(
            GigeSource::new("t", bad),
            Err(SourceError::Config { .. })
        ));
        let bad = GigeConfig {
            frame_rate: Some(0.0),
            ..GigeConfig::default()
        };
        assert!(GigeSource::new("t", bad).is_err());
        assert!(GigeSource::new("t", GigeConfig::default()).is_ok());
        let slow = GigeConfig {
            frame_rate: Some(0.5),
            ..GigeConfig::default()
        };
        assert_eq!(slow.effective_lost_after(), Duration::from_secs(6));
        assert_eq!(
            GigeConfig::default().effective_lost_after(),
            Duration::from_secs(2)
        );
    }
}
