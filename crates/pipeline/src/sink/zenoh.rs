//! The Zenoh sink (`[zenoh]`, docs/zenoh.md): the daemon's pose messages,
//! its status and a queryable of the latest pose on a Zenoh session, and
//! with `ros2 = true` the pose as a ROS 2
//! `geometry_msgs/msg/PoseWithCovarianceStamped` that `rmw_zenoh` nodes
//! receive.
//!
//! The session lives on the edge runtime: one task opens it, declares the
//! publishers, the queryable and (for ROS 2) the liveliness tokens, then
//! forwards what the output thread hands it. The output thread never
//! waits: it copies the already-encoded JSON line (and the CDR bytes of
//! the ROS 2 message, encoded into a reused buffer) into a line feed of
//! preallocated buffers (`photopose_stream::edge::line_feed`); when none
//! is free the message is dropped and counted
//! (`photopose_zenoh_*_dropped_total`). Nothing here allocates per frame
//! on the output thread once the buffers have grown to the message size.

use super::{Outgoing, PoseSink};
use crate::config::{Config, Zenoh as Settings};
use crate::metrics::{Counters, ZenohStats};
use crate::run::PipelineError;
use photopose_stream::edge::{line_feed, FeedReceiver, FeedSender};
use photopose_stream::{EdgeHandle, PoseMessage, PoseStatus};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};
use zenoh::Wait;

/// Messages handed from the output thread to the session at most at once.
const FEED_MESSAGES: usize = 256;
/// Initial capacity of a JSON feed buffer (a pose line is about 2 kB).
const LINE_CAPACITY: usize = 4096;
/// Size of the CDR `PoseWithCovarianceStamped` with a frame id of up to
/// 64 bytes (header 4 + stamp 8 + string 4 + 65 + pad + 43 doubles).
const CDR_CAPACITY: usize = 4 + 8 + 4 + 65 + 7 + 43 * 8;
/// How long the start waits for the session to open.
const OPEN_TIMEOUT: Duration = Duration::from_secs(20);

/// The ROS 2 type carried (`rmw_zenoh`'s mangled DDS name).
pub const ROS2_TYPE: &str = "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_";
/// The type hash of `geometry_msgs/msg/PoseWithCovarianceStamped` (REP
/// 2011, `RIHS01_` + SHA-256 of the type description). Computed with the
/// `rosbags` type store's `hash_rihs01` for ROS 2 Jazzy and Kilted (the
/// same for both, and for Humble's definition: the message has not
/// changed); the acceptance test recomputes it.
pub const ROS2_TYPE_HASH: &str =
    "RIHS01_26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e";
/// The publisher's QoS in `rmw_zenoh`'s liveliness token: reliable,
/// volatile, keep last 10, the rest default (empty fields are `rmw_zenoh`'s
/// defaults: reliable, volatile, keep last; only the depth 10 differs from
/// its default 42).
const ROS2_QOS: &str = "::,10:,:,:,,";

/// The key expression `rmw_zenoh` uses for a topic:
/// `<domain>/<topic without its leading '/'>/<type>/<type hash>`.
pub fn ros2_key(domain_id: u32, topic: &str) -> String {
    format!(
        "{domain_id}/{}/{ROS2_TYPE}/{ROS2_TYPE_HASH}",
        topic.trim_start_matches('/')
    )
}

/// The ROS 2 node name of a camera's daemon (`photopose_<camera>`, '-' as
/// '_').
pub fn ros2_node(camera: &str) -> String {
    format!("photopose_{}", camera.replace('-', "_"))
}

