//! The closed-loop simulated cell source (test and demo support): a frame
//! source that owns a simulated KUKA controller (`photopose_rsi::controller`)
//! talking to the daemon's RSI server over real UDP, moves the simulated
//! robot along a programmed path ([`CellPath`]: the circle of
//! `photopose_circle::cell`, or still stations with moves between them)
//! with the cell's injected kinematic error *plus the corrections the
//! daemon sends*, and renders every frame at the robot's **true** camera
//! pose over the exposure (motion blur from the pose at the exposure's
//! start to the pose at its end), delivered after the transfer delay.
//!
//! Time: frame `k`'s exposure middle is the controller's first cycle plus
//! `first_exposure_s + k / rate_hz` on `CLOCK_MONOTONIC`. A frame can be
//! rendered only once the controller has begun the cycle after its
//! exposure (the corrections acting during the exposure are known then);
//! render threads of the source's own do that ahead of the hand-over,
//! which waits for the exposure's end plus the transfer (`transfer_ms`, by
//! default the frame's bytes at 1 Gbit/s). A frame whose rendering takes
//! longer is handed over late, with its exposure instant still exact.
//!
//! Per frame the truth is logged ([`CellFrameTruth`]: programmed, believed
//! and true TCP at mid-exposure, the correction then), and at the end the
//! controller's report ([`SimReport`]), both through [`CellHandle`].

use super::ensure_mono8;
use crossbeam_channel::{bounded, Receiver, RecvTimeoutError, Sender};
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use photopose_acquire::{FrameSource, Slot, SourceError};
use photopose_circle::cell::{CameraMount, CirclePath, RobotError};
use photopose_field::Field;
use photopose_frame::Image;
use photopose_geometry::pose::{exterior_from_camera_pose, isometry_from_xyzabc};
use photopose_geometry::Camera;
use photopose_render::{RenderError, RenderOptions, Renderer};
use photopose_rsi::controller::{
    PathTruth, RobotPath, SimConfig, SimController, SimReport, TcpTruth,
};
use photopose_rsi::server::RsiClock;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// What the robot is programmed to do.
#[derive(Debug, Clone, PartialEq)]
enum Program {
    /// The cell's circle at constant feed and orientation.
    Circle {
        path: CirclePath,
        rotation: UnitQuaternion<f64>,
    },
    /// Still stations, `dwell_s` each, with smooth moves of `move_s`
    /// between them.
    Stations {
        poses: Vec<Isometry3<f64>>,
        dwell_s: f64,
        move_s: f64,
    },
}

/// The programmed path of the simulated robot with the cell's kinematic
/// error: the injected radial deviation and wobble of
/// [`RobotError`], taken at the phase angle of the programmed TCP about
/// the circle's centre axis (the error of a robot depends on where it is).
#[derive(Debug, Clone, PartialEq)]
pub struct CellPath {
    program: Program,
    error: RobotError,
    centre: Vector3<f64>,
}

impl CellPath {
    /// The circle `path` (its `revolutions` long; the robot stands at its
    /// ends before and after), with `error`.
    pub fn circle(path: CirclePath, error: RobotError) -> CellPath {
        let [a, b, c] = path.orientation_abc_deg;
        CellPath {
            program: Program::Circle {
                path,
                rotation: isometry_from_xyzabc([0.0, 0.0, 0.0, a, b, c]).rotation,
            },
            error,
            centre: Vector3::from(path.center_mm),
        }
    }

    /// Still `poses` (TCP in the base frame), each held `dwell_s`, with
    /// moves of `move_s` between them (smooth start and stop); the error
    /// taken about the vertical axis through `centre_mm`.
    pub fn stations(
        poses: Vec<Isometry3<f64>>,
        dwell_s: f64,
        move_s: f64,
        error: RobotError,
        centre_mm: [f64; 3],
    ) -> CellPath {
        CellPath {
            program: Program::Stations {
                poses,
                dwell_s: dwell_s.max(0.0),
                move_s: move_s.max(1e-3),
            },
            error,
            centre: Vector3::from(centre_mm),
        }
    }

    /// Time for the whole program, s.
    pub fn duration_s(&self) -> f64 {
        match &self.program {
            Program::Circle { path, .. } => path.duration_s(),
            Program::Stations {
                poses,
                dwell_s,
                move_s,
            } => poses.len() as f64 * dwell_s + poses.len().saturating_sub(1) as f64 * move_s,
        }
    }

