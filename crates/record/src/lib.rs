//! photopose-record: recordings of camera frames and poses in MCAP, in
//! the standard Foxglove schemas, readable by the official `mcap` readers and
//! by Foxglove with no photopose plugin.
//!
//! What a recording holds (see [`writer`]):
//!
//! | topic | schema (encoding) | what |
//! | --- | --- | --- |
//! | `/camera/image` | `foxglove.RawImage` (protobuf) | every recorded frame, `mono8` or `mono16` (little-endian) |
//! | `/pose` | `foxglove.PoseInFrame` (protobuf) | the camera pose of each frame with a pose, frame `field` |
//! | `/pose/message` | `photopose.PoseMessage` (json, JSON Schema) | the full pose message, one per result |
//! | `/camera/frame_times` | `photopose.FrameTimes` (json, JSON Schema) | each frame's full sequence number and times (reception, mid-exposure, its σ, exposure time), just before its image |
//! | `/camera/targets` | `foxglove.ImageAnnotations` (protobuf) | each recorded frame's identified targets with their ids ([`TargetMark`]) |
//! | `/rsi/cycle` | `photopose.RsiCycle` (json, JSON Schema) | every answered RSI controller cycle ([`RsiCycle`]) |
//!
//! A frame message's `log_time` is the host time (ns since the Unix epoch),
//! `publish_time` the camera time and `sequence` the low 32 bits of the
//! frame's sequence number; the JSON Schemas of our own JSON messages are
//! kept in the repository's `docs/schema/` and stored in every file. The image channel's metadata holds the
//! camera's saturation level (`max_value`). Attachments carry the camera,
//! field and configuration files; a metadata record `photopose` the
//! version, the host and the start time. Chunks are compressed (zstd by
//! default, lz4 or none: [`Compression`]).
//!
//! Reading is checked: the file is read as a regular file of at most a
//! limit (`photopose_formats::file`, kind "recording", 4 GiB unless the
//! caller gives another), the data section's CRC and every chunk's CRC are
//! verified, and every frame is checked against its size. A file that fails
//! any of these is refused at [`Recording::open`] with its name; the whole
//! recording is then held in memory (the replay copies frames out of it).
//! [`pose_messages`] reads only the pose messages (for `circle-test`).
//! Recordings of the first format (topic `/camera/frames`, encoding
//! `photopose.frame.v1`: a 35-byte little-endian header `seq`,
//! `camera_time_ns`, `host_time_ns`, `width`, `height`, bytes per pixel,
//! `max_value`, then the pixels) are still read.

pub mod writer;

pub use photopose_frame::FrameMeta;
pub use writer::{
    Attachment, Compression, PoseRecord, RecordOptions, Recorder, RsiCycle, TargetMark,
};

use photopose_formats::file::{read_bytes_limited, FileError, FileKind};
use photopose_frame::{Image, Pixels};
use std::path::Path;
use std::sync::Arc;
use thiserror::Error;

/// The topic of the frames in the first format.
pub const TOPIC: &str = "/camera/frames";
/// The message encoding of the frames in the first format.
pub const ENCODING: &str = "photopose.frame.v1";
/// The topic of the frames (`foxglove.RawImage`).
pub const IMAGE_TOPIC: &str = "/camera/image";
/// The topic of the poses (`foxglove.PoseInFrame`).
pub const POSE_TOPIC: &str = "/pose";
/// The topic of the full pose messages (JSON).
pub const MESSAGE_TOPIC: &str = "/pose/message";
/// The topic of each frame's identity and times (JSON,
/// `photopose.FrameTimes`).
pub const FRAME_TIMES_TOPIC: &str = "/camera/frame_times";
/// The topic of each recorded frame's identified targets
/// (`foxglove.ImageAnnotations`).
pub const ANNOTATIONS_TOPIC: &str = "/camera/targets";
/// The topic of the RSI server's controller cycles (JSON,
/// `photopose.RsiCycle`).
pub const RSI_TOPIC: &str = "/rsi/cycle";
/// The schema name of the frames.
pub const IMAGE_SCHEMA: &str = "foxglove.RawImage";
/// The JSON Schema of the RSI cycles (`docs/schema/rsi-cycle.schema.json`).
pub const RSI_SCHEMA: &str = include_str!("../../../docs/schema/rsi-cycle.schema.json");
/// The JSON Schema of the frame times
/// (`docs/schema/frame-times.schema.json`).
pub const FRAME_TIMES_SCHEMA: &str = include_str!("../../../docs/schema/frame-times.schema.json");
const HEADER: usize = 35;

