//! The live view: a Foxglove WebSocket server (the `foxglove` crate's) on
//! the edge runtime, and the bounded hand-over that feeds it from the
//! pipeline's threads.
//!
//! The pipeline never waits for the view. The grabber fills a throttled,
//! downscaled frame into one of a few preallocated image buffers
//! ([`LiveSender::send_image`]; none free: dropped and counted); the output
//! thread fills the latest state ([`LiveSender::send_state`]: pose, σ,
//! status, RSI state, the JSON pose line) into a slot it only ever
//! `try_lock`s (busy: dropped and counted, latest wins). One task on the
//! edge runtime turns them into messages of the standard Foxglove schemas
//! and logs them to the connected clients; the server's per-client queues
//! are bounded (oldest messages dropped for a slow client).
//!
//! Channels (docs/live-view.md): `/camera/image` (`foxglove.RawImage`,
//! mono8), `/camera/annotations` (`foxglove.ImageAnnotations`), `/pose`
//! (`foxglove.PoseInFrame`, frame `field`), `/tf` (`foxglove.FrameTransforms`,
//! field → camera), `/scene` (`foxglove.SceneUpdate`: plate and camera),
//! `/pose/message` (the JSON pose line) and `/status` (JSON). Positions on
//! the 3-D channels are in metres, as Foxglove's 3-D panel expects.

use crate::edge::EdgeHandle;
use crate::live_front::FrontStats;
use crate::StreamError;
use crossbeam_queue::ArrayQueue;
use foxglove::schemas::{
    line_primitive, CircleAnnotation, Color, FrameTransform, FrameTransforms, ImageAnnotations,
    LinePrimitive, Point2, Point3, Pose, PoseInFrame, Quaternion, RawImage, SceneEntity,
    SceneUpdate, SpherePrimitive, TextAnnotation, TextPrimitive, Timestamp, Vector3,
};
use foxglove::{Channel, Context, RawChannel, Schema, WebSocketServerHandle};
use serde::Serialize;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::Notify;

/// The topic of the downscaled frames.
pub const IMAGE_TOPIC: &str = "/camera/image";
/// The topic of the detected targets drawn on the image.
pub const ANNOTATIONS_TOPIC: &str = "/camera/annotations";
/// The topic of the camera pose (`foxglove.PoseInFrame`).
pub const POSE_TOPIC: &str = "/pose";
/// The topic of the field → camera transform.
pub const TF_TOPIC: &str = "/tf";
/// The topic of the 3-D scene (plate and camera).
pub const SCENE_TOPIC: &str = "/scene";
/// The topic of the JSON pose line, as the streams send it.
pub const MESSAGE_TOPIC: &str = "/pose/message";
/// The topic of the status (σ, σ0, targets, status, RSI state).
pub const STATUS_TOPIC: &str = "/status";
/// The frame of the plate (the field frame).
pub const FIELD_FRAME: &str = "field";
/// The frame of the camera (x right, y up, z backwards: it looks along −z).
pub const CAMERA_FRAME: &str = "camera";

/// Messages queued per client before the oldest are dropped (a slow
/// client costs at most this many messages of memory: about 3 MB of
/// images at the default scale).
const CLIENT_BACKLOG: usize = 32;
/// How often the plate is sent again (a client that connects later gets
/// it within this time).
const PLATE_EVERY: Duration = Duration::from_secs(1);
/// How long starting the server may take.
const START_TIMEOUT: Duration = Duration::from_secs(5);
/// Room for the JSON pose line in the state slot (a longer line grows the
/// buffer once).
const LINE_BYTES: usize = 4096;
/// Room for detected targets in the state slot.
const TARGETS: usize = 512;

