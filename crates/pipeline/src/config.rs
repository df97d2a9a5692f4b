//! The daemon's configuration file (TOML): the typed file as written by the
//! user, unknown keys rejected, and its validation into [`Config`] with
//! errors that name the key. `config/photopose.toml` documents every key.

use photopose_formats::file::{read_text, FileError, FileKind};
use serde::Deserialize;
use std::net::{SocketAddr, ToSocketAddrs};
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
    /// A host name where an address is asked does not resolve (or is not
    /// `host:port`).
    #[error("{path}: `{key}` = \"{value}\": {reason}")]
    Resolve {
        /// The file.
        path: String,
        /// The key, dotted.
        key: &'static str,
        /// The address as written.
        value: String,
        /// Why it gives no address (the resolver's word).
        reason: String,
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

pub use crate::source::{Replay, Source, Speed, Synthetic};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    camera: CameraSection,
    #[serde(default)]
    source: crate::source::SourceSection,
    #[serde(default)]
    pipeline: PipelineSection,
    #[serde(default)]
    output: OutputSection,
    #[serde(default)]
    metrics: MetricsSection,
    #[serde(default)]
    rsi: photopose_rsi::RsiConfig,
    #[serde(default)]
    record: RecordSection,
    #[serde(default)]
    tracking: crate::track::TrackingSection,
    #[serde(default)]
    live: LiveSection,
    #[serde(default)]
    zenoh: ZenohSection,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct LiveSection {
    enabled: bool,
    address: String,
    image_hz: f64,
    image_scale: u32,
    pose_hz: f64,
    max_clients: usize,
}

impl Default for LiveSection {
    fn default() -> Self {
        LiveSection {
            enabled: false,
            address: "127.0.0.1:8765".into(),
            image_hz: 5.0,
            image_scale: 4,
            pose_hz: 20.0,
            max_clients: 4,
        }
    }
}

/// The live view in Foxglove (`[live]`, docs/live-view.md): a Foxglove
/// WebSocket server on the edge runtime.
#[derive(Debug, Clone, PartialEq)]
pub struct Live {
    /// Whether the daemon serves it (off by default).
    pub enabled: bool,
    /// Where it listens (`ws://ADDRESS`).
    pub address: SocketAddr,
    /// Frames per second sent to the view (throttled on the grabber).
    pub image_hz: f64,
    /// Downscale factor of the frames (box filter; 1: full size).
    pub image_scale: u32,
    /// Poses (and status) per second sent to the view.
    pub pose_hz: f64,
    /// Clients served at once (one more is refused).
    pub max_clients: usize,
}

impl Live {
    fn from_section(
        l: &LiveSection,
        bad: &dyn Fn(&'static str, String, &'static str) -> ConfigError,
    ) -> Result<Live, ConfigError> {
        let address = l.address.parse::<SocketAddr>().map_err(|_| {
            bad(
                "live.address",
                l.address.clone(),
                "must be an IP:port to listen on",
            )
        })?;
        if !(l.image_hz.is_finite() && l.image_hz > 0.0 && l.image_hz <= 60.0) {
            return Err(bad(
                "live.image_hz",
                l.image_hz.to_string(),
                "must be > 0 and at most 60 frames per second",
            ));
        }
        if !(1..=64).contains(&l.image_scale) {
            return Err(bad(
                "live.image_scale",
                l.image_scale.to_string(),
                "must be 1..=64 (1: full size)",
            ));
        }
        if !(l.pose_hz.is_finite() && l.pose_hz > 0.0 && l.pose_hz <= 1000.0) {
            return Err(bad(
                "live.pose_hz",
                l.pose_hz.to_string(),
                "must be > 0 and at most 1000 per second",
            ));
        }
        if !(1..=64).contains(&l.max_clients) {
            return Err(bad(
                "live.max_clients",
                l.max_clients.to_string(),
                "must be 1..=64 clients at once",
            ));
        }
        Ok(Live {
            enabled: l.enabled,
            address,
            image_hz: l.image_hz,
            image_scale: l.image_scale,
            pose_hz: l.pose_hz,
            max_clients: l.max_clients,
        })
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct RecordSection {
    path: Option<PathBuf>,
    frames: RecordFramesToml,
    poses: bool,
    compression: String,
    rotate_mb: u64,
    rotate_minutes: u64,
    queue: usize,
    rsi: bool,
    annotations: bool,
}

#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum RecordFramesToml {
    Word(String),
    Every(i64),
}

impl Default for RecordSection {
    fn default() -> Self {
        RecordSection {
            path: None,
            frames: RecordFramesToml::Word("all".into()),
            poses: true,
            compression: "zstd".into(),
            rotate_mb: 0,
            rotate_minutes: 0,
            queue: 8,
            rsi: true,
            annotations: true,
        }
    }
}

/// Which frames a recording keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordFrames {
    /// Every frame.
    All,
    /// Every `n`th frame (the first, the `n+1`th …).
    Every(u32),
    /// No frame (poses only).
    None,
    /// The first frame and every frame whose status (ok, too few targets,
    /// error) differs from the frame processed before it.
    OnChange,
}

/// The recording of the running daemon (`[record]`, `run --record FILE`).
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// The recording (first file); `None`: no recording.
    pub path: Option<PathBuf>,
    /// Which frames.
    pub frames: RecordFrames,
    /// Whether the poses are recorded.
    pub poses: bool,
    /// Chunk compression.
    pub compression: photopose_record::Compression,
    /// Next file once this many bytes are written.
    pub rotate_bytes: Option<u64>,
    /// Next file once the current one is this old.
    pub rotate_after: Option<std::time::Duration>,
    /// Frames that can wait for the writer (preallocated buffers).
    pub queue: usize,
    /// Whether the RSI server's cycles are recorded (when it runs).
    pub rsi: bool,
    /// Whether each recorded frame's identified targets are recorded as
    /// image annotations.
    pub annotations: bool,
    /// The running recording (its writer thread and the frame tap), set
    /// by whoever starts it before the pipeline (the binary); the sink
    /// otherwise starts one of its own, poses only.
    pub link: Option<crate::sink::record::RecordLink>,
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
#[serde(deny_unknown_fields, default)]
struct PipelineSection {
    workers: u32,
    slots: u32,
    /// `None`: `block` for a replay at speed `max` (complete and
    /// deterministic), `drop-newest` for every other source.
    overflow: Option<Overflow>,
    max_age_ms: f64,
}

impl Default for PipelineSection {
    fn default() -> Self {
        PipelineSection {
            workers: 2,
            slots: 8,
            overflow: None,
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
    /// Tracking mode (`[tracking]`).
    pub tracking: crate::track::Tracking,
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
    /// The recording (`[record]`).
    pub record: Record,
    /// The live view (`[live]`).
    pub live: Live,
    /// The Zenoh publisher (`[zenoh]`, docs/zenoh.md).
    pub zenoh: Zenoh,
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
                    let at = s.start.min(text.len());
                    format!(
                        "line {}: {}",
                        text[..at].matches('\n').count() + 1,
                        key_at(text, at).map_or(String::new(), |k| format!("`{k}`: "))
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
        let source = crate::source::Source::from_section(f.source, &bad)?;
        let tracking = crate::track::Tracking::from_section(f.tracking, &bad)?;
        let overflow = f.pipeline.overflow.unwrap_or(match &source {
            Source::Replay(r) if r.speed == Speed::Max => Overflow::Block,
            _ => Overflow::DropNewest,
        });
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
        let resolve = |key: &'static str, text: &str| resolve(origin, key, text);
        let udp = f
            .output
            .udp
            .iter()
            .map(|d| resolve("output.udp", d))
            .collect::<Result<Vec<_>, _>>()?;
        let tcp_listen = f
            .output
            .tcp_listen
            .as_deref()
            .map(|a| resolve("output.tcp_listen", a))
            .transpose()?;
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
        let r = &f.record;
        const FRAMES_RULE: &str =
            "must be \"all\", \"none\", \"on_change\" or N (every Nth frame, 1..=1000000)";
        let frames = match &r.frames {
            RecordFramesToml::Word(w) if w == "all" => RecordFrames::All,
            RecordFramesToml::Word(w) if w == "none" => RecordFrames::None,
            RecordFramesToml::Word(w) if w == "on_change" => RecordFrames::OnChange,
            RecordFramesToml::Every(n) if (1..=1_000_000).contains(n) => {
                RecordFrames::Every(*n as u32)
            }
            RecordFramesToml::Word(w) => return Err(bad("record.frames", w.clone(), FRAMES_RULE)),
            RecordFramesToml::Every(n) => {
                return Err(bad("record.frames", n.to_string(), FRAMES_RULE))
            }
        };
        let Some(compression) = photopose_record::Compression::from_name(&r.compression) else {
            return Err(bad(
                "record.compression",
                r.compression.clone(),
                "must be \"zstd\", \"lz4\" or \"none\"",
            ));
        };
        if !(1..=1024).contains(&r.queue) {
            return Err(bad(
                "record.queue",
                r.queue.to_string(),
                "must be 1..=1024 frames",
            ));
        }
        let record = Record {
            path: r.path.clone(),
            frames,
            poses: r.poses,
            compression,
            rotate_bytes: (r.rotate_mb > 0).then(|| r.rotate_mb.saturating_mul(1 << 20)),
            rotate_after: (r.rotate_minutes > 0)
                .then(|| std::time::Duration::from_secs(r.rotate_minutes.saturating_mul(60))),
            queue: r.queue,
            rsi: r.rsi,
            annotations: r.annotations,
            link: None,
        };
        let live = Live::from_section(&f.live, &bad)?;
        let camera_id = camera_id(f.camera.id, &bad)?;
        let zenoh = Zenoh::from_section(&f.zenoh, &camera_id, &bad)?;
        Ok(Config {
            record,
            live,
            zenoh,
            rsi,
            camera_id,
            camera_file: f.camera.camera_file,
            field_file: f.camera.field_file,
            source,
            workers: p.workers as usize,
            slots: p.slots as usize,
            overflow,
            max_age_ms: p.max_age_ms,
            tracking,
            udp,
            tcp_listen,
            tcp_client_queue: f.output.tcp_client_queue,
            tcp_max_clients: f.output.tcp_max_clients,
            metrics_listen: f
                .metrics
                .listen
                .as_deref()
                .map(|a| resolve("metrics.listen", a))
                .transpose()?,
        })
    }
}

/// An address where one is asked: an IP literal with its port, or a host
/// name with its port (`localhost:5005`), resolved now; a name with both
/// gives its IPv4 address (a listener on `localhost` is then reached by
/// clients that say `127.0.0.1`).
pub fn resolve(origin: &str, key: &'static str, text: &str) -> Result<SocketAddr, ConfigError> {
    if let Ok(a) = text.parse::<SocketAddr>() {
        return Ok(a);
    }
    let err = |reason: String| ConfigError::Resolve {
        path: origin.into(),
        key,
        value: text.into(),
        reason,
    };
    if text
        .rsplit_once(':')
        .is_none_or(|(_, p)| p.parse::<u16>().is_err())
    {
        return Err(err(
            "must be host:port (an IP address or a host name, and a port)".into(),
        ));
    }
    let found: Vec<SocketAddr> = text
        .to_socket_addrs()
        .map_err(|e| err(format!("does not resolve: {e}")))?
        .collect();
    found
        .iter()
        .find(|a| a.is_ipv4())
        .or(found.first())
        .copied()
        .ok_or_else(|| err("the name resolves to no address".into()))
}

/// The dotted key whose value starts at byte `at` of a TOML text (`key =
/// value` on that line, under the last `[section]` header), so that a
/// mistyped value's error names its key.
fn key_at(text: &str, at: usize) -> Option<String> {
    let start = text[..at].rfind('\n').map_or(0, |n| n + 1);
    let (key, _) = text[start..].split_once('=')?;
    let key = key.trim();
    if key.is_empty() || key.starts_with('#') || key.starts_with('[') || key.contains('\n') {
        return None;
    }
    let section = text[..start].lines().rev().find_map(|l| {
        let l = l.trim();
        (l.starts_with('[') && !l.starts_with("[["))
            .then(|| l.trim_matches(|c| c == '[' || c == ']'))
    });
    Some(match section {
        Some(s) => format!("{}.{key}", s.trim()),
        None => key.to_string(),
    })
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct ZenohSection {
    enabled: bool,
    mode: String,
    connect: Vec<String>,
    listen: Vec<String>,
    scouting_multicast: bool,
    pose_key: String,
    status_key: String,
    query_key: String,
    status_period_ms: u64,
    wait_for_subscriber_ms: u64,
    ros2: bool,
    ros2_domain_id: u32,
    ros2_topic: String,
}

impl Default for ZenohSection {
    fn default() -> Self {
        ZenohSection {
            enabled: false,
            mode: "peer".into(),
            connect: Vec::new(),
            listen: Vec::new(),
            scouting_multicast: false,
            pose_key: "photopose/{camera}/pose".into(),
            status_key: "photopose/{camera}/status".into(),
            query_key: "photopose/{camera}/latest".into(),
            status_period_ms: 1000,
            wait_for_subscriber_ms: 0,
            ros2: false,
            ros2_domain_id: 0,
            ros2_topic: "/photopose/{camera}/pose".into(),
        }
    }
}

/// How the Zenoh session is joined (`[zenoh] mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ZenohMode {
    /// A peer: talks to other peers and routers directly.
    Peer,
    /// A client: talks through one router (`connect`).
    Client,
}

impl ZenohMode {
    /// The word Zenoh's configuration uses.
    pub fn name(self) -> &'static str {
        match self {
            ZenohMode::Peer => "peer",
            ZenohMode::Client => "client",
        }
    }
}

/// The Zenoh publisher (`[zenoh]`, docs/zenoh.md): pose messages, a
/// status and a queryable of the latest pose on a Zenoh session run from
/// the edge runtime; optionally the pose as a ROS 2 message for
/// `rmw_zenoh`. Key expressions are given with `{camera}` already
/// replaced by the camera's id.
#[derive(Debug, Clone, PartialEq)]
pub struct Zenoh {
    /// Whether the daemon publishes on Zenoh (off by default).
    pub enabled: bool,
    /// Peer or client.
    pub mode: ZenohMode,
    /// Endpoints to connect to (`tcp/HOST:PORT`).
    pub connect: Vec<String>,
    /// Endpoints to listen on (`tcp/HOST:PORT`).
    pub listen: Vec<String>,
    /// Whether multicast scouting finds other peers and routers.
    pub scouting_multicast: bool,
    /// Where each pose message (v2 JSON) is put.
    pub pose_key: String,
    /// Where the status (JSON) is put.
    pub status_key: String,
    /// What the queryable of the latest pose answers.
    pub query_key: String,
    /// Time between two status messages.
    pub status_period: std::time::Duration,
    /// At start, how long to wait for a subscriber of `pose_key` before
    /// frames are taken (zero: do not wait).
    pub wait_for_subscriber: std::time::Duration,
    /// Whether the pose also goes out as a ROS 2 message.
    pub ros2: bool,
    /// The ROS 2 domain id.
    pub ros2_domain_id: u32,
    /// The ROS 2 topic (absolute name).
    pub ros2_topic: String,
}

impl Default for Zenoh {
    fn default() -> Self {
        let bad = |key: &'static str, value: String, why: &'static str| ConfigError::Value {
            path: String::new(),
            key,
            value,
            why,
        };
        // The defaults are valid for the default camera id.
        Zenoh::from_section(&ZenohSection::default(), "camera", &bad)
            .expect("the [zenoh] defaults are valid")
    }
}

/// A Zenoh endpoint of the TCP transport (`tcp/HOST:PORT`): the only
/// transport the daemon is built with. `listen`: port 0 (any) is allowed.
fn zenoh_endpoint(text: &str, listen: bool) -> bool {
    let Some(rest) = text.strip_prefix("tcp/") else {
        return false;
    };
    if let Ok(a) = rest.parse::<SocketAddr>() {
        return listen || a.port() != 0;
    }
    let Some((host, port)) = rest.rsplit_once(':') else {
        return false;
    };
    let port_ok = port.parse::<u16>().is_ok_and(|p| listen || p != 0);
    let host_ok = !host.is_empty()
        && host.len() <= 253
        && host.split('.').all(|label| {
            !label.is_empty()
                && label.len() <= 63
                && !label.starts_with('-')
                && label
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b == b'-')
        });
    port_ok && host_ok
}

/// `{camera}` replaced; `Some` when the result is a concrete Zenoh key
/// expression (chunks separated by '/', none empty, no wildcard or
/// reserved character).
fn zenoh_key(template: &str, camera: &str) -> Option<String> {
    let key = template.replace("{camera}", camera);
    let ok = !key.is_empty()
        && key.len() <= 512
        && key.split('/').all(|chunk| {
            !chunk.is_empty()
                && chunk
                    .bytes()
                    .all(|b| b.is_ascii_graphic() && !b"*$?#{}".contains(&b))
        })
        && !key.starts_with('@');
    ok.then_some(key)
}

/// `{camera}` replaced; `Some` when the result is a valid absolute ROS 2
/// topic name (`/` then tokens of letters, digits and `_`, none starting
/// with a digit, no `__`).
fn ros2_topic(template: &str, camera: &str) -> Option<String> {
    let topic = template.replace("{camera}", camera);
    let rest = topic.strip_prefix('/')?;
    let ok = !rest.is_empty()
        && topic.len() <= 256
        && !topic.contains("__")
        && rest.split('/').all(|token| {
            token
                .bytes()
                .next()
                .is_some_and(|b| b.is_ascii_alphabetic() || b == b'_')
                && token
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b == b'_')
        });
    ok.then_some(topic)
}

