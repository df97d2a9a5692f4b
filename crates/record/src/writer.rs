//! The recording writer: frames as `foxglove.RawImage`, poses as
//! `foxglove.PoseInFrame` plus the full pose message in JSON, attachments
//! and a metadata record, in compressed MCAP chunks. The schemas of the
//! Foxglove types come from the `foxglove` crate (its published protobuf
//! descriptors); only the pose message's JSON Schema is ours.

use crate::{
    FrameMeta, RecordError, ANNOTATIONS_TOPIC, FRAME_TIMES_SCHEMA, FRAME_TIMES_TOPIC, IMAGE_TOPIC,
    MESSAGE_TOPIC, POSE_TOPIC, RSI_SCHEMA, RSI_TOPIC,
};
use foxglove::messages::{
    points_annotation, Color, ImageAnnotations, Point2, PointsAnnotation, TextAnnotation,
};
use foxglove::schemas::{Pose, PoseInFrame, Quaternion, RawImage, Timestamp, Vector3};
use foxglove::Encode;
use photopose_frame::{Image, Pixels};
use std::collections::BTreeMap;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// The chunk compression of a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compression {
    /// Zstandard (the default: the smaller files).
    #[default]
    Zstd,
    /// LZ4 (faster, larger).
    Lz4,
    /// No compression.
    None,
}

impl Compression {
    /// The name in configuration files (`zstd`, `lz4`, `none`).
    pub fn name(self) -> &'static str {
        match self {
            Compression::Zstd => "zstd",
            Compression::Lz4 => "lz4",
            Compression::None => "none",
        }
    }

    /// The compression of a configuration name.
    pub fn from_name(name: &str) -> Option<Compression> {
        match name {
            "zstd" => Some(Compression::Zstd),
            "lz4" => Some(Compression::Lz4),
            "none" => Some(Compression::None),
            _ => None,
        }
    }

    fn mcap(self) -> Option<mcap::Compression> {
        match self {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        }
    }
}

/// A file stored in the recording (camera, field, configuration).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Attachment {
    /// Its name (the file's name).
    pub name: String,
    /// Its media type (`text/plain`, `application/toml`, …).
    pub media_type: String,
    /// Its bytes.
    pub data: Vec<u8>,
}

/// How a recording is written.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RecordOptions {
    /// Chunk compression.
    pub compression: Compression,
    /// Files stored with the recording.
    pub attachments: Vec<Attachment>,
    /// The `photopose` metadata record (version, host, start …).
    pub metadata: BTreeMap<String, String>,
}

/// One pose result to record.
#[derive(Debug, Clone, Copy)]
pub struct PoseRecord<'a> {
    /// The frame's sequence number.
    pub seq: u64,
    /// The frame's camera time, ns.
    pub camera_time_ns: u64,
    /// The frame's host time, ns since the Unix epoch.
    pub host_time_ns: u64,
    /// The camera's projection centre in the field (mm) and its rotation
    /// (quaternion `w, x, y, z`), when the frame has a pose.
    pub pose: Option<([f64; 3], [f64; 4])>,
    /// The full pose message, one JSON object (a trailing newline is
    /// dropped).
    pub json: &'a [u8],
}

/// One identified target of a frame, drawn as an image annotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetMark {
    /// The target's id in the field.
    pub id: u64,
    /// Coded (id read from its ring) or uncoded (identified by projection).
    pub coded: bool,
    /// The image of its centre, column, pixels (origin at the centre of
    /// the top-left pixel).
    pub col_px: f64,
    /// The image of its centre, row, pixels.
    pub row_px: f64,
    /// Used by the final adjustment (not rejected).
    pub used: bool,
}