/// The JSON Schema of the `/status` channel.
const STATUS_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "photopose live status",
  "type": "object",
  "properties": {
    "seq": {"type": "integer", "description": "the frame's sequence number"},
    "status": {"type": "string", "description": "ok, too_few_targets, error or stale"},
    "n_targets": {"type": "integer", "description": "targets used in the adjustment"},
    "sigma0_px": {"type": ["number", "null"], "description": "a-posteriori sigma0 of an image coordinate, px"},
    "std_position_mm": {"type": ["array", "null"], "items": {"type": "number"}, "description": "standard deviations of the projection centre X, Y, Z, mm"},
    "std_rotation_deg": {"type": ["array", "null"], "items": {"type": "number"}, "description": "standard deviations of the rotations about the field's X, Y, Z axes, deg"},
    "position_mm": {"type": ["array", "null"], "items": {"type": "number"}, "description": "projection centre in the field frame, mm"},
    "latency_ms": {"type": "number", "description": "frame hand-over to pose, ms"},
    "rsi": {"type": ["object", "null"], "properties": {
      "state": {"type": "string", "description": "tracking, measure_only, stale_..., frozen_invalid or waiting"},
      "robot_xyzabc": {"type": ["array", "null"], "items": {"type": "number"}, "description": "the controller's last RIst: X, Y, Z mm, A, B, C deg"}
    }},
    "dropped": {"type": "object", "description": "hand-overs the live view dropped (it never holds the pipeline up)", "properties": {
      "images": {"type": "integer"}, "states": {"type": "integer"}
    }}
  }
}"#;

/// A generic JSON Schema for the pose line (its own schema is in the
/// stream documentation).
const MESSAGE_SCHEMA: &str =
    r#"{"title": "photopose pose message (docs/streams.md)", "type": "object"}"#;

/// Where the live view listens and how it draws.
#[derive(Debug, Clone, PartialEq)]
pub struct LiveOptions {
    /// The WebSocket address (`ws://ADDRESS`).
    pub address: SocketAddr,
    /// Downscale factor of the published frames (1: full size); the
    /// annotations are scaled alike.
    pub image_scale: u32,
    /// Clients served at once; one more is refused (`503`).
    pub max_clients: usize,
}

/// A target of the plate, for the 3-D scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneTarget {
    /// Its id.
    pub id: u64,
    /// Its centre in the field frame, mm.
    pub position_mm: [f64; 3],
    /// Its radius, mm.
    pub radius_mm: f64,
    /// Whether it is a coded target.
    pub coded: bool,
}

/// The camera's sensor and principal distance, for the frustum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraShape {
    /// Sensor width, px.
    pub width_px: u32,
    /// Sensor height, px.
    pub height_px: u32,
    /// Pixel pitch, mm.
    pub pixel_mm: f64,
    /// Principal distance, mm.
    pub c_mm: f64,
}

/// A detected target of a frame, for the image annotations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectedTarget {
    /// Its id, if identified.
    pub id: Option<u64>,
    /// Column of its centre in the full frame, px (pixel coordinates:
    /// integer values are pixel centres).
    pub col: f64,
    /// Row of its centre in the full frame, px.
    pub row: f64,
    /// Whether it is a coded target.
    pub coded: bool,
}

/// One downscaled frame (mono8) on its way to the view.
#[derive(Debug, Default)]
pub struct LiveImage {
    /// The frame's sequence number.
    pub seq: u64,
    /// Its time, ns since the Unix epoch (the hand-over; the annotations of
    /// the same frame carry the same).
    pub time_ns: u64,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// `width × height` grey values, rows top to bottom.
    pub data: Vec<u8>,
}

/// The camera's pose and its precision.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LivePose {
    /// The projection centre in the field frame, mm.
    pub position_mm: [f64; 3],
    /// The camera's orientation in the field frame (`Rᵀ`: its columns
    /// are the camera axes in field coordinates) as a quaternion `x, y,
    /// z, w`.
    pub orientation_xyzw: [f64; 4],
    /// Standard deviations of the projection centre, mm.
    pub std_position_mm: [f64; 3],
    /// Standard deviations of the rotations about the field axes, deg.
    pub std_rotation_deg: [f64; 3],
    /// σ0 of an image coordinate, px.
    pub sigma0_px: f64,
}

/// The RSI server's state as the view shows it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveRsi {
    /// The correction state (`tracking`, `measure_only`, `stale_…`,
    /// `frozen_invalid`, `waiting`).
    pub state: &'static str,
    /// The controller's last `RIst` (X, Y, Z mm, A, B, C deg).
    pub robot_xyzabc: Option<[f64; 6]>,
}