/// The liveliness tokens `rmw_zenoh` reads the ROS graph from: the node
/// and its publisher (`@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/
/// <enclave>/<namespace>/<node>[/<topic>/<type>/<hash>/<qos>]`, '/' in
/// names written '%'; enclave and namespace are the root `/`).
pub fn ros2_tokens(domain_id: u32, zid: &str, camera: &str, topic: &str) -> [String; 2] {
    let node = ros2_node(camera);
    let base = |id: u32, kind: &str| format!("@ros2_lv/{domain_id}/{zid}/0/{id}/{kind}/%/%/{node}");
    [
        base(0, "NN"),
        format!(
            "{}/{}/{ROS2_TYPE}/{ROS2_TYPE_HASH}/{ROS2_QOS}",
            base(1, "MP"),
            topic.replace('/', "%")
        ),
    ]
}

/// The publisher's GID: a 128-bit hash of its liveliness token (twox-hash's
/// XXH3-128, low 64 bits then high 64 bits, little-endian), as `rmw_zenoh`
/// derives its GIDs. twox-hash 1.6's XXH3-128 does not match the reference
/// values for every input (the empty one differs), so the GID may differ
/// from the one `rmw_zenoh` would compute; it is stable and unique per
/// token, which is what subscribers use it for.
pub fn ros2_gid(token: &str) -> [u8; 16] {
    let h = twox_hash::xxh3::hash128(token.as_bytes());
    let mut gid = [0u8; 16];
    gid[..8].copy_from_slice(&(h as u64).to_le_bytes());
    gid[8..].copy_from_slice(&((h >> 64) as u64).to_le_bytes());
    gid
}

/// The attachment `rmw_zenoh` expects on every sample: the publisher's
/// sequence number (i64), the source timestamp (i64, ns since the Unix
/// epoch) and the GID (16 bytes), in Zenoh's serialisation format
/// (little-endian integers; the byte array with its length as a LEB128
/// prefix, here one byte 16). Written by hand: 33 fixed bytes. This is
/// the positional layout of `rmw_zenoh` 0.2.4 and later on Jazzy (and of
/// Kilted's); Jazzy releases before 0.2.4 wrote a key name before each
/// field and do not read it.
pub fn ros2_attachment(seq: i64, source_ns: i64, gid: &[u8; 16]) -> [u8; 33] {
    let mut a = [0u8; 33];
    a[..8].copy_from_slice(&seq.to_le_bytes());
    a[8..16].copy_from_slice(&source_ns.to_le_bytes());
    a[16] = 16;
    a[17..].copy_from_slice(gid);
    a
}

/// Encodes an `ok` message as a `geometry_msgs/msg/PoseWithCovarianceStamped`
/// in CDR (little-endian, 4-byte encapsulation header) into `buf`, with
/// docs/streams.md's mapping: stamp = exposure UTC (else the hand-over),
/// `header.frame_id` = the message's frame, position in m, orientation of
/// the camera's ROS optical frame, covariance in m and rad about the
/// field's axes. `false` (buf left empty) for a message without a pose.
///
/// Hand-written rather than through a serialiser: it runs on the output
/// thread for every pose and must not allocate (the message is fixed
/// apart from the frame id).
pub fn encode_ros2_pose(message: &PoseMessage, buf: &mut Vec<u8>) -> bool {
    buf.clear();
    let (Some(pose), PoseStatus::Ok) = (&message.pose, message.status) else {
        return false;
    };
    let Some(ns) = message
        .time
        .exposure_utc_ns
        .or(message.time.handover_utc_ns)
    else {
        return false;
    };
    // Encapsulation: CDR, little-endian; alignment counts from after it.
    buf.extend_from_slice(&[0, 1, 0, 0]);
    let sec = i32::try_from(ns / 1_000_000_000).unwrap_or(i32::MAX);
    buf.extend_from_slice(&sec.to_le_bytes());
    buf.extend_from_slice(&((ns % 1_000_000_000) as u32).to_le_bytes());
    let frame = message.frame_id.as_bytes();
    buf.extend_from_slice(&(frame.len() as u32 + 1).to_le_bytes());
    buf.extend_from_slice(frame);
    buf.push(0);
    while !(buf.len() - 4).is_multiple_of(8) {
        buf.push(0);
    }
    let mut f64s = |v: &[f64]| {
        for x in v {
            buf.extend_from_slice(&x.to_le_bytes());
        }
    };
    let [px, py, pz] = pose.position_mm;
    f64s(&[px / 1000.0, py / 1000.0, pz / 1000.0]);
    // The optical frame (x right, y down, z forward) is the camera frame
    // turned 180° about its x axis: q ⊗ (1, 0, 0, 0) = (w, z, −y, −x).
    let [x, y, z, w] = pose.quaternion_xyzw;
    f64s(&[w, z, -y, -x]);
    // C_ros = D·C·D, D = diag(10⁻³, 10⁻³, 10⁻³, −1, −1, −1): metres, and
    // the camera's rotation φ = −ω about the field's axes.
    const D: [f64; 6] = [1e-3, 1e-3, 1e-3, -1.0, -1.0, -1.0];
    for (k, c) in pose.covariance.iter().enumerate() {
        f64s(&[D[k / 6] * c * D[k % 6]]);
    }
    true
}