/// A recording that cannot be written or read, with the file and why.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RecordError {
    /// The file could not be created or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The IO error.
        source: std::io::Error,
    },
    /// The file could not be read (missing, not a regular file, larger than
    /// the limit, IO error).
    #[error(transparent)]
    File(#[from] FileError),
    /// The file's checksums do not match its contents (flipped bits,
    /// overwritten bytes).
    #[error("{path}: corrupt recording: {what}")]
    Corrupt {
        /// The file.
        path: String,
        /// Which checksum failed.
        what: String,
    },
    /// The MCAP container is invalid.
    #[error("{path}: not a readable MCAP recording: {message}")]
    Mcap {
        /// The file.
        path: String,
        /// What the MCAP library said.
        message: String,
    },
    /// A frame message is malformed.
    #[error("{path}: frame message {index}: {what}")]
    Frame {
        /// The file.
        path: String,
        /// Index of the message on the frame channel.
        index: usize,
        /// What is wrong.
        what: String,
    },
    /// The file has no frames.
    #[error("{path}: the recording holds no frames (no {IMAGE_SCHEMA} messages on {IMAGE_TOPIC}, nor photopose.frame.v1 frames)")]
    Empty {
        /// The file.
        path: String,
    },
}

/// A recording read into memory: its frames decoded, in file order, each an
/// [`Image`] behind a counted reference (the replay lends them to the frame
/// ring instead of copying them: [`Recording::shared`]).
pub struct Recording {
    path: String,
    frames: Vec<Arc<Image>>,
    metas: Vec<FrameMeta>,
}

impl std::fmt::Debug for Recording {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recording")
            .field("path", &self.path)
            .field("frames", &self.frames.len())
            .finish()
    }
}

impl Recording {
    /// Reads and checks a recording of at most the recording kind's limit
    /// (4 GiB).
    pub fn open(path: &Path) -> Result<Self, RecordError> {
        Self::open_limited(path, FileKind::Recording.limit())
    }

