//! The GigE source's settings: what is asked of the camera (pixel format,
//! exposure, gain, frame rate, ROI, packet size, packet socket, buffers) and
//! the loss and back-off timing, with their one set of defaults and checks;
//! any further GenICam feature by name (`[source.gige.features]`); and the
//! exposure control loop's settings (`[source.gige.exposure_control]`).

use crate::exposure::{ExposureSettings, SettingsError};
use crate::source::SourceError;
use std::time::Duration;

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

/// The value of a GenICam feature set by name: its type decides how it is
/// written (an enumeration takes its entry's name as a string).
#[derive(Debug, Clone, PartialEq)]
pub enum FeatureValue {
    /// An integer feature.
    Int(i64),
    /// A float feature.
    Float(f64),
    /// A boolean feature.
    Bool(bool),
    /// A string feature or an enumeration entry.
    Text(String),
}

impl std::fmt::Display for FeatureValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FeatureValue::Int(v) => write!(f, "{v}"),
            FeatureValue::Float(v) => write!(f, "{v}"),
            FeatureValue::Bool(v) => write!(f, "{v}"),
            FeatureValue::Text(v) => write!(f, "\"{v}\""),
        }
    }
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
    /// Further GenICam features (name, value), written in this order at
    /// each opening after the settings above; each must exist in the
    /// camera's node map and take its value, or the opening fails naming it.
    pub features: Vec<(String, FeatureValue)>,
    /// The transfer of one frame from the end of its exposure to its
    /// arrival at the host, at the least (`None`: the payload's bits at
    /// 1 Gbit/s, about 11 ms for 1300×1030 Mono8).
    pub transfer: Option<Duration>,
    /// For frames without a camera timestamp: the fixed latency from the
    /// middle of the exposure to the reception (`None`: the exposure
    /// instant is not known).
    pub fixed_latency: Option<Duration>,
    /// The exposure control loop (`None`: off, the exposure is left as
    /// set): the camera's `ExposureTime` (or `ExposureTimeAbs`) steered to
    /// hold the targets' peak (`crate::exposure`).
    pub exposure_control: Option<ExposureSettings>,
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
            features: Vec::new(),
            transfer: None,
            fixed_latency: None,
            exposure_control: None,
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

    pub(crate) fn validate(&self) -> Result<(), SourceError> {
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
                return bad(
                    "roi",
                    format!(
                        "[{}, {}, {}, {}] (x, y, width, height px) is empty or too large",
                        r.x, r.y, r.width, r.height
                    ),
                );
            }
        }
        for (name, value) in &self.features {
            if name.is_empty() || !name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') {
                return bad(
                    "features",
                    format!("\"{name}\" is not a GenICam feature name"),
                );
            }
            if let FeatureValue::Float(v) = value {
                if !v.is_finite() {
                    return bad("features", format!("{name} = {v} is not finite"));
                }
            }
        }
        if let Some(Err(SettingsError::OutOfRange { key, value, reason })) =
            self.exposure_control.as_ref().map(ExposureSettings::check)
        {
            return bad(
                &format!("exposure_control.{key}"),
                format!("{value} {reason}"),
            );
        }
        if self.lost_after.is_zero() || self.backoff_initial.is_zero() {
            return bad("lost_after/backoff_initial", "must be positive".into());
        }
        Ok(())
    }
}