/// The Zenoh publisher of one daemon.
pub struct ZenohSink {
    poses: Option<FeedSender>,
    ros2: Option<FeedSender>,
    cdr: Vec<u8>,
    stats: Arc<ZenohStats>,
    done: Option<std::sync::mpsc::Receiver<()>>,
}

impl std::fmt::Debug for ZenohSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohSink").finish_non_exhaustive()
    }
}

/// What the session task owns.
struct Session {
    settings: Settings,
    camera: String,
    poses: FeedReceiver,
    ros2: Option<FeedReceiver>,
    stats: Arc<ZenohStats>,
    counters: Arc<Counters>,
    summary: String,
}

fn zenoh_config(s: &Settings) -> Result<zenoh::Config, String> {
    let mut c = zenoh::Config::default();
    let list = |l: &[String]| {
        let quoted: Vec<String> = l.iter().map(|e| format!("\"{e}\"")).collect();
        format!("[{}]", quoted.join(","))
    };
    for (key, value) in [
        ("mode", format!("\"{}\"", s.mode.name())),
        ("connect/endpoints", list(&s.connect)),
        ("listen/endpoints", list(&s.listen)),
        (
            "scouting/multicast/enabled",
            s.scouting_multicast.to_string(),
        ),
    ] {
        c.insert_json5(key, &value)
            .map_err(|e| format!("zenoh configuration `{key}` = {value}: {e}"))?;
    }
    Ok(c)
}

impl ZenohSink {
    /// Opens the session of `config.zenoh` on `edge` and declares its
    /// publishers and queryable; waits (at most `wait_for_subscriber`) for
    /// a subscriber of the pose key when asked. `counters`: the pipeline's,
    /// for the status.
    pub fn start(
        config: &Config,
        edge: &EdgeHandle,
        stats: Arc<ZenohStats>,
        counters: Arc<Counters>,
    ) -> Result<ZenohSink, PipelineError> {
        let settings = config.zenoh.clone();
        let zenoh_config = zenoh_config(&settings).map_err(|why| PipelineError::Zenoh { why })?;
        let (pose_tx, pose_rx) = line_feed(FEED_MESSAGES, LINE_CAPACITY);
        let (ros_tx, ros_rx) = if settings.ros2 {
            let (t, r) = line_feed(FEED_MESSAGES, CDR_CAPACITY);
            (Some(t), Some(r))
        } else {
            (None, None)
        };
        let summary = summary(config);
        let session = Session {
            settings,
            camera: config.camera_id.clone(),
            poses: pose_rx,
            ros2: ros_rx,
            stats: Arc::clone(&stats),
            counters,
            summary,
        };
        let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel::<Result<(), String>>(1);
        let (done_tx, done_rx) = std::sync::mpsc::sync_channel::<()>(1);
        let stop = edge.stop_token();
        edge.spawn(async move {
            session.run(zenoh_config, ready_tx, stop).await;
            let _ = done_tx.send(());
        });
        let wait = OPEN_TIMEOUT + config.zenoh.wait_for_subscriber;
        match ready_rx.recv_timeout(wait) {
            Ok(Ok(())) => {}
            Ok(Err(why)) => return Err(PipelineError::Zenoh { why }),
            Err(_) => {
                return Err(PipelineError::Zenoh {
                    why: format!("the session did not open within {} s", wait.as_secs()),
                })
            }
        }
        Ok(ZenohSink {
            poses: Some(pose_tx),
            ros2: ros_tx,
            cdr: Vec::with_capacity(CDR_CAPACITY),
            stats,
            done: Some(done_rx),
        })
    }
}