    fn phase(&self, t: f64, programmed: &Isometry3<f64>) -> f64 {
        match &self.program {
            Program::Circle { path, .. } => path.phase_at(t.clamp(0.0, path.duration_s())),
            Program::Stations { .. } => {
                let d = programmed.translation.vector - self.centre;
                d.y.atan2(d.x)
            }
        }
    }
}

impl RobotPath for CellPath {
    fn programmed(&self, t: f64) -> Isometry3<f64> {
        match &self.program {
            Program::Circle { path, rotation } => {
                let theta = path.phase_at(t.clamp(0.0, path.duration_s()));
                let dir = Vector3::new(theta.cos(), theta.sin(), 0.0);
                Isometry3::from_parts((self.centre + dir * path.radius_mm).into(), *rotation)
            }
            Program::Stations {
                poses,
                dwell_s,
                move_s,
            } => {
                let Some(last) = poses.last() else {
                    return Isometry3::identity();
                };
                let leg = dwell_s + move_s;
                let t = t.max(0.0);
                let i = (t / leg).floor() as usize;
                if i + 1 >= poses.len() {
                    return *last;
                }
                let local = t - i as f64 * leg;
                if local <= *dwell_s {
                    return poses[i];
                }
                let f = ((local - dwell_s) / move_s).clamp(0.0, 1.0);
                let s = f * f * (3.0 - 2.0 * f);
                let (a, b) = (&poses[i], &poses[i + 1]);
                Isometry3::from_parts(
                    a.translation.vector.lerp(&b.translation.vector, s).into(),
                    a.rotation.slerp(&b.rotation, s),
                )
            }
        }
    }

    fn actual(&self, t: f64, believed: &Isometry3<f64>) -> Isometry3<f64> {
        let theta = self.phase(t, &self.programmed(t));
        let dir = Vector3::new(theta.cos(), theta.sin(), 0.0);
        let w = Vector3::from(self.error.wobble_at(theta).map(f64::to_radians));
        Isometry3::from_parts(
            (believed.translation.vector + dir * self.error.radial_at(theta)).into(),
            UnitQuaternion::from_scaled_axis(w) * believed.rotation,
        )
    }
}

/// The cell source's settings.
#[derive(Debug, Clone)]
pub struct CellSettings {
    /// Frames per second.
    pub rate_hz: f64,
    /// Frames to deliver, then the source ends.
    pub frames: u64,
    /// The first frame's exposure middle after the controller's first
    /// cycle, s.
    pub first_exposure_s: f64,
    /// Exposure time, ms (motion blur over it).
    pub exposure_ms: f64,
    /// From the end of the exposure to the hand-over, ms (`None`: the
    /// frame's bytes at 1 Gbit/s).
    pub transfer_ms: Option<f64>,
    /// Image noise, DN.
    pub noise_dn: f64,
    /// Blur, px.
    pub blur_px: f64,
    /// Noise seed.
    pub seed: u64,
    /// The camera on the robot.
    pub mount: CameraMount,
    /// Render threads (1–4).
    pub render_threads: usize,
    /// The simulated controller (its `server` is the daemon's RSI
    /// address; `nominal` and the error fields are not used).
    pub controller: SimConfig,
}

impl CellSettings {
    /// Settings for `frames` frames at `rate_hz` against the RSI server at
    /// `server`: 2 ms exposure, transfer at 1 Gbit/s, the renderer's usual
    /// noise and blur, the default mount, two render threads, and a
    /// controller (4 ms, relative Base corrections, no Timeout) running
    /// until half a second after the last frame.
    pub fn new(server: std::net::SocketAddr, rate_hz: f64, frames: u64) -> CellSettings {
        let mut s = CellSettings {
            rate_hz,
            frames,
            first_exposure_s: 0.1,
            exposure_ms: 2.0,
            transfer_ms: None,
            noise_dn: 2.0,
            blur_px: 0.6,
            seed: 1,
            mount: CameraMount::default(),
            render_threads: 2,
            controller: SimConfig {
                timeout: u64::MAX,
                ..SimConfig::new(server)
            },
        };
        s.controller.cycles = s.controller_cycles();
        s
    }

    /// Controller cycles that cover every frame plus half a second.
    pub fn controller_cycles(&self) -> u64 {
        let secs = self.first_exposure_s + self.frames as f64 / self.rate_hz.max(1e-3) + 0.5;
        (secs / self.controller.cycle.as_secs_f64().max(1e-4)).ceil() as u64
    }