/// One controller cycle of the RSI server, as recorded on [`RSI_TOPIC`]
/// (JSON; the schema is `docs/schema/rsi-cycle.schema.json`, stored in
/// the file). Poses are `X, Y, Z` mm and `A, B, C` deg.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RsiCycle {
    /// The controller's interpolation counter.
    pub ipoc: u64,
    /// Arrival of the controller's datagram, ns since the Unix epoch.
    pub arrival_utc_ns: u64,
    /// Arrival on the host's `CLOCK_MONOTONIC`, ns.
    pub arrival_mono_ns: u64,
    /// `RIst`, the actual TCP pose, when sent.
    pub rist_xyzabc: Option<[f64; 6]>,
    /// `RSol`, the commanded TCP pose, when sent.
    pub rsol_xyzabc: Option<[f64; 6]>,
    /// The controller's late-reply count, when sent.
    pub delay: Option<u64>,
    /// The correction written into the reply.
    pub correction_sent_xyzabc: [f64; 6],
    /// The total correction in effect after the cycle.
    pub correction_total_xyzabc: [f64; 6],
    /// The error of the measurement used this cycle (correction frame),
    /// when a new one was used.
    pub error_xyzabc: Option<[f64; 6]>,
    /// The correction law's state (`tracking`, `measure_only`,
    /// `stale_too_old`, …).
    pub state: &'static str,
    /// The slew limit cut this cycle's step.
    pub slew_limited: bool,
    /// The clamp cut the total correction.
    pub clamped: bool,
}

/// The JSON Schema of the pose message (`photopose.pose.v2`), the
/// repository's one copy (`docs/schema/pose-message.v2.json`).
const POSE_MESSAGE_SCHEMA: &str = include_str!("../../../docs/schema/pose-message.v2.json");

/// A file writer that knows how far it has written (for rotation by size).
struct Counted {
    file: BufWriter<std::fs::File>,
    end: Arc<AtomicU64>,
    at: u64,
}

impl Write for Counted {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.file.write(buf)?;
        self.at += n as u64;
        self.end.fetch_max(self.at, Ordering::Relaxed);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl Seek for Counted {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.at = self.file.seek(pos)?;
        self.end.fetch_max(self.at, Ordering::Relaxed);
        Ok(self.at)
    }
}

/// Writes a recording.
pub struct Recorder {
    path: String,
    writer: mcap::Writer<Counted>,
    written: Arc<AtomicU64>,
    image: Option<u16>,
    pose: u16,
    message: u16,
    times: Option<u16>,
    annotations: Option<u16>,
    rsi: Option<u16>,
    buf: Vec<u8>,
    frames: u64,
    poses: u64,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("path", &self.path)
            .field("frames", &self.frames)
            .field("poses", &self.poses)
            .finish()
    }
}

fn schema_of<T: Encode>() -> foxglove::Schema {
    T::get_schema().expect("the foxglove schema types carry their schema")
}

impl Recorder {
    /// Creates (or replaces) the recording at `path`, zstd-compressed, no
    /// attachments.
    pub fn create(path: &Path) -> Result<Self, RecordError> {
        Self::create_with(path, &RecordOptions::default())
    }

    /// Creates (or replaces) the recording at `path` with `options`.
    pub fn create_with(path: &Path, options: &RecordOptions) -> Result<Self, RecordError> {
        let name = path.display().to_string();
        let file = std::fs::File::create(path).map_err(|source| RecordError::Io {
            path: name.clone(),
            source,
        })?;
        let mcap_err = |e: mcap::McapError| RecordError::Mcap {
            path: name.clone(),
            message: e.to_string(),
        };
        let written = Arc::new(AtomicU64::new(0));
        let mut writer = mcap::WriteOptions::new()
            .compression(options.compression.mcap())
            .profile("")
            .library(concat!("photopose-record ", env!("CARGO_PKG_VERSION")))
            .create(Counted {
                file: BufWriter::new(file),
                end: written.clone(),
                at: 0,
            })
            .map_err(mcap_err)?;
        let pose_schema = schema_of::<PoseInFrame>();
        let id = writer
            .add_schema(&pose_schema.name, &pose_schema.encoding, &pose_schema.data)
            .map_err(mcap_err)?;
        let pose = writer
            .add_channel(
                id,
                POSE_TOPIC,
                &PoseInFrame::get_message_encoding(),
                &BTreeMap::new(),
            )
            .map_err(mcap_err)?;
        let id = writer
            .add_schema(
                "photopose.PoseMessage",
                "jsonschema",
                POSE_MESSAGE_SCHEMA.as_bytes(),
            )
            .map_err(mcap_err)?;
        let message = writer
            .add_channel(id, MESSAGE_TOPIC, "json", &BTreeMap::new())
            .map_err(mcap_err)?;
        for a in &options.attachments {
            writer
                .attach(&mcap::Attachment {
                    log_time: 0,
                    create_time: 0,
                    name: a.name.clone(),
                    media_type: a.media_type.clone(),
                    data: std::borrow::Cow::Borrowed(&a.data),
                })
                .map_err(mcap_err)?;
        }
        if !options.metadata.is_empty() {
            writer
                .write_metadata(&mcap::records::Metadata {
                    name: "photopose".into(),
                    metadata: options.metadata.clone(),
                })
                .map_err(mcap_err)?;
        }
        Ok(Recorder {
            path: name,
            writer,
            written,
            image: None,
            pose,
            message,
            times: None,
            annotations: None,
            rsi: None,
            buf: Vec::new(),
            frames: 0,
            poses: 0,
        })
    }