/// The latest state of the pipeline, filled by the output thread.
#[derive(Debug)]
pub struct LiveState {
    /// The frame's sequence number.
    pub seq: u64,
    /// Its time, ns since the Unix epoch.
    pub time_ns: u64,
    /// `ok`, `too_few_targets`, `error` or `stale`.
    pub status: &'static str,
    /// Targets used in the adjustment.
    pub n_targets: u32,
    /// The pose, when the frame gave one.
    pub pose: Option<LivePose>,
    /// The RSI server's state, when it runs.
    pub rsi: Option<LiveRsi>,
    /// Frame hand-over to result, ms.
    pub latency_ms: f64,
    /// The JSON pose line as the streams send it (`\n` optional).
    pub line: Vec<u8>,
    /// The detected targets of the frame, when it is the frame last
    /// published as an image (`targets_time_ns` is then its time).
    pub targets: Vec<DetectedTarget>,
    /// The time of the frame the targets belong to; `None`: no targets.
    pub targets_time_ns: Option<u64>,
}

impl Default for LiveState {
    fn default() -> Self {
        LiveState {
            seq: 0,
            time_ns: 0,
            status: "ok",
            n_targets: 0,
            pose: None,
            rsi: None,
            latency_ms: 0.0,
            line: Vec::with_capacity(LINE_BYTES),
            targets: Vec::with_capacity(TARGETS),
            targets_time_ns: None,
        }
    }
}

/// What the live view sent and dropped.
#[derive(Debug, Default)]
pub struct LiveStats {
    /// Frames published.
    pub images: AtomicU64,
    /// Frames dropped at the hand-over (no free buffer).
    pub images_dropped: AtomicU64,
    /// States published.
    pub states: AtomicU64,
    /// States dropped at the hand-over (the slot was busy).
    pub states_dropped: AtomicU64,
}

struct Shared {
    free: ArrayQueue<LiveImage>,
    filled: ArrayQueue<LiveImage>,
    state: Mutex<LiveState>,
    state_fresh: AtomicBool,
    ready: Notify,
    /// Some client is subscribed to the image channel (the grabber skips
    /// the copy otherwise).
    image_wanted: AtomicBool,
    /// Some client is subscribed to any channel.
    anyone: AtomicBool,
    stats: LiveStats,
}

/// The pipeline's end of the hand-over; cheap to clone (the frame tap and
/// the sink each hold one). Never blocks.
#[derive(Clone)]
pub struct LiveSender(Arc<Shared>);

impl std::fmt::Debug for LiveSender {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveSender").finish_non_exhaustive()
    }
}

impl LiveSender {
    /// Whether a client is subscribed to the image channel: when not, the
    /// frame tap copies nothing.
    pub fn image_wanted(&self) -> bool {
        self.0.image_wanted.load(Ordering::Relaxed)
    }

    /// Whether any client is subscribed to anything.
    pub fn anyone(&self) -> bool {
        self.0.anyone.load(Ordering::Relaxed)
    }

    /// Hands a frame to the view: `fill` writes it into a free
    /// preallocated buffer. Returns `false` (and counts it) when no buffer
    /// is free.
    pub fn send_image(&self, fill: impl FnOnce(&mut LiveImage)) -> bool {
        let Some(mut image) = self.0.free.pop() else {
            self.0.stats.images_dropped.fetch_add(1, Ordering::Relaxed);
            return false;
        };
        fill(&mut image);
        // Every buffer is in exactly one queue: `filled` has room.
        if let Err(image) = self.0.filled.push(image) {
            let _ = self.0.free.push(image);
            self.0.stats.images_dropped.fetch_add(1, Ordering::Relaxed);
            return false;
        }
        self.0.ready.notify_one();
        true
    }

    /// Hands the latest state to the view: `fill` overwrites the slot
    /// (latest wins). Returns `false` (and counts it) when the view was
    /// reading the slot at that instant.
    pub fn send_state(&self, fill: impl FnOnce(&mut LiveState)) -> bool {
        let Ok(mut slot) = self.0.state.try_lock() else {
            self.0.stats.states_dropped.fetch_add(1, Ordering::Relaxed);
            return false;
        };
        fill(&mut slot);
        drop(slot);
        self.0.state_fresh.store(true, Ordering::Release);
        self.0.ready.notify_one();
        true
    }

    /// The counters.
    pub fn stats(&self) -> &LiveStats {
        &self.0.stats
    }
}

/// The channels of the view.
struct Channels {
    image: Channel<RawImage>,
    annotations: Channel<ImageAnnotations>,
    pose: Channel<PoseInFrame>,
    tf: Channel<FrameTransforms>,
    scene: Channel<SceneUpdate>,
    message: Arc<RawChannel>,
    status: Arc<RawChannel>,
}

