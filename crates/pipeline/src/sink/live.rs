//! The live view's side of the pipeline (`[live]`, docs/live-view.md): the
//! frame tap on the grabber thread and the sink on the output thread that
//! feed the Foxglove WebSocket server (`photopose_stream::live`) running on
//! the edge runtime.
//!
//! Neither ever waits. The tap ([`LiveLink::tap`]) copies nothing unless a
//! client watches the image; then, at most `image_hz` times a second, it
//! box-filters the frame down by `image_scale` straight into a free
//! preallocated buffer (none free: dropped and counted). The sink
//! ([`LiveSink`]), at most `pose_hz` times a second and only while a
//! client is connected, copies the pose, its σ, the status, the RSI state
//! and the JSON pose line into the view's latest-state slot, which it only
//! `try_lock`s. Nothing here allocates once the buffers exist.

use super::{Outgoing, PoseSink};
use crate::config::Live;
use crate::result::{PoseResult, ResultStatus};
use crate::run::PipelineError;
use photopose_acquire::{FrameSource, Slot, SourceError};
use photopose_frame::{Image, Pixels};
use photopose_geometry::rotation::quaternion_wxyz_from_matrix;
use photopose_stream::live::{
    CameraShape, LiveImage, LiveOptions, LivePose, LiveRsi, LiveSender, LiveServer, SceneTarget,
};
use photopose_stream::EdgeHandle;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Image buffers between the grabber and the view: one being published,
/// one filled, one spare.
const IMAGE_BUFFERS: usize = 3;
/// No frame shown yet.
const NONE_SHOWN: u64 = u64::MAX;

/// The running live view: its server, and what the tap and the sink share.
/// Cloned into both; the sink's `finish` stops the server.
#[derive(Clone)]
pub struct LiveLink {
    server: Arc<Mutex<Option<LiveServer>>>,
    sender: LiveSender,
    addr: SocketAddr,
    settings: Live,
    /// The sequence number of the frame last handed over as an image (its
    /// detected targets go with it).
    shown: Arc<AtomicU64>,
    /// The camera's sensor size, px.
    sensor: (u32, u32),
}

impl std::fmt::Debug for LiveLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveLink")
            .field("addr", &self.addr)
            .finish_non_exhaustive()
    }
}

impl LiveLink {
    /// Starts the view's server on `edge` for `camera` looking at `field`
    /// (the plate of the 3-D scene).
    pub fn start(
        settings: &Live,
        edge: &EdgeHandle,
        camera: &photopose_geometry::Camera,
        field: &photopose_field::Field,
    ) -> Result<LiveLink, PipelineError> {
        let scale = settings.image_scale.max(1);
        let (w, h) = (camera.sensor.width, camera.sensor.height);
        let image_bytes = (w / scale) as usize * (h / scale) as usize;
        let plate: Vec<SceneTarget> = field
            .targets()
            .iter()
            .map(|t| SceneTarget {
                id: t.id,
                position_mm: [t.position.x, t.position.y, t.position.z],
                radius_mm: t.radius,
                coded: t.kind == photopose_field::TargetKind::Coded,
            })
            .collect();
        let server = LiveServer::start(
            edge,
            &LiveOptions {
                address: settings.address,
                image_scale: scale,
                max_clients: settings.max_clients,
            },
            IMAGE_BUFFERS,
            image_bytes,
            &plate,
            CameraShape {
                width_px: w,
                height_px: h,
                pixel_mm: camera.sensor.pixel_size,
                c_mm: camera.interior.c,
            },
        )?;
        let addr = server.local_addr();
        tracing::info!(address = %format!("ws://{addr}"), "live view (Foxglove WebSocket)");
        Ok(LiveLink {
            sender: server.sender(),
            server: Arc::new(Mutex::new(Some(server))),
            addr,
            settings: settings.clone(),
            shown: Arc::new(AtomicU64::new(NONE_SHOWN)),
            sensor: (w, h),
        })
    }