/// The configuration summary the queryable answers with (JSON).
fn summary(config: &Config) -> String {
    let z = &config.zenoh;
    let source = match &config.source {
        crate::config::Source::Synthetic(_) => "synthetic",
        crate::config::Source::Replay(_) => "replay",
        #[cfg(feature = "gige")]
        crate::config::Source::Gige(_) => "gige",
        #[cfg(feature = "gentl")]
        crate::config::Source::Gentl(_) => "gentl",
    };
    serde_json::json!({
        "camera": config.camera_id,
        "version": env!("CARGO_PKG_VERSION"),
        "source": source,
        "workers": config.workers,
        "tracking": config.tracking.enabled,
        "rsi": config.rsi.is_some(),
        "zenoh": {
            "mode": z.mode.name(),
            "pose_key": z.pose_key,
            "status_key": z.status_key,
            "query_key": z.query_key,
            "ros2": z.ros2.then(|| serde_json::json!({
                "domain_id": z.ros2_domain_id,
                "topic": z.ros2_topic,
                "key": ros2_key(z.ros2_domain_id, &z.ros2_topic),
                "type": "geometry_msgs/msg/PoseWithCovarianceStamped",
                "type_hash": ROS2_TYPE_HASH,
            })),
        },
    })
    .to_string()
}

/// Waits until the ROS 2 feed has a message or is closed; never without one.
async fn ros2_ready(feed: &Option<FeedReceiver>) {
    match feed {
        Some(r) => r.ready().await,
        None => std::future::pending().await,
    }
}

fn unix_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

