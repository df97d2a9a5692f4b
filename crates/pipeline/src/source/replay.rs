//! The replay source (`[source.replay]`): recorded frames (MCAP, see
//! `photopose-record`: the `foxglove.RawImage` channel, or the frames of a
//! first-format recording) at the recorded pace times a factor, or as fast as
//! the pipeline takes them. It owns its section: keys, defaults and checks.
//! Host times come from the recording (shifted per pass), so a replay is
//! the same run every time.
//!
//! Time on this host: a replayed frame is received when it is handed over
//! (`host_mono_ns`); its exposure instant is that minus the latency of the
//! camera it was recorded from — `[source] latency_ms` when set, else the
//! synthetic model of a GigE camera (half of a 2 ms exposure plus the
//! frame's bytes at 1 Gbit/s). Recordings do not carry the exposure
//! instants of their frames yet.

use super::{wait_until, Bad};
use crate::config::ConfigError;
use photopose_acquire::{FrameSource, Slot, SourceError};
use photopose_formats::file::FileKind;
use photopose_geometry::Camera;
use serde::Deserialize;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use thiserror::Error;

#[derive(Debug, Deserialize, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct ReplaySection {
    path: PathBuf,
    #[serde(default = "default_speed")]
    speed: SpeedToml,
    #[serde(default = "default_passes")]
    passes: u64,
    #[serde(default = "default_max_bytes")]
    max_bytes: u64,
}

fn default_passes() -> u64 {
    1
}

fn default_max_bytes() -> u64 {
    FileKind::Recording.limit()
}

#[derive(Debug, Deserialize, Clone)]
#[serde(untagged)]
enum SpeedToml {
    Word(String),
    Factor(f64),
}

fn default_speed() -> SpeedToml {
    SpeedToml::Word("recorded".into())
}

/// The largest `source.replay.max_bytes` accepted (1 TiB).
const MAX_REPLAY_BYTES: u64 = 1 << 40;

/// How fast a recording is replayed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Speed {
    /// At the recorded pace times this factor (1 = as recorded).
    Factor(f64),
    /// As fast as the pipeline takes the frames.
    Max,
}

/// Replay of a recording (see `photopose-record`).
#[derive(Debug, Clone, PartialEq)]
pub struct Replay {
    /// The MCAP recording.
    pub path: PathBuf,
    /// Pace.
    pub speed: Speed,
    /// Times the recording is played, 0 for endless (soak tests); later
    /// passes continue the sequence numbers and camera times.
    pub passes: u64,
    /// Largest recording read, bytes (the replay holds it in memory).
    pub max_bytes: u64,
    /// From the middle of the exposure to the hand-over (`[source]
    /// latency_ms`); `None`: the model of a GigE camera (see the module
    /// docs).
    pub fixed_latency: Option<Duration>,
}

/// The exposure time the replay assumes when no latency is configured, ns.
pub const MODEL_EXPOSURE_NS: u64 = 2_000_000;

/// Validates `[source.replay]` (`path` is required).
pub(crate) fn validate(
    section: Option<&ReplaySection>,
    bad: Bad<'_>,
) -> Result<Replay, ConfigError> {
    let Some(r) = section else {
        return Err(bad(
            "source.replay.path",
            "(missing)".into(),
            "a replay source needs [source.replay] with `path`",
        ));
    };
    let speed = match &r.speed {
        SpeedToml::Word(w) if w == "recorded" => Speed::Factor(1.0),
        SpeedToml::Word(w) if w == "max" => Speed::Max,
        SpeedToml::Factor(x) if x.is_finite() && *x > 0.0 && *x <= 1000.0 => Speed::Factor(*x),
        SpeedToml::Word(w) => {
            return Err(bad(
                "source.replay.speed",
                w.clone(),
                "must be \"recorded\", \"max\" or a factor in (0, 1000]",
            ))
        }
        SpeedToml::Factor(x) => {
            return Err(bad(
                "source.replay.speed",
                x.to_string(),
                "must be \"recorded\", \"max\" or a factor in (0, 1000]",
            ))
        }
    };
    if !(1..=MAX_REPLAY_BYTES).contains(&r.max_bytes) {
        return Err(bad(
            "source.replay.max_bytes",
            r.max_bytes.to_string(),
            "must be 1..=1099511627776 (1 TiB)",
        ));
    }
    Ok(Replay {
        path: r.path.clone(),
        speed,
        passes: r.passes,
        max_bytes: r.max_bytes,
        fixed_latency: None,
    })
}

