//! The recording output (`[record]`, `photopose run --record FILE`): the
//! daemon's frames and poses into MCAP recordings (`photopose-record`:
//! standard Foxglove schemas) written by a thread of their own.
//!
//! Nothing on the frame path waits for the disk: the frame tap (a
//! [`FrameSource`] wrapper on the grabber thread) copies a recorded frame
//! into a buffer taken from a preallocated pool and queues it; the sink
//! ([`RecordSink`], on the output thread) copies each result's JSON line
//! into a pooled buffer likewise. When the pool is empty (the writer is
//! behind) the frame or pose is dropped and counted ([`RecordStats`]); the
//! writer thread hands the buffers back after writing. Files rotate by size
//! or by time: `FILE.mcap`, then `FILE-1.mcap`, `FILE-2.mcap` …
//!
//! With `frames = "on_change"` the detection workers record a frame whose
//! status differs from the previous one ([`RecordLink::frame_on_change`]).
//! The identified targets of every recorded frame go with its pose line
//! (a pooled list) and become an image annotation; the RSI server's cycles
//! come through its [`CycleTap`] (bounded, the server never waits), which
//! the writer thread drains.

use super::{Outgoing, PoseSink};
use crate::config::{Config, Record, RecordFrames};
use crate::result::ResultStatus;
use crate::run::PipelineError;
use crossbeam_channel::{Receiver, Sender, TrySendError};
use photopose_acquire::{FrameSource, Slot, SourceError};
use photopose_frame::FrameMeta;
use photopose_frame::Pixels;
use photopose_record::{PoseRecord, RecordError, RecordOptions, Recorder, RsiCycle, TargetMark};
use photopose_rsi::tap::{CycleRecord, CycleTap};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Room for one pose line in a pooled buffer (a message is about 700
/// bytes; a longer one grows its buffer once).
const LINE_BYTES: usize = 4096;
/// Pose lines that can wait for the writer.
const POSE_QUEUE: usize = 256;
/// Room for a frame's targets in a pooled list (a larger field grows a
/// list once).
const TARGETS: usize = 512;
/// RSI cycles that can wait for the writer (4 s at 4 ms).
const RSI_QUEUE: usize = 1024;
/// The sequence numbers of the last frames recorded, by `seq % RECENT`:
/// tells the sink which results' targets to record.
const RECENT: usize = 1024;
/// How long the writer waits for an item before it looks at the RSI tap.
const RSI_POLL: Duration = Duration::from_millis(20);

/// What a recording wrote and dropped.
#[derive(Debug, Default)]
pub struct RecordStats {
    /// Frames written.
    pub frames: AtomicU64,
    /// Frames dropped: the writer was behind (no free buffer) or failed.
    pub frames_dropped: AtomicU64,
    /// Pose results written.
    pub poses: AtomicU64,
    /// Pose results dropped.
    pub poses_dropped: AtomicU64,
    /// Bytes written to the files (all segments).
    pub bytes: AtomicU64,
    /// Bytes of frame pixels handed to the writer (uncompressed).
    pub pixel_bytes: AtomicU64,
    /// Files written (segments).
    pub files: AtomicU64,
    /// Frames' target annotations written.
    pub annotations: AtomicU64,
    /// Target annotations dropped (no free list, or the writer failed).
    pub annotations_dropped: AtomicU64,
    /// RSI cycles written.
    pub rsi_cycles: AtomicU64,
    /// RSI cycles dropped: the tap was full, or the writer failed.
    pub rsi_dropped: AtomicU64,
}

struct FrameItem {
    meta: FrameMeta,
    width: u32,
    height: u32,
    max_value: u16,
    bytes_per_pixel: u8,
    pixels: Vec<u8>,
}

struct PoseItem {
    meta: FrameMeta,
    pose: Option<([f64; 3], [f64; 4])>,
    line: Vec<u8>,
    /// The frame's targets, when its frame was recorded.
    marks: Option<Vec<TargetMark>>,
}

enum Item {
    Frame(FrameItem),
    Pose(PoseItem),
    /// Write what came before, finish the file, end the thread.
    Finish,
}

struct Shared {
    queue: Sender<Item>,
    free_frames: Receiver<Vec<u8>>,
    free_lines: Receiver<Vec<u8>>,
    free_marks: Receiver<Vec<TargetMark>>,
    /// `seq` of recently recorded frames at `seq % RECENT` (`u64::MAX`:
    /// none).
    recent: Box<[AtomicU64]>,
    /// The status of the frame the workers saw last (`on_change`; 255:
    /// none yet).
    last_status: AtomicU8,
    rsi: Option<Arc<CycleTap>>,
    /// Whether the targets of recorded frames are recorded.
    annotations: bool,
    stats: Arc<RecordStats>,
    thread: Mutex<Option<JoinHandle<()>>>,
    closed: Mutex<bool>,
    path: PathBuf,
}

/// A running recording: the writer thread, its queue and its buffer pools.
/// Cloned into the frame tap and the sink; [`RecordLink::close`] (or the
/// sink's `finish`) ends it.
#[derive(Clone)]
pub struct RecordLink(Arc<Shared>);

impl std::fmt::Debug for RecordLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordLink")
            .field("path", &self.0.path)
            .finish()
    }
}