    /// The address clients connect to (`ws://ADDR`).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Wraps `source`: while a client watches the image, a frame at most
    /// `image_hz` times a second is downscaled into the view's buffers.
    pub fn tap(&self, source: Box<dyn FrameSource>) -> Box<dyn FrameSource> {
        let scale = self.settings.image_scale.max(1);
        Box::new(LiveTap {
            inner: source,
            link: self.clone(),
            scale,
            every: Duration::from_secs_f64(1.0 / self.settings.image_hz),
            next: None,
            sums: Vec::with_capacity((self.sensor.0 / scale) as usize),
        })
    }

    /// The sink of the pose results; `rsi`: the RSI server's counters when
    /// it runs (its state and the robot's pose are shown).
    pub fn sink(&self, rsi: Option<Arc<photopose_rsi::monitor::Stats>>) -> LiveSink {
        LiveSink {
            link: self.clone(),
            every: Duration::from_secs_f64(1.0 / self.settings.pose_hz),
            next: None,
            rsi,
        }
    }

    /// Stops the server (its clients are closed); logs what was sent and
    /// dropped. A second call does nothing.
    pub fn close(&self) {
        let server = self.server.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(server) = server {
            let s = self.sender.stats();
            tracing::info!(
                images = s.images.load(Ordering::Relaxed),
                images_dropped = s.images_dropped.load(Ordering::Relaxed),
                states = s.states.load(Ordering::Relaxed),
                states_dropped = s.states_dropped.load(Ordering::Relaxed),
                "live view stopped"
            );
            server.shutdown();
        }
    }
}

/// Whether a throttle due at `next` lets an event through at `now`; moves
/// `next` on by `every` (or to a period from now when far behind).
fn due(next: &mut Option<Instant>, every: Duration, now: Instant) -> bool {
    match *next {
        Some(t) if now < t => false,
        Some(t) => {
            let after = t + every;
            *next = Some(if after <= now { now + every } else { after });
            true
        }
        None => {
            *next = Some(now + every);
            true
        }
    }
}

/// Box-filters `image` down by `scale` into `out` (mono8, rows top to
/// bottom; a 16-bit frame is mapped onto 0..=255 by its saturation level);
/// the last `width % scale` columns and `height % scale` rows are left
/// out. `sums` is the caller's row of accumulators; neither it nor `out`
/// grows beyond the capacity given for this size. Returns the size.
///
/// Hand-written: it runs on the grabber thread and must not allocate; the
/// resizing crates allocate their output.
pub fn downscale_box(
    image: &Image,
    scale: u32,
    sums: &mut Vec<u32>,
    out: &mut Vec<u8>,
) -> (u32, u32) {
    let s = scale.max(1) as usize;
    let width = image.width() as usize;
    let (w, h) = (width / s, image.height() as usize / s);
    out.clear();
    sums.clear();
    sums.resize(w, 0);
    let n = (s * s) as u64;
    match image.pixels() {
        Pixels::Mono8(p) => {
            for r in 0..h {
                sums.fill(0);
                for row in p[r * s * width..].chunks(width).take(s) {
                    for (sum, block) in sums.iter_mut().zip(row.chunks_exact(s)) {
                        *sum += block.iter().map(|&v| u32::from(v)).sum::<u32>();
                    }
                }
                out.extend(sums.iter().map(|&t| ((u64::from(t) + n / 2) / n) as u8));
            }
        }
        Pixels::Mono16(p) => {
            let full = n * u64::from(image.max_value().max(1));
            for r in 0..h {
                sums.fill(0);
                for row in p[r * s * width..].chunks(width).take(s) {
                    for (sum, block) in sums.iter_mut().zip(row.chunks_exact(s)) {
                        *sum += block.iter().map(|&v| u32::from(v)).sum::<u32>();
                    }
                }
                out.extend(
                    sums.iter()
                        .map(|&t| ((u64::from(t) * 255 + full / 2) / full).min(255) as u8),
                );
            }
        }
    }
    (w as u32, h as u32)
}