    /// From the exposure's middle to the hand-over, ns, for `bytes`.
    fn delivery_ns(&self, bytes: usize) -> u64 {
        let transfer = match self.transfer_ms {
            Some(t) => (t.max(0.0) * 1e6).round() as u64,
            None => photopose_acquire::clock_map::bytes_at_gigabit_ns(bytes),
        };
        (self.exposure_ms.max(0.0) * 0.5e6).round() as u64 + transfer
    }
}

/// The truth of one delivered frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellFrameTruth {
    /// The frame's sequence number.
    pub seq: u64,
    /// The exposure's middle, s on `CLOCK_MONOTONIC`.
    pub exposure_s: f64,
    /// The robot at the exposure's middle (programmed, believed, true TCP,
    /// correction in effect).
    pub tcp: TcpTruth,
    /// The true camera pose in the plate (= base) frame at mid-exposure.
    pub camera: Isometry3<f64>,
}

#[derive(Debug, Default)]
struct Shared {
    frames: Mutex<Vec<CellFrameTruth>>,
    report: Mutex<Option<SimReport>>,
    controller_error: Mutex<Option<String>>,
}

/// The caller's view of a cell source that has moved into a pipeline.
#[derive(Debug, Clone)]
pub struct CellHandle {
    shared: Arc<Shared>,
    truth: Arc<PathTruth>,
}

impl CellHandle {
    /// The truth of every frame delivered so far, in order.
    pub fn frames(&self) -> Vec<CellFrameTruth> {
        lock(&self.shared.frames).clone()
    }

    /// The controller's report, once the source has stopped.
    pub fn report(&self) -> Option<SimReport> {
        lock(&self.shared.report).clone()
    }

    /// Why the controller could not run, if it could not.
    pub fn controller_error(&self) -> Option<String> {
        lock(&self.shared.controller_error).clone()
    }

    /// The controller's per-cycle truth.
    pub fn truth(&self) -> &Arc<PathTruth> {
        &self.truth
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// A rendered frame on its way to the hand-over.
struct Rendered {
    seq: u64,
    image: Image,
    truth: CellFrameTruth,
}

struct Worker {
    frames: Receiver<Rendered>,
    free: Sender<Image>,
    handle: JoinHandle<()>,
}

/// The closed-loop cell source.
pub struct CellSource {
    settings: CellSettings,
    renderer: Renderer,
    truth: Arc<PathTruth>,
    shared: Arc<Shared>,
    clock: RsiClock,
    controller: Option<SimController>,
    workers: Vec<Worker>,
    stop: Arc<AtomicBool>,
    pending: Option<Rendered>,
    next: u64,
}

impl std::fmt::Debug for CellSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CellSource")
            .field("settings", &self.settings)
            .field("next", &self.next)
            .finish_non_exhaustive()
    }
}

impl CellSource {
    /// A cell source for `camera` over `field` (the plate frame is the
    /// robot's base frame), the robot following `path`. Nothing runs until
    /// the grabber starts it.
    pub fn new(
        camera: Camera,
        field: &Field,
        settings: CellSettings,
        path: CellPath,
    ) -> Result<CellSource, RenderError> {
        let renderer = Renderer::new(
            camera,
            field,
            RenderOptions {
                noise_dn: settings.noise_dn,
                blur_px: settings.blur_px,
                seed: settings.seed,
                ..RenderOptions::default()
            },
        )?;
        let cycles = (10.0 / settings.controller.cycle.as_secs_f64().max(1e-4)) as usize;
        let truth = PathTruth::new(Arc::new(path), settings.controller.frame, cycles);
        Ok(CellSource {
            settings,
            renderer,
            truth,
            shared: Arc::new(Shared::default()),
            clock: RsiClock::new(),
            controller: None,
            workers: Vec::new(),
            stop: Arc::new(AtomicBool::new(false)),
            pending: None,
            next: 0,
        })
    }

    /// The view that stays with the caller.
    pub fn handle(&self) -> CellHandle {
        CellHandle {
            shared: self.shared.clone(),
            truth: self.truth.clone(),
        }
    }
}

