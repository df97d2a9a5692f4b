//! The [`FrameSource`] seam: what a grabber asks of a camera, a recording or
//! a renderer, and the error that tells a grabber whether to carry on.
//!
//! A source fills a caller-owned [`Slot`] (one from the ring); it never
//! allocates frames of its own. Time comes in through a [`Clock`], so tests
//! and replays can fix it.

use crate::exposure::ExposureLink;
use crate::ring::Slot;
use photopose_frame::Image;
use photopose_telemetry::{Collect, Counter, Scrape};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use thiserror::Error;

/// Why a source gave no frame.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum SourceError {
    /// No frame within the timeout; the source is alive: call again.
    #[error("no frame within {} ms", .0.as_millis())]
    Timeout(Duration),
    /// The camera was lost just now (returned once per loss); the source
    /// reconnects by itself: call again.
    #[error("camera lost: {reason}")]
    Lost {
        /// What gave the loss away (timeouts, control lost, a failed read).
        reason: String,
    },
    /// The camera is not connected (waiting for it or reopening it); the
    /// source keeps trying: call again.
    #[error("camera unavailable: {reason}")]
    Unavailable {
        /// Why the last attempt failed.
        reason: String,
    },
    /// This one frame could not be delivered (a corrupt record in a
    /// recording, a renderer refusing a pose); the source goes on: call
    /// again.
    #[error("frame skipped: {reason}")]
    Frame {
        /// What was wrong with the frame.
        reason: String,
    },
    /// The source has no more frames (a recording ran out).
    #[error("source ended")]
    Ended,
    /// A configuration the camera refuses: fatal, do not call again.
    #[error("configuration refused: {what}: {reason}")]
    Config {
        /// The setting (feature) concerned.
        what: String,
        /// The camera's or library's word.
        reason: String,
    },
}

impl SourceError {
    /// Whether a grabber should give up (configuration refused, source ended).
    pub fn is_fatal(&self) -> bool {
        matches!(self, SourceError::Config { .. } | SourceError::Ended)
    }
}

/// A source of frames: GigE camera, recording or renderer.
///
/// Lifecycle: [`start`](FrameSource::start), then
/// [`next_frame`](FrameSource::next_frame) until done, then
/// [`stop`](FrameSource::stop). A source that loses its device reports
/// [`SourceError::Lost`] once and [`SourceError::Unavailable`] until it is
/// back, reconnecting by itself.
pub trait FrameSource: Send {
    /// Begins acquisition (may return before the device is open).
    fn start(&mut self) -> Result<(), SourceError>;

    /// Fills `slot` with the next frame (pixels and metadata), waiting at
    /// most about `timeout`. The slot's image is resized only if the frame
    /// differs in size or depth from it.
    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError>;

    /// Ends acquisition; slow device work is done off the caller's thread
    /// where the source can.
    fn stop(&mut self);

    /// A one-line description for logs.
    fn describe(&self) -> String;

    /// The source's own counters, if it keeps any.
    fn stats(&self) -> SourceStats {
        SourceStats::default()
    }

    /// The live counters behind [`stats`](FrameSource::stats), shareable
    /// with a metrics thread, if the source keeps them in atomics.
    fn shared_counters(&self) -> Option<Arc<SourceCounters>> {
        None
    }

    /// The source's [`ExposureLink`], if it reports its exposure time
    /// (and, when [`ExposureLink::steering`], steers it from the frames'
    /// peaks the detection workers offer there).
    fn exposure_link(&self) -> Option<Arc<ExposureLink>> {
        None
    }
}

impl<S: FrameSource + ?Sized> FrameSource for Box<S> {
    fn start(&mut self) -> Result<(), SourceError> {
        (**self).start()
    }
    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        (**self).next_frame(slot, timeout)
    }
    fn stop(&mut self) {
        (**self).stop()
    }
    fn describe(&self) -> String {
        (**self).describe()
    }
    fn stats(&self) -> SourceStats {
        (**self).stats()
    }
    fn shared_counters(&self) -> Option<Arc<SourceCounters>> {
        (**self).shared_counters()
    }
    fn exposure_link(&self) -> Option<Arc<ExposureLink>> {
        (**self).exposure_link()
    }
}

/// A snapshot of a source's counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SourceStats {
    /// Frames delivered into slots.
    pub frames: u64,
    /// Frames the source knows it missed (gaps in the camera's frame ids
    /// between delivered frames).
    pub missing: u64,
    /// Buffers that arrived incomplete or damaged (not delivered).
    pub incomplete: u64,
    /// Times the device was lost.
    pub losses: u64,
    /// Times the device was (re)opened.
    pub opens: u64,
    /// Whether the device is connected and streaming now.
    pub connected: bool,
}

/// Live counters behind [`SourceStats`], shared with other threads.
#[derive(Debug, Default)]
pub struct SourceCounters {
    /// See [`SourceStats::frames`].
    pub frames: Counter,
    /// See [`SourceStats::missing`].
    pub missing: Counter,
    /// See [`SourceStats::incomplete`].
    pub incomplete: Counter,
    /// See [`SourceStats::losses`].
    pub losses: Counter,
    /// See [`SourceStats::opens`].
    pub opens: Counter,
    /// See [`SourceStats::connected`].
    pub connected: AtomicBool,
}