impl Channels {
    fn new(ctx: &Arc<Context>) -> Result<Channels, foxglove::FoxgloveError> {
        Ok(Channels {
            image: ctx.channel_builder(IMAGE_TOPIC).build(),
            annotations: ctx.channel_builder(ANNOTATIONS_TOPIC).build(),
            pose: ctx.channel_builder(POSE_TOPIC).build(),
            tf: ctx.channel_builder(TF_TOPIC).build(),
            scene: ctx.channel_builder(SCENE_TOPIC).build(),
            message: ctx
                .channel_builder(MESSAGE_TOPIC)
                .message_encoding("json")
                .schema(Schema::new(
                    "photopose.PoseMessage",
                    "jsonschema",
                    MESSAGE_SCHEMA.as_bytes(),
                ))
                .build_raw()?,
            status: ctx
                .channel_builder(STATUS_TOPIC)
                .message_encoding("json")
                .schema(Schema::new(
                    "photopose.LiveStatus",
                    "jsonschema",
                    STATUS_SCHEMA.as_bytes(),
                ))
                .build_raw()?,
        })
    }

    fn anyone(&self) -> bool {
        self.image.has_sinks()
            || self.annotations.has_sinks()
            || self.pose.has_sinks()
            || self.tf.has_sinks()
            || self.scene.has_sinks()
            || self.message.has_sinks()
            || self.status.has_sinks()
    }
}

/// The running live view: its address and the hand-over into it.
pub struct LiveServer {
    sender: LiveSender,
    addr: SocketAddr,
    server: Option<WebSocketServerHandle>,
    front: Arc<FrontStats>,
    stop: tokio_util::sync::CancellationToken,
}

impl std::fmt::Debug for LiveServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveServer")
            .field("addr", &self.addr)
            .finish_non_exhaustive()
    }
}

impl LiveServer {
    /// Starts the server on `edge` at `options.address`, with `images`
    /// preallocated image buffers of `image_bytes` each, and the plate and
    /// camera of the 3-D scene.
    pub fn start(
        edge: &EdgeHandle,
        options: &LiveOptions,
        images: usize,
        image_bytes: usize,
        plate: &[SceneTarget],
        camera: CameraShape,
    ) -> Result<LiveServer, StreamError> {
        let images = images.max(1);
        let shared = Arc::new(Shared {
            free: ArrayQueue::new(images),
            filled: ArrayQueue::new(images),
            state: Mutex::new(LiveState::default()),
            state_fresh: AtomicBool::new(false),
            ready: Notify::new(),
            image_wanted: AtomicBool::new(false),
            anyone: AtomicBool::new(false),
            stats: LiveStats::default(),
        });
        for _ in 0..images {
            let _ = shared.free.push(LiveImage {
                data: Vec::with_capacity(image_bytes),
                ..LiveImage::default()
            });
        }
        let addr = options.address;
        let failed = |what: &'static str| {
            move |e: &dyn std::fmt::Display| StreamError::Socket {
                what,
                addr: addr.to_string(),
                source: std::io::Error::other(e.to_string()),
            }
        };
        // A context of its own: these channels go to the live view only,
        // never to a recording.
        let ctx = Context::new();
        let channels =
            Channels::new(&ctx).map_err(|e| failed("cannot open the live view on")(&e))?;
        // The public listener is the front door (`live_front`: client
        // limit, both names of the protocol); the SDK's server listens on
        // the loopback behind it.
        let (front, local) = edge.listen(addr, "cannot serve the live view on")?;
        let server = ctx
            .websocket_server()
            .name("photopose")
            .bind("127.0.0.1", 0)
            .message_backlog_size(CLIENT_BACKLOG);
        // The server starts (binds, spawns its accept task) on the edge
        // runtime; this thread waits for the outcome.
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        edge.spawn(async move {
            let _ = tx.send(server.start().await);
        });
        let handle = match rx.recv_timeout(START_TIMEOUT) {
            Ok(Ok(h)) => h,
            Ok(Err(e)) => return Err(failed("cannot serve the live view on")(&e)),
            Err(_) => {
                return Err(failed("the live view did not start on")(
                    &"no answer from the edge runtime",
                ))
            }
        };
        let inner = SocketAddr::from(([127, 0, 0, 1], handle.port()));
        let stop = edge.stop_token();
        let front_stats = Arc::new(FrontStats::default());
        edge.spawn(crate::live_front::serve(
            front,
            inner,
            options.max_clients.max(1),
            front_stats.clone(),
            stop.clone(),
        ));
        let publisher = Publisher {
            _context: ctx,
            shared: shared.clone(),
            channels,
            scale: options.image_scale.max(1),
            plate: plate_entity(plate),
            camera,
            state: LiveState::default(),
            last_time_ns: 0,
        };
        edge.spawn(publisher.run(stop.clone()));
        Ok(LiveServer {
            sender: LiveSender(shared),
            addr: local,
            server: Some(handle),
            front: front_stats,
            stop,
        })
    }

    /// The address clients connect to (`ws://ADDR`).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The hand-over into the view.
    pub fn sender(&self) -> LiveSender {
        self.sender.clone()
    }

    /// The front door's counters (connections served, refused, renamed).
    pub fn front(&self) -> &FrontStats {
        &self.front
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.server.as_ref().map_or(0, |s| s.client_count())
    }

    /// Closes the clients and ends the view's task.
    pub fn shutdown(mut self) {
        self.close();
    }

    fn close(&mut self) {
        self.stop.cancel();
        if let Some(server) = self.server.take() {
            // The clients are told and their tasks end with the runtime.
            server.stop().detach_all();
        }
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        self.close();
    }
}

