//! Frame sources: the [`FrameSource`] seam, the synthetic source, which
//! renders the plate along a configured camera path in real time (the
//! default of `photopose run`, so the whole chain runs without hardware),
//! and the replay of recordings.

use crate::config::Synthetic;
use photopose_field::Field;
use photopose_frame::Image;
use photopose_geometry::{Camera, Exterior};
use photopose_render::{RenderError, RenderOptions, Renderer};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use thiserror::Error;

/// One frame slot of the ring: the image and its metadata.
#[derive(Debug)]
pub struct Frame {
    /// Sequence number given by the source.
    pub seq: u64,
    /// The source's timestamp of the exposure, ns (camera clock).
    pub camera_time_ns: u64,
    /// Host time of reception, ns since the Unix epoch.
    pub host_time_ns: u64,
    /// Monotonic instant of hand-over to the pipeline (for latency).
    pub received: Instant,
    /// Order of admission into the ring (set by the pipeline).
    pub(crate) order: u64,
    /// The pixels.
    pub image: Image,
}

impl Frame {
    /// A slot with a black 8-bit image of the given size.
    pub fn new(width: u32, height: u32) -> Self {
        Frame {
            seq: 0,
            camera_time_ns: 0,
            host_time_ns: 0,
            received: Instant::now(),
            order: 0,
            image: Image::new_mono8(width, height),
        }
    }
}

/// What a source did when asked for a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SourceEvent {
    /// The slot holds a new frame.
    Frame,
    /// No frame within the timeout (the source is alive).
    Timeout,
    /// The source has no more frames.
    End,
}

/// A source that cannot deliver.
#[derive(Debug, Error)]
pub enum SourceError {
    /// The renderer refused (synthetic source).
    #[error("synthetic source: {0}")]
    Render(#[from] RenderError),
    /// A recorded frame could not be read (replay).
    #[error("replay: {0}")]
    Record(photopose_record::RecordError),
}

/// A source of frames: GigE camera, recording or renderer.
pub trait FrameSource: Send {
    /// Fills `frame` with the next frame, waiting at most `timeout`.
    fn next_frame(
        &mut self,
        frame: &mut Frame,
        timeout: Duration,
    ) -> Result<SourceEvent, SourceError>;
    /// A one-line description for logs.
    fn describe(&self) -> String;
}

/// Host time now, ns since the Unix epoch.
pub fn host_time_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// Frames rendered along a circle in a horizontal plane, the camera looking
/// straight down at the plate, paced at the configured rate.
#[derive(Debug)]
pub struct SyntheticSource {
    config: Synthetic,
    renderer: Renderer,
    next: u64,
    start: Option<Instant>,
}

impl SyntheticSource {
    /// A synthetic source for `camera` over `field`.
    pub fn new(camera: Camera, field: &Field, config: Synthetic) -> Result<Self, SourceError> {
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
            next: 0,
            start: None,
        })
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
    fn next_frame(
        &mut self,
        frame: &mut Frame,
        timeout: Duration,
    ) -> Result<SourceEvent, SourceError> {
        if self.config.frames > 0 && self.next >= self.config.frames {
            return Ok(SourceEvent::End);
        }
        let start = *self.start.get_or_insert_with(Instant::now);
        let due = start + Duration::from_secs_f64(self.next as f64 / self.config.rate_hz);
        let now = Instant::now();
        if due > now {
            if due - now > timeout {
                std::thread::sleep(timeout);
                return Ok(SourceEvent::Timeout);
            }
            std::thread::sleep(due - now);
        }
        let seq = self.next;
        self.renderer.set_options(RenderOptions {
            seed: self.config.seed.wrapping_mul(1_000_003).wrapping_add(seq),
            ..*self.renderer.options()
        })?;
        self.renderer
            .render(&Self::pose_at(&self.config, seq), &mut frame.image)?;
        frame.seq = seq;
        frame.camera_time_ns = (seq as f64 / self.config.rate_hz * 1e9) as u64;
        frame.host_time_ns = host_time_ns();
        frame.received = Instant::now();
        self.next += 1;
        Ok(SourceEvent::Frame)
    }

    fn describe(&self) -> String {
        format!(
            "synthetic: {} frames/s on a circle of {} mm radius at {:?} mm",
            self.config.rate_hz, self.config.radius_mm, self.config.center_mm
        )
    }
}

/// Recorded frames (see `photopose-record`), at the recorded pace times a
/// factor, or as fast as the pipeline takes them.
#[derive(Debug)]
pub struct ReplaySource {
    recording: photopose_record::Recording,
    speed: crate::config::Speed,
    next: usize,
    start: Option<(Instant, u64)>,
}

/// Why a replay cannot start.
#[derive(Debug, Error)]
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
    /// Opens a recording for `camera`.
    pub fn open(camera: &Camera, config: &crate::config::Replay) -> Result<Self, ReplayError> {
        let recording = photopose_record::Recording::open(&config.path)?;
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
        Ok(ReplaySource {
            recording,
            speed: config.speed,
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
    fn next_frame(
        &mut self,
        frame: &mut Frame,
        timeout: Duration,
    ) -> Result<SourceEvent, SourceError> {
        if self.next >= self.recording.len() {
            return Ok(SourceEvent::End);
        }
        let (meta, _, _) = self.recording.meta(self.next);
        if let crate::config::Speed::Factor(f) = self.speed {
            let (t0, c0) = *self
                .start
                .get_or_insert((Instant::now(), meta.camera_time_ns));
            let offset = meta.camera_time_ns.saturating_sub(c0) as f64 / 1e9 / f;
            let due = t0 + Duration::from_secs_f64(offset);
            let now = Instant::now();
            if due > now {
                if due - now > timeout {
                    std::thread::sleep(timeout);
                    return Ok(SourceEvent::Timeout);
                }
                std::thread::sleep(due - now);
            }
        }
        let meta = self
            .recording
            .copy_into(self.next, &mut frame.image)
            .map_err(SourceError::Record)?;
        frame.seq = meta.seq;
        frame.camera_time_ns = meta.camera_time_ns;
        frame.host_time_ns = host_time_ns();
        frame.received = Instant::now();
        self.next += 1;
        Ok(SourceEvent::Frame)
    }

    fn describe(&self) -> String {
        format!(
            "replay of {} ({} frames, {:?})",
            self.recording.path(),
            self.recording.len(),
            self.speed
        )
    }
}
