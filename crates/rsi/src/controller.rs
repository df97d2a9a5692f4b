//! A simulated KUKA controller (test support, also for demos): sends `<Rob>`
//! every cycle on its own clock whether or not the last one was answered,
//! counts late, mismatched and unparsable replies into `Delay`, stops after
//! `timeout` faults, and simulates a robot whose actual TCP deviates from
//! the commanded one by a known error (offset plus a slow drift),
//! integrating the received corrections (relative or absolute, in the Base
//! or Tool frame, HOLDON as the mode needs) into the commanded pose.
//!
//! [`SimController::spawn_on_path`] runs the same controller along a
//! programmed path given as a function of time ([`RobotPath`]: a circle, or
//! still stations with moves between them) with the path's own kinematic
//! error, and keeps the truth of every cycle ([`PathTruth`]: when it began
//! and the total correction in effect from then on, bounded) so that a
//! simulated camera can render the robot's true pose at any instant of the
//! recent past.

use crate::codec::{parse_sen, Pose6, SenFormat};
use crate::law::{apply_correction, isometry_to_pose, pose_to_isometry, CorrFrame, CorrectionMode};
use crate::server::RsiClock;
use nalgebra::Isometry3;
use std::collections::VecDeque;
use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The simulation's parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// The sensor's address.
    pub server: SocketAddr,
    /// The controller's own address (port 0: any).
    pub bind: SocketAddr,
    /// Interpolation cycle (4 ms with `#IPO_FAST`).
    pub cycle: Duration,
    /// Cycles to run.
    pub cycles: u64,
    /// First IPOC.
    pub ipoc_start: u64,
    /// IPOC step per cycle (the cycle in ms on KR C4, 1 on KR C2).
    pub ipoc_step: u64,
    /// Faults (late, mismatched, unparsable replies) after which RSI stops.
    pub timeout: u64,
    /// Correction mode.
    pub mode: CorrectionMode,
    /// POSCORR frame.
    pub frame: CorrFrame,
    /// SENTYPE and element the replies must carry.
    pub sen: SenFormat,
    /// The programmed TCP pose (`X Y Z A B C`).
    pub nominal: Pose6,
    /// The robot's error at start: actual = error ∘ commanded, in the base frame.
    pub error_offset: Pose6,
    /// The error's drift per second (components added linearly).
    pub error_drift_per_s: Pose6,
    /// Send RSol with the RSI correction included (else the programmed pose).
    pub rsol_includes_correction: bool,
    /// Start like a KR C2: the first datagram holds only `<IPOC>`.
    pub krc2_first_packet: bool,
    /// SCHED_FIFO priority of the controller thread (a real controller is
    /// hard real-time); failing to get it is a warning.
    pub realtime_priority: Option<u8>,
    /// How long before sending its `<Rob>` datagram the controller sampled
    /// `RIst`/`RSol` (the start of its cycle; about a millisecond on a KUKA
    /// controller). Used by [`SimController::spawn_on_path`]: the robot is
    /// sampled, and the cycle recorded, this long before the send.
    pub sample_lead: Duration,
}

impl SimConfig {
    /// A KR C4 at 4 ms sending to `server`, relative Base-frame corrections,
    /// `Timeout` 10, a robot 0.8 mm / 0.05° off with a slow drift.
    pub fn new(server: SocketAddr) -> SimConfig {
        SimConfig {
            server,
            bind: SocketAddr::from(([127, 0, 0, 1], 0)),
            cycle: Duration::from_millis(4),
            cycles: 1000,
            ipoc_start: 123_645_634_563,
            ipoc_step: 4,
            timeout: 10,
            mode: CorrectionMode::Relative,
            frame: CorrFrame::Base,
            sen: SenFormat::default(),
            nominal: [445.0, 0.0, 790.0, 180.0, 0.0, 180.0],
            error_offset: [0.8, -0.5, 0.3, 0.05, -0.03, 0.02],
            error_drift_per_s: [0.01, 0.005, -0.005, 0.0005, 0.0, -0.0005],
            rsol_includes_correction: false,
            krc2_first_packet: false,
            realtime_priority: None,
            sample_lead: Duration::from_millis(1),
        }
    }
}