/// The edge task: turns hand-overs into messages.
struct Publisher {
    /// The channels' context: the server holds it only weakly, so it
    /// lives as long as the task.
    _context: Arc<Context>,
    shared: Arc<Shared>,
    channels: Channels,
    scale: u32,
    plate: SceneEntity,
    camera: CameraShape,
    state: LiveState,
    last_time_ns: u64,
}

impl Publisher {
    async fn run(mut self, stop: tokio_util::sync::CancellationToken) {
        let mut plate = tokio::time::interval(PLATE_EVERY);
        plate.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        loop {
            tokio::select! {
                () = stop.cancelled() => break,
                () = self.shared.ready.notified() => {}
                _ = plate.tick() => {
                    if self.channels.scene.has_sinks() {
                        self.plate.timestamp = Some(timestamp(self.last_time_ns));
                        self.channels.scene.log(&SceneUpdate {
                            deletions: Vec::new(),
                            entities: vec![self.plate.clone()],
                        });
                    }
                }
            }
            self.shared
                .image_wanted
                .store(self.channels.image.has_sinks(), Ordering::Relaxed);
            self.shared
                .anyone
                .store(self.channels.anyone(), Ordering::Relaxed);
            while let Some(image) = self.shared.filled.pop() {
                self.publish_image(&image);
                let _ = self.shared.free.push(image);
            }
            if self.shared.state_fresh.swap(false, Ordering::Acquire) {
                {
                    let mut slot = self.shared.state.lock().unwrap_or_else(|e| e.into_inner());
                    std::mem::swap(&mut *slot, &mut self.state);
                }
                self.publish_state();
            }
        }
    }

    fn publish_image(&mut self, image: &LiveImage) {
        self.last_time_ns = self.last_time_ns.max(image.time_ns);
        self.channels.image.log_with_time(
            &RawImage {
                timestamp: Some(timestamp(image.time_ns)),
                frame_id: CAMERA_FRAME.into(),
                width: image.width,
                height: image.height,
                encoding: "mono8".into(),
                step: image.width,
                data: foxglove::bytes::Bytes::copy_from_slice(&image.data),
            },
            image.time_ns,
        );
        self.shared.stats.images.fetch_add(1, Ordering::Relaxed);
    }

