//! The source seam of the daemon: every frame source implements
//! `photopose-acquire`'s [`FrameSource`] and owns its `[source.X]` section —
//! keys, defaults, checks — in its own module; [`Source`] is the validated
//! choice and [`open`] builds the source it names.
//!
//! - [`synthetic`]: frames rendered of the plate (no hardware; the default);
//! - [`cell`]: the closed-loop simulated cell (test and demo support:
//!   built programmatically, it owns a simulated KUKA controller);
//! - [`replay`]: recordings, as recorded or as fast as the workers take them;
//! - `gige` (the `gige` feature): a GigE Vision camera through aravis;
//! - `gentl` (the `gentl` feature): a frame grabber or camera through its
//!   vendor's GenTL producer (`photopose-gentl`).
//!
//! Adding a source: a module here with its section type, its `validate`
//! and its `FrameSource`; one variant in `SourceKind`, `SourceSection`
//! and [`Source`], one arm in `Source::from_section` and in [`open`].

pub mod cell;
#[cfg(feature = "gentl")]
pub mod gentl;
#[cfg(feature = "gige")]
pub mod gige;
pub mod replay;
pub mod synthetic;

use crate::config::ConfigError;
pub use cell::{CellFrameTruth, CellHandle, CellPath, CellSettings, CellSource};
pub use photopose_acquire::{FrameSource, Slot, SourceError};
use photopose_field::Field;
use photopose_frame::{Image, Pixels};
use photopose_geometry::Camera;
pub use replay::{Replay, ReplayError, ReplaySource, Speed};
use serde::Deserialize;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
pub use synthetic::{Synthetic, SyntheticSource};
use thiserror::Error;

/// How a section reports a bad value: the key, the value, the valid range.
pub(crate) type Bad<'a> = &'a dyn Fn(&'static str, String, &'static str) -> ConfigError;

/// `source.kind` (absent: `synthetic`, the shipped default).
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub(crate) enum SourceKind {
    #[default]
    Synthetic,
    Replay,
    Gige,
    Gentl,
}

/// `[source]` as written: the kind and each source's own section.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct SourceSection {
    #[serde(default)]
    kind: SourceKind,
    /// Fixed latency from the middle of the exposure to the reception, ms,
    /// for frames without an exposure time of their own.
    latency_ms: Option<f64>,
    synthetic: Option<synthetic::SyntheticSection>,
    replay: Option<replay::ReplaySection>,
    #[cfg(feature = "gige")]
    gige: Option<gige::GigeSection>,
    /// Read (a configuration written for a build with GigE still parses)
    /// but refused by kind in a build without it.
    #[cfg(not(feature = "gige"))]
    #[allow(dead_code)]
    gige: Option<toml::Value>,
    #[cfg(feature = "gentl")]
    gentl: Option<gentl::GentlSection>,
    /// Read but refused by kind in a build without GenTL.
    #[cfg(not(feature = "gentl"))]
    #[allow(dead_code)]
    gentl: Option<toml::Value>,
}

impl Default for SourceSection {
    fn default() -> Self {
        SourceSection {
            kind: SourceKind::Synthetic,
            latency_ms: None,
            synthetic: None,
            replay: None,
            gige: None,
            gentl: None,
        }
    }
}

/// Where frames come from (validated).
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// Rendered frames of the plate.
    Synthetic(Synthetic),
    /// Recorded frames.
    Replay(Replay),
    /// A GigE Vision camera (aravis).
    #[cfg(feature = "gige")]
    Gige(photopose_acquire::GigeConfig),
    /// A device through a GenTL producer.
    #[cfg(feature = "gentl")]
    Gentl(photopose_gentl::GentlConfig),
}