impl PartialEq for RecordLink {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

/// The file of segment `n` of a recording at `path`: `path` itself, then
/// `STEM-n.EXT`.
pub fn segment_path(path: &Path, n: u64) -> PathBuf {
    if n == 0 {
        return path.to_path_buf();
    }
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match path.extension() {
        Some(e) => format!("{stem}-{n}.{}", e.to_string_lossy()),
        None => format!("{stem}-{n}"),
    };
    path.with_file_name(name)
}

impl RecordLink {
    /// Creates the first file and starts the writer thread, with `frames`
    /// preallocated frame buffers of `frame_bytes` each (the camera's
    /// width × height; a 16-bit frame grows its buffer once).
    pub fn start(
        record: &Record,
        options: RecordOptions,
        frame_bytes: usize,
    ) -> Result<RecordLink, RecordError> {
        let path = record
            .path
            .clone()
            .unwrap_or_else(|| PathBuf::from("photopose.mcap"));
        let first = Recorder::create_with(&path, &options)?;
        let frames = if record.frames == RecordFrames::None {
            0
        } else {
            record.queue
        };
        let (queue, items) = crossbeam_channel::bounded(frames + POSE_QUEUE);
        let (give_frame, free_frames) = crossbeam_channel::bounded(frames.max(1));
        let (give_line, free_lines) = crossbeam_channel::bounded(POSE_QUEUE);
        let (give_marks, free_marks) = crossbeam_channel::bounded(POSE_QUEUE);
        let annotations = record.annotations && record.poses && frames > 0;
        if annotations {
            for _ in 0..POSE_QUEUE {
                let _ = give_marks.try_send(Vec::with_capacity(TARGETS));
            }
        }
        let rsi = record.rsi.then(|| CycleTap::new(RSI_QUEUE));
        for _ in 0..frames {
            let _ = give_frame.try_send(Vec::with_capacity(frame_bytes));
        }
        if record.poses {
            for _ in 0..POSE_QUEUE {
                let _ = give_line.try_send(Vec::with_capacity(LINE_BYTES));
            }
        }
        let stats = Arc::new(RecordStats::default());
        stats.files.store(1, Ordering::Relaxed);
        let writer = Writer {
            path: path.clone(),
            options,
            rotate_bytes: record.rotate_bytes,
            rotate_after: record.rotate_after,
            stats: stats.clone(),
            give_frame,
            give_line,
            give_marks,
            rsi: rsi.clone(),
            rsi_failed: AtomicU64::new(0),
        };
        let thread = std::thread::Builder::new()
            .name("record".into())
            .spawn(move || writer.run(first, items))
            .map_err(|source| RecordError::Io {
                path: path.display().to_string(),
                source,
            })?;
        tracing::info!(path = %path.display(), "recording");
        Ok(RecordLink(Arc::new(Shared {
            queue,
            free_frames,
            free_lines,
            free_marks,
            recent: (0..RECENT).map(|_| AtomicU64::new(u64::MAX)).collect(),
            last_status: AtomicU8::new(u8::MAX),
            rsi,
            annotations,
            stats,
            thread: Mutex::new(Some(thread)),
            closed: Mutex::new(false),
            path,
        })))
    }