    fn publish_state(&mut self) {
        let s = &self.state;
        let t = s.time_ns;
        self.last_time_ns = self.last_time_ns.max(t);
        if let Some(p) = &s.pose {
            let pose = pose_in_metres(p);
            self.channels.pose.log_with_time(
                &PoseInFrame {
                    timestamp: Some(timestamp(t)),
                    frame_id: FIELD_FRAME.into(),
                    pose: Some(pose),
                },
                t,
            );
            self.channels.tf.log_with_time(
                &FrameTransforms {
                    transforms: vec![FrameTransform {
                        timestamp: Some(timestamp(t)),
                        parent_frame_id: FIELD_FRAME.into(),
                        child_frame_id: CAMERA_FRAME.into(),
                        translation: pose.position,
                        rotation: pose.orientation,
                    }],
                },
                t,
            );
            if self.channels.scene.has_sinks() {
                self.channels.scene.log_with_time(
                    &SceneUpdate {
                        deletions: Vec::new(),
                        entities: vec![camera_entity(&pose, &self.camera, t)],
                    },
                    t,
                );
            }
        }
        if let Some(at) = s.targets_time_ns {
            self.channels
                .annotations
                .log_with_time(&image_annotations(&s.targets, self.scale, at), at);
        }
        if !s.line.is_empty() && self.channels.message.has_sinks() {
            let line = s.line.strip_suffix(b"\n").unwrap_or(&s.line);
            self.channels
                .message
                .log_with_meta(line, foxglove::PartialMetadata::with_log_time(t));
        }
        if self.channels.status.has_sinks() {
            let stats = &self.shared.stats;
            let status = Status {
                seq: s.seq,
                status: s.status,
                n_targets: s.n_targets,
                sigma0_px: s.pose.map(|p| p.sigma0_px),
                std_position_mm: s.pose.map(|p| p.std_position_mm),
                std_rotation_deg: s.pose.map(|p| p.std_rotation_deg),
                position_mm: s.pose.map(|p| p.position_mm),
                latency_ms: s.latency_ms,
                rsi: s.rsi.map(|r| StatusRsi {
                    state: r.state,
                    robot_xyzabc: r.robot_xyzabc,
                }),
                dropped: Dropped {
                    images: stats.images_dropped.load(Ordering::Relaxed),
                    states: stats.states_dropped.load(Ordering::Relaxed),
                },
            };
            if let Ok(json) = serde_json::to_vec(&status) {
                self.channels
                    .status
                    .log_with_meta(&json, foxglove::PartialMetadata::with_log_time(t));
            }
        }
        self.shared.stats.states.fetch_add(1, Ordering::Relaxed);
    }
}

#[derive(Serialize)]
struct Status {
    seq: u64,
    status: &'static str,
    n_targets: u32,
    sigma0_px: Option<f64>,
    std_position_mm: Option<[f64; 3]>,
    std_rotation_deg: Option<[f64; 3]>,
    position_mm: Option<[f64; 3]>,
    latency_ms: f64,
    rsi: Option<StatusRsi>,
    dropped: Dropped,
}

#[derive(Serialize)]
struct StatusRsi {
    state: &'static str,
    robot_xyzabc: Option<[f64; 6]>,
}

#[derive(Serialize)]
struct Dropped {
    images: u64,
    states: u64,
}

/// A Foxglove timestamp from ns since the Unix epoch.
fn timestamp(ns: u64) -> Timestamp {
    Timestamp::new(
        u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
        (ns % 1_000_000_000) as u32,
    )
}

fn color(r: f64, g: f64, b: f64, a: f64) -> Option<Color> {
    Some(Color { r, g, b, a })
}

/// The camera's pose in the field frame, position in metres.
fn pose_in_metres(p: &LivePose) -> Pose {
    let [x, y, z, w] = p.orientation_xyzw;
    Pose {
        position: Some(Vector3 {
            x: p.position_mm[0] / 1000.0,
            y: p.position_mm[1] / 1000.0,
            z: p.position_mm[2] / 1000.0,
        }),
        orientation: Some(Quaternion { x, y, z, w }),
    }
}

/// The coded targets' colour (orange); uncoded ones are light grey.
const CODED: [f64; 3] = [1.0, 0.55, 0.0];
const UNCODED: [f64; 3] = [0.85, 0.85, 0.85];

/// The plate as spheres (coded: orange, with their ids; uncoded: grey), in
/// the field frame, metres.
pub fn plate_entity(targets: &[SceneTarget]) -> SceneEntity {
    let mut spheres = Vec::with_capacity(targets.len());
    let mut texts = Vec::new();
    for t in targets {
        let [x, y, z] = t.position_mm.map(|v| v / 1000.0);
        let d = 2.0 * t.radius_mm / 1000.0;
        let [r, g, b] = if t.coded { CODED } else { UNCODED };
        let pose = |z_up: f64| Pose {
            position: Some(Vector3 { x, y, z: z + z_up }),
            orientation: Some(Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            }),
        };
        spheres.push(SpherePrimitive {
            pose: Some(pose(0.0)),
            size: Some(Vector3 { x: d, y: d, z: d }),
            color: color(r, g, b, 1.0),
        });
        if t.coded {
            texts.push(TextPrimitive {
                pose: Some(pose(d)),
                billboard: true,
                font_size: 14.0,
                scale_invariant: true,
                color: color(r, g, b, 1.0),
                text: t.id.to_string(),
            });
        }
    }
    SceneEntity {
        frame_id: FIELD_FRAME.into(),
        id: "plate".into(),
        spheres,
        texts,
        ..SceneEntity::default()
    }
}