/// The simulated robot's state, shared with the test's camera thread.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotState {
    /// Cycles sent.
    pub cycle: u64,
    /// Total correction in effect.
    pub total: Pose6,
    /// The actual TCP pose in the base frame.
    pub actual: Isometry3<f64>,
    /// When `actual` was last updated, s on the shared clock.
    pub time_s: f64,
}

/// What happened over the run.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SimReport {
    /// Cycles sent.
    pub cycles: u64,
    /// Cycle slots the simulator itself missed (its thread woke more than a
    /// cycle late on a loaded machine); skipped like a clock that moved on,
    /// never counted against the sensor.
    pub skipped: u64,
    /// Cycles without a matching reply before the next cycle.
    pub late: u64,
    /// The cycles (slot numbers) that were late.
    pub late_cycles: Vec<u64>,
    /// Replies with another IPOC, a wrong Type or that did not parse.
    pub mismatched: u64,
    /// The final `Delay` (late + mismatched).
    pub delay: u64,
    /// RSI stopped because `Delay` passed `timeout`.
    pub stopped_by_timeout: bool,
    /// Largest per-cycle change of each component of the total correction.
    pub max_step: Pose6,
    /// Largest magnitude of each component of the total correction.
    pub max_total: Pose6,
    /// Per cycle: `(translation error mm, rotation error deg)` of the actual
    /// TCP against the programmed pose.
    pub errors: Vec<(f64, f64)>,
    /// Per cycle: when it was sent, s on the shared clock.
    pub times: Vec<f64>,
    /// Per cycle: the total correction after the cycle's reply.
    pub totals: Vec<Pose6>,
    /// The final total correction.
    pub total: Pose6,
}

impl SimReport {
    /// The first component whose largest step per cycle exceeds the law's
    /// slew limit, or whose largest total exceeds its clamp, named with its
    /// value; `None` when the run kept both. Replies carry 4 decimals, so a
    /// step may exceed its limit by the rounding of one value (5e-5) and a
    /// total by 1e-3.
    pub fn limits_broken(&self, law: &crate::law::LawConfig) -> Option<String> {
        (0..6).find_map(|i| {
            let (step, clamp) = if i < 3 {
                (law.max_step_mm, law.clamp_mm)
            } else {
                (law.max_step_deg, law.clamp_deg)
            };
            if self.max_step[i] > step + 5e-5 {
                Some(format!("step {i}: {} beyond {step}", self.max_step[i]))
            } else if self.max_total[i] > clamp + 1e-3 {
                Some(format!("total {i}: {} beyond {clamp}", self.max_total[i]))
            } else {
                None
            }
        })
    }
}

/// A cheap, cloneable view of a running simulation for other threads (the
/// test's camera).
#[derive(Debug, Clone)]
pub struct SimProbe {
    state: Arc<Mutex<RobotState>>,
    finished: Arc<AtomicBool>,
}

impl SimProbe {
    /// The robot's state now.
    pub fn state(&self) -> RobotState {
        self.state
            .lock()
            .map(|s| s.clone())
            .unwrap_or_else(|p| p.into_inner().clone())
    }

    /// The run has ended (cycles done, timeout or stop).
    pub fn is_finished(&self) -> bool {
        self.finished.load(Ordering::Relaxed)
    }
}

/// A programmed robot motion with its kinematic error: what
/// [`SimController::spawn_on_path`] moves the robot along.
pub trait RobotPath: Send + Sync {
    /// The programmed TCP pose in the base frame `t` seconds after the
    /// run's first cycle.
    fn programmed(&self, t: f64) -> Isometry3<f64>;
    /// The true TCP when the robot, running its program at `t`, believes
    /// it is at `believed` (the programmed pose with the RSI correction):
    /// the robot's kinematic error.
    fn actual(&self, t: f64, believed: &Isometry3<f64>) -> Isometry3<f64>;
}

/// One controller cycle of a path run: when it began and the total
/// correction in effect from then until the next cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleTruth {
    /// The cycle's start (where `RIst`/`RSol` are sampled), s on the
    /// shared clock.
    pub time_s: f64,
    /// The total RSI correction in effect during the cycle.
    pub total: Pose6,
}

