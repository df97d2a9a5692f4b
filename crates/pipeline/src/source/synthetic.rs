//! The synthetic source (`[source.synthetic]`): frames rendered of the
//! plate along a camera path in real time — the default of `photopose run`,
//! so the whole chain runs without hardware. It owns its section: the keys,
//! their defaults and their checks live here and nowhere else.
//!
//! Time: frame `k` is exposed (its middle) at the source's start plus
//! `k / rate_hz` on the host's monotonic clock, rendered at the pose of
//! that instant, and handed over after half the exposure and the transfer
//! (`exposure_ms`, 2 ms by default; `transfer_ms`, by default the frame's
//! bytes at 1 Gbit/s: about 10.7 ms for 1300×1030 Mono8), as a GigE camera
//! would deliver it. The stamped exposure instant is exact.

use super::{ensure_mono8, wait_until, Bad};
use crate::config::ConfigError;
pub use photopose_acquire::source::{Clock, SystemClock};
use photopose_acquire::{FrameSource, Slot, SourceError};
use photopose_field::Field;
use photopose_geometry::{Camera, Exterior};
use photopose_render::{RenderError, RenderOptions, Renderer};
use serde::Deserialize;
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Debug, Deserialize, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct SyntheticSection {
    #[serde(default = "default_rate")]
    rate_hz: f64,
    #[serde(default)]
    frames: u64,
    #[serde(default = "default_centre")]
    center_mm: [f64; 3],
    #[serde(default = "default_radius")]
    radius_mm: f64,
    #[serde(default = "default_period")]
    period_s: f64,
    #[serde(default = "default_noise")]
    noise_dn: f64,
    #[serde(default = "default_blur")]
    blur_px: f64,
    #[serde(default = "default_seed")]
    seed: u64,
    #[serde(default = "default_exposure")]
    exposure_ms: f64,
    #[serde(default)]
    transfer_ms: Option<f64>,
}

fn default_exposure() -> f64 {
    2.0
}

fn default_rate() -> f64 {
    20.0
}
fn default_centre() -> [f64; 3] {
    [0.0, 0.0, 1000.0]
}
fn default_radius() -> f64 {
    50.0
}
fn default_period() -> f64 {
    10.0
}
fn default_noise() -> f64 {
    2.0
}
fn default_blur() -> f64 {
    0.6
}
fn default_seed() -> u64 {
    1
}

/// The synthetic source: frames rendered along a circle in a horizontal
/// plane, the camera looking straight down at the plate.
#[derive(Debug, Clone, PartialEq)]
pub struct Synthetic {
    /// Frames per second.
    pub rate_hz: f64,
    /// Frames to produce, 0 for endless.
    pub frames: u64,
    /// Centre of the circle (camera positions), mm.
    pub center_mm: [f64; 3],
    /// Radius of the circle, mm.
    pub radius_mm: f64,
    /// Time for one turn, s.
    pub period_s: f64,
    /// Image noise, DN.
    pub noise_dn: f64,
    /// Blur, px.
    pub blur_px: f64,
    /// Noise seed.
    pub seed: u64,
    /// Exposure time, ms (the hand-over waits for its second half).
    pub exposure_ms: f64,
    /// Transfer from the end of the exposure to the hand-over, ms (`None`:
    /// the frame's bytes at 1 Gbit/s).
    pub transfer_ms: Option<f64>,
}