/// The frame tap of the live view, on the grabber thread.
struct LiveTap {
    inner: Box<dyn FrameSource>,
    link: LiveLink,
    scale: u32,
    every: Duration,
    next: Option<Instant>,
    sums: Vec<u32>,
}

impl LiveTap {
    fn offer(&mut self, slot: &Slot) {
        let sender = &self.link.sender;
        if !sender.image_wanted() || !due(&mut self.next, self.every, Instant::now()) {
            return;
        }
        let (scale, sums) = (self.scale, &mut self.sums);
        let sent = sender.send_image(|image: &mut LiveImage| {
            let (w, h) = downscale_box(slot.image(), scale, sums, &mut image.data);
            image.width = w;
            image.height = h;
            image.seq = slot.meta.seq;
            image.time_ns = slot.meta.host_time_ns;
        });
        if sent {
            self.link.shown.store(slot.meta.seq, Ordering::Relaxed);
        }
    }
}

impl FrameSource for LiveTap {
    fn start(&mut self) -> Result<(), SourceError> {
        self.inner.start()
    }

    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        self.inner.next_frame(slot, timeout)?;
        self.offer(slot);
        Ok(())
    }

    fn stop(&mut self) {
        self.inner.stop();
    }

    fn describe(&self) -> String {
        format!(
            "{} (live view at ws://{})",
            self.inner.describe(),
            self.link.addr
        )
    }

    fn stats(&self) -> photopose_acquire::SourceStats {
        self.inner.stats()
    }

    fn shared_counters(&self) -> Option<Arc<photopose_acquire::SourceCounters>> {
        self.inner.shared_counters()
    }

    fn exposure_link(&self) -> Option<Arc<photopose_acquire::ExposureLink>> {
        self.inner.exposure_link()
    }
}

/// The live view's sink: the latest state, throttled to `pose_hz`.
pub struct LiveSink {
    link: LiveLink,
    every: Duration,
    next: Option<Instant>,
    rsi: Option<Arc<photopose_rsi::monitor::Stats>>,
}

impl std::fmt::Debug for LiveSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveSink")
            .field("link", &self.link)
            .finish_non_exhaustive()
    }
}

/// The camera's pose and precision as the view shows them: the
/// orientation is `Rᵀ` (camera axes in the field frame), the conjugate of
/// `R`'s quaternion.
fn live_pose(result: &PoseResult) -> Option<LivePose> {
    let p = result.pose.as_ref()?;
    let e = &p.exterior;
    let [w, x, y, z] = quaternion_wxyz_from_matrix(&e.rotation)?;
    Some(LivePose {
        position_mm: [e.center.x, e.center.y, e.center.z],
        orientation_xyzw: [-x, -y, -z, w],
        std_position_mm: p.std_center().into(),
        std_rotation_deg: p.std_rotation_deg().into(),
        sigma0_px: p.sigma0_px,
    })
}

