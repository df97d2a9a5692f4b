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
//! an *opener* thread (both threads are a [`Reopener`]). The source retries with exponential back-off and
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
//! # Time
//! Each frame is stamped on the host's monotonic clock ([`crate::mono`]):
//! `host_mono_ns` is its arrival (aravis' reception stamp, moved onto the
//! monotonic clock; the pop when aravis gives none), and
//! `exposure_mono_ns` the middle of its exposure, from the camera's
//! timestamp through a [`ClockMap`] (the lower envelope of camera time
//! against arrival; reset at every opening) — assuming, as GigE Vision
//! cameras commonly do, that the timestamp is latched at the *start* of
//! the exposure, so the earliest arrival is the stamp plus the exposure
//! time plus the transfer ([`GigeConfig::transfer`], by default the
//! payload at 1 Gbit/s), and the middle is half an exposure after the
//! stamp. `exposure_ns` is the camera's `ExposureTime` as read at opening,
//! `exposure_sigma_ns` the mapping's uncertainty. A camera that sends no
//! timestamps gets its exposure from [`GigeConfig::fixed_latency`], or none.
//!
//! # Exposure control
//! With [`GigeConfig::exposure_control`] the source steers the camera's
//! exposure time to hold its targets' peak (`crate::exposure`): at each
//! opening it finds the feature (`ExposureTime`, else `ExposureTimeAbs`;
//! neither refuses the configuration), turns `ExposureAuto` off and
//! brings the exposure inside the loop's limits (narrowed to the
//! camera's range). Between frames — at the start of
//! [`FrameSource::next_frame`], never while a frame is being copied — it
//! reads the newest measurement the detection workers offered on its
//! [`ExposureLink`], runs the law and writes the feature (then reads back
//! what the camera took). Only measurements of frames exposed after the
//! last write count: the frames already queued in the stream and the one
//! being exposed are skipped, and from the first fresh frame on the
//! frames carry the new `exposure_ns`. A camera that may be dying (no
//! buffer for half of `lost_after`, or control lost) is not written to.
//! A failed write is counted and logged, never fatal. The exposure in
//! effect is the link's gauge, with or without the loop.
//!
//! # Missing frames
//! Gaps in the camera's frame (block) ids between delivered frames are
//! counted in [`SourceStats::missing`](crate::source::SourceStats) and
//! advance [`FrameMeta::seq`](photopose_frame::FrameMeta), so a consumer
//! sees a missed frame as a gap in `seq`. The first frame after each start
//! usually arrives incomplete and is counted in `incomplete`, not delivered.

mod camera;
mod config;
mod copy;

pub use camera::{list_cameras, CameraInfo};
pub use config::{FeatureValue, GigeConfig, PixelDepth, Roi};
pub use copy::id_gap;

use crate::clock_map::{ClockMap, ClockMapConfig};
use crate::exposure::{seq_after, ExposureLaw, ExposureLink, ExposureSettings, Step};
use crate::reopen::{Backoff, Device, OpenFailure, Ready, Reopener};
use crate::ring::Slot;
use crate::source::{Clock, FrameSource, SourceCounters, SourceError, SourceStats, SystemClock};
use aravis::prelude::*;
use aravis::BufferStatus;
use camera::{close, open, OpenError, Opened};
use copy::{copy_frame, Copy};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A GigE Vision camera as a [`FrameSource`] (see the module docs).
pub struct GigeSource {
    name: String,
    config: GigeConfig,
    clock: Box<dyn Clock>,
    counters: Arc<SourceCounters>,
    link: Reopener<Opened>,
    lost_after: Duration,
    next_seq: u64,
    resized_logged: bool,
    clock_map: ClockMap,
    exposure: Arc<ExposureLink>,
    steer: Option<Steer>,
    /// The exposure time of the frames from this `seq` on, ns, after a
    /// write whose frames have not arrived yet.
    pending_exposure: Option<(u64, u64)>,
}

/// Frames after the ones queued in the stream that may still have been
/// exposed before an exposure write took effect (the one being exposed).
const SETTLE_FRAMES: u64 = 2;

/// Shortest time between two log lines of exposure changes.
const EXPOSURE_LOG_EVERY: Duration = Duration::from_secs(1);