/// Validates `[source.synthetic]` (absent: every default).
pub(crate) fn validate(
    section: Option<SyntheticSection>,
    bad: Bad<'_>,
) -> Result<Synthetic, ConfigError> {
    let s = section.unwrap_or(SyntheticSection {
        rate_hz: default_rate(),
        frames: 0,
        center_mm: default_centre(),
        radius_mm: default_radius(),
        period_s: default_period(),
        noise_dn: default_noise(),
        blur_px: default_blur(),
        seed: default_seed(),
        exposure_ms: default_exposure(),
        transfer_ms: None,
    });
    if !(s.rate_hz.is_finite() && s.rate_hz > 0.0 && s.rate_hz <= 10_000.0) {
        return Err(bad(
            "source.synthetic.rate_hz",
            s.rate_hz.to_string(),
            "must be in (0, 10000] frames per second",
        ));
    }
    if !s.center_mm.iter().all(|v| v.is_finite()) || s.center_mm[2] <= 0.0 {
        return Err(bad(
            "source.synthetic.center_mm",
            format!(
                "[{}, {}, {}]",
                s.center_mm[0], s.center_mm[1], s.center_mm[2]
            ),
            "must be finite with Z above the plate (> 0)",
        ));
    }
    if !(s.radius_mm.is_finite() && s.radius_mm >= 0.0) {
        return Err(bad(
            "source.synthetic.radius_mm",
            s.radius_mm.to_string(),
            "must be ≥ 0",
        ));
    }
    if !(s.period_s.is_finite() && s.period_s > 0.0) {
        return Err(bad(
            "source.synthetic.period_s",
            s.period_s.to_string(),
            "must be > 0",
        ));
    }
    if !(s.noise_dn.is_finite() && s.noise_dn >= 0.0) {
        return Err(bad(
            "source.synthetic.noise_dn",
            s.noise_dn.to_string(),
            "must be ≥ 0",
        ));
    }
    if !(s.blur_px.is_finite() && (0.0..=10.0).contains(&s.blur_px)) {
        return Err(bad(
            "source.synthetic.blur_px",
            s.blur_px.to_string(),
            "must be in [0, 10]",
        ));
    }
    if !(s.exposure_ms.is_finite() && (0.0..=1000.0).contains(&s.exposure_ms)) {
        return Err(bad(
            "source.synthetic.exposure_ms",
            s.exposure_ms.to_string(),
            "must be in [0, 1000] ms",
        ));
    }
    if let Some(t) = s.transfer_ms {
        if !(t.is_finite() && (0.0..=10_000.0).contains(&t)) {
            return Err(bad(
                "source.synthetic.transfer_ms",
                t.to_string(),
                "must be in [0, 10000] ms",
            ));
        }
    }
    Ok(Synthetic {
        rate_hz: s.rate_hz,
        frames: s.frames,
        center_mm: s.center_mm,
        radius_mm: s.radius_mm,
        period_s: s.period_s,
        noise_dn: s.noise_dn,
        blur_px: s.blur_px,
        seed: s.seed,
        exposure_ms: s.exposure_ms,
        transfer_ms: s.transfer_ms,
    })
}

impl Synthetic {
    /// From the middle of the exposure to the hand-over, ns, for frames
    /// of `bytes`: half the exposure plus the transfer.
    pub fn delivery_ns(&self, bytes: usize) -> u64 {
        let transfer = match self.transfer_ms {
            Some(t) => (t * 1e6).round() as u64,
            None => photopose_acquire::clock_map::bytes_at_gigabit_ns(bytes),
        };
        (self.exposure_ms * 0.5e6).round() as u64 + transfer
    }
}

/// Frames rendered along a circle in a horizontal plane, the camera looking
/// straight down at the plate, paced at the configured rate — or, built
/// with [`SyntheticSource::along`], at given camera poses (a simulated robot
/// cell's path).
pub struct SyntheticSource {
    config: Synthetic,
    renderer: Renderer,
    /// Camera poses to render one after the other instead of the circle.
    poses: Option<Vec<Exterior>>,
    next: u64,
    /// The first frame's exposure middle, as an `Instant` and on
    /// `CLOCK_MONOTONIC` (ns).
    start: Option<(Instant, u64)>,
    clock: Arc<dyn Clock>,
}

impl std::fmt::Debug for SyntheticSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SyntheticSource")
            .field("config", &self.config)
            .field("next", &self.next)
            .finish_non_exhaustive()
    }
}

impl SyntheticSource {
    /// A synthetic source for `camera` over `field`.
    pub fn new(camera: Camera, field: &Field, config: Synthetic) -> Result<Self, RenderError> {
        let renderer = Renderer::new(
            camera,
            field,
            RenderOptions {
                noise_dn: config.noise_dn,
                blur_px: config.blur_px,
                seed: config.seed,
                ..RenderOptions::default()
            },
        )?;
        Ok(SyntheticSource {
            config,
            renderer,
            poses: None,
            next: 0,
            start: None,
            clock: Arc::new(SystemClock),
        })
    }