/// Sleeps a little while `cond` is false; `false` if stopped first.
fn wait_for(stop: &AtomicBool, mut cond: impl FnMut() -> bool) -> bool {
    while !cond() {
        if stop.load(Ordering::Relaxed) {
            return false;
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    true
}

#[allow(clippy::too_many_arguments)] // one render thread's whole state
fn render_thread(
    index: usize,
    threads: usize,
    settings: CellSettings,
    mut renderer: Renderer,
    truth: Arc<PathTruth>,
    stop: Arc<AtomicBool>,
    out: Sender<Rendered>,
    free: Receiver<Image>,
) {
    let half = settings.exposure_ms.max(0.0) * 0.5e-3;
    let mount = settings.mount.camera_in_tcp;
    let mut seq = index as u64;
    while seq < settings.frames {
        let Some(start_s) = ({
            let mut s = None;
            wait_for(&stop, || {
                s = truth.start_s();
                s.is_some() || truth.is_finished()
            });
            s
        }) else {
            return;
        };
        let mid = start_s + settings.first_exposure_s + seq as f64 / settings.rate_hz;
        // The corrections acting until the exposure's end are known once
        // the controller has begun a cycle after it.
        if !wait_for(&stop, || {
            truth.known_until_s().is_some_and(|k| k >= mid + half)
        }) {
            return;
        }
        let (Some(a), Some(m), Some(b)) =
            (truth.at(mid - half), truth.at(mid), truth.at(mid + half))
        else {
            return;
        };
        let image = loop {
            match free.recv_timeout(Duration::from_millis(50)) {
                Ok(i) => break i,
                Err(RecvTimeoutError::Timeout) if !stop.load(Ordering::Relaxed) => {}
                Err(_) => return,
            }
        };
        let mut image = image;
        let options = RenderOptions {
            seed: settings.seed.wrapping_mul(1_000_003).wrapping_add(seq),
            ..*renderer.options()
        };
        let start = exterior_from_camera_pose(&(a.actual * mount));
        let end = exterior_from_camera_pose(&(b.actual * mount));
        if renderer.set_options(options).is_err()
            || renderer.render_moving(&start, &end, &mut image).is_err()
        {
            // A pose the renderer refuses: an empty frame (the pipeline
            // reports it as a frame without targets).
            if let photopose_frame::Pixels::Mono8(p) = image.pixels_mut() {
                p.fill(0);
            }
        }
        let frame = Rendered {
            seq,
            image,
            truth: CellFrameTruth {
                seq,
                exposure_s: mid,
                tcp: m,
                camera: m.actual * mount,
            },
        };
        if out.send(frame).is_err() {
            return;
        }
        seq += threads as u64;
    }
}

impl FrameSource for CellSource {
    fn start(&mut self) -> Result<(), SourceError> {
        if self.controller.is_some() {
            return Ok(());
        }
        let threads = self.settings.render_threads.clamp(1, 4);
        lock(&self.shared.frames).reserve(self.settings.frames as usize);
        for index in 0..threads {
            let (out_tx, out_rx) = bounded(2);
            let (free_tx, free_rx) = bounded(4);
            for _ in 0..2 {
                let _ = free_tx.send(self.renderer.new_image());
            }
            let (settings, renderer, truth, stop) = (
                self.settings.clone(),
                self.renderer.clone(),
                self.truth.clone(),
                self.stop.clone(),
            );
            let handle = std::thread::Builder::new()
                .name(format!("cell-render-{index}"))
                .spawn(move || {
                    render_thread(
                        index, threads, settings, renderer, truth, stop, out_tx, free_rx,
                    )
                })
                .map_err(|e| SourceError::Config {
                    what: "cell render thread".into(),
                    reason: e.to_string(),
                })?;
            self.workers.push(Worker {
                frames: out_rx,
                free: free_tx,
                handle,
            });
        }
        match SimController::spawn_on_path(
            self.settings.controller.clone(),
            self.clock,
            self.truth.clone(),
        ) {
            Ok(c) => self.controller = Some(c),
            Err(e) => {
                *lock(&self.shared.controller_error) = Some(e.to_string());
                return Err(SourceError::Config {
                    what: "simulated controller".into(),
                    reason: e.to_string(),
                });
            }
        }
        Ok(())
    }

    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        if self.next >= self.settings.frames || self.workers.is_empty() {
            return Err(SourceError::Ended);
        }
        let frame = match self.pending.take() {
            Some(f) => f,
            None => {
                let w = &self.workers[(self.next % self.workers.len() as u64) as usize];
                match w.frames.recv_timeout(timeout) {
                    Ok(f) => f,
                    Err(RecvTimeoutError::Timeout) => return Err(SourceError::Timeout(timeout)),
                    Err(RecvTimeoutError::Disconnected) => return Err(SourceError::Ended),
                }
            }
        };
        // Handed over after the exposure's end and the transfer.
        let sensor = self.renderer.camera().sensor;
        let bytes = sensor.width as usize * sensor.height as usize;
        let mid_ns = (frame.truth.exposure_s * 1e9).round() as u64;
        let due_ns = mid_ns + self.settings.delivery_ns(bytes);
        let now_ns = photopose_acquire::mono::now_ns();
        if due_ns > now_ns {
            let wait = Duration::from_nanos(due_ns - now_ns);
            if wait > timeout {
                std::thread::sleep(timeout);
                self.pending = Some(frame);
                return Err(SourceError::Timeout(timeout));
            }
            std::thread::sleep(wait);
        }
        let Rendered {
            seq,
            mut image,
            truth,
        } = frame;
        debug_assert_eq!(seq, self.next);
        // The rendered image becomes the slot's; the slot's old one goes
        // back to the render thread (no copy, no allocation once warm).
        ensure_mono8(slot, sensor.width, sensor.height);
        std::mem::swap(slot.image_mut(), &mut image);
        let w = &self.workers[(self.next % self.workers.len() as u64) as usize];
        let _ = w.free.try_send(image);
        self.next += 1;
        slot.meta.seq = seq;
        slot.meta.camera_frame_id = seq;
        slot.meta.camera_time_ns = (seq as f64 / self.settings.rate_hz * 1e9) as u64;
        slot.meta.host_time_ns = super::host_time_ns();
        slot.meta.host_mono_ns = photopose_acquire::mono::now_ns();
        slot.meta.exposure_mono_ns = mid_ns;
        slot.meta.exposure_sigma_ns = 1;
        slot.meta.exposure_ns = (self.settings.exposure_ms * 1e6).round() as u64;
        lock(&self.shared.frames).push(truth);
        Ok(())
    }

    fn stop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(c) = self.controller.take() {
            match c.stop() {
                Ok(r) => *lock(&self.shared.report) = Some(r),
                Err(e) => *lock(&self.shared.controller_error) = Some(e.to_string()),
            }
        }
        for w in self.workers.drain(..) {
            drop(w.frames);
            drop(w.free);
            let _ = w.handle.join();
        }
    }

    fn describe(&self) -> String {
        format!(
            "closed-loop cell: {} frames at {} frames/s, simulated controller to {}",
            self.settings.frames, self.settings.rate_hz, self.settings.controller.server
        )
    }
}

