//! The daemon's configuration file (TOML): the typed file as written by the
//! user, unknown keys rejected, and its validation into [`Config`] with
//! errors that name the key. `config/photopose.toml` documents every key.

use photopose_formats::file::{read_text, FileError, FileKind};
use serde::Deserialize;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// A configuration that cannot be used, with the key and why.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The file, or a file it names, could not be read (missing, not a
    /// regular file, too large for its kind, not text).
    #[error("{source}{}", key.map(|k| format!(" (named by `{k}`)")).unwrap_or_default())]
    File {
        /// The key that names the file; `None`: the configuration itself.
        key: Option<&'static str>,
        /// What went wrong, with the path and the kind of file.
        source: FileError,
    },
    /// The TOML is malformed or has an unknown or mistyped key.
    #[error("{path}: {message}")]
    Syntax {
        /// The file.
        path: String,
        /// toml's message (names the key and line).
        message: String,
    },
    /// The `[rsi]` section is invalid (the key is named).
    #[error("{path}: {source}")]
    Rsi {
        /// The file.
        path: String,
        /// What is wrong with the section.
        source: photopose_rsi::ConfigError,
    },
    /// A value is out of range.
    #[error("{path}: `{key}` = {value}: {why}")]
    Value {
        /// The file.
        path: String,
        /// The key, dotted.
        key: &'static str,
        /// The value as written.
        value: String,
        /// The valid range.
        why: &'static str,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    camera: CameraSection,
    source: SourceSection,
    #[serde(default)]
    pipeline: PipelineSection,
    #[serde(default)]
    output: OutputSection,
    #[serde(default)]
    metrics: MetricsSection,
    #[serde(default)]
    rsi: photopose_rsi::RsiConfig,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct MetricsSection {
    listen: Option<String>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct CameraSection {
    id: Option<String>,
    camera_file: Option<PathBuf>,
    field_file: Option<PathBuf>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SourceSection {
    kind: SourceKind,
    synthetic: Option<SyntheticSection>,
    replay: Option<ReplaySection>,
    gige: Option<GigeSection>,
}

#[derive(Debug, Deserialize, Clone)]
#[serde(deny_unknown_fields)]
struct GigeSection {
    camera: Option<String>,
    #[serde(default)]
    pixel_format: PixelFormatToml,
    exposure_us: Option<f64>,
    gain: Option<f64>,
    frame_rate: Option<f64>,
    roi: Option<[u32; 4]>,
    packet_size: Option<u32>,
    #[serde(default)]
    packet_socket: bool,
    #[serde(default = "default_buffers")]
    buffers: u32,
    #[serde(default = "default_lost_after")]
    lost_after_ms: f64,
    #[serde(default = "default_backoff_initial")]
    backoff_initial_ms: f64,
    #[serde(default = "default_backoff_max")]
    backoff_max_ms: f64,
}

#[derive(Debug, Deserialize, Clone, Copy, Default, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
enum PixelFormatToml {
    #[default]
    Mono8,
    Mono16,
}

impl Default for GigeSection {
    fn default() -> Self {
        GigeSection {
            camera: None,
            pixel_format: PixelFormatToml::Mono8,
            exposure_us: None,
            gain: None,
            frame_rate: None,
            roi: None,
            packet_size: None,
            packet_socket: false,
            buffers: default_buffers(),
            lost_after_ms: default_lost_after(),
            backoff_initial_ms: default_backoff_initial(),
            backoff_max_ms: default_backoff_max(),
        }
    }
}

fn default_buffers() -> u32 {
    8
}
fn default_lost_after() -> f64 {
    2000.0
}
fn default_backoff_initial() -> f64 {
    100.0
}
fn default_backoff_max() -> f64 {
    5000.0
}

#[derive(Debug, Deserialize, Clone)]
#[serde(deny_unknown_fields)]
struct ReplaySection {
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
}

#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
enum SourceKind {
    Synthetic,
    Replay,
    Gige,
}

#[derive(Debug, Deserialize, Clone)]
#[serde(deny_unknown_fields)]
struct SyntheticSection {
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

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct PipelineSection {
    workers: u32,
    slots: u32,
    overflow: Overflow,
    max_age_ms: f64,
}

impl Default for PipelineSection {
    fn default() -> Self {
        PipelineSection {
            workers: 2,
            slots: 8,
            overflow: Overflow::DropNewest,
            max_age_ms: 200.0,
        }
    }
}

/// What the grabber does when every frame slot is in use.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Overflow {
    /// Drop the frame just arriving (count it).
    DropNewest,
    /// Drop the oldest frame waiting for a worker (count it) and queue the new one.
    DropOldest,
    /// Wait for a free slot (only for sources that can wait: replay, synthetic).
    Block,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct OutputSection {
    #[serde(default)]
    udp: Vec<String>,
    tcp_listen: Option<String>,
    #[serde(default = "default_queue")]
    tcp_client_queue: usize,
    #[serde(default = "default_max_clients")]
    tcp_max_clients: usize,
}

fn default_queue() -> usize {
    256
}

fn default_max_clients() -> usize {
    16
}

impl Default for OutputSection {
    fn default() -> Self {
        OutputSection {
            udp: Vec::new(),
            tcp_listen: None,
            tcp_client_queue: default_queue(),
            tcp_max_clients: default_max_clients(),
        }
    }
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
}

/// Where frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// Rendered frames of the plate.
    Synthetic(Synthetic),
    /// Recorded frames.
    Replay(Replay),
    /// A GigE Vision camera (aravis).
    Gige(photopose_acquire::GigeConfig),
}

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// The camera's id (`[camera] id`, default `"camera"`): tags its
    /// results, messages and metrics.
    pub camera_id: String,
    /// Camera file; `None`: the built-in camera.
    pub camera_file: Option<PathBuf>,
    /// Test field file; `None`: the built-in plate.
    pub field_file: Option<PathBuf>,
    /// The frame source.
    pub source: Source,
    /// Detection workers.
    pub workers: usize,
    /// Frame slots in the ring.
    pub slots: usize,
    /// Overflow policy of the ring.
    pub overflow: Overflow,
    /// Age after which the last pose is stale, ms.
    pub max_age_ms: f64,
    /// UDP destinations.
    pub udp: Vec<SocketAddr>,
    /// TCP listen address.
    pub tcp_listen: Option<SocketAddr>,
    /// Lines queued per TCP client.
    pub tcp_client_queue: usize,
    /// TCP clients served at once.
    pub tcp_max_clients: usize,
    /// Prometheus endpoint address.
    pub metrics_listen: Option<SocketAddr>,
    /// The KUKA RSI server, when `[rsi] enabled = true`.
    pub rsi: Option<Rsi>,
}

/// The RSI server of the daemon: validated settings and the hand-eye file.
#[derive(Debug, Clone, PartialEq)]
pub struct Rsi {
    /// Socket, reply spelling, correction law, thread options.
    pub settings: photopose_rsi::RsiSettings,
    /// The hand-eye file giving `X = T_tcp←camera` and `Z = T_base←plate`.
    pub hand_eye: PathBuf,
}

impl Config {
    /// Loads and validates a configuration file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = read_text(path, FileKind::Config)
            .map_err(|source| ConfigError::File { key: None, source })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses and validates configuration text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let f: File = toml::from_str(text).map_err(|e| {
            let line = e
                .span()
                .map(|s| {
                    format!(
                        "line {}: ",
                        text[..s.start.min(text.len())].matches('\n').count() + 1
                    )
                })
                .unwrap_or_default();
            ConfigError::Syntax {
                path: origin.into(),
                message: format!("{line}{}", e.message()),
            }
        })?;
        let bad = |key: &'static str, value: String, why: &'static str| ConfigError::Value {
            path: origin.into(),
            key,
            value,
            why,
        };
        let source = match (f.source.kind, &f.source.replay) {
            (SourceKind::Synthetic, _) => Source::Synthetic({
                let s = f.source.synthetic.clone().unwrap_or(SyntheticSection {
                    rate_hz: default_rate(),
                    frames: 0,
                    center_mm: default_centre(),
                    radius_mm: default_radius(),
                    period_s: default_period(),
                    noise_dn: default_noise(),
                    blur_px: default_blur(),
                    seed: default_seed(),
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
                        format!("{:?}", s.center_mm),
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
                Synthetic {
                    rate_hz: s.rate_hz,
                    frames: s.frames,
                    center_mm: s.center_mm,
                    radius_mm: s.radius_mm,
                    period_s: s.period_s,
                    noise_dn: s.noise_dn,
                    blur_px: s.blur_px,
                    seed: s.seed,
                }
            }),
            (SourceKind::Gige, _) => {
                Source::Gige(gige(f.source.gige.clone().unwrap_or_default(), &bad)?)
            }
            (SourceKind::Replay, None) => {
                return Err(bad(
                    "source.replay.path",
                    "(missing)".into(),
                    "a replay source needs [source.replay] with `path`",
                ));
            }
            (SourceKind::Replay, Some(r)) => {
                let speed = match &r.speed {
                    SpeedToml::Word(w) if w == "recorded" => Speed::Factor(1.0),
                    SpeedToml::Word(w) if w == "max" => Speed::Max,
                    SpeedToml::Factor(x) if x.is_finite() && *x > 0.0 && *x <= 1000.0 => {
                        Speed::Factor(*x)
                    }
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
                Source::Replay(Replay {
                    path: r.path.clone(),
                    speed,
                    passes: r.passes,
                    max_bytes: r.max_bytes,
                })
            }
        };
        let p = &f.pipeline;
        if !(1..=64).contains(&p.workers) {
            return Err(bad(
                "pipeline.workers",
                p.workers.to_string(),
                "must be 1..=64",
            ));
        }
        if !(2..=1024).contains(&p.slots) || p.slots < p.workers + 1 {
            return Err(bad(
                "pipeline.slots",
                p.slots.to_string(),
                "must be 2..=1024 and more than the workers",
            ));
        }
        if !(p.max_age_ms.is_finite() && p.max_age_ms > 0.0) {
            return Err(bad(
                "pipeline.max_age_ms",
                p.max_age_ms.to_string(),
                "must be > 0",
            ));
        }
        let mut udp = Vec::new();
        for d in &f.output.udp {
            udp.push(d.parse::<SocketAddr>().map_err(|_| {
                bad(
                    "output.udp",
                    d.clone(),
                    "must be host:port addresses (IP literal)",
                )
            })?);
        }
        let tcp_listen = match &f.output.tcp_listen {
            Some(a) => Some(a.parse::<SocketAddr>().map_err(|_| {
                bad(
                    "output.tcp_listen",
                    a.clone(),
                    "must be an IP:port to listen on",
                )
            })?),
            None => None,
        };
        // Per-client memory is bounded: a queue of at most 4096 lines
        // (about 2.5 MB of pose lines), at most 1024 clients.
        if !(1..=photopose_stream::tcp::MAX_CLIENT_QUEUE).contains(&f.output.tcp_client_queue) {
            return Err(bad(
                "output.tcp_client_queue",
                f.output.tcp_client_queue.to_string(),
                "must be 1..=4096 lines",
            ));
        }
        if !(1..=photopose_stream::tcp::MAX_CLIENTS).contains(&f.output.tcp_max_clients) {
            return Err(bad(
                "output.tcp_max_clients",
                f.output.tcp_max_clients.to_string(),
                "must be 1..=1024 clients",
            ));
        }
        let rsi = if f.rsi.enabled {
            let rsi_err = |source| ConfigError::Rsi {
                path: origin.into(),
                source,
            };
            let xml = match &f.rsi.ethernet_config {
                Some(p) => Some(read_text(p, FileKind::ControllerFile).map_err(|source| {
                    ConfigError::File {
                        key: Some("rsi.ethernet_config"),
                        source,
                    }
                })?),
                None => None,
            };
            let settings = f.rsi.settings(xml.as_deref()).map_err(rsi_err)?;
            let Some(hand_eye) = f.rsi.hand_eye.clone() else {
                return Err(bad(
                    "rsi.hand_eye",
                    "(missing)".into(),
                    "name the hand-eye file (photopose calibrate hand-eye) when [rsi] is enabled",
                ));
            };
            Some(Rsi { settings, hand_eye })
        } else {
            None
        };
        Ok(Config {
            rsi,
            camera_id: camera_id(f.camera.id, &bad)?,
            camera_file: f.camera.camera_file,
            field_file: f.camera.field_file,
            source,
            workers: p.workers as usize,
            slots: p.slots as usize,
            overflow: p.overflow,
            max_age_ms: p.max_age_ms,
            udp,
            tcp_listen,
            tcp_client_queue: f.output.tcp_client_queue,
            tcp_max_clients: f.output.tcp_max_clients,
            metrics_listen: match &f.metrics.listen {
                Some(a) => Some(a.parse::<SocketAddr>().map_err(|_| {
                    bad(
                        "metrics.listen",
                        a.clone(),
                        "must be an IP:port to listen on",
                    )
                })?),
                None => None,
            },
        })
    }
}

/// Validates `[camera] id`: 1–64 characters of `A–Z a–z 0–9 _ -` (it is
/// used in key expressions, metric labels and file names).
fn camera_id(
    id: Option<String>,
    bad: &dyn Fn(&'static str, String, &'static str) -> ConfigError,
) -> Result<String, ConfigError> {
    let id = id.unwrap_or_else(|| "camera".into());
    let ok = !id.is_empty()
        && id.len() <= 64
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
    if ok {
        Ok(id)
    } else {
        Err(bad(
            "camera.id",
            id,
            "must be 1 to 64 characters of A-Z, a-z, 0-9, '_' and '-'",
        ))
    }
}

/// Validates `[source.gige]` into the acquisition crate's settings.
fn gige(
    g: GigeSection,
    bad: &dyn Fn(&'static str, String, &'static str) -> ConfigError,
) -> Result<photopose_acquire::GigeConfig, ConfigError> {
    use photopose_acquire::{GigeConfig, PixelDepth, Roi};
    let positive = |key: &'static str, v: Option<f64>| match v {
        Some(x) if !(x.is_finite() && x > 0.0) => Err(bad(key, x.to_string(), "must be > 0")),
        _ => Ok(v),
    };
    let ms = |key: &'static str, v: f64, max: f64| {
        if v.is_finite() && v > 0.0 && v <= max {
            Ok(std::time::Duration::from_secs_f64(v / 1000.0))
        } else {
            Err(bad(key, v.to_string(), "must be in (0, 600000] ms"))
        }
    };
    if g.camera.as_deref().is_some_and(|c| c.trim().is_empty()) {
        return Err(bad(
            "source.gige.camera",
            "\"\"".into(),
            "must name a device id, address or serial (omit it for the first camera found)",
        ));
    }
    if let Some(gain) = g.gain {
        if !gain.is_finite() {
            return Err(bad("source.gige.gain", gain.to_string(), "must be finite"));
        }
    }
    let roi = match g.roi {
        Some([x, y, width, height]) => {
            if width == 0 || height == 0 || x.max(y).max(width).max(height) > 65_535 {
                return Err(bad(
                    "source.gige.roi",
                    format!("{:?}", [x, y, width, height]),
                    "must be [x, y, width, height] with a non-empty size below 65536",
                ));
            }
            Some(Roi {
                x,
                y,
                width,
                height,
            })
        }
        None => None,
    };
    if let Some(p) = g.packet_size {
        if !(576..=16_384).contains(&p) {
            return Err(bad(
                "source.gige.packet_size",
                p.to_string(),
                "must be 576..=16384 bytes",
            ));
        }
    }
    if !(2..=256).contains(&g.buffers) {
        return Err(bad(
            "source.gige.buffers",
            g.buffers.to_string(),
            "must be 2..=256",
        ));
    }
    let config = GigeConfig {
        camera: g.camera,
        pixel: match g.pixel_format {
            PixelFormatToml::Mono8 => PixelDepth::Mono8,
            PixelFormatToml::Mono16 => PixelDepth::Mono16,
        },
        exposure_us: positive("source.gige.exposure_us", g.exposure_us)?,
        gain: g.gain,
        frame_rate: positive("source.gige.frame_rate", g.frame_rate)?,
        roi,
        packet_size: g.packet_size,
        packet_socket: g.packet_socket,
        buffers: g.buffers as usize,
        lost_after: ms("source.gige.lost_after_ms", g.lost_after_ms, 600_000.0)?,
        backoff_initial: ms(
            "source.gige.backoff_initial_ms",
            g.backoff_initial_ms,
            600_000.0,
        )?,
        backoff_max: ms("source.gige.backoff_max_ms", g.backoff_max_ms, 600_000.0)?,
    };
    if config.backoff_max < config.backoff_initial {
        return Err(bad(
            "source.gige.backoff_max_ms",
            g.backoff_max_ms.to_string(),
            "must be ≥ backoff_initial_ms",
        ));
    }
    Ok(config)
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = include_str!("../../../config/photopose.toml");

    #[test]
    fn the_shipped_example_is_valid() {
        let c = Config::parse(EXAMPLE, "config/photopose.toml").unwrap();
        assert!(matches!(c.source, Source::Synthetic(_)));
        assert!(c.tcp_listen.is_some());
    }

    /// The example with one commented-out source section switched on.
    fn example_with(section: &str, kind: &str) -> String {
        let mut on = false;
        let mut out = String::new();
        for line in EXAMPLE.lines() {
            if line.starts_with(&format!("# [source.{section}]")) {
                on = true;
            } else if line.trim().is_empty() {
                on = false;
            }
            let line = match line.strip_prefix("# ") {
                Some(rest) if on => rest,
                _ => line,
            };
            out.push_str(&line.replace("kind = \"synthetic\"", &format!("kind = \"{kind}\"")));
            out.push('\n');
        }
        out
    }

    #[test]
    fn the_examples_commented_sections_are_valid_too() {
        let g = Config::parse(&example_with("gige", "gige"), "gige example").unwrap();
        let Source::Gige(g) = g.source else {
            panic!("gige expected")
        };
        assert_eq!(g.camera.as_deref(), Some("Aravis-Fake-GV01"));
        assert_eq!(g.roi.map(|r| (r.width, r.height)), Some((1300, 1030)));
        assert_eq!(g.packet_size, Some(1500));
        let r = Config::parse(&example_with("replay", "replay"), "replay example").unwrap();
        assert!(matches!(
            r.source,
            Source::Replay(Replay {
                speed: Speed::Factor(f),
                passes: 1,
                ..
            }) if f == 1.0
        ));
    }

    #[test]
    fn missing_sections_take_their_defaults() {
        let c = Config::parse("[source]\nkind = \"synthetic\"\n", "x").unwrap();
        assert_eq!((c.tcp_client_queue, c.tcp_max_clients), (256, 16));
        assert_eq!((c.workers, c.slots), (2, 8));
        let r = Config::parse(
            "[source]\nkind = \"replay\"\n[source.replay]\npath = \"a.mcap\"\nspeed = 2.5\n",
            "x",
        )
        .unwrap();
        assert!(
            matches!(r.source, Source::Replay(Replay { speed: Speed::Factor(f), .. }) if f == 2.5)
        );
    }

    #[test]
    fn gige_section_maps_onto_the_acquisition_settings() {
        let c = Config::parse(
            "[source]\nkind = \"gige\"\n[source.gige]\ncamera = \"GV01\"\nframe_rate = 100.0\n\
             roi = [8, 4, 640, 480]\npacket_socket = false\nbuffers = 6\npixel_format = \"mono16\"\n",
            "x",
        )
        .unwrap();
        let Source::Gige(g) = c.source else {
            panic!("not gige")
        };
        assert_eq!(g.camera.as_deref(), Some("GV01"));
        assert_eq!(g.frame_rate, Some(100.0));
        assert_eq!(
            g.roi.map(|r| (r.x, r.y, r.width, r.height)),
            Some((8, 4, 640, 480))
        );
        assert_eq!(g.buffers, 6);
        assert_eq!(g.pixel, photopose_acquire::PixelDepth::Mono16);
        assert_eq!(g.lost_after, std::time::Duration::from_secs(2));
        // No section: the first camera found, with the defaults.
        let d = Config::parse("[source]\nkind = \"gige\"\n", "x").unwrap();
        assert!(matches!(d.source, Source::Gige(ref g) if g.camera.is_none() && g.buffers == 8));
    }

    #[test]
    fn the_stream_keys_are_documented_with_their_defaults() {
        let defaults = Config::parse("[source]\nkind = \"synthetic\"\n", "x").unwrap();
        let example = Config::parse(EXAMPLE, "config/photopose.toml").unwrap();
        for key in ["udp", "tcp_listen", "tcp_client_queue", "tcp_max_clients"] {
            assert!(
                EXAMPLE.lines().any(|l| l.starts_with(&format!("{key} = "))),
                "output.{key} is not in config/photopose.toml"
            );
        }
        assert_eq!(example.tcp_client_queue, defaults.tcp_client_queue);
        assert_eq!(example.tcp_max_clients, defaults.tcp_max_clients);
    }

    #[test]
    fn errors_name_the_key() {
        let cases = [
            (
                EXAMPLE.replace("workers = 2", "workers = 0"),
                "pipeline.workers",
            ),
            (
                EXAMPLE.replace("workers = 2", "workers = 2\nthreads = 4"),
                "threads",
            ),
            (
                EXAMPLE.replace("rate_hz = 20.0", "rate_hz = -1.0"),
                "source.synthetic.rate_hz",
            ),
            (
                EXAMPLE.replace("kind = \"synthetic\"", "kind = \"webcam\""),
                "webcam",
            ),
            (
                EXAMPLE.replace("overflow = \"drop-newest\"", "overflow = \"sometimes\""),
                "sometimes",
            ),
            (
                EXAMPLE.replace(
                    "tcp_listen = \"127.0.0.1:5006\"",
                    "tcp_listen = \"localhost\"",
                ),
                "output.tcp_listen",
            ),
            (
                EXAMPLE.replace("tcp_client_queue = 256", "tcp_client_queue = 1000000"),
                "output.tcp_client_queue",
            ),
            (
                EXAMPLE.replace("tcp_client_queue = 256", "tcp_client_queue = 0"),
                "output.tcp_client_queue",
            ),
            (
                EXAMPLE.replace("tcp_max_clients = 16", "tcp_max_clients = 0"),
                "output.tcp_max_clients",
            ),
            (
                EXAMPLE.replace("tcp_max_clients = 16", "tcp_max_clients = 5000"),
                "output.tcp_max_clients",
            ),
            ("[source]\n".to_string(), "kind"),
            ("[source]\nkind = \"replay\"\n".to_string(), "source.replay.path"),
            ("[source]\nkind = \"gige\"\n[source.gige]\nbuffers = 1\n".to_string(), "source.gige.buffers"),
            ("[source]\nkind = \"gige\"\n[source.gige]\nroi = [0, 0, 0, 10]\n".to_string(), "source.gige.roi"),
            ("[source]\nkind = \"gige\"\n[source.gige]\nframe_rate = -5.0\n".to_string(), "source.gige.frame_rate"),
            ("[source]\nkind = \"gige\"\n[source.gige]\nexposure = 5.0\n".to_string(), "exposure"),
            ("[source]\nkind = \"gige\"\n[source.gige]\npixel_format = \"rgb8\"\n".to_string(), "rgb8"),
            ("[source]\nkind = \"replay\"\n[source.replay]\npath = \"r.mcap\"\nspeed = \"fast\"\n".to_string(), "source.replay.speed"),
        ];
        for (text, want) in cases {
            let e = Config::parse(&text, "x.toml").unwrap_err().to_string();
            assert!(
                e.starts_with("x.toml: ") && e.contains(want),
                "{e:?} lacks {want:?}"
            );
        }
    }
}