    fn mcap_err(&self, e: mcap::McapError) -> RecordError {
        RecordError::Mcap {
            path: self.path.clone(),
            message: e.to_string(),
        }
    }

    /// Encodes a protobuf message into the write buffer; `what` names it
    /// in the error.
    fn encode(
        &mut self,
        message: &impl Encode,
        what: impl FnOnce() -> String,
    ) -> Result<(), RecordError> {
        self.buf.clear();
        message
            .encode(&mut self.buf)
            .map_err(|e| RecordError::Mcap {
                path: self.path.clone(),
                message: format!("cannot encode {}: {e}", what()),
            })
    }

    /// Serialises a JSON value into the write buffer; `what` names it in
    /// the error.
    fn encode_json(
        &mut self,
        value: &impl serde::Serialize,
        what: impl FnOnce() -> String,
    ) -> Result<(), RecordError> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, value).map_err(|e| RecordError::Mcap {
            path: self.path.clone(),
            message: format!("cannot encode {}: {e}", what()),
        })
    }

    /// Writes the write buffer as one message on `channel`: sequence, log
    /// and publish time as given (the sequence's low 32 bits).
    fn write_buf(
        &mut self,
        channel: u16,
        sequence: u64,
        log_time: u64,
        publish_time: u64,
    ) -> Result<(), RecordError> {
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: sequence as u32,
            log_time,
            publish_time,
        };
        self.writer
            .write_to_known_channel(&header, &self.buf)
            .map_err(|e| self.mcap_err(e))
    }

    /// Bytes written to the file so far (compressed chunks as they close).
    pub fn bytes_written(&self) -> u64 {
        self.written.load(Ordering::Relaxed)
    }

    /// Frames written.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// The file.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// Appends one frame.
    pub fn write(&mut self, meta: FrameMeta, image: &Image) -> Result<(), RecordError> {
        match image.pixels() {
            Pixels::Mono8(p) => {
                self.write_pixels(meta, image.width(), image.height(), image.max_value(), 1, p)
            }
            Pixels::Mono16(p) => {
                let mut bytes = Vec::with_capacity(p.len() * 2);
                for v in p {
                    bytes.extend_from_slice(&v.to_le_bytes());
                }
                self.write_pixels(
                    meta,
                    image.width(),
                    image.height(),
                    image.max_value(),
                    2,
                    &bytes,
                )
            }
        }
    }

    /// Appends one frame given as rows of little-endian pixels of
    /// `bytes_per_pixel` (1: mono8, 2: mono16) bytes; `max_value` is the
    /// saturation level (stored once, in the image channel's metadata).
    pub fn write_pixels(
        &mut self,
        meta: FrameMeta,
        width: u32,
        height: u32,
        max_value: u16,
        bytes_per_pixel: u8,
        pixels: &[u8],
    ) -> Result<(), RecordError> {
        let channel = match self.image {
            Some(c) => c,
            None => {
                let schema = schema_of::<RawImage>();
                let id = self
                    .writer
                    .add_schema(&schema.name, &schema.encoding, &schema.data)
                    .map_err(|e| self.mcap_err(e))?;
                let metadata = BTreeMap::from([("max_value".to_string(), max_value.to_string())]);
                let c = self
                    .writer
                    .add_channel(
                        id,
                        IMAGE_TOPIC,
                        &RawImage::get_message_encoding(),
                        &metadata,
                    )
                    .map_err(|e| self.mcap_err(e))?;
                self.image = Some(c);
                c
            }
        };
        self.write_frame_times(&meta)?;
        let message = RawImage {
            timestamp: Some(timestamp(
                meta.exposure_utc_ns().unwrap_or(meta.host_time_ns),
            )),
            frame_id: "camera".into(),
            width,
            height,
            encoding: if bytes_per_pixel == 2 {
                "mono16"
            } else {
                "mono8"
            }
            .into(),
            step: width * u32::from(bytes_per_pixel),
            data: foxglove::bytes::Bytes::copy_from_slice(pixels),
        };
        self.encode(&message, || format!("frame {}", meta.seq))?;
        self.write_buf(channel, meta.seq, meta.host_time_ns, meta.camera_time_ns)?;
        self.frames += 1;
        Ok(())
    }

    /// A channel made when first used, with its schema.
    #[allow(clippy::too_many_arguments)]
    fn lazy_channel(
        &mut self,
        which: fn(&mut Recorder) -> &mut Option<u16>,
        schema_name: &str,
        schema_encoding: &str,
        schema: &[u8],
        topic: &str,
        message_encoding: &str,
    ) -> Result<u16, RecordError> {
        if let Some(c) = *which(self) {
            return Ok(c);
        }
        let id = self
            .writer
            .add_schema(schema_name, schema_encoding, schema)
            .map_err(|e| self.mcap_err(e))?;
        let c = self
            .writer
            .add_channel(id, topic, message_encoding, &BTreeMap::new())
            .map_err(|e| self.mcap_err(e))?;
        *which(self) = Some(c);
        Ok(c)
    }

    /// The frame's identity and times on [`FRAME_TIMES_TOPIC`] (written
    /// just before its image, with the same log time).
    fn write_frame_times(&mut self, meta: &FrameMeta) -> Result<(), RecordError> {
        let channel = self.lazy_channel(
            |r| &mut r.times,
            "photopose.FrameTimes",
            "jsonschema",
            FRAME_TIMES_SCHEMA.as_bytes(),
            FRAME_TIMES_TOPIC,
            "json",
        )?;
        let json = serde_json::json!({
            "seq": meta.seq,
            "camera_frame_id": meta.camera_frame_id,
            "camera_time_ns": meta.camera_time_ns,
            "host_time_ns": meta.host_time_ns,
            "host_mono_ns": meta.host_mono_ns,
            "exposure_mono_ns": meta.exposure_mono_ns,
            "exposure_sigma_ns": meta.exposure_sigma_ns,
            "exposure_ns": meta.exposure_ns,
            "exposure_utc_ns": meta.exposure_utc_ns(),
        });
        self.encode_json(&json, || format!("the times of frame {}", meta.seq))?;
        self.write_buf(channel, meta.seq, meta.host_time_ns, meta.camera_time_ns)
    }

    /// Appends the identified targets of frame `meta` as one
    /// `foxglove.ImageAnnotations` on [`ANNOTATIONS_TOPIC`], with the
    /// frame's times: a point per target (coded green, uncoded orange; a
    /// target the adjustment rejected red) and its id as text beside it
    /// (`c` before the id of a coded target).
    pub fn write_targets(
        &mut self,
        meta: &FrameMeta,
        targets: &[TargetMark],
    ) -> Result<(), RecordError> {
        let channel = {
            let schema = schema_of::<ImageAnnotations>();
            self.lazy_channel(
                |r| &mut r.annotations,
                &schema.name,
                &schema.encoding,
                &schema.data,
                ANNOTATIONS_TOPIC,
                &ImageAnnotations::get_message_encoding(),
            )?
        };
        let stamp = timestamp(meta.exposure_utc_ns().unwrap_or(meta.host_time_ns));
        let color = |r: f64, g: f64, b: f64| Color { r, g, b, a: 1.0 };
        let coded = color(0.1, 0.9, 0.2);
        let uncoded = color(1.0, 0.6, 0.0);
        let rejected = color(1.0, 0.1, 0.1);
        let points = |want_coded: bool, fill: Color| PointsAnnotation {
            timestamp: Some(stamp),
            r#type: points_annotation::Type::Points as i32,
            points: targets
                .iter()
                .filter(|t| t.coded == want_coded)
                .map(|t| Point2 {
                    x: t.col_px,
                    y: t.row_px,
                })
                .collect(),
            outline_color: Some(fill),
            outline_colors: targets
                .iter()
                .filter(|t| t.coded == want_coded)
                .map(|t| if t.used { fill } else { rejected })
                .collect(),
            fill_color: Some(fill),
            thickness: if want_coded { 6.0 } else { 4.0 },
            metadata: Vec::new(),
        };
        let message = ImageAnnotations {
            timestamp: Some(stamp),
            circles: Vec::new(),
            points: vec![points(true, coded), points(false, uncoded)],
            texts: targets
                .iter()
                .map(|t| TextAnnotation {
                    timestamp: Some(stamp),
                    position: Some(Point2 {
                        x: t.col_px + 6.0,
                        y: t.row_px - 6.0,
                    }),
                    text: if t.coded {
                        format!("c{}", t.id)
                    } else {
                        t.id.to_string()
                    },
                    font_size: 12.0,
                    text_color: Some(if t.coded { coded } else { uncoded }),
                    background_color: Some(Color {
                        r: 0.0,
                        g: 0.0,
                        b: 0.0,
                        a: 0.5,
                    }),
                    metadata: Vec::new(),
                })
                .collect(),
            metadata: Vec::new(),
        };
        self.encode(&message, || format!("the targets of frame {}", meta.seq))?;
        self.write_buf(channel, meta.seq, meta.host_time_ns, meta.camera_time_ns)
    }

    /// Appends one RSI controller cycle on [`RSI_TOPIC`] (JSON, schema
    /// `photopose.RsiCycle`); its log time is the datagram's arrival (UTC),
    /// its sequence the low 32 bits of the IPOC.
    pub fn write_rsi(&mut self, cycle: &RsiCycle) -> Result<(), RecordError> {
        let channel = self.lazy_channel(
            |r| &mut r.rsi,
            "photopose.RsiCycle",
            "jsonschema",
            RSI_SCHEMA.as_bytes(),
            RSI_TOPIC,
            "json",
        )?;
        self.encode_json(cycle, || format!("RSI cycle {}", cycle.ipoc))?;
        self.write_buf(
            channel,
            cycle.ipoc,
            cycle.arrival_utc_ns,
            cycle.arrival_utc_ns,
        )
    }

    /// Appends one pose result: the full message always, the
    /// `PoseInFrame` when the frame has a pose.
    pub fn write_pose(&mut self, pose: &PoseRecord<'_>) -> Result<(), RecordError> {
        let header = |channel_id| mcap::records::MessageHeader {
            channel_id,
            sequence: pose.seq as u32,
            log_time: pose.host_time_ns,
            publish_time: pose.camera_time_ns,
        };
        if let Some((c, q)) = pose.pose {
            let message = PoseInFrame {
                timestamp: Some(timestamp(pose.host_time_ns)),
                frame_id: "field".into(),
                pose: Some(Pose {
                    position: Some(Vector3 {
                        x: c[0],
                        y: c[1],
                        z: c[2],
                    }),
                    orientation: Some(Quaternion {
                        x: q[1],
                        y: q[2],
                        z: q[3],
                        w: q[0],
                    }),
                }),
            };
            self.encode(&message, || format!("pose {}", pose.seq))?;
            self.write_buf(self.pose, pose.seq, pose.host_time_ns, pose.camera_time_ns)?;
        }
        let json = pose.json.strip_suffix(b"\n").unwrap_or(pose.json);
        self.writer
            .write_to_known_channel(&header(self.message), json)
            .map_err(|e| self.mcap_err(e))?;
        self.poses += 1;
        Ok(())
    }

    /// Finishes the file (summary and footer) and flushes it to disk.
    pub fn finish(mut self) -> Result<(), RecordError> {
        let path = self.path.clone();
        self.writer.finish().map_err(|e| RecordError::Mcap {
            path: path.clone(),
            message: e.to_string(),
        })?;
        let mut inner = self.writer.into_inner();
        inner.flush().map_err(|source| RecordError::Io {
            path: path.clone(),
            source,
        })?;
        inner
            .file
            .get_ref()
            .sync_all()
            .map_err(|source| RecordError::Io { path, source })
    }
}

fn timestamp(ns: u64) -> Timestamp {
    Timestamp::new(
        u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
        (ns % 1_000_000_000) as u32,
    )
}