impl Session {
    async fn run(
        self,
        config: zenoh::Config,
        ready: std::sync::mpsc::SyncSender<Result<(), String>>,
        stop: tokio_util::sync::CancellationToken,
    ) {
        let s = &self.settings;
        let fail = |what: &str, e: zenoh::Error| format!("{what}: {e}");
        let opened =
            async {
                let session = zenoh::open(config)
                    .await
                    .map_err(|e| fail("cannot open the Zenoh session", e))?;
                let poses = session
                    .declare_publisher(s.pose_key.clone())
                    .congestion_control(zenoh::qos::CongestionControl::Block)
                    .encoding(zenoh::bytes::Encoding::APPLICATION_JSON)
                    .await
                    .map_err(|e| fail("cannot declare the pose publisher", e))?;
                let status = session
                    .declare_publisher(s.status_key.clone())
                    .encoding(zenoh::bytes::Encoding::APPLICATION_JSON)
                    .await
                    .map_err(|e| fail("cannot declare the status publisher", e))?;
                let queryable = session
                    .declare_queryable(s.query_key.clone())
                    .await
                    .map_err(|e| fail("cannot declare the queryable", e))?;
                let ros2 =
                    if s.ros2 {
                        let publisher = session
                            .declare_publisher(ros2_key(s.ros2_domain_id, &s.ros2_topic))
                            .congestion_control(zenoh::qos::CongestionControl::Block)
                            .await
                            .map_err(|e| fail("cannot declare the ROS 2 publisher", e))?;
                        let zid = session.zid().to_string();
                        let [node, pub_token] =
                            ros2_tokens(s.ros2_domain_id, &zid, &self.camera, &s.ros2_topic);
                        let gid = ros2_gid(&pub_token);
                        let mut tokens = Vec::new();
                        for t in [node, pub_token] {
                            tokens.push(session.liveliness().declare_token(t).await.map_err(
                                |e| fail("cannot declare the ROS 2 liveliness token", e),
                            )?);
                        }
                        Some((publisher, gid, tokens))
                    } else {
                        None
                    };
                Ok::<_, String>((session, poses, status, queryable, ros2))
            }
            .await;
        let (session, poses, status, queryable, ros2) = match opened {
            Ok(o) => o,
            Err(why) => {
                let _ = ready.send(Err(why));
                return;
            }
        };
        if !s.wait_for_subscriber.is_zero() {
            let deadline = tokio::time::Instant::now() + s.wait_for_subscriber;
            loop {
                let matched = poses.matching_status().await.is_ok_and(|m| m.matching());
                if matched || tokio::time::Instant::now() >= deadline {
                    if !matched {
                        tracing::warn!(
                            key = %s.pose_key,
                            "no Zenoh subscriber of the poses after zenoh.wait_for_subscriber_ms; starting anyway"
                        );
                    }
                    break;
                }
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
        }
        tracing::info!(
            zid = %session.zid(),
            pose_key = %s.pose_key,
            ros2 = s.ros2,
            "Zenoh session open"
        );
        let _ = ready.send(Ok(()));
        let mut latest: Vec<u8> = Vec::with_capacity(LINE_CAPACITY);
        let mut ticks = tokio::time::interval(s.status_period);
        let mut rates = Rates::new(&self.counters);
        let mut ros_seq = 0i64;
        loop {
            tokio::select! {
                _ = stop.cancelled() => break,
                _ = self.poses.ready() => {}
                _ = ros2_ready(&self.ros2) => {}
                _ = ticks.tick() => {
                    let text = self.status(&mut rates);
                    match status.put(text).await {
                        Ok(()) => self.stats.statuses.inc(),
                        Err(_) => self.stats.put_errors.inc(),
                    }
                }
                q = queryable.recv_async() => {
                    let Ok(query) = q else { break };
                    let pose = match std::str::from_utf8(&latest) {
                        Ok(t) if !t.trim().is_empty() => t.trim(),
                        _ => "null",
                    };
                    let reply = format!("{{\"pose\":{pose},\"config\":{}}}", self.summary);
                    if query
                        .reply(s.query_key.clone(), reply)
                        .encoding(zenoh::bytes::Encoding::APPLICATION_JSON)
                        .await
                        .is_ok()
                    {
                        self.stats.queries.inc();
                    }
                }
            }
            // The puts may wait (congestion control "block") when the
            // network is behind: off the tokio worker, so the other edges
            // go on; the output thread meanwhile drops and counts.
            tokio::task::block_in_place(|| {
                while let Some(line) = self.poses.take() {
                    latest.clear();
                    latest.extend_from_slice(&line);
                    let body = line.strip_suffix(b"\n").unwrap_or(&line);
                    match poses.put(body).wait() {
                        Ok(()) => self.stats.poses_published.inc(),
                        Err(_) => self.stats.put_errors.inc(),
                    }
                    self.poses.give_back(line);
                }
                if let (Some(feed), Some((publisher, gid, _))) = (&self.ros2, &ros2) {
                    while let Some(cdr) = feed.take() {
                        ros_seq += 1;
                        let attachment = ros2_attachment(ros_seq, unix_ns(), gid);
                        match publisher.put(&cdr[..]).attachment(attachment).wait() {
                            Ok(()) => self.stats.ros2_published.inc(),
                            Err(_) => self.stats.put_errors.inc(),
                        }
                        feed.give_back(cdr);
                    }
                }
            });
            if self.poses.is_closed() && self.ros2.as_ref().is_none_or(|r| r.is_closed()) {
                // The output thread finished: a last status, then close.
                let text = self.status(&mut rates);
                if status.put(text).await.is_ok() {
                    self.stats.statuses.inc();
                }
                break;
            }
        }
        drop(ros2);
        let _ = session.close().await;
    }

    /// The status message (JSON).
    fn status(&self, rates: &mut Rates) -> String {
        let c = &self.counters;
        let (poses_per_s, frames_per_s) = rates.update(c);
        let camera = match &c.source {
            Some(s) if s.connected.load(Ordering::Relaxed) => "connected",
            Some(_) => "absent",
            None if c.last_frame_age_seconds().is_some_and(|a| a < 2.0) => "frames arriving",
            None => "no frames",
        };
        let rsi = match &c.rsi {
            None => "off",
            Some(s) => photopose_rsi::LawStatus::from_code(s.status.load(Ordering::Relaxed))
                .map_or("waiting for the controller", |st| st.name()),
        };
        serde_json::json!({
            "schema": "photopose.status.v1",
            "camera": self.camera,
            "state": camera,
            "rsi": rsi,
            "poses_per_s": poses_per_s,
            "frames_per_s": frames_per_s,
            "frames_in": c.frames_in.get(),
            "frames_dropped": c.frames_dropped.get(),
            "poses_ok": c.poses_ok.get(),
            "poses_failed": c.poses_failed.get(),
            "last_pose_age_s": c.last_pose_age_seconds(),
            "zenoh": {
                "poses_published": self.stats.poses_published.get(),
                "poses_dropped": self.stats.poses_dropped.get(),
                "ros2_published": self.stats.ros2_published.get(),
                "ros2_dropped": self.stats.ros2_dropped.get(),
            },
            "time_utc_ns": unix_ns(),
        })
        .to_string()
    }
}

/// Poses and frames per second between two status messages.
struct Rates {
    at: Instant,
    poses: u64,
    frames: u64,
}

impl Rates {
    fn new(c: &Counters) -> Rates {
        Rates {
            at: Instant::now(),
            poses: c.poses_ok.get(),
            frames: c.frames_in.get(),
        }
    }