/// The camera at `pose` (field frame, metres): its axes (x red, y green,
/// z blue, 50 mm) and its viewing frustum (100 mm deep, along −z).
pub fn camera_entity(pose: &Pose, camera: &CameraShape, time_ns: u64) -> SceneEntity {
    let p = |x: f64, y: f64, z: f64| Point3 { x, y, z };
    let axis = 0.05;
    let axes = LinePrimitive {
        r#type: line_primitive::Type::LineList as i32,
        pose: Some(*pose),
        thickness: 3.0,
        scale_invariant: true,
        points: vec![
            p(0.0, 0.0, 0.0),
            p(axis, 0.0, 0.0),
            p(0.0, 0.0, 0.0),
            p(0.0, axis, 0.0),
            p(0.0, 0.0, 0.0),
            p(0.0, 0.0, axis),
        ],
        colors: [
            [1.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.8, 0.0],
            [0.0, 0.8, 0.0],
            [0.2, 0.4, 1.0],
            [0.2, 0.4, 1.0],
        ]
        .iter()
        .map(|&[r, g, b]| Color { r, g, b, a: 1.0 })
        .collect(),
        ..LinePrimitive::default()
    };
    // The image's corners at depth `d` in front of the camera (along −z).
    let d = 0.1;
    let c = camera.c_mm.max(1e-6);
    let hw = 0.5 * f64::from(camera.width_px) * camera.pixel_mm / c * d;
    let hh = 0.5 * f64::from(camera.height_px) * camera.pixel_mm / c * d;
    let corners = [
        p(-hw, hh, -d),
        p(hw, hh, -d),
        p(hw, -hh, -d),
        p(-hw, -hh, -d),
    ];
    let mut points = Vec::with_capacity(16);
    for k in 0..4 {
        points.push(p(0.0, 0.0, 0.0));
        points.push(corners[k]);
        points.push(corners[k]);
        points.push(corners[(k + 1) % 4]);
    }
    let frustum = LinePrimitive {
        r#type: line_primitive::Type::LineList as i32,
        pose: Some(*pose),
        thickness: 1.5,
        scale_invariant: true,
        points,
        color: color(1.0, 1.0, 0.3, 1.0),
        ..LinePrimitive::default()
    };
    SceneEntity {
        timestamp: Some(timestamp(time_ns)),
        frame_id: FIELD_FRAME.into(),
        id: "camera".into(),
        lines: vec![axes, frustum],
        ..SceneEntity::default()
    }
}