/// Recorded frames (see `photopose-record`), at the recorded pace times a
/// factor, or as fast as the pipeline takes them.
#[derive(Debug)]
pub struct ReplaySource {
    recording: photopose_record::Recording,
    speed: Speed,
    passes: u64,
    pass: u64,
    /// Added per pass to sequence numbers and camera times.
    span: (u64, u64),
    next: usize,
    start: Option<(Instant, u64)>,
    fixed_latency: Option<Duration>,
    /// The camera's frame size, every frame's.
    size: (u32, u32),
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
    pub fn open(camera: &Camera, config: &Replay) -> Result<Self, ReplayError> {
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
            fixed_latency: config.fixed_latency,
            size: (camera.sensor.width, camera.sensor.height),
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
        let index = self.next;
        let (meta, width, height) = self.recording.meta(index);
        let camera_time_ns = meta.camera_time_ns + time_offset;
        if let Speed::Factor(f) = self.speed {
            let (t0, c0) = *self.start.get_or_insert((Instant::now(), camera_time_ns));
            let offset = camera_time_ns.saturating_sub(c0) as f64 / 1e9 / f;
            if !wait_until(t0 + Duration::from_secs_f64(offset), timeout) {
                return Err(SourceError::Timeout(timeout));
            }
        }
        self.next += 1;
        // The recorded frame is lent to the slot, not copied (the
        // recording holds it unchanged for the whole replay).
        if (width, height) != self.size {
            return Err(SourceError::Frame {
                reason: format!(
                    "{}: frame {index} is {width}×{height}, the camera is {}×{}",
                    self.recording.path(),
                    self.size.0,
                    self.size.1
                ),
            });
        }
        slot.share(self.recording.shared(index).clone());
        slot.meta.seq = meta.seq + seq_offset;
        slot.meta.camera_frame_id = meta.seq;
        slot.meta.camera_time_ns = camera_time_ns;
        // The recorded reception time, shifted like the camera time: the
        // replay's clock is the recording's.
        slot.meta.host_time_ns = meta.host_time_ns + time_offset;
        let now = photopose_acquire::mono::now_ns();
        let (latency, exposure) = match self.fixed_latency {
            Some(l) => (l.as_nanos() as u64, 0),
            None => {
                let per_pixel = match slot.image().pixels() {
                    photopose_frame::Pixels::Mono8(_) => 1,
                    _ => 2,
                };
                let bytes =
                    slot.image().width() as usize * slot.image().height() as usize * per_pixel;
                (
                    MODEL_EXPOSURE_NS / 2
                        + photopose_acquire::clock_map::bytes_at_gigabit_ns(bytes),
                    MODEL_EXPOSURE_NS,
                )
            }
        };
        slot.meta.host_mono_ns = now;
        slot.meta.exposure_mono_ns = now.saturating_sub(latency);
        slot.meta.exposure_sigma_ns = 0;
        slot.meta.exposure_ns = exposure;
        Ok(())
    }

    fn stop(&mut self) {}

    fn describe(&self) -> String {
        format!(
            "replay of {} ({} frames, {}, {})",
            self.recording.path(),
            self.recording.len(),
            match self.speed {
                Speed::Max => "speed max".to_string(),
                Speed::Factor(f) => format!("{f} × the recorded pace"),
            },
            match self.passes {
                0 => "endless".to_string(),
                n => format!("{n} passes"),
            }
        )
    }
}
