//! The daemon's frame sources behind `photopose-acquire`'s [`FrameSource`]
//! seam (the GigE camera lives there): the synthetic source, which renders
//! the plate along a configured camera path in real time (the default of
//! `photopose run`, so the whole chain runs without hardware), and the
//! replay of recordings.

use crate::config::Synthetic;
pub use photopose_acquire::{FrameSource, Slot, SourceError};
use photopose_field::Field;
use photopose_frame::{Image, Pixels};
use photopose_geometry::{Camera, Exterior};
use photopose_render::{RenderError, RenderOptions, Renderer};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use thiserror::Error;

/// Makes `slot`'s image an 8-bit `width`×`height` one (allocates only if
/// it was not: slots are built at the camera's size).
fn ensure_mono8(slot: &mut Slot, width: u32, height: u32) {
    if slot.image.width() != width
        || slot.image.height() != height
        || !matches!(slot.image.pixels(), Pixels::Mono8(_))
    {
        slot.image = Image::new_mono8(width, height);
    }
}

/// Sleeps until `due`, or for `timeout` if that is sooner; `false` if the
/// frame is not due yet after the wait.
fn wait_until(due: Instant, timeout: Duration) -> bool {
    let now = Instant::now();
    if due > now {
        if due - now > timeout {
            std::thread::sleep(timeout);
            return false;
        }
        std::thread::sleep(due - now);
    }
    true
}

/// Host time now, ns since the Unix epoch.
pub fn host_time_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// Frames rendered along a circle in a horizontal plane, the camera looking
/// straight down at the plate, paced at the configured rate — or, built
/// with [`SyntheticSource::along`], at given camera poses (a simulated robot
/// cell's path).
#[derive(Debug)]
pub struct SyntheticSource {
    config: Synthetic,
    renderer: Renderer,
    /// Camera poses to render one after the other instead of the circle.
    poses: Option<Vec<Exterior>>,
    next: u64,
    start: Option<Instant>,
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
        })
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
        let start = *self.start.get_or_insert_with(Instant::now);
        let due = start + Duration::from_secs_f64(self.next as f64 / self.config.rate_hz);
        if !wait_until(due, timeout) {
            return Err(SourceError::Timeout(timeout));
        }
        let seq = self.next;
        self.next += 1;
        let sensor = self.renderer.camera().sensor;
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
            .and_then(|()| self.renderer.render(&pose, &mut slot.image).map(|_| ()));
        if let Err(e) = rendered {
            return Err(SourceError::Frame {
                reason: format!("synthetic frame {seq}: {e}"),
            });
        }
        slot.meta.seq = seq;
        slot.meta.camera_frame_id = seq;
        slot.meta.camera_time_ns = (seq as f64 / self.config.rate_hz * 1e9) as u64;
        slot.meta.host_time_ns = host_time_ns();
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
                "synthetic: {} frames/s on a circle of {} mm radius at {:?} mm",
                self.config.rate_hz, self.config.radius_mm, self.config.center_mm
            ),
        }
    }
}

/// Recorded frames (see `photopose-record`), at the recorded pace times a
/// factor, or as fast as the pipeline takes them.
#[derive(Debug)]
pub struct ReplaySource {
    recording: photopose_record::Recording,
    speed: crate::config::Speed,
    passes: u64,
    pass: u64,
    /// Added per pass to sequence numbers and camera times.
    span: (u64, u64),
    next: usize,
    start: Option<(Instant, u64)>,
}

/// Why a replay cannot start.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ReplayError {
    /// The recording cannot be read.
    #[error(transparent)]
    Record(#[from] photopose_record::RecordError),
    /// The recording's frames do not fit the camera.
    #[error("{path}: frames are {width}×{height}, the camera file says {cam_width}×{cam_height}")]
    Size {
        /// The recording.
        path: String,
        /// Frame width.
        width: u32,
        /// Frame height.
        height: u32,
        /// Camera width.
        cam_width: u32,
        /// Camera height.
        cam_height: u32,
    },
}

impl ReplaySource {
    /// Opens a recording for `camera`: at most `config.max_bytes`, a
    /// regular file, every checksum verified (a corrupt file is refused
    /// here; a frame that does not fit the slot is skipped and counted
    /// later, as a bad frame).
    pub fn open(camera: &Camera, config: &crate::config::Replay) -> Result<Self, ReplayError> {
        let recording = photopose_record::Recording::open_limited(&config.path, config.max_bytes)?;
        let (_, width, height) = recording.meta(0);
        if (width, height) != (camera.sensor.width, camera.sensor.height) {
            return Err(ReplayError::Size {
                path: recording.path().to_string(),
                width,
                height,
                cam_width: camera.sensor.width,
                cam_height: camera.sensor.height,
            });
        }
        let (first, _, _) = recording.meta(0);
        let (last, _, _) = recording.meta(recording.len() - 1);
        let frames = recording.len() as u64;
        // One mean frame period beyond the last frame.
        let duration = last.camera_time_ns.saturating_sub(first.camera_time_ns);
        let period = duration / frames.saturating_sub(1).max(1);
        let span = (
            last.seq.saturating_sub(first.seq) + 1,
            duration.saturating_add(period),
        );
        Ok(ReplaySource {
            recording,
            speed: config.speed,
            passes: config.passes,
            pass: 0,
            span,
            next: 0,
            start: None,
        })
    }

    /// Frames in the recording.
    pub fn len(&self) -> usize {
        self.recording.len()
    }

    /// Whether the recording is empty (never once opened).
    pub fn is_empty(&self) -> bool {
        self.recording.is_empty()
    }
}

impl FrameSource for ReplaySource {
    fn start(&mut self) -> Result<(), SourceError> {
        Ok(())
    }

    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        if self.next >= self.recording.len() {
            if self.passes != 0 && self.pass + 1 >= self.passes {
                return Err(SourceError::Ended);
            }
            self.pass += 1;
            self.next = 0;
        }
        let (seq_offset, time_offset) = (self.span.0 * self.pass, self.span.1 * self.pass);
        let (mut meta, _, _) = self.recording.meta(self.next);
        meta.camera_time_ns += time_offset;
        if let crate::config::Speed::Factor(f) = self.speed {
            let (t0, c0) = *self
                .start
                .get_or_insert((Instant::now(), meta.camera_time_ns));
            let offset = meta.camera_time_ns.saturating_sub(c0) as f64 / 1e9 / f;
            if !wait_until(t0 + Duration::from_secs_f64(offset), timeout) {
                return Err(SourceError::Timeout(timeout));
            }
        }
        let index = self.next;
        self.next += 1;
        let meta = self
            .recording
            .copy_into(index, &mut slot.image)
            .map_err(|e| SourceError::Frame {
                reason: e.to_string(),
            })?;
        slot.meta.seq = meta.seq + seq_offset;
        slot.meta.camera_frame_id = meta.seq;
        slot.meta.camera_time_ns = meta.camera_time_ns + time_offset;
        slot.meta.host_time_ns = host_time_ns();
        Ok(())
    }

    fn stop(&mut self) {}

    fn describe(&self) -> String {
        format!(
            "replay of {} ({} frames, {:?}, {})",
            self.recording.path(),
            self.recording.len(),
            self.speed,
            match self.passes {
                0 => "endless".to_string(),
                n => format!("{n} passes"),
            }
        )
    }
}