    /// The counters.
    pub fn stats(&self) -> Arc<RecordStats> {
        self.0.stats.clone()
    }

    /// The first file.
    pub fn path(&self) -> &Path {
        &self.0.path
    }

    /// The tap the RSI server hands its cycles to, when `[record] rsi` is
    /// on (the pipeline gives it to the server it starts).
    pub fn rsi_tap(&self) -> Option<Arc<CycleTap>> {
        self.0.rsi.clone()
    }

    /// Whether frame `seq` was recorded (one of the last `RECENT`).
    fn was_recorded(&self, seq: u64) -> bool {
        self.0.recent[(seq % RECENT as u64) as usize].load(Ordering::Acquire) == seq
    }

    /// `frames = "on_change"`, from a detection worker: records the frame
    /// when its status differs from that of the frame the workers saw
    /// before (the first frame always). With several workers "before" is
    /// the order in which they finish.
    pub fn frame_on_change(&self, slot: &Slot, status: ResultStatus) {
        let code = match status {
            ResultStatus::Ok => 0,
            ResultStatus::TooFewTargets => 1,
            ResultStatus::Error => 2,
        };
        if self.0.last_status.swap(code, Ordering::AcqRel) != code {
            self.frame(slot);
        }
    }

    /// Wraps `source`: every recorded frame (all, or every `n`th, as
    /// `record` says) is copied into the writer's queue.
    pub fn tap(&self, source: Box<dyn FrameSource>, record: &Record) -> Box<dyn FrameSource> {
        let every = match record.frames {
            RecordFrames::None | RecordFrames::OnChange => return source,
            RecordFrames::All => 1,
            RecordFrames::Every(n) => n,
        };
        Box::new(FrameTap {
            inner: source,
            link: self.clone(),
            every,
            count: 0,
        })
    }

    /// Writes what is queued, finishes the file and joins the writer
    /// thread (blocks until then; a second call returns at once).
    pub fn close(&self) {
        {
            let mut closed = self.0.closed.lock().unwrap_or_else(|e| e.into_inner());
            if *closed {
                return;
            }
            *closed = true;
        }
        let _ = self.0.queue.send(Item::Finish);
        let handle = self
            .0
            .thread
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        if let Some(h) = handle {
            let _ = h.join();
        }
    }

    fn frame(&self, slot: &Slot) {
        let stats = &self.0.stats;
        let Ok(mut pixels) = self.0.free_frames.try_recv() else {
            stats.frames_dropped.fetch_add(1, Ordering::Relaxed);
            return;
        };
        pixels.clear();
        let image = slot.image();
        let bytes_per_pixel = match image.pixels() {
            Pixels::Mono8(p) => {
                pixels.extend_from_slice(p);
                1
            }
            Pixels::Mono16(p) => {
                for v in p {
                    pixels.extend_from_slice(&v.to_le_bytes());
                }
                2
            }
        };
        let seq = slot.meta.seq;
        let item = Item::Frame(FrameItem {
            meta: slot.meta,
            width: image.width(),
            height: image.height(),
            max_value: image.max_value(),
            bytes_per_pixel,
            pixels,
        });
        if let Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) =
            self.0.queue.try_send(item)
        {
            stats.frames_dropped.fetch_add(1, Ordering::Relaxed);
        } else {
            self.0.recent[(seq % RECENT as u64) as usize].store(seq, Ordering::Release);
        }
    }