    /// The same source stamping host times from `clock` (tests fix it).
    pub fn with_clock(mut self, clock: Arc<dyn Clock>) -> Self {
        self.clock = clock;
        self
    }

    /// A source rendering `poses` in turn at `config.rate_hz` (the circle
    /// settings of `config` are not used), then ending.
    pub fn along(
        camera: Camera,
        field: &Field,
        config: Synthetic,
        poses: Vec<Exterior>,
    ) -> Result<Self, RenderError> {
        let mut me = Self::new(camera, field, config)?;
        me.poses = Some(poses);
        Ok(me)
    }

    /// The camera's exterior orientation for frame `seq` (the truth).
    pub fn pose_at(config: &Synthetic, seq: u64) -> Exterior {
        let t = seq as f64 / config.rate_hz;
        let phi = std::f64::consts::TAU * t / config.period_s;
        let [x, y, z] = config.center_mm;
        Exterior::from_kuka_pose([
            x + config.radius_mm * phi.cos(),
            y + config.radius_mm * phi.sin(),
            z,
            0.0,
            0.0,
            0.0,
        ])
    }
}

impl FrameSource for SyntheticSource {
    fn start(&mut self) -> Result<(), SourceError> {
        Ok(())
    }

    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        let end = match &self.poses {
            Some(p) => Some(p.len() as u64),
            None => (self.config.frames > 0).then_some(self.config.frames),
        };
        if end.is_some_and(|n| self.next >= n) {
            return Err(SourceError::Ended);
        }
        let (start, start_ns) = *self.start.get_or_insert_with(|| {
            let t = Instant::now();
            (t, photopose_acquire::mono::instant_ns(t))
        });
        let sensor = self.renderer.camera().sensor;
        let bytes = sensor.width as usize * sensor.height as usize;
        let delivery = self.config.delivery_ns(bytes);
        let since_start = Duration::from_secs_f64(self.next as f64 / self.config.rate_hz);
        let due = start + since_start + Duration::from_nanos(delivery);
        if !wait_until(due, timeout) {
            return Err(SourceError::Timeout(timeout));
        }
        let seq = self.next;
        self.next += 1;
        ensure_mono8(slot, sensor.width, sensor.height);
        let options = RenderOptions {
            seed: self.config.seed.wrapping_mul(1_000_003).wrapping_add(seq),
            ..*self.renderer.options()
        };
        let pose = match &self.poses {
            Some(p) => p[seq as usize],
            None => Self::pose_at(&self.config, seq),
        };
        let rendered = self
            .renderer
            .set_options(options)
            .and_then(|()| self.renderer.render(&pose, slot.image_mut()).map(|_| ()));
        if let Err(e) = rendered {
            return Err(SourceError::Frame {
                reason: format!("synthetic frame {seq}: {e}"),
            });
        }
        slot.meta.seq = seq;
        slot.meta.camera_frame_id = seq;
        slot.meta.camera_time_ns = (seq as f64 / self.config.rate_hz * 1e9) as u64;
        slot.meta.host_time_ns = self.clock.now_ns();
        slot.meta.host_mono_ns = photopose_acquire::mono::now_ns();
        slot.meta.exposure_mono_ns = start_ns + since_start.as_nanos() as u64;
        // Exact by construction: 1 ns stands for "known exactly".
        slot.meta.exposure_sigma_ns = 1;
        slot.meta.exposure_ns = (self.config.exposure_ms * 1e6).round() as u64;
        Ok(())
    }

    fn stop(&mut self) {}

    fn describe(&self) -> String {
        match &self.poses {
            Some(p) => format!(
                "synthetic: {} frames/s along {} given camera poses",
                self.config.rate_hz,
                p.len()
            ),
            None => format!(
                "synthetic: {} frames/s on a circle of {} mm radius at ({}, {}, {}) mm",
                self.config.rate_hz,
                self.config.radius_mm,
                self.config.center_mm[0],
                self.config.center_mm[1],
                self.config.center_mm[2]
            ),
        }
    }
}