impl Source {
    /// Validates `[source]`: the section of the chosen kind, by its module.
    pub(crate) fn from_section(
        section: SourceSection,
        bad: Bad<'_>,
    ) -> Result<Source, ConfigError> {
        let latency = match section.latency_ms {
            None => None,
            Some(l) if l.is_finite() && (0.0..=10_000.0).contains(&l) => {
                Some(Duration::from_secs_f64(l / 1000.0))
            }
            Some(l) => {
                return Err(bad(
                    "source.latency_ms",
                    l.to_string(),
                    "must be in [0, 10000] ms",
                ))
            }
        };
        Ok(match section.kind {
            SourceKind::Synthetic => {
                Source::Synthetic(synthetic::validate(section.synthetic, bad)?)
            }
            SourceKind::Replay => {
                let mut r = replay::validate(section.replay.as_ref(), bad)?;
                r.fixed_latency = latency;
                Source::Replay(r)
            }
            #[cfg(feature = "gige")]
            SourceKind::Gige => {
                let mut g = gige::validate(section.gige.unwrap_or_default(), bad)?;
                g.fixed_latency = latency;
                Source::Gige(g)
            }
            #[cfg(not(feature = "gige"))]
            SourceKind::Gige => {
                return Err(bad(
                    "source.kind",
                    "\"gige\"".into(),
                    "this build has no GigE Vision support (cargo feature `gige`)",
                ))
            }
            #[cfg(feature = "gentl")]
            SourceKind::Gentl => {
                Source::Gentl(gentl::validate(section.gentl.unwrap_or_default(), bad)?)
            }
            #[cfg(not(feature = "gentl"))]
            SourceKind::Gentl => {
                return Err(bad(
                    "source.kind",
                    "\"gentl\"".into(),
                    "this build has no GenTL support (cargo feature `gentl`)",
                ))
            }
        })
    }
}

/// Why a configured source could not be built.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum OpenError {
    /// The synthetic source's renderer refused the camera or field.
    #[error("synthetic source: {0}")]
    Synthetic(#[from] photopose_render::RenderError),
    /// The recording cannot be replayed.
    #[error(transparent)]
    Replay(#[from] ReplayError),
    /// The GigE source refused its settings.
    #[error("GigE source ([source.gige]): {0}")]
    Gige(SourceError),
    /// The GenTL producer cannot be loaded or initialised.
    #[cfg(feature = "gentl")]
    #[error("GenTL source ([source.gentl]): {0}")]
    Gentl(photopose_gentl::GentlError),
}

/// Builds the source `source` names for `camera` (not started: the
/// grabber starts it).
pub fn open(
    source: &Source,
    camera: &Camera,
    field: &Field,
) -> Result<Box<dyn FrameSource>, OpenError> {
    Ok(match source {
        Source::Synthetic(s) => Box::new(SyntheticSource::new(*camera, field, s.clone())?),
        Source::Replay(r) => Box::new(ReplaySource::open(camera, r)?),
        #[cfg(feature = "gige")]
        Source::Gige(g) => Box::new(
            photopose_acquire::GigeSource::new("gige", g.clone()).map_err(OpenError::Gige)?,
        ),
        #[cfg(feature = "gentl")]
        Source::Gentl(g) => Box::new(
            photopose_gentl::GentlSource::new("gentl", g.clone()).map_err(OpenError::Gentl)?,
        ),
    })
}

/// A source that ends after `frames` frames (`photopose run --frames N`,
/// `photopose record --frames N`, whatever the source).
pub fn limit(source: Box<dyn FrameSource>, frames: u64) -> Box<dyn FrameSource> {
    Box::new(Limited {
        inner: source,
        left: frames,
    })
}

struct Limited {
    inner: Box<dyn FrameSource>,
    left: u64,
}

impl FrameSource for Limited {
    fn start(&mut self) -> Result<(), SourceError> {
        self.inner.start()
    }

    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        if self.left == 0 {
            return Err(SourceError::Ended);
        }
        self.inner.next_frame(slot, timeout)?;
        self.left -= 1;
        Ok(())
    }

    fn stop(&mut self) {
        self.inner.stop();
    }

    fn describe(&self) -> String {
        format!("{} (the next {} frames)", self.inner.describe(), self.left)
    }

    fn stats(&self) -> photopose_acquire::SourceStats {
        self.inner.stats()
    }

    fn shared_counters(&self) -> Option<std::sync::Arc<photopose_acquire::SourceCounters>> {
        self.inner.shared_counters()
    }

    fn exposure_link(&self) -> Option<std::sync::Arc<photopose_acquire::ExposureLink>> {
        self.inner.exposure_link()
    }
}

/// Makes `slot`'s image an 8-bit `width`×`height` one (allocates only if
/// it was not: slots are built at the camera's size).
pub(crate) fn ensure_mono8(slot: &mut Slot, width: u32, height: u32) {
    let image = slot.image_mut();
    if image.width() != width
        || image.height() != height
        || !matches!(image.pixels(), Pixels::Mono8(_))
    {
        *image = Image::new_mono8(width, height);
    }
}

/// Sleeps until `due`, or for `timeout` if that is sooner; `false` if the
/// frame is not due yet after the wait.
pub(crate) fn wait_until(due: Instant, timeout: Duration) -> bool {
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

/// Host time now, ns since the Unix epoch (the output stage's stamp of a
/// stale message).
pub fn host_time_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}