/// The exposure control loop's side in the source.
struct Steer {
    settings: ExposureSettings,
    /// The law as configured (each opening starts from a copy of it).
    configured: ExposureLaw,
    /// The law of this opening (limits narrowed to the camera's range).
    law: ExposureLaw,
    /// The exposure in effect as the camera reported it, µs.
    current_us: f64,
    /// Measurements of frames before this `seq` were exposed before the
    /// last write or opening: not used.
    fresh_from: u64,
    /// The frame number of the last measurement used.
    last_used: Option<u32>,
    /// The exposure last logged, µs, and when.
    logged: Option<(f64, Instant)>,
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

impl Device for Opened {
    fn id(&self) -> &str {
        &self.id
    }
    fn close(self, lost: bool) {
        close(self, lost);
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
        let steer = match config.exposure_control {
            Some(settings) => {
                let law = ExposureLaw::new(settings).map_err(|e| SourceError::Config {
                    what: "exposure_control".into(),
                    reason: e.to_string(),
                })?;
                Some(Steer {
                    settings,
                    configured: law.clone(),
                    law,
                    current_us: 0.0,
                    fresh_from: 0,
                    last_used: None,
                    logged: None,
                })
            }
            None => None,
        };
        let counters = Arc::new(SourceCounters::default());
        let cfg = config.clone();
        let mut resolved = None;
        let link = Reopener::spawn(
            name,
            "camera",
            Backoff::new(config.backoff_initial, config.backoff_max),
            Arc::clone(&counters),
            move || {
                open(&cfg, &mut resolved).map_err(|e| match e {
                    OpenError::Absent(reason) => OpenFailure::Absent(reason),
                    OpenError::Config { what, reason } => OpenFailure::Refused { what, reason },
                })
            },
        )
        .map_err(|e| SourceError::Config {
            what: "thread".into(),
            reason: e.to_string(),
        })?;
        Ok(GigeSource {
            name: name.to_string(),
            lost_after: config.effective_lost_after(),
            config,
            clock,
            counters,
            link,
            next_seq: 0,
            resized_logged: false,
            clock_map: ClockMap::new(ClockMapConfig::default()),
            exposure: Arc::new(ExposureLink::new(steer.is_some())),
            steer,
            pending_exposure: None,
        })
    }

    /// The live counters (shareable with a metrics thread).
    pub fn counters(&self) -> Arc<SourceCounters> {
        Arc::clone(&self.counters)
    }

    fn on_opened(&mut self) {
        if let Some(live) = self.link.live() {
            let opened = &live.device;
            tracing::info!(source = %self.name, camera = %opened.id,
                took_ms = opened.took.as_millis() as u64, "camera opened, streaming");
        }
        // A reopened camera may have restarted its clock.
        self.clock_map.reset();
        self.pending_exposure = None;
        let Some(live) = self.link.live() else { return };
        let exposure_us = live.device.exposure_ns as f64 / 1e3;
        self.exposure.exposure_s.set(exposure_us * 1e-6);
        if let (Some(st), Some(node)) = (self.steer.as_mut(), live.device.exposure_control) {
            let queued = live.device.stream.n_buffers().1.max(0) as u64;
            st.law = st.configured.clone();
            st.law.limit_to(node.range.0, node.range.1);
            st.current_us = exposure_us;
            st.fresh_from = self.next_seq + queued + SETTLE_FRAMES;
            st.last_used = None;
            tracing::info!(source = %self.name, feature = node.feature, exposure_us,
                min_us = node.range.0, max_us = node.range.1,
                target_peak = st.settings.target_peak, "exposure control on");
        }
    }

    /// The exposure control loop's turn, between frames: the newest fresh
    /// measurement through the law, and the camera's exposure written if
    /// the law asks (see the module docs).
    fn steer(&mut self) {
        let Some(st) = self.steer.as_mut() else {
            return;
        };
        let Some(live) = self.link.live_mut() else {
            return;
        };
        let Some(node) = live.device.exposure_control else {
            return;
        };
        // Every register access to a dead camera blocks for seconds.
        if live.device.control_lost.load(Ordering::Acquire)
            || live.last_buffer.elapsed() > self.lost_after / 2
        {
            return;
        }
        let Some((seq, peak)) = self.exposure.latest() else {
            return;
        };
        if st.last_used.is_some_and(|l| !seq_after(seq, l)) || seq_after(st.fresh_from as u32, seq)
        {
            return;
        }
        st.last_used = Some(seq);
        let Step::Set(us) = st.law.observe(f64::from(peak), st.current_us) else {
            return;
        };
        let camera = &live.device.camera;
        let written = camera
            .set_float(node.feature, us)
            .and_then(|()| camera.float(node.feature));
        let failure = match written {
            Ok(got) if got.is_finite() && got > 0.0 => {
                let queued = live.device.stream.n_buffers().1.max(0) as u64;
                st.fresh_from = self.next_seq + queued + SETTLE_FRAMES;
                self.pending_exposure = Some((st.fresh_from, (got * 1e3).round() as u64));
                let from = st.current_us;
                st.current_us = got;
                self.exposure.exposure_s.set(got * 1e-6);
                self.exposure.writes.inc();
                let now = Instant::now();
                let worth = st.logged.is_none_or(|(logged, at)| {
                    (got / logged - 1.0).abs() > st.settings.dead_band
                        && now.duration_since(at) >= EXPOSURE_LOG_EVERY
                });
                if worth {
                    tracing::info!(source = %self.name, from_us = from, to_us = got,
                        peak = f64::from(peak), target_peak = st.settings.target_peak, "exposure changed");
                    st.logged = Some((got, now));
                } else {
                    tracing::debug!(source = %self.name, from_us = from, to_us = got, peak = f64::from(peak), "exposure changed");
                }
                return;
            }
            Ok(got) => format!("the camera reports {got} µs after the write"),
            Err(e) => e.to_string(),
        };
        self.exposure.write_failures.inc();
        let n = self.exposure.write_failures.get();
        if n.is_power_of_two() {
            tracing::warn!(source = %self.name, feature = node.feature, exposure_us = us,
                error = %failure, failures = n, "exposure write failed");
        }
    }