    fn update(&mut self, c: &Counters) -> (f64, f64) {
        let now = Instant::now();
        let secs = now.duration_since(self.at).as_secs_f64().max(1e-3);
        let (poses, frames) = (c.poses_ok.get(), c.frames_in.get());
        let rates = (
            (poses - self.poses) as f64 / secs,
            (frames - self.frames) as f64 / secs,
        );
        (self.at, self.poses, self.frames) = (now, poses, frames);
        rates
    }
}

impl PoseSink for ZenohSink {
    fn name(&self) -> &'static str {
        "zenoh"
    }

    fn publish(&mut self, out: &Outgoing<'_>) {
        if let Some(feed) = &self.poses {
            if !feed.send(out.line) {
                self.stats.poses_dropped.inc();
            }
        }
        if let Some(feed) = &self.ros2 {
            if out.result.is_some()
                && encode_ros2_pose(out.message, &mut self.cdr)
                && !feed.send(&self.cdr)
            {
                self.stats.ros2_dropped.inc();
            }
        }
    }

    fn finish(&mut self) {
        // Closing the feeds lets the session task put what is waiting, a
        // last status, and close the session.
        self.poses.take();
        self.ros2.take();
        if let Some(done) = self.done.take() {
            let _ = done.recv_timeout(Duration::from_secs(2));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use photopose_stream::PoseEstimate;

    fn message() -> PoseMessage {
        let mut m = PoseMessage::new(&Arc::from("cell_a"), 7, PoseStatus::Ok);
        m.time.exposure_utc_ns = Some(1_700_000_000_123_456_789);
        let mut covariance = [0.0; 36];
        for (k, c) in covariance.iter_mut().enumerate() {
            *c = (k as f64 + 1.0) * 1e-3;
        }
        m.pose = Some(PoseEstimate {
            position_mm: [100.0, -20.0, 1500.0],
            quaternion_xyzw: [0.1, 0.2, 0.3, (1.0f64 - 0.14).sqrt()],
            rotation_field_to_camera: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            covariance,
            covariance_order: photopose_stream::message::COVARIANCE_ORDER,
            std_position_mm: [0.01; 3],
            std_rotation_deg: [0.001; 3],
            sigma0_px: 0.02,
            n_targets: 40,
        });
        m
    }

    fn f64_at(b: &[u8], at: usize) -> f64 {
        f64::from_le_bytes(b[at..at + 8].try_into().unwrap())
    }

    #[test]
    fn the_cdr_message_has_the_layout_of_pose_with_covariance_stamped() {
        let m = message();
        let mut buf = Vec::with_capacity(CDR_CAPACITY);
        assert!(encode_ros2_pose(&m, &mut buf));
        assert_eq!(&buf[..4], &[0, 1, 0, 0]);
        assert_eq!(
            i32::from_le_bytes(buf[4..8].try_into().unwrap()),
            1_700_000_000
        );
        assert_eq!(
            u32::from_le_bytes(buf[8..12].try_into().unwrap()),
            123_456_789
        );
        let n = u32::from_le_bytes(buf[12..16].try_into().unwrap()) as usize;
        assert_eq!(&buf[16..16 + n], b"field\0");
        // Doubles aligned on 8 from the end of the encapsulation header.
        let first = 16 + n + (8 - (16 + n - 4) % 8) % 8;
        assert_eq!((first - 4) % 8, 0);
        assert_eq!(buf.len(), first + 43 * 8);
        assert_eq!(f64_at(&buf, first + 16), 1.5);
        // (w, z, −y, −x).
        assert_eq!(f64_at(&buf, first + 24), (1.0f64 - 0.14).sqrt());
        assert_eq!(f64_at(&buf, first + 40), -0.2);
        // Position–position × 10⁻⁶, position–rotation × −10⁻³.
        let cov = first + 56;
        assert!((f64_at(&buf, cov) - 1e-9).abs() < 1e-21);
        assert!((f64_at(&buf, cov + 3 * 8) + 4e-6).abs() < 1e-18);
        assert!((f64_at(&buf, cov + 35 * 8) - 36e-3).abs() < 1e-15);
        // No allocation once warm: the buffer's capacity suffices.
        assert!(buf.capacity() <= CDR_CAPACITY);
        let mut stale = m.clone();
        stale.status = PoseStatus::Stale;
        assert!(!encode_ros2_pose(&stale, &mut buf) && buf.is_empty());
    }

    #[test]
    fn the_ros2_names_follow_rmw_zenoh() {
        assert_eq!(
            ros2_key(3, "/photopose/cell_a/pose"),
            format!("3/photopose/cell_a/pose/{ROS2_TYPE}/{ROS2_TYPE_HASH}")
        );
        let [node, publisher] = ros2_tokens(0, "abc123", "cell-a", "/photopose/cell_a/pose");
        assert_eq!(node, "@ros2_lv/0/abc123/0/0/NN/%/%/photopose_cell_a");
        assert_eq!(
            publisher,
            format!(
                "@ros2_lv/0/abc123/0/1/MP/%/%/photopose_cell_a/%photopose%cell_a%pose/\
                 {ROS2_TYPE}/{ROS2_TYPE_HASH}/::,10:,:,:,,"
            )
        );
        let a = ros2_attachment(5, 9, &[7; 16]);
        assert_eq!(&a[..8], &5i64.to_le_bytes());
        assert_eq!((a[16], a[32]), (16, 7));
        // The GID: stable per token, distinct between tokens.
        assert_eq!(ros2_gid(&publisher), ros2_gid(&publisher));
        assert_ne!(ros2_gid(&publisher), ros2_gid(&node));
    }
}