impl Zenoh {
    fn from_section(
        z: &ZenohSection,
        camera: &str,
        bad: &dyn Fn(&'static str, String, &'static str) -> ConfigError,
    ) -> Result<Zenoh, ConfigError> {
        if z.enabled && !cfg!(feature = "zenoh") {
            return Err(bad(
                "zenoh.enabled",
                "true".into(),
                "this build has no Zenoh (built without the cargo feature `zenoh`)",
            ));
        }
        let mode = match z.mode.as_str() {
            "peer" => ZenohMode::Peer,
            "client" => ZenohMode::Client,
            _ => {
                return Err(bad(
                    "zenoh.mode",
                    z.mode.clone(),
                    "must be \"peer\" or \"client\"",
                ))
            }
        };
        const ENDPOINT_RULE: &str =
            "must be a TCP endpoint \"tcp/HOST:PORT\" (e.g. \"tcp/127.0.0.1:7447\")";
        for (key, list, listen) in [
            ("zenoh.connect", &z.connect, false),
            ("zenoh.listen", &z.listen, true),
        ] {
            if list.len() > 64 {
                return Err(bad(key, list.len().to_string(), "at most 64 endpoints"));
            }
            if let Some(e) = list.iter().find(|e| !zenoh_endpoint(e, listen)) {
                return Err(bad(key, format!("\"{e}\""), ENDPOINT_RULE));
            }
        }
        if mode == ZenohMode::Client && z.enabled && z.connect.is_empty() {
            return Err(bad(
                "zenoh.connect",
                "[]".into(),
                "a client needs the router to connect to (\"tcp/HOST:PORT\")",
            ));
        }
        const KEY_RULE: &str = "must be a Zenoh key expression without wildcards: chunks \
             separated by '/', none empty, no '*', '$', '?', '#', no leading '@' \
             ({camera} is replaced by the camera id)";
        let key = |name: &'static str, template: &String| {
            zenoh_key(template, camera)
                .ok_or_else(|| bad(name, format!("\"{template}\""), KEY_RULE))
        };
        let pose_key = key("zenoh.pose_key", &z.pose_key)?;
        let status_key = key("zenoh.status_key", &z.status_key)?;
        let query_key = key("zenoh.query_key", &z.query_key)?;
        if status_key == pose_key || query_key == pose_key || query_key == status_key {
            return Err(bad(
                "zenoh.query_key",
                format!("\"{}\"", z.query_key),
                "pose_key, status_key and query_key must differ",
            ));
        }
        if !(100..=60_000).contains(&z.status_period_ms) {
            return Err(bad(
                "zenoh.status_period_ms",
                z.status_period_ms.to_string(),
                "must be 100..=60000 ms",
            ));
        }
        if z.wait_for_subscriber_ms > 60_000 {
            return Err(bad(
                "zenoh.wait_for_subscriber_ms",
                z.wait_for_subscriber_ms.to_string(),
                "must be 0..=60000 ms (0: do not wait)",
            ));
        }
        // ROS 2 (DDS) domain ids are 0..=232; rmw_zenoh takes the same.
        if z.ros2_domain_id > 232 {
            return Err(bad(
                "zenoh.ros2_domain_id",
                z.ros2_domain_id.to_string(),
                "must be 0..=232",
            ));
        }
        // Checked when used: a camera id with '-' is fine without ROS 2.
        let ros2_topic = match ros2_topic(&z.ros2_topic, camera) {
            Some(t) => t,
            None if !z.ros2 => z.ros2_topic.replace("{camera}", camera),
            None => {
                return Err(bad(
                    "zenoh.ros2_topic",
                    format!("\"{}\"", z.ros2_topic),
                    "must be an absolute ROS 2 topic name: '/' then tokens of A-Z, a-z, 0-9 \
                 and '_' ({camera} is replaced by the camera id, which then must not \
                 contain '-')",
                ))
            }
        };
        Ok(Zenoh {
            enabled: z.enabled,
            mode,
            connect: z.connect.clone(),
            listen: z.listen.clone(),
            scouting_multicast: z.scouting_multicast,
            pose_key,
            status_key,
            query_key,
            status_period: std::time::Duration::from_millis(z.status_period_ms),
            wait_for_subscriber: std::time::Duration::from_millis(z.wait_for_subscriber_ms),
            ros2: z.ros2,
            ros2_domain_id: z.ros2_domain_id,
            ros2_topic,
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

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = include_str!("../../../config/photopose.toml");

    #[test]
    fn a_replay_at_full_speed_blocks_unless_told_otherwise() {
        let replay = |extra: &str| {
            Config::parse(
                &format!(
                    "[source]\nkind = \"replay\"\n[source.replay]\npath = \"r.mcap\"\nspeed = \"max\"\n{extra}"
                ),
                "test",
            )
            .unwrap()
            .overflow
        };
        assert_eq!(replay(""), Overflow::Block);
        assert_eq!(
            replay("[pipeline]\noverflow = \"drop-oldest\"\n"),
            Overflow::DropOldest
        );
        let synthetic = Config::parse("[source]\nkind = \"synthetic\"\n", "test").unwrap();
        assert_eq!(synthetic.overflow, Overflow::DropNewest);
    }

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
        // The exposure loop's keys as documented: its defaults.
        assert_eq!(
            g.exposure_control,
            Some(photopose_acquire::ExposureSettings::default())
        );
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
    fn every_section_may_be_left_out_or_left_empty() {
        let none = Config::parse("", "x").unwrap();
        assert!(matches!(none.source, Source::Synthetic(_)));
        for section in [
            "camera",
            "source",
            "source.synthetic",
            "pipeline",
            "output",
            "metrics",
            "rsi",
            "record",
        ] {
            let c = Config::parse(&format!("[{section}]\n"), "x")
                .unwrap_or_else(|e| panic!("[{section}] alone: {e}"));
            assert_eq!(c, none, "[{section}] alone changes the defaults");
        }
        // Only what differs: a synthetic source at another rate, kind implied.
        let c = Config::parse("[source.synthetic]\nrate_hz = 5.0\n", "x").unwrap();
        assert!(matches!(c.source, Source::Synthetic(ref s) if s.rate_hz == 5.0));
    }

    #[test]
    fn host_names_are_resolved_where_an_address_is_asked() {
        let c = Config::parse(
            "[output]\nudp = [\"localhost:5005\", \"127.0.0.1:5007\"]\ntcp_listen = \"localhost:5006\"\n\
             [metrics]\nlisten = \"localhost:9464\"\n",
            "x",
        )
        .unwrap();
        let local = |port: u16| SocketAddr::from(([127, 0, 0, 1], port));
        assert_eq!(c.udp, vec![local(5005), local(5007)]);
        assert_eq!(c.tcp_listen, Some(local(5006)));
        assert_eq!(c.metrics_listen, Some(local(9464)));
        for (text, key, value) in [
            (
                "[output]\nudp = [\"no-such-host.invalid:5005\"]\n",
                "output.udp",
                "no-such-host.invalid:5005",
            ),
            (
                "[output]\ntcp_listen = \"localhost\"\n",
                "output.tcp_listen",
                "localhost",
            ),
            (
                "[metrics]\nlisten = \"localhost:http\"\n",
                "metrics.listen",
                "localhost:http",
            ),
        ] {
            let e = Config::parse(text, "x.toml").unwrap_err().to_string();
            assert!(
                e.starts_with("x.toml: ") && e.contains(key) && e.contains(value),
                "{e:?} lacks {key} or {value}"
            );
        }
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
    fn gige_features_keep_their_order_and_types() {
        use photopose_acquire::FeatureValue;
        let c = Config::parse(
            "[source]\nkind = \"gige\"\n[source.gige.features]\nTriggerSelector = \"FrameStart\"\n\
             TriggerMode = \"On\"\nGevSCPD = 2000\nPtpEnable = true\nAcquisitionFrameRate = 25.5\n",
            "x",
        )
        .unwrap();
        let Source::Gige(g) = c.source else {
            panic!("not gige")
        };
        assert_eq!(
            g.features,
            vec![
                (
                    "TriggerSelector".into(),
                    FeatureValue::Text("FrameStart".into())
                ),
                ("TriggerMode".into(), FeatureValue::Text("On".into())),
                ("GevSCPD".into(), FeatureValue::Int(2000)),
                ("PtpEnable".into(), FeatureValue::Bool(true)),
                ("AcquisitionFrameRate".into(), FeatureValue::Float(25.5)),
            ]
        );
        for text in [
            "[source]\nkind = \"gige\"\n[source.gige.features]\n\"Bad Name\" = 1\n",
            "[source]\nkind = \"gige\"\n[source.gige.features]\nGain = nan\n",
        ] {
            let e = Config::parse(text, "x.toml").unwrap_err().to_string();
            assert!(e.contains("source.gige.features"), "{e}");
        }
        let e = Config::parse(
            "[source]\nkind = \"gige\"\n[source.gige.features]\nRoi = [1, 2]\n",
            "x.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("features"), "{e}");
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
    fn the_live_view_is_off_by_default_and_its_keys_are_checked() {
        let d = Config::parse("[source]\nkind = \"synthetic\"\n", "x").unwrap();
        assert!(!d.live.enabled);
        assert_eq!(d.live.address, "127.0.0.1:8765".parse().unwrap());
        assert_eq!((d.live.image_hz, d.live.image_scale), (5.0, 4));
        let example = Config::parse(EXAMPLE, "config/photopose.toml").unwrap();
        assert!(!example.live.enabled, "the example leaves it off");
        // The example's commented section, switched on, is valid and
        // documents the defaults.
        let mut on = false;
        let mut text = String::new();
        for line in EXAMPLE.lines() {
            on = (on || line.starts_with("# [live]")) && !line.trim().is_empty();
            text.push_str(if on { &line[2..] } else { line });
            text.push('\n');
        }
        let live = Config::parse(&text, "live example").unwrap().live;
        assert!(live.enabled);
        assert_eq!(
            Live {
                enabled: false,
                ..live
            },
            d.live
        );
        let cases = [
            ("address = \"localhost:8765\"", "live.address"),
            ("image_hz = 0.0", "live.image_hz"),
            ("image_hz = -2.0", "live.image_hz"),
            ("image_hz = 1000.0", "live.image_hz"),
            ("max_clients = 0", "live.max_clients"),
            ("max_clients = 65", "live.max_clients"),
            ("image_scale = 0", "live.image_scale"),
            ("image_scale = 65", "live.image_scale"),
            ("pose_hz = 0.0", "live.pose_hz"),
            ("max_viewers = 4", "max_viewers"),
            ("enabled = \"yes\"", "live.enabled"),
            ("image_scale = \"big\"", "live.image_scale"),
        ];
        for (line, want) in cases {
            let text = format!("[source]\nkind = \"synthetic\"\n[live]\n{line}\n");
            let e = Config::parse(&text, "x.toml").unwrap_err().to_string();
            assert!(
                e.starts_with("x.toml: ") && e.contains(want),
                "{line}: {e:?} lacks {want:?}"
            );
        }
    }

    fn built_with_zenoh() -> bool {
        std::hint::black_box(cfg!(feature = "zenoh"))
    }

    #[test]
    fn zenoh_is_off_by_default_documented_and_its_keys_are_checked() {
        let d = Config::parse("[camera]\nid = \"cell-7\"\n", "x").unwrap();
        assert!(!d.zenoh.enabled);
        assert_eq!(d.zenoh.mode, ZenohMode::Peer);
        assert!(!d.zenoh.scouting_multicast && d.zenoh.connect.is_empty());
        assert_eq!(d.zenoh.pose_key, "photopose/cell-7/pose");
        assert_eq!(d.zenoh.status_key, "photopose/cell-7/status");
        assert_eq!(d.zenoh.query_key, "photopose/cell-7/latest");
        let example = Config::parse(EXAMPLE, "config/photopose.toml").unwrap();
        assert!(!example.zenoh.enabled, "the example leaves it off");
        // The example's commented section, switched on, documents the
        // defaults (and is refused by a build without Zenoh).
        let mut on = false;
        let mut text = String::new();
        for line in EXAMPLE.lines() {
            on = (on || line.starts_with("# [zenoh]")) && !line.trim().is_empty();
            text.push_str(if on { &line[2..] } else { line });
            text.push('\n');
        }
        match Config::parse(&text, "zenoh example") {
            Ok(c) => {
                assert!(built_with_zenoh());
                assert!(c.zenoh.enabled);
                let defaults = Config::parse("", "x").unwrap().zenoh;
                assert_eq!(
                    Zenoh {
                        enabled: false,
                        ..c.zenoh
                    },
                    defaults
                );
                assert_eq!(defaults, Zenoh::default());
            }
            Err(e) => {
                assert!(!built_with_zenoh(), "{e}");
                assert!(e.to_string().contains("zenoh.enabled"), "{e}");
            }
        }
        let cases = [
            ("connect = [\"tcp/127.0.0.1:0\"]", "zenoh.connect"),
            ("connect = [\"quic/127.0.0.1:7447\"]", "zenoh.connect"),
            ("connect = [\"tcp/bad host:7447\"]", "zenoh.connect"),
            ("listen = [\"tcp/127.0.0.1:99999\"]", "zenoh.listen"),
            ("mode = \"router\"", "zenoh.mode"),
            ("pose_key = \"photopose/**\"", "zenoh.pose_key"),
            ("pose_key = \"/photopose/{camera}\"", "zenoh.pose_key"),
            ("status_key = \"@admin/x\"", "zenoh.status_key"),
            ("query_key = \"a/$b\"", "zenoh.query_key"),
            ("ros2 = true", "zenoh.ros2_topic"),
            ("ros2_domain_id = 233", "zenoh.ros2_domain_id"),
            (
                "wait_for_subscriber_ms = 60001",
                "zenoh.wait_for_subscriber_ms",
            ),
            ("status_period_ms = 99", "zenoh.status_period_ms"),
            ("mode = 3", "zenoh.mode"),
            ("topic = \"x\"", "topic"),
        ];
        for (line, want) in cases {
            // cell-7: '-' is no ROS 2 name character.
            let text = format!("[camera]\nid = \"cell-7\"\n[zenoh]\n{line}\n");
            let e = Config::parse(&text, "x.toml").unwrap_err().to_string();
            assert!(
                e.starts_with("x.toml: ") && e.contains(want),
                "{line}: {e:?} lacks {want:?}"
            );
        }
        let ok = Config::parse(
            "[camera]\nid = \"cell_7\"\n[zenoh]\nmode = \"client\"\n\
             connect = [\"tcp/router.local:7447\", \"tcp/[::1]:7447\"]\n\
             listen = [\"tcp/0.0.0.0:0\"]\nros2 = true\nros2_domain_id = 42\n",
            "x",
        )
        .unwrap()
        .zenoh;
        assert_eq!(ok.ros2_topic, "/photopose/cell_7/pose");
        assert_eq!(ok.mode, ZenohMode::Client);
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