/// The detected targets of a frame drawn on its image downscaled by
/// `scale`: a circle on each (coded: orange, uncoded: green, unidentified:
/// red) and its id beside it. Pixel coordinates (integer = pixel centre)
/// become Foxglove's image coordinates (origin at the top-left corner of
/// the top-left pixel) of the downscaled image.
pub fn image_annotations(targets: &[DetectedTarget], scale: u32, time_ns: u64) -> ImageAnnotations {
    let s = f64::from(scale.max(1));
    let mut circles = Vec::with_capacity(targets.len());
    let mut texts = Vec::with_capacity(targets.len());
    for t in targets {
        let at = Point2 {
            x: (t.col + 0.5) / s,
            y: (t.row + 0.5) / s,
        };
        let [r, g, b] = match (t.id, t.coded) {
            (None, _) => [1.0, 0.2, 0.2],
            (Some(_), true) => CODED,
            (Some(_), false) => [0.2, 0.9, 0.2],
        };
        circles.push(CircleAnnotation {
            timestamp: Some(timestamp(time_ns)),
            position: Some(at),
            diameter: 12.0,
            thickness: 1.5,
            fill_color: color(0.0, 0.0, 0.0, 0.0),
            outline_color: color(r, g, b, 1.0),
            ..CircleAnnotation::default()
        });
        if let Some(id) = t.id {
            texts.push(TextAnnotation {
                timestamp: Some(timestamp(time_ns)),
                position: Some(Point2 {
                    x: at.x + 7.0,
                    y: at.y - 7.0,
                }),
                text: id.to_string(),
                font_size: 12.0,
                text_color: color(r, g, b, 1.0),
                background_color: color(0.0, 0.0, 0.0, 0.5),
                ..TextAnnotation::default()
            });
        }
    }
    ImageAnnotations {
        timestamp: Some(timestamp(time_ns)),
        circles,
        texts,
        ..ImageAnnotations::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn annotations_land_on_the_downscaled_image_with_their_ids() {
        let targets = [
            DetectedTarget {
                id: Some(7),
                col: 399.5,
                row: 3.5,
                coded: true,
            },
            DetectedTarget {
                id: None,
                col: 0.0,
                row: 0.0,
                coded: false,
            },
        ];
        let a = image_annotations(&targets, 4, 1_500_000_000_250);
        assert_eq!(a.circles.len(), 2);
        let c0 = a.circles[0].position.unwrap();
        assert_eq!((c0.x, c0.y), (100.0, 1.0));
        // The centre of the top-left pixel: half a pixel from the corner.
        let c1 = a.circles[1].position.unwrap();
        assert_eq!((c1.x, c1.y), (0.125, 0.125));
        // Only identified targets are labelled.
        assert_eq!(a.texts.len(), 1);
        assert_eq!(a.texts[0].text, "7");
        assert_ne!(a.circles[0].outline_color, a.circles[1].outline_color);
        let t = a.timestamp.unwrap();
        assert_eq!((t.sec(), t.nsec()), (1500, 250));
    }

    #[test]
    fn the_plate_shows_coded_targets_apart() {
        let plate = [
            SceneTarget {
                id: 1,
                position_mm: [100.0, 50.0, 0.0],
                radius_mm: 5.0,
                coded: true,
            },
            SceneTarget {
                id: 101,
                position_mm: [0.0, 0.0, 0.0],
                radius_mm: 2.0,
                coded: false,
            },
        ];
        let e = plate_entity(&plate);
        assert_eq!(e.frame_id, FIELD_FRAME);
        assert_eq!(e.spheres.len(), 2);
        let p = e.spheres[0].pose.as_ref().unwrap().position.unwrap();
        assert_eq!((p.x, p.y), (0.1, 0.05));
        assert_eq!(e.spheres[0].size.unwrap().x, 0.01);
        assert_ne!(e.spheres[0].color, e.spheres[1].color);
        assert_eq!(e.texts.len(), 1);
        assert_eq!(e.texts[0].text, "1");
    }

    #[test]
    fn the_frustum_opens_along_minus_z() {
        let pose = pose_in_metres(&LivePose {
            position_mm: [0.0, 0.0, 1000.0],
            orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
            ..LivePose::default()
        });
        let camera = CameraShape {
            width_px: 1000,
            height_px: 500,
            pixel_mm: 0.01,
            c_mm: 10.0,
        };
        let e = camera_entity(&pose, &camera, 0);
        assert_eq!(e.lines.len(), 2);
        let f = &e.lines[1];
        assert_eq!(f.points.len(), 16);
        // A corner: half the sensor (5 mm × 2.5 mm) over c, at 0.1 m.
        let corner = f.points[1];
        assert!((corner.x + 0.05).abs() < 1e-12 && (corner.y - 0.025).abs() < 1e-12);
        assert_eq!(corner.z, -0.1);
        assert_eq!(f.pose.as_ref().unwrap().position.unwrap().z, 1.0);
    }

    #[test]
    fn the_hand_over_never_waits_and_counts_what_it_drops() {
        let edge = crate::Edge::start(1).unwrap();
        let server = LiveServer::start(
            edge.handle(),
            &LiveOptions {
                address: "127.0.0.1:0".parse().unwrap(),
                image_scale: 4,
                max_clients: 4,
            },
            2,
            16,
            &[],
            CameraShape {
                width_px: 8,
                height_px: 8,
                pixel_mm: 0.01,
                c_mm: 10.0,
            },
        )
        .unwrap();
        assert_ne!(server.local_addr().port(), 0);
        let tx = server.sender();
        assert!(!tx.image_wanted(), "no client, no image wanted");
        // Held by the view: the state is dropped, not waited for.
        {
            let _held = tx.0.state.lock().unwrap();
            assert!(!tx.send_state(|s| s.seq = 1));
        }
        assert_eq!(tx.stats().states_dropped.load(Ordering::Relaxed), 1);
        assert!(tx.send_state(|s| s.seq = 2));
        server.shutdown();
        edge.stop();
    }
}