impl Drop for CellSource {
    fn drop(&mut self) {
        self.stop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use photopose_circle::cell::Cell;

    #[test]
    fn the_circle_program_is_the_cells_path_with_its_error() {
        let cell = Cell::default();
        let path = CellPath::circle(cell.path, cell.error.clone());
        let samples = cell.samples().unwrap();
        for s in samples.iter().step_by(97) {
            let p = path.programmed(s.time_s);
            assert!((p.translation.vector - s.commanded_tcp.translation.vector).norm() < 1e-9);
            assert!(p.rotation.angle_to(&s.commanded_tcp.rotation) < 1e-12);
            // Without correction the true TCP is the cell's actual one.
            let a = path.actual(s.time_s, &p);
            assert!((a.translation.vector - s.actual_tcp.translation.vector).norm() < 1e-9);
            assert!(a.rotation.angle_to(&s.actual_tcp.rotation) < 1e-12);
        }
    }

    #[test]
    fn stations_dwell_then_move_smoothly() {
        let a = isometry_from_xyzabc([0.0, 0.0, 500.0, 0.0, 0.0, 180.0]);
        let b = isometry_from_xyzabc([100.0, 0.0, 500.0, 10.0, 0.0, 180.0]);
        let path = CellPath::stations(vec![a, b], 1.0, 2.0, RobotError::none(), [0.0; 3]);
        assert_eq!(path.duration_s(), 4.0);
        assert_eq!(path.programmed(0.5), a);
        let mid = path.programmed(2.0);
        assert!((mid.translation.vector.x - 50.0).abs() < 1e-9);
        assert_eq!(path.programmed(3.5), b);
        assert_eq!(path.programmed(99.0), b);
        // No error: the true TCP is the belief.
        assert_eq!(path.actual(0.5, &a), a);
    }
}