/// The robot's poses at one instant of a path run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TcpTruth {
    /// Seconds since the run's first cycle.
    pub t: f64,
    /// The programmed TCP pose.
    pub programmed: Isometry3<f64>,
    /// What the robot believes (`RIst`): programmed with the correction.
    pub believed: Isometry3<f64>,
    /// The true TCP.
    pub actual: Isometry3<f64>,
    /// The total correction in effect.
    pub total: Pose6,
}

#[derive(Debug)]
struct TruthCycles {
    /// The first cycle's start, s on the shared clock.
    start_s: Option<f64>,
    cycles: VecDeque<CycleTruth>,
    finished: bool,
}

/// The shared truth of a path run (test support: a mutex is fine here,
/// never in the daemon's RSI thread): the path, the correction frame and
/// the last `capacity` cycles, written by the controller, read by a
/// simulated camera.
pub struct PathTruth {
    path: Arc<dyn RobotPath>,
    frame: CorrFrame,
    capacity: usize,
    cycles: Mutex<TruthCycles>,
}

impl std::fmt::Debug for PathTruth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PathTruth")
            .field("frame", &self.frame)
            .field("capacity", &self.capacity)
            .finish_non_exhaustive()
    }
}

impl PathTruth {
    /// The truth of a run along `path`, corrections applied in `frame`,
    /// keeping the last `capacity` cycles (at least 2).
    pub fn new(path: Arc<dyn RobotPath>, frame: CorrFrame, capacity: usize) -> Arc<PathTruth> {
        let capacity = capacity.max(2);
        Arc::new(PathTruth {
            path,
            frame,
            capacity,
            cycles: Mutex::new(TruthCycles {
                start_s: None,
                cycles: VecDeque::with_capacity(capacity),
                finished: false,
            }),
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, TruthCycles> {
        self.cycles.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Records a cycle; returns the run's start.
    fn push(&self, c: CycleTruth) -> f64 {
        let mut g = self.lock();
        let start = *g.start_s.get_or_insert(c.time_s);
        if g.cycles.len() == self.capacity {
            g.cycles.pop_front();
        }
        g.cycles.push_back(c);
        start
    }

    /// The robot `t` s into the run with the correction `total`.
    pub fn tcp(&self, t: f64, total: Pose6) -> TcpTruth {
        let programmed = self.path.programmed(t);
        let believed = apply_correction(&programmed, &total, self.frame);
        TcpTruth {
            t,
            programmed,
            believed,
            actual: self.path.actual(t, &believed),
            total,
        }
    }

    fn finish(&self) {
        self.lock().finished = true;
    }

    /// The path.
    pub fn path(&self) -> &Arc<dyn RobotPath> {
        &self.path
    }

    /// The run's first cycle, s on the shared clock (`None` before it).
    pub fn start_s(&self) -> Option<f64> {
        self.lock().start_s
    }

    /// The newest cycle's start: the truth is known up to here (and on,
    /// once the run has finished: the robot then holds its correction).
    pub fn known_until_s(&self) -> Option<f64> {
        let g = self.lock();
        if g.finished {
            return Some(f64::INFINITY);
        }
        g.cycles.back().map(|c| c.time_s)
    }

    /// The run has ended (cycles done, timeout or stop).
    pub fn is_finished(&self) -> bool {
        self.lock().finished
    }

    /// The total correction in effect at `time_s` (the newest cycle begun
    /// by then; zero before the first; the oldest kept before that).
    pub fn total_at(&self, time_s: f64) -> Pose6 {
        let g = self.lock();
        let i = g.cycles.partition_point(|c| c.time_s <= time_s);
        match i {
            0 => [0.0; 6],
            i => g.cycles[i - 1].total,
        }
    }

    /// The robot at `time_s` (s on the shared clock), or `None` before
    /// the run's first cycle.
    pub fn at(&self, time_s: f64) -> Option<TcpTruth> {
        let t = time_s - self.start_s()?;
        Some(self.tcp(t, self.total_at(time_s)))
    }
}

/// A running simulated controller.
#[derive(Debug)]
pub struct SimController {
    state: Arc<Mutex<RobotState>>,
    finished: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<io::Result<SimReport>>>,
    local: SocketAddr,
    truth: Option<Arc<PathTruth>>,
}

fn robot_error(cfg: &SimConfig, t: f64) -> Pose6 {
    std::array::from_fn(|i| cfg.error_offset[i] + cfg.error_drift_per_s[i] * t)
}

fn actual_pose(cfg: &SimConfig, total: &Pose6, t: f64) -> Isometry3<f64> {
    let commanded = apply_correction(&pose_to_isometry(&cfg.nominal), total, cfg.frame);
    apply_correction(&commanded, &robot_error(cfg, t), CorrFrame::Base)
}

fn fmt_pose(out: &mut String, name: &str, p: &Pose6) {
    use std::fmt::Write;
    let _ = write!(
        out,
        "<{name} X=\"{:.4}\" Y=\"{:.4}\" Z=\"{:.4}\" A=\"{:.4}\" B=\"{:.4}\" C=\"{:.4}\"/>",
        p[0], p[1], p[2], p[3], p[4], p[5]
    );
}

impl SimController {
    /// Binds the controller's socket and starts sending.
    pub fn spawn(cfg: SimConfig, clock: RsiClock) -> io::Result<SimController> {
        Self::spawn_inner(cfg, clock, None)
    }

    /// Like [`SimController::spawn`], but the robot follows `truth`'s
    /// programmed path (`cfg.nominal` and the error fields are not used):
    /// each cycle samples, at its start, `RSol` = the programmed pose (with
    /// the correction when `rsol_includes_correction`) and `RIst` = the
    /// robot's belief, programmed ∘ correction; the true TCP is the path's
    /// kinematic error applied to that belief. Every cycle is recorded in
    /// `truth`; the report's `errors` are the true TCP against the
    /// programmed pose.
    pub fn spawn_on_path(
        cfg: SimConfig,
        clock: RsiClock,
        truth: Arc<PathTruth>,
    ) -> io::Result<SimController> {
        Self::spawn_inner(cfg, clock, Some(truth))
    }

    /// The truth of a path run (`None` for a fixed nominal pose).
    pub fn truth(&self) -> Option<&Arc<PathTruth>> {
        self.truth.as_ref()
    }

    fn spawn_inner(
        cfg: SimConfig,
        clock: RsiClock,
        truth: Option<Arc<PathTruth>>,
    ) -> io::Result<SimController> {
        let socket = UdpSocket::bind(cfg.bind)?;
        let local = socket.local_addr()?;
        let start_s = clock.now_s();
        let state = Arc::new(Mutex::new(RobotState {
            cycle: 0,
            total: [0.0; 6],
            actual: actual_pose(&cfg, &[0.0; 6], 0.0),
            time_s: start_s,
        }));
        let stop = Arc::new(AtomicBool::new(false));
        let finished = Arc::new(AtomicBool::new(false));
        let (st, sp, fin) = (state.clone(), stop.clone(), finished.clone());
        let tr = truth.clone();
        let handle = std::thread::Builder::new()
            .name("rsi-sim-controller".into())
            .spawn(move || {
                let r = run(cfg, clock, socket, st, sp, tr.as_deref());
                if let Some(t) = &tr {
                    t.finish();
                }
                fin.store(true, Ordering::Relaxed);
                r
            })?;
        Ok(SimController {
            state,
            finished,
            stop,
            handle: Some(handle),
            local,
            truth,
        })
    }

    /// The controller's own address (the sender the server sees).
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// A view for other threads.
    pub fn probe(&self) -> SimProbe {
        SimProbe {
            state: self.state.clone(),
            finished: self.finished.clone(),
        }
    }

    /// The robot's state now.
    pub fn state(&self) -> RobotState {
        self.probe().state()
    }

    /// The run has ended (cycles done, timeout or stop).
    pub fn is_finished(&self) -> bool {
        self.finished.load(Ordering::Relaxed)
    }

    /// Waits for the run to end and returns its report.
    pub fn join(mut self) -> io::Result<SimReport> {
        self.handle
            .take()
            .expect("joined once")
            .join()
            .map_err(|_| io::Error::other("simulated controller panicked"))?
    }

    /// Stops early and returns the report.
    pub fn stop(self) -> io::Result<SimReport> {
        self.stop.store(true, Ordering::Relaxed);
        self.join()
    }
}

impl Drop for SimController {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn run(
    cfg: SimConfig,
    clock: RsiClock,
    socket: UdpSocket,
    state: Arc<Mutex<RobotState>>,
    stop: Arc<AtomicBool>,
    truth: Option<&PathTruth>,
) -> io::Result<SimReport> {
    let mut report = SimReport::default();
    let start = Instant::now();
    let t0 = clock.at(start);
    let mut total = [0.0; 6];
    let mut msg = String::with_capacity(1024);
    let mut buf = vec![0u8; 70_000];
    if let Some(p) = cfg.realtime_priority {
        if let Err(e) = crate::server::set_realtime_priority(p) {
            tracing::warn!(target: "photopose::rsi", "simulated controller without SCHED_FIFO: {e}");
        }
    }
    let mut k: u64 = 0;
    while k < cfg.cycles {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let mut deadline = start + cfg.cycle * k as u32;
        let now = Instant::now();
        if let Some(d) = deadline.checked_duration_since(now) {
            std::thread::sleep(d);
        } else if now - deadline > cfg.cycle / 2 {
            // This thread was not scheduled in time (a loaded test machine;
            // a real controller is hard real-time): the clock moved on, so
            // skip to the next slot instead of sending late and blaming the
            // sensor for a short reply window.
            let slots = ((now - deadline).as_nanos() / cfg.cycle.as_nanos()) as u64 + 1;
            report.skipped += slots.min(cfg.cycles - k);
            k += slots;
            if k >= cfg.cycles {
                break;
            }
            deadline = start + cfg.cycle * k as u32;
            if let Some(d) = deadline.checked_duration_since(Instant::now()) {
                std::thread::sleep(d);
            }
        }
        let next = deadline + cfg.cycle;
        let now_s = clock.now_s();
        // The programmed pose, the robot's belief (RIst) and its true TCP,
        // all sampled at the start of the cycle.
        let (programmed, believed, actual) = match truth {
            Some(path) => {
                // Sampled at the start of the cycle, `sample_lead` before
                // the datagram leaves.
                let sampled_s = now_s - cfg.sample_lead.as_secs_f64();
                let start = path.push(CycleTruth {
                    time_s: sampled_s,
                    total,
                });
                let tcp = path.tcp(sampled_s - start, total);
                (tcp.programmed, tcp.believed, tcp.actual)
            }
            None => {
                let programmed = pose_to_isometry(&cfg.nominal);
                let believed = apply_correction(&programmed, &total, cfg.frame);
                (programmed, believed, actual_pose(&cfg, &total, now_s - t0))
            }
        };
        let rsol = if cfg.rsol_includes_correction {
            isometry_to_pose(&believed)
        } else {
            isometry_to_pose(&programmed)
        };
        // The fixed-pose robot reports its true TCP as RIst (as before);
        // the path robot its belief.
        let rist = if truth.is_some() { believed } else { actual };
        let ipoc = cfg.ipoc_start + k * cfg.ipoc_step;
        msg.clear();
        if k == 0 && cfg.krc2_first_packet {
            msg.push_str(&format!("<Rob Type=\"KUKA\"><IPOC>{ipoc}</IPOC></Rob>"));
        } else {
            msg.push_str("<Rob Type=\"KUKA\">");
            fmt_pose(&mut msg, "RIst", &isometry_to_pose(&rist));
            fmt_pose(&mut msg, "RSol", &rsol);
            msg.push_str(&format!(
                "<Delay D=\"{}\"/><IPOC>{ipoc}</IPOC></Rob>",
                report.late + report.mismatched
            ));
        }
        socket.send_to(msg.as_bytes(), cfg.server)?;
        report.cycles += 1;
        // Never wait on an observer: skip the update if one holds the lock.
        if let Ok(mut s) = state.try_lock() {
            s.cycle = k;
            s.total = total;
            s.actual = actual;
            s.time_s = now_s;
        }
        let nominal = programmed;
        report.errors.push((
            (actual.translation.vector - nominal.translation.vector).norm(),
            actual.rotation.angle_to(&nominal.rotation).to_degrees(),
        ));
        // Wait for the reply until the next cycle.
        let mut answered: Option<Pose6> = None;
        while let Some(left) = next
            .checked_duration_since(Instant::now())
            .filter(|d| !d.is_zero())
        {
            socket.set_read_timeout(Some(left))?;
            match socket.recv_from(&mut buf) {
                Ok((n, _)) => {
                    match parse_sen(&buf[..n], &cfg.sen.sentype, &cfg.sen.correction_element) {
                        Ok(f) if f.type_matches && f.ipoc.value() == ipoc => match f.correction {
                            Some(c) => {
                                answered = Some(c);
                                break;
                            }
                            None => report.mismatched += 1,
                        },
                        _ => report.mismatched += 1,
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) =>
                {
                    break
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(_) => break, // ICMP errors: no reply this cycle
            }
        }
        if answered.is_none() {
            // This thread may itself have woken late: a reply already queued
            // arrived in time.
            socket.set_nonblocking(true)?;
            while let Ok((n, _)) = socket.recv_from(&mut buf) {
                match parse_sen(&buf[..n], &cfg.sen.sentype, &cfg.sen.correction_element) {
                    Ok(f) if f.type_matches && f.ipoc.value() == ipoc && f.correction.is_some() => {
                        answered = f.correction;
                    }
                    _ => report.mismatched += 1,
                }
            }
            socket.set_nonblocking(false)?;
        }
        let before = total;
        match answered {
            Some(c) => match cfg.mode {
                CorrectionMode::Relative => (0..6).for_each(|i| total[i] += c[i]),
                CorrectionMode::Absolute => total = c,
            },
            // HOLDON: absolute keeps the last value, relative adds nothing.
            None => {
                report.late += 1;
                report.late_cycles.push(k);
            }
        }
        for i in 0..6 {
            report.max_step[i] = report.max_step[i].max((total[i] - before[i]).abs());
            report.max_total[i] = report.max_total[i].max(total[i].abs());
        }
        report.times.push(now_s);
        report.totals.push(total);
        if report.late + report.mismatched > cfg.timeout {
            report.stopped_by_timeout = true;
            break;
        }
        k += 1;
    }
    report.delay = report.late + report.mismatched;
    report.total = total;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Along X at 10 mm/s; the true TCP 0.1 mm above the belief.
    struct Line;

    impl RobotPath for Line {
        fn programmed(&self, t: f64) -> Isometry3<f64> {
            pose_to_isometry(&[10.0 * t, 0.0, 500.0, 0.0, 0.0, 180.0])
        }
        fn actual(&self, _t: f64, believed: &Isometry3<f64>) -> Isometry3<f64> {
            apply_correction(believed, &[0.0, 0.0, 0.1, 0.0, 0.0, 0.0], CorrFrame::Base)
        }
    }

    #[test]
    fn the_truth_holds_each_cycles_correction_until_the_next() {
        let truth = PathTruth::new(Arc::new(Line), CorrFrame::Base, 3);
        assert_eq!(truth.at(5.0), None);
        assert_eq!(truth.known_until_s(), None);
        for (k, x) in [(0, 0.0), (1, 0.01), (2, 0.02), (3, 0.03)] {
            truth.push(CycleTruth {
                time_s: 5.0 + 0.004 * k as f64,
                total: [x, 0.0, 0.0, 0.0, 0.0, 0.0],
            });
        }
        assert_eq!(truth.start_s(), Some(5.0));
        assert_eq!(truth.known_until_s(), Some(5.012));
        // Three cycles kept: the oldest one's total before them.
        assert_eq!(truth.total_at(5.0061)[0], 0.01);
        assert_eq!(truth.total_at(5.0081)[0], 0.02);
        assert_eq!(truth.total_at(6.0)[0], 0.03);
        let tcp = truth.at(5.0101).unwrap();
        assert!((tcp.t - 0.0101).abs() < 1e-12);
        let p = tcp.programmed.translation.vector;
        let b = tcp.believed.translation.vector;
        let a = tcp.actual.translation.vector;
        assert!((p.x - 0.101).abs() < 1e-9);
        assert!((b.x - p.x - 0.02).abs() < 1e-9);
        assert!((a.z - b.z - 0.1).abs() < 1e-9);
        truth.finish();
        assert_eq!(truth.known_until_s(), Some(f64::INFINITY));
    }
}