impl SourceCounters {
    /// A snapshot (relaxed reads).
    pub fn snapshot(&self) -> SourceStats {
        SourceStats {
            frames: self.frames.get(),
            missing: self.missing.get(),
            incomplete: self.incomplete.get(),
            losses: self.losses.get(),
            opens: self.opens.get(),
            connected: self.connected.load(Ordering::Relaxed),
        }
    }
}

impl Collect for SourceCounters {
    fn collect(&self, out: &mut Scrape<'_>) -> std::fmt::Result {
        let st = self.snapshot();
        for (name, help, v) in [
            (
                "photopose_source_frames_total",
                "Frames the camera source delivered into slots.",
                st.frames,
            ),
            (
                "photopose_source_missing_frames_total",
                "Frames the camera sent that never arrived (gaps in its frame ids).",
                st.missing,
            ),
            (
                "photopose_source_incomplete_frames_total",
                "Frames that arrived incomplete or damaged (not processed).",
                st.incomplete,
            ),
            (
                "photopose_source_losses_total",
                "Times the camera was lost.",
                st.losses,
            ),
            (
                "photopose_source_opens_total",
                "Times the camera was (re)opened.",
                st.opens,
            ),
        ] {
            out.counter(name, help, v)?;
        }
        out.gauge(
            "photopose_source_connected",
            "Camera state: 1 while the camera is connected and streaming, else 0.",
            f64::from(u8::from(st.connected)),
        )
    }
}

/// Host time, passed in so that tests and replays can fix it.
pub trait Clock: Send + Sync {
    /// Now, ns since the Unix epoch.
    fn now_ns(&self) -> u64;
}

/// The system's real-time clock.
#[derive(Debug, Clone, Copy, Default)]
pub struct SystemClock;

impl Clock for SystemClock {
    fn now_ns(&self) -> u64 {
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_nanos() as u64)
            .unwrap_or(0)
    }
}

/// A test source: frames of a fixed size whose first pixel row carries the
/// sequence number (little-endian, 8 bytes), produced as fast as asked or
/// paced at a rate, ending after a given count. For grabber and ring tests
/// without a camera.
pub struct CountingSource<C: Clock> {
    width: u32,
    height: u32,
    count: Option<u64>,
    period: Option<Duration>,
    clock: C,
    next_seq: u64,
    next_due: Option<Instant>,
    started: bool,
}

impl<C: Clock> CountingSource<C> {
    /// `count` frames (or endless if `None`) of `width`×`height` Mono8
    /// (`width` ≥ 8), at `rate` frames/s (or unpaced if `None`).
    pub fn new(width: u32, height: u32, count: Option<u64>, rate: Option<f64>, clock: C) -> Self {
        CountingSource {
            width: width.max(8),
            height: height.max(1),
            count,
            period: rate
                .filter(|r| *r > 0.0)
                .map(|r| Duration::from_secs_f64(1.0 / r)),
            clock,
            next_seq: 0,
            next_due: None,
            started: false,
        }
    }

    /// The sequence number written into a frame by this source.
    pub fn seq_of(image: &Image) -> Option<u64> {
        match image.pixels() {
            photopose_frame::Pixels::Mono8(v) if v.len() >= 8 => {
                let mut b = [0u8; 8];
                b.copy_from_slice(&v[..8]);
                Some(u64::from_le_bytes(b))
            }
            _ => None,
        }
    }
}

impl<C: Clock> FrameSource for CountingSource<C> {
    fn start(&mut self) -> Result<(), SourceError> {
        self.started = true;
        self.next_due = Some(Instant::now());
        Ok(())
    }

    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        if !self.started {
            return Err(SourceError::Unavailable {
                reason: "not started".into(),
            });
        }
        if self.count.is_some_and(|n| self.next_seq >= n) {
            return Err(SourceError::Ended);
        }
        if let (Some(period), Some(due)) = (self.period, self.next_due) {
            let now = Instant::now();
            if due > now {
                let wait = due - now;
                if wait > timeout {
                    std::thread::sleep(timeout);
                    return Err(SourceError::Timeout(timeout));
                }
                std::thread::sleep(wait);
            }
            self.next_due = Some(due + period);
        }
        let image = slot.image_mut();
        if image.width() != self.width
            || image.height() != self.height
            || !matches!(image.pixels(), photopose_frame::Pixels::Mono8(_))
        {
            *image = Image::new_mono8(self.width, self.height);
        }
        if let photopose_frame::Pixels::Mono8(v) = image.pixels_mut() {
            v[..8].copy_from_slice(&self.next_seq.to_le_bytes());
        }
        slot.meta.seq = self.next_seq;
        slot.meta.camera_frame_id = self.next_seq;
        slot.meta.camera_time_ns = self.next_seq;
        slot.meta.host_time_ns = self.clock.now_ns();
        self.next_seq += 1;
        Ok(())
    }

    fn stop(&mut self) {
        self.started = false;
    }

    fn describe(&self) -> String {
        format!("counting source {}×{}", self.width, self.height)
    }

    fn stats(&self) -> SourceStats {
        SourceStats {
            frames: self.next_seq,
            connected: self.started,
            ..SourceStats::default()
        }
    }
}