    fn pose(&self, out: &Outgoing<'_>) {
        let Some(result) = out.result else {
            return;
        };
        let stats = &self.0.stats;
        let Ok(mut line) = self.0.free_lines.try_recv() else {
            stats.poses_dropped.fetch_add(1, Ordering::Relaxed);
            return;
        };
        line.clear();
        line.extend_from_slice(out.line);
        let m = out.message;
        let t = &result.times;
        let meta = FrameMeta {
            seq: result.seq,
            camera_time_ns: t.camera_ns,
            host_time_ns: t.handover_utc_ns,
            host_mono_ns: t.handover_mono_ns,
            exposure_mono_ns: t.exposure_mono_ns,
            exposure_sigma_ns: t.exposure_sigma_ns,
            ..FrameMeta::default()
        };
        let marks = if self.was_recorded(result.seq) {
            match self.0.free_marks.try_recv() {
                Ok(mut marks) => {
                    marks.clear();
                    marks.extend(result.targets.iter().map(|t| TargetMark {
                        id: t.id,
                        coded: t.coded,
                        col_px: t.col_px,
                        row_px: t.row_px,
                        used: t.used,
                    }));
                    Some(marks)
                }
                Err(_) => {
                    // Annotations off (no lists) or the writer is behind.
                    if self.0.annotations {
                        stats.annotations_dropped.fetch_add(1, Ordering::Relaxed);
                    }
                    None
                }
            }
        } else {
            None
        };
        let item = Item::Pose(PoseItem {
            meta,
            // The camera's pose in the field: the centre and Rᵀ (w, x, y, z).
            pose: m.pose.as_ref().map(|p| {
                let [x, y, z, w] = p.quaternion_xyzw;
                (p.position_mm, [w, x, y, z])
            }),
            line,
            marks,
        });
        if self.0.queue.try_send(item).is_err() {
            stats.poses_dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

struct FrameTap {
    inner: Box<dyn FrameSource>,
    link: RecordLink,
    every: u32,
    count: u64,
}

impl FrameSource for FrameTap {
    fn start(&mut self) -> Result<(), SourceError> {
        self.inner.start()
    }

    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        self.inner.next_frame(slot, timeout)?;
        if self.count.is_multiple_of(u64::from(self.every)) {
            self.link.frame(slot);
        }
        self.count += 1;
        Ok(())
    }

    fn stop(&mut self) {
        self.inner.stop();
    }

    fn describe(&self) -> String {
        format!(
            "{} (recorded into {})",
            self.inner.describe(),
            self.link.path().display()
        )
    }

    fn stats(&self) -> photopose_acquire::SourceStats {
        self.inner.stats()
    }

    fn shared_counters(&self) -> Option<Arc<photopose_acquire::SourceCounters>> {
        self.inner.shared_counters()
    }
}

/// The writer thread's state.
struct Writer {
    path: PathBuf,
    options: RecordOptions,
    rotate_bytes: Option<u64>,
    rotate_after: Option<Duration>,
    stats: Arc<RecordStats>,
    give_frame: Sender<Vec<u8>>,
    give_line: Sender<Vec<u8>>,
    give_marks: Sender<Vec<TargetMark>>,
    rsi: Option<Arc<CycleTap>>,
    /// RSI cycles the recorder could not write.
    rsi_failed: AtomicU64,
}

impl Writer {
    fn run(self, first: Recorder, items: Receiver<Item>) {
        let mut current = Some(first);
        let mut opened = Instant::now();
        let mut segment = 0u64;
        let mut done_bytes = 0u64;
        loop {
            if let Some(rec) = current.as_mut() {
                self.drain_rsi(rec);
            }
            let item = match items.recv_timeout(RSI_POLL) {
                Ok(Item::Finish) | Err(crossbeam_channel::RecvTimeoutError::Disconnected) => break,
                Ok(item) => item,
                Err(crossbeam_channel::RecvTimeoutError::Timeout) => continue,
            };
            let Some(rec) = current.as_mut() else {
                self.drop_item(item);
                continue;
            };
            let written = match item {
                Item::Frame(f) => {
                    let r = rec.write_pixels(
                        f.meta,
                        f.width,
                        f.height,
                        f.max_value,
                        f.bytes_per_pixel,
                        &f.pixels,
                    );
                    if r.is_ok() {
                        self.stats.frames.fetch_add(1, Ordering::Relaxed);
                        self.stats
                            .pixel_bytes
                            .fetch_add(f.pixels.len() as u64, Ordering::Relaxed);
                    } else {
                        self.stats.frames_dropped.fetch_add(1, Ordering::Relaxed);
                    }
                    let _ = self.give_frame.try_send(f.pixels);
                    r
                }
                Item::Finish => continue,
                Item::Pose(p) => {
                    let r = rec.write_pose(&PoseRecord {
                        seq: p.meta.seq,
                        camera_time_ns: p.meta.camera_time_ns,
                        host_time_ns: p.meta.host_time_ns,
                        pose: p.pose,
                        json: &p.line,
                    });
                    if r.is_ok() {
                        self.stats.poses.fetch_add(1, Ordering::Relaxed);
                    } else {
                        self.stats.poses_dropped.fetch_add(1, Ordering::Relaxed);
                    }
                    let _ = self.give_line.try_send(p.line);
                    match (r, p.marks) {
                        (Ok(()), Some(marks)) => {
                            let r = rec.write_targets(&p.meta, &marks);
                            let counter = if r.is_ok() {
                                &self.stats.annotations
                            } else {
                                &self.stats.annotations_dropped
                            };
                            counter.fetch_add(1, Ordering::Relaxed);
                            let _ = self.give_marks.try_send(marks);
                            r
                        }
                        (r, marks) => {
                            if let Some(marks) = marks {
                                self.stats
                                    .annotations_dropped
                                    .fetch_add(1, Ordering::Relaxed);
                                let _ = self.give_marks.try_send(marks);
                            }
                            r
                        }
                    }
                }
            };
            if let Err(e) = written {
                tracing::error!(error = %e, "the recording failed; what follows is dropped");
                current = None;
                continue;
            }
            self.stats
                .bytes
                .store(done_bytes + rec.bytes_written(), Ordering::Relaxed);
            let full = self.rotate_bytes.is_some_and(|b| rec.bytes_written() >= b);
            let old = self.rotate_after.is_some_and(|d| opened.elapsed() >= d);
            if full || old {
                let rec = current.take().expect("a recorder is open");
                done_bytes += self.finish(rec);
                self.stats.bytes.store(done_bytes, Ordering::Relaxed);
                segment += 1;
                let next = segment_path(&self.path, segment);
                match Recorder::create_with(&next, &self.options) {
                    Ok(r) => {
                        tracing::info!(path = %next.display(), "recording into the next file");
                        self.stats.files.fetch_add(1, Ordering::Relaxed);
                        current = Some(r);
                        opened = Instant::now();
                    }
                    Err(e) => {
                        tracing::error!(error = %e, "the recording stops; what follows is dropped")
                    }
                }
            }
        }
        if let Some(mut rec) = current {
            self.drain_rsi(&mut rec);
            done_bytes += self.finish(rec);
            self.stats.bytes.store(done_bytes, Ordering::Relaxed);
        }
        // Whatever is still queued is dropped (the pipeline has stopped).
        while let Ok(item) = items.try_recv() {
            self.drop_item(item);
        }
    }

    /// Writes the RSI cycles waiting in the tap; the tap's drops are the
    /// recording's.
    fn drain_rsi(&self, rec: &mut Recorder) {
        let Some(tap) = &self.rsi else {
            return;
        };
        while let Some(c) = tap.pop() {
            match rec.write_rsi(&rsi_cycle(&c)) {
                Ok(()) => self.stats.rsi_cycles.fetch_add(1, Ordering::Relaxed),
                Err(_) => self.rsi_failed.fetch_add(1, Ordering::Relaxed),
            };
        }
        self.stats.rsi_dropped.store(
            tap.dropped() + self.rsi_failed.load(Ordering::Relaxed),
            Ordering::Relaxed,
        );
    }

    /// Finishes a file; its size (what was written if it cannot be read).
    fn finish(&self, rec: Recorder) -> u64 {
        let path = rec.path().to_string();
        let written = rec.bytes_written();
        if let Err(e) = rec.finish() {
            tracing::error!(error = %e, "cannot finish the recording");
            return written;
        }
        tracing::info!(%path, "recording finished");
        std::fs::metadata(&path).map_or(written, |m| m.len())
    }

    fn drop_item(&self, item: Item) {
        match item {
            Item::Frame(f) => {
                self.stats.frames_dropped.fetch_add(1, Ordering::Relaxed);
                let _ = self.give_frame.try_send(f.pixels);
            }
            Item::Finish => {}
            Item::Pose(p) => {
                self.stats.poses_dropped.fetch_add(1, Ordering::Relaxed);
                let _ = self.give_line.try_send(p.line);
                if let Some(marks) = p.marks {
                    self.stats
                        .annotations_dropped
                        .fetch_add(1, Ordering::Relaxed);
                    let _ = self.give_marks.try_send(marks);
                }
            }
        }
    }
}

/// A cycle of the RSI server as the recording stores it.
fn rsi_cycle(c: &CycleRecord) -> RsiCycle {
    RsiCycle {
        ipoc: c.ipoc,
        arrival_utc_ns: c.arrival_utc_ns,
        arrival_mono_ns: c.arrival_mono_ns,
        rist_xyzabc: c.rist,
        rsol_xyzabc: c.rsol,
        delay: c.delay,
        correction_sent_xyzabc: c.sent,
        correction_total_xyzabc: c.total,
        error_xyzabc: c.error,
        state: c.status.name(),
        slew_limited: c.slew_limited,
        clamped: c.clamped,
    }
}

/// The recording's side of the output stage: each result's pose and full
/// message into the writer's queue.
#[derive(Debug)]
pub struct RecordSink {
    link: RecordLink,
    poses: bool,
}

impl RecordSink {
    /// The sink of `[record]`, when it names a file: on the recording the
    /// caller started ([`Record::link`], which also taps the frames), or on
    /// one of its own (poses only).
    pub fn from_config(config: &Config) -> Result<Option<RecordSink>, PipelineError> {
        let record = &config.record;
        if record.path.is_none() {
            return Ok(None);
        }
        let link = match &record.link {
            Some(l) => l.clone(),
            None => {
                let options = RecordOptions {
                    compression: record.compression,
                    ..RecordOptions::default()
                };
                let mut poses_only = record.clone();
                poses_only.frames = RecordFrames::None;
                // The pipeline's error has no variant of its own for this:
                // the file that cannot be created is named in the text.
                RecordLink::start(&poses_only, options, 0).map_err(|e| PipelineError::Thread {
                    name: "record".into(),
                    source: std::io::Error::other(e.to_string()),
                })?
            }
        };
        Ok(Some(RecordSink {
            link,
            poses: record.poses,
        }))
    }

    /// The recording's counters.
    pub fn stats(&self) -> Arc<RecordStats> {
        self.link.stats()
    }
}

impl PoseSink for RecordSink {
    fn name(&self) -> &'static str {
        "record"
    }

    fn publish(&mut self, out: &Outgoing<'_>) {
        if self.poses {
            self.link.pose(out);
        }
    }

    fn finish(&mut self) {
        self.link.close();
    }
}