    /// Reads and checks a recording of at most `max_bytes`.
    pub fn open_limited(path: &Path, max_bytes: u64) -> Result<Self, RecordError> {
        let name = path.display().to_string();
        let mut frames = Vec::new();
        let mut metas = Vec::new();
        // The frame times written just before each image.
        let mut times: Option<FrameMeta> = None;
        for_each_message(path, max_bytes, |m| {
            let schema = m.channel.schema.as_ref().map(|s| s.name.as_str());
            if m.channel.topic == FRAME_TIMES_TOPIC {
                times = frame_times(&m.data);
                return Ok(());
            }
            if schema == Some(IMAGE_SCHEMA) {
                let frame = frame_from_raw_image(&m).map_err(|what| RecordError::Frame {
                    path: name.clone(),
                    index: frames.len(),
                    what,
                })?;
                let meta = match times.take() {
                    Some(t) if t.seq as u32 == m.sequence && t.host_time_ns == m.log_time => t,
                    _ => FrameMeta {
                        seq: u64::from(m.sequence),
                        camera_time_ns: m.publish_time,
                        host_time_ns: m.log_time,
                        ..FrameMeta::default()
                    },
                };
                let frame = decode_frame(&frame).map_err(|what| RecordError::Frame {
                    path: name.clone(),
                    index: frames.len(),
                    what,
                })?;
                frames.push(Arc::new(frame));
                metas.push(meta);
                return Ok(());
            }
            if m.channel.topic != TOPIC {
                return Ok(());
            }
            if m.channel.message_encoding != ENCODING {
                return Err(RecordError::Frame {
                    path: name.clone(),
                    index: frames.len(),
                    what: format!(
                        "encoding `{}`, expected `{ENCODING}`",
                        m.channel.message_encoding
                    ),
                });
            }
            check_frame(&m.data).map_err(|what| RecordError::Frame {
                path: name.clone(),
                index: frames.len(),
                what,
            })?;
            let d = &m.data;
            let u64_at = |o: usize| u64::from_le_bytes(d[o..o + 8].try_into().unwrap_or([0; 8]));
            metas.push(FrameMeta {
                seq: u64_at(0),
                camera_time_ns: u64_at(8),
                host_time_ns: u64_at(16),
                ..FrameMeta::default()
            });
            let frame = decode_frame(d).map_err(|what| RecordError::Frame {
                path: name.clone(),
                index: frames.len(),
                what,
            })?;
            frames.push(Arc::new(frame));
            Ok(())
        })?;
        if frames.is_empty() {
            return Err(RecordError::Empty { path: name });
        }
        Ok(Recording {
            path: name,
            frames,
            metas,
        })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether there are no frames (never, for an opened recording).
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The file.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The metadata and size `(width, height)` of frame `index`.
    pub fn meta(&self, index: usize) -> (FrameMeta, u32, u32) {
        let f = &self.frames[index];
        (self.metas[index], f.width(), f.height())
    }

    /// Frame `index` as a new image of its recorded depth and saturation
    /// level, with its metadata (for export, not for the replay's hot path).
    pub fn frame(&self, index: usize) -> Result<(FrameMeta, Image), RecordError> {
        Ok((self.metas[index], Image::clone(&self.frames[index])))
    }

    /// Frame `index` itself, shared (a counted reference: the replay lends
    /// it to a frame slot without copying or allocating).
    pub fn shared(&self, index: usize) -> &Arc<Image> {
        &self.frames[index]
    }

    /// Copies frame `index` into `image` (which must have its size and
    /// depth); returns its metadata.
    pub fn copy_into(&self, index: usize, image: &mut Image) -> Result<FrameMeta, RecordError> {
        let (meta, w, h) = self.meta(index);
        if (image.width(), image.height()) != (w, h) {
            return Err(RecordError::Frame {
                path: self.path.clone(),
                index,
                what: format!(
                    "frame is {w}×{h}, the camera is {}×{}",
                    image.width(),
                    image.height()
                ),
            });
        }
        match (image.pixels_mut(), self.frames[index].pixels()) {
            (Pixels::Mono8(out), Pixels::Mono8(px)) => out.copy_from_slice(px),
            (Pixels::Mono16(out), Pixels::Mono16(px)) => out.copy_from_slice(px),
            (_, px) => {
                return Err(RecordError::Frame {
                    path: self.path.clone(),
                    index,
                    what: format!(
                        "{} bytes per pixel do not fit the frame slot",
                        match px {
                            Pixels::Mono8(_) => 1,
                            Pixels::Mono16(_) => 2,
                        }
                    ),
                })
            }
        }
        Ok(meta)
    }
}

/// The full pose messages of a recording (the JSON objects on
/// [`MESSAGE_TOPIC`], in file order), read and checked as
/// [`Recording::open`] reads a recording; a recording without frames is
/// fine, one without pose messages gives an empty list.
pub fn pose_messages(path: &Path) -> Result<Vec<Vec<u8>>, RecordError> {
    let mut out = Vec::new();
    for_each_message(path, FileKind::Recording.limit(), |m| {
        if m.channel.topic == MESSAGE_TOPIC {
            out.push(m.data.into_owned());
        }
        Ok(())
    })?;
    Ok(out)
}

/// Reads the file (a regular file of at most `max_bytes`), verifies the
/// chunk CRCs and the data section's CRC, and calls `each` with every
/// message in file order.
fn for_each_message(
    path: &Path,
    max_bytes: u64,
    mut each: impl FnMut(mcap::Message<'_>) -> Result<(), RecordError>,
) -> Result<(), RecordError> {
    let name = path.display().to_string();
    let bytes = read_bytes_limited(path, FileKind::Recording, max_bytes)?;
    let mcap_err = |e: mcap::McapError| match e {
        mcap::McapError::BadChunkCrc { saved, calculated } => RecordError::Corrupt {
            path: name.clone(),
            what: format!("a chunk's CRC is {calculated:08x}, the file stores {saved:08x}"),
        },
        e => RecordError::Mcap {
            path: name.clone(),
            message: e.to_string(),
        },
    };
    let stream = mcap::MessageStream::new_with_options(
        &bytes,
        mcap::read::Options::ValidateChunkCrcs.into(),
    )
    .map_err(mcap_err)?;
    for message in stream {
        each(message.map_err(mcap_err)?)?;
    }
    // Chunk CRCs cover the messages; this covers the rest of the data
    // section (record headers, message indexes).
    check_data_section_crc(&bytes).map_err(|what| RecordError::Corrupt {
        path: name.clone(),
        what,
    })
}

/// The frame meta of a `photopose.FrameTimes` message; `None` when it is
/// not one (the image's own times are used then).
fn frame_times(data: &[u8]) -> Option<FrameMeta> {
    let v: serde_json::Value = serde_json::from_slice(data).ok()?;
    let n = |k: &str| v.get(k).and_then(serde_json::Value::as_u64);
    Some(FrameMeta {
        seq: n("seq")?,
        camera_frame_id: n("camera_frame_id").unwrap_or(0),
        camera_time_ns: n("camera_time_ns").unwrap_or(0),
        host_time_ns: n("host_time_ns")?,
        host_mono_ns: n("host_mono_ns").unwrap_or(0),
        exposure_mono_ns: n("exposure_mono_ns").unwrap_or(0),
        exposure_sigma_ns: n("exposure_sigma_ns").unwrap_or(0),
        exposure_ns: n("exposure_ns").unwrap_or(0),
    })
}

/// Checks the CRC of the data section (everything before the Data End
/// record) that the writer stores in the Data End record; a stored 0 means
/// "not computed". A file whose end cannot be found this way is left to
/// the MCAP reader's errors.
fn check_data_section_crc(bytes: &[u8]) -> Result<(), String> {
    const MAGIC: usize = 8;
    const FOOTER: usize = 1 + 8 + 8 + 8 + 4;
    const DATA_END: usize = 1 + 8 + 4;
    let Some(footer) = bytes.len().checked_sub(MAGIC + FOOTER) else {
        return Ok(());
    };
    if bytes[footer] != mcap::records::op::FOOTER {
        return Ok(());
    }
    let u64_at = |o: usize| {
        bytes
            .get(o..o + 8)
            .map(|b| u64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
    };
    let Some(summary_start) = u64_at(footer + 9) else {
        return Ok(());
    };
    let data_end_end = if summary_start == 0 {
        footer
    } else {
        match usize::try_from(summary_start) {
            Ok(s) if s <= footer => s,
            _ => {
                return Err(format!(
                    "the footer's summary start {summary_start} lies outside the file"
                ))
            }
        }
    };
    let Some(at) = data_end_end.checked_sub(DATA_END) else {
        return Ok(());
    };
    if bytes[at] != mcap::records::op::DATA_END || u64_at(at + 1) != Some(4) {
        return Ok(());
    }
    let saved = u32::from_le_bytes([
        bytes[at + 9],
        bytes[at + 10],
        bytes[at + 11],
        bytes[at + 12],
    ]);
    if saved == 0 {
        return Ok(());
    }
    let calculated = crc32fast::hash(&bytes[..at]);
    if calculated != saved {
        return Err(format!(
            "the data section's CRC is {calculated:08x}, the file stores {saved:08x}"
        ));
    }
    Ok(())
}

fn check_frame(d: &[u8]) -> Result<(), String> {
    if d.len() < HEADER {
        return Err(format!(
            "{} bytes, shorter than the {HEADER}-byte header",
            d.len()
        ));
    }
    let w = u32::from_le_bytes([d[24], d[25], d[26], d[27]]) as usize;
    let h = u32::from_le_bytes([d[28], d[29], d[30], d[31]]) as usize;
    let bpp = d[32] as usize;
    if !(bpp == 1 || bpp == 2) {
        return Err(format!("{bpp} bytes per pixel (1 or 2 expected)"));
    }
    if w == 0 || h == 0 || w > 65_536 || h > 65_536 {
        return Err(format!("frame size {w}×{h} is out of range"));
    }
    let need = HEADER + w * h * bpp;
    if d.len() != need {
        return Err(format!("{} bytes, a {w}×{h} frame needs {need}", d.len()));
    }
    Ok(())
}

/// A checked frame of the first format (header and little-endian pixels)
/// as an image of its depth and saturation level.
fn decode_frame(d: &[u8]) -> Result<Image, String> {
    let w = u32::from_le_bytes([d[24], d[25], d[26], d[27]]);
    let h = u32::from_le_bytes([d[28], d[29], d[30], d[31]]);
    let max_value = u16::from_le_bytes([d[33], d[34]]);
    let px = &d[HEADER..];
    let pixels = if d[32] == 1 {
        Pixels::Mono8(px.to_vec())
    } else {
        Pixels::Mono16(
            px.chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect(),
        )
    };
    Image::from_pixels(w, h, max_value, pixels).map_err(|e| e.to_string())
}

/// A `foxglove.RawImage` message as a frame of the first format (header
/// and little-endian pixels), the replay's one layout in memory.
fn frame_from_raw_image(m: &mcap::Message<'_>) -> Result<Vec<u8>, String> {
    use foxglove::Decode;
    if m.channel.message_encoding != "protobuf" {
        return Err(format!(
            "{IMAGE_SCHEMA} with message encoding `{}`, expected `protobuf`",
            m.channel.message_encoding
        ));
    }
    let image = foxglove::schemas::RawImage::decode(&m.data[..])
        .map_err(|e| format!("not a {IMAGE_SCHEMA}: {e}"))?;
    let bpp: usize = match image.encoding.as_str() {
        "mono8" | "8UC1" => 1,
        "mono16" | "16UC1" => 2,
        other => {
            return Err(format!(
                "image encoding `{other}` (mono8 or mono16 expected)"
            ))
        }
    };
    let (w, h) = (image.width as usize, image.height as usize);
    if w == 0 || h == 0 || w > 65_536 || h > 65_536 {
        return Err(format!("frame size {w}×{h} is out of range"));
    }
    let row = w * bpp;
    let step = image.step as usize;
    if step < row || image.data.len() < step * (h - 1) + row {
        return Err(format!(
            "{} bytes with a step of {step}, a {w}×{h} {} frame needs {}",
            image.data.len(),
            image.encoding,
            step * (h - 1) + row
        ));
    }
    let max_value: u16 = m
        .channel
        .metadata
        .get("max_value")
        .and_then(|v| v.parse().ok())
        .unwrap_or(if bpp == 1 { 255 } else { u16::MAX });
    let mut d = Vec::with_capacity(HEADER + row * h);
    d.extend_from_slice(&u64::from(m.sequence).to_le_bytes());
    d.extend_from_slice(&m.publish_time.to_le_bytes());
    d.extend_from_slice(&m.log_time.to_le_bytes());
    d.extend_from_slice(&image.width.to_le_bytes());
    d.extend_from_slice(&image.height.to_le_bytes());
    d.push(bpp as u8);
    d.extend_from_slice(&max_value.to_le_bytes());
    for r in 0..h {
        d.extend_from_slice(&image.data[r * step..r * step + row]);
    }
    Ok(d)
}