    fn grab(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        let Some(live) = self.link.live_mut() else {
            return Err(SourceError::Unavailable {
                reason: "not streaming".into(),
            });
        };
        if live.device.control_lost.load(Ordering::Acquire) {
            return Err(self.link.lose("control lost".into()));
        }
        let timeout_us = timeout.as_micros().clamp(1, u64::MAX as u128) as u64;
        let Some(buffer) = live.device.stream.timeout_pop_buffer(timeout_us) else {
            let silent = live.last_buffer.elapsed();
            if silent >= self.lost_after {
                return Err(self
                    .link
                    .lose(format!("no frame for {:.1} s", silent.as_secs_f64())));
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
        let (utc_now, mono_now) = (self.clock.now_ns(), crate::mono::now_ns());
        let (host_time_ns, host_mono_ns) = match buffer.system_timestamp() {
            // aravis stamped the reception (UTC): the same instant on the
            // monotonic clock, never after now, at most a second back.
            t if t != 0 && t <= utc_now && utc_now - t < 1_000_000_000 => {
                (t, mono_now - (utc_now - t))
            }
            _ => (utc_now, mono_now),
        };
        live.device.stream.push_buffer(buffer);
        if let Some((from, ns)) = self.pending_exposure {
            if self.next_seq >= from {
                live.device.exposure_ns = ns;
                self.pending_exposure = None;
            }
        }
        let (exposure_ns, payload) = (live.device.exposure_ns, live.device.payload);
        match copied {
            Ok(resized) => {
                if resized && !self.resized_logged {
                    tracing::warn!(source = %self.name, width = slot.image().width(), height = slot.image().height(),
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
                slot.meta.host_mono_ns = host_mono_ns;
                slot.meta.exposure_ns = exposure_ns;
                let (mid, sigma) =
                    self.exposure_instant(camera_time_ns, host_mono_ns, exposure_ns, payload);
                slot.meta.exposure_mono_ns = mid;
                slot.meta.exposure_sigma_ns = sigma;
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
impl GigeSource {
    /// The middle of a frame's exposure on the host's monotonic clock and
    /// its uncertainty (see the module docs), `(0, 0)` when not known.
    fn exposure_instant(
        &mut self,
        camera_ns: u64,
        arrival_ns: u64,
        exposure_ns: u64,
        payload: usize,
    ) -> (u64, u64) {
        if camera_ns == 0 {
            return match self.config.fixed_latency {
                Some(l) => (
                    arrival_ns.saturating_sub(l.as_nanos() as u64),
                    (l.as_nanos() as u64) / 10,
                ),
                None => (0, 0),
            };
        }
        let m = self.clock_map.update(camera_ns, arrival_ns);
        let transfer = self.config.transfer.map_or_else(
            || crate::clock_map::bytes_at_gigabit_ns(payload),
            |t| t.as_nanos() as u64,
        );
        let stamp = m
            .floor_ns
            .saturating_sub(exposure_ns.saturating_add(transfer));
        (stamp.saturating_add(exposure_ns / 2), m.sigma_ns)
    }
}

impl FrameSource for GigeSource {
    fn start(&mut self) -> Result<(), SourceError> {
        self.link.start()
    }

    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        let (ready, left) = self.link.ready(timeout)?;
        if ready == Ready::Opened {
            self.on_opened();
        } else {
            self.steer();
        }
        self.grab(slot, left)
    }

    fn stop(&mut self) {
        self.link.stop();
    }

    fn describe(&self) -> String {
        format!(
            "GigE Vision camera {} ({})",
            self.config.camera.as_deref().unwrap_or("(first found)"),
            match self.config.pixel {
                PixelDepth::Mono8 => "Mono8",
                PixelDepth::Mono16 => "Mono16",
            }
        )
    }

    fn stats(&self) -> SourceStats {
        self.counters.snapshot()
    }

    fn shared_counters(&self) -> Option<Arc<SourceCounters>> {
        Some(self.counters())
    }

    fn exposure_link(&self) -> Option<Arc<ExposureLink>> {
        Some(Arc::clone(&self.exposure))
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
        let bad = GigeConfig {
            exposure_control: Some(crate::ExposureSettings {
                min_us: 500.0,
                max_us: 100.0,
                ..crate::ExposureSettings::default()
            }),
            ..GigeConfig::default()
        };
        match GigeSource::new("t", bad) {
            Err(SourceError::Config { what, .. }) => assert_eq!(what, "exposure_control.max_us"),
            other => panic!("{other:?}"),
        }
        let steered = GigeSource::new(
            "t",
            GigeConfig {
                exposure_control: Some(crate::ExposureSettings::default()),
                ..GigeConfig::default()
            },
        )
        .unwrap();
        assert!(steered.exposure_link().is_some_and(|l| l.steering()));
        let plain = GigeSource::new("t", GigeConfig::default()).unwrap();
        assert!(plain.exposure_link().is_some_and(|l| !l.steering()));
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