impl PoseSink for LiveSink {
    fn name(&self) -> &'static str {
        "live"
    }

    fn publish(&mut self, out: &Outgoing<'_>) {
        let sender = &self.link.sender;
        if !sender.anyone() {
            return;
        }
        // The frame shown as an image always goes (its targets with it).
        let shown = out
            .result
            .is_some_and(|r| r.seq == self.link.shown.load(Ordering::Relaxed));
        if !due(&mut self.next, self.every, Instant::now()) && !shown {
            return;
        }
        let rsi = self.rsi.as_deref().map(|s| LiveRsi {
            state: photopose_rsi::LawStatus::from_code(s.status.load(Ordering::Relaxed))
                .map_or("waiting", |st| st.name()),
            robot_xyzabc: s.robot_pose(),
        });
        sender.send_state(|s| {
            match out.result {
                Some(r) => {
                    s.seq = r.seq;
                    s.time_ns = r.times.handover_utc_ns;
                    s.status = match r.status {
                        ResultStatus::Ok => "ok",
                        ResultStatus::TooFewTargets => "too_few_targets",
                        ResultStatus::Error => "error",
                    };
                    s.pose = live_pose(r);
                    s.n_targets = r.pose.as_ref().map_or(0, |p| p.n_points as u32);
                    s.latency_ms = r.times.handover.elapsed().as_secs_f64() * 1e3;
                }
                None => {
                    // Stale: no fresh frame; the last pose is not repeated.
                    s.time_ns = crate::source::host_time_ns();
                    s.status = "stale";
                    s.pose = None;
                    s.n_targets = 0;
                }
            }
            s.rsi = rsi;
            s.line.clear();
            s.line.extend_from_slice(out.line);
            // The identified targets of the frame shown as an image, on
            // it (same time stamp: the frame's hand-over, UTC).
            s.targets.clear();
            s.targets_time_ns = None;
            if let (true, Some(r)) = (shown, out.result) {
                s.targets.extend(r.targets.iter().map(|t| {
                    photopose_stream::live::DetectedTarget {
                        id: Some(t.id),
                        col: t.col_px,
                        row: t.row_px,
                        coded: t.coded,
                    }
                }));
                s.targets_time_ns = Some(r.times.handover_utc_ns);
            }
        });
    }

    fn finish(&mut self) {
        self.link.close();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_box_filter_averages_blocks_and_drops_the_remainder() {
        // 5 × 3, scale 2: a 2 × 1 result from the top-left 4 × 2.
        let px: Vec<u8> = vec![
            0, 2, 10, 20, 99, //
            4, 6, 30, 40, 99, //
            99, 99, 99, 99, 99,
        ];
        let image = Image::from_pixels(5, 3, 255, Pixels::Mono8(px)).unwrap();
        let (mut sums, mut out) = (Vec::with_capacity(2), Vec::with_capacity(2));
        assert_eq!(downscale_box(&image, 2, &mut sums, &mut out), (2, 1));
        assert_eq!(out, [3, 25]);
        // Scale 1 is a copy.
        let mut all = Vec::with_capacity(15);
        let mut s1 = Vec::with_capacity(5);
        assert_eq!(downscale_box(&image, 1, &mut s1, &mut all), (5, 3));
        assert_eq!(all[..5], [0, 2, 10, 20, 99]);
    }

    #[test]
    fn a_16_bit_frame_is_mapped_by_its_saturation_level() {
        let image = Image::from_pixels(2, 2, 4095, Pixels::Mono16(vec![4095; 4])).unwrap();
        let (mut sums, mut out) = (Vec::new(), Vec::new());
        downscale_box(&image, 2, &mut sums, &mut out);
        assert_eq!(out, [255]);
        let half = Image::from_pixels(2, 2, 4095, Pixels::Mono16(vec![0, 0, 4095, 4095])).unwrap();
        downscale_box(&half, 2, &mut sums, &mut out);
        assert_eq!(out, [128]);
    }

    #[test]
    fn the_box_filter_stays_within_the_buffers_it_was_given() {
        let image = Image::new_mono8(1300, 1030);
        let mut sums = Vec::with_capacity(1300 / 4);
        let mut out = Vec::with_capacity((1300 / 4) * (1030 / 4));
        let (p_sums, p_out) = (sums.as_ptr(), out.as_ptr());
        for _ in 0..3 {
            assert_eq!(downscale_box(&image, 4, &mut sums, &mut out), (325, 257));
        }
        assert_eq!(
            (sums.as_ptr(), out.as_ptr()),
            (p_sums, p_out),
            "no reallocation"
        );
    }

    #[test]
    fn the_throttle_lets_one_event_through_per_period() {
        let t0 = Instant::now();
        let every = Duration::from_millis(200);
        let mut next = None;
        let passed = (0..40)
            .filter(|k| due(&mut next, every, t0 + Duration::from_millis(50) * *k))
            .count();
        // 2 s of frames at 20 Hz, throttled to 5 Hz.
        assert_eq!(passed, 10);
        // Far behind: the next period starts from now.
        let late = t0 + Duration::from_secs(10);
        assert!(due(&mut next, every, late));
        assert!(!due(&mut next, every, late + Duration::from_millis(100)));
    }
}
