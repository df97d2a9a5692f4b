//! The correction law: from the latest camera pose (in the plate frame) and
//! the controller's commanded TCP pose to the Cartesian correction sent in
//! this RSI cycle. Pure: the time of the cycle and of the measurement are
//! passed in, seconds on one monotonic clock (the daemon uses
//! `CLOCK_MONOTONIC`, see `crate::server::RsiClock`).
//!
//! # Time
//! Every cycle goes into a history (sized from `max_age` and the cycle):
//! the instant the controller sampled its `RIst`/`RSol` on the host clock
//! (the datagram's arrival minus the configured controller latency), the
//! IPOC (the controller's own clock), `RSol` and the total correction in
//! effect during that cycle. A measurement is compared with the programmed
//! pose *at its exposure instant*: interpolated between the two cycles
//! that bracket it (translation linearly, rotation by slerp), or carried
//! on from the last two cycles when it lies less than one cycle after the
//! newest. The total correction is taken from the earlier of the two: the
//! controller applies a correction as a step at the start of a cycle and
//! holds it until the next, so the correction acting on the robot at any
//! instant between two samples is the earlier cycle's. A measurement
//! exposed less than a cycle before the oldest cycle kept (just before the
//! session's first datagram) takes the oldest cycle's pose; one exposed
//! earlier is stale ([`StaleReason::BeforeHistory`]); one exposed more
//! than a cycle after the newest is not used yet
//! ([`StaleReason::AheadOfHistory`]: a clock or latency setting is wrong,
//! or the controller paused).
//!
//! Per cycle:
//! 1. the measured TCP is `Z · T_plate←camera · X⁻¹` ([`HandEye`]);
//! 2. a measurement that is too old, shows too few targets or is too
//!    uncertain is *stale*: the correction freezes (absolute mode keeps
//!    sending the held total, relative mode sends zero) and the status says
//!    why;
//! 3. each *new* measurement updates a target total correction: the total
//!    that was in effect when the frame was taken plus `gain` times the
//!    error between the commanded pose of that cycle and the measured pose,
//!    expressed in the POSCORR frame (Base or Tool), clamped to the total
//!    limits (an integrating controller whose fixed point is zero error);
//! 4. every cycle the total moves towards the target by at most the
//!    per-cycle slew limit (so a camera at 25 Hz drives a 250 Hz loop
//!    smoothly, and resuming after a freeze never jumps);
//! 5. relative mode sends the increment of this cycle, absolute mode the total.
//!
//! The total lives on the grid of the printed decimals (integer units of
//! `10^-decimals`): a step is rounded onto the grid and the remainder stays
//! in the distance to the target, so the sum of the increments a relative
//! controller integrates is exactly the law's total, and neither a printed
//! step nor a printed total ever exceeds the slew limit or the clamp.
//!
//! Every candidate correction is checked before it enters the total: a
//! non-finite or implausible error (a broken hand-eye or measurement), or a
//! value outside the clamp or slew limit, freezes the correction
//! ([`LawStatus::FrozenInvalid`]) and leaves the total as it was.
//!
//! Corrections are 6-vectors `X, Y, Z` (mm), `A, B, C` (degrees, KUKA
//! `Rz(A)·Ry(B)·Rx(C)` of the correction rotation).

use crate::codec::Pose6;
use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use photopose_geometry::pose;
use photopose_geometry::rotation::{kuka_abc_deg_from_matrix, matrix_from_kuka_abc_deg};
use photopose_geometry::ResectionReport;

/// RSI correction mode (`RSI_ON(#RELATIVE | #ABSOLUTE)`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CorrectionMode {
    /// Each reply is this cycle's increment, integrated by the controller
    /// (pair with `HOLDON="0"`).
    Relative,
    /// Each reply is the total offset from the pose at RSI start (pair with
    /// `HOLDON="1"`).
    Absolute,
}

/// The frame the controller applies `RKorr` in (POSCORR `RefCorrSys`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CorrFrame {
    /// Robot base frame: translations along and rotations about base axes.
    Base,
    /// Tool frame: translations along and rotations about the TCP's axes.
    Tool,
}

/// The law's parameters (validated by [`crate::config`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LawConfig {
    /// Relative or absolute corrections.
    pub mode: CorrectionMode,
    /// POSCORR frame.
    pub frame: CorrFrame,
    /// Share of the measured error taken per new measurement, (0, 1].
    pub gain: f64,
    /// Largest change of any translation component per cycle, mm.
    pub max_step_mm: f64,
    /// Largest change of any angle component per cycle, degrees.
    pub max_step_deg: f64,
    /// Largest total translation component, mm.
    pub clamp_mm: f64,
    /// Largest total angle component, degrees.
    pub clamp_deg: f64,
    /// A measurement older than this is stale, s.
    pub max_age_s: f64,
    /// A measurement with fewer targets is stale.
    pub min_targets: u32,
    /// A measurement whose largest position std exceeds this is stale, mm.
    pub max_std_mm: f64,
    /// A measurement whose largest rotation std exceeds this is stale, degrees.
    pub max_std_deg: f64,
    /// Answer with zero correction, only measure (commissioning).
    pub measure_only: bool,
    /// The controller's `RSol` already contains the RSI correction (the law
    /// then removes its own total to get the programmed pose).
    pub rsol_includes_correction: bool,
    /// Decimals printed in the reply (the grid of the total), 4–6.
    pub decimals: u32,
    /// The controller's cycle, s: the history covers `max_age_s` in
    /// cycles of this length, and a measurement may lie up to one cycle
    /// after the newest.
    pub cycle_s: f64,
    /// How long before a datagram's arrival the controller sampled its
    /// `RIst`/`RSol` (the start of its cycle), s.
    pub controller_latency_s: f64,
    /// Feed-forward of the error's rate: the error is predicted from the
    /// exposure instant to this cycle's sample instant from the rate of
    /// the last two measurements (off by default; see `docs/rsi.md`).
    pub feed_forward: bool,
    /// Compare a measurement with the programmed pose at its exposure
    /// instant (on by default). Off, the law compares it with the newest
    /// cycle's pose and total, as a system that ignores the frame's age
    /// would: the contrast of `photopose demo` (see `docs/rsi.md`).
    pub compensate_latency: bool,
}

impl Default for LawConfig {
    fn default() -> Self {
        LawConfig {
            mode: CorrectionMode::Relative,
            frame: CorrFrame::Base,
            gain: 0.5,
            max_step_mm: 0.05,
            max_step_deg: 0.005,
            clamp_mm: 4.0,
            clamp_deg: 2.0,
            max_age_s: 0.2,
            min_targets: 8,
            max_std_mm: 0.1,
            max_std_deg: 0.02,
            measure_only: false,
            rsol_includes_correction: false,
            decimals: 4,
            cycle_s: 0.004,
            controller_latency_s: 0.001,
            feed_forward: false,
            compensate_latency: true,
        }
    }
}

/// Largest plausible magnitude of a translation error, mm: a larger error
/// comes from a broken hand-eye or measurement, never from a robot, and
/// freezes the correction ([`LawStatus::FrozenInvalid`]).
pub const MAX_ERROR_MM: f64 = 1.0e5;

/// The two calibrated transforms that take a camera pose to a TCP pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandEye {
    /// `X = T_tcp←camera`: the camera's pose in the TCP frame.
    pub tcp_from_camera: Isometry3<f64>,
    /// `Z = T_base←plate`: the plate's pose in the robot's base frame.
    pub base_from_plate: Isometry3<f64>,
}

impl HandEye {
    /// The TCP pose in the base frame given the camera's pose in the plate
    /// frame: `Z · T_plate←camera · X⁻¹`.
    pub fn tcp_in_base(&self, plate_from_camera: &Isometry3<f64>) -> Isometry3<f64> {
        self.base_from_plate * plate_from_camera * self.tcp_from_camera.inverse()
    }

    /// The camera pose in the plate frame of a TCP pose in the base frame
    /// (the inverse of [`HandEye::tcp_in_base`]).
    pub fn camera_in_plate(&self, base_from_tcp: &Isometry3<f64>) -> Isometry3<f64> {
        self.base_from_plate.inverse() * base_from_tcp * self.tcp_from_camera
    }
}

/// One camera measurement as the vision side publishes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// The camera's pose in the plate frame (`T_plate←camera`).
    pub plate_from_camera: Isometry3<f64>,
    /// Largest standard deviation of the projection centre, mm.
    pub std_mm: f64,
    /// Largest standard deviation of the rotation, degrees.
    pub std_deg: f64,
    /// Targets used in the pose.
    pub n_targets: u32,
    /// When the frame was exposed, s on the law's clock.
    pub time_s: f64,
    /// Sequence number, increasing with each publication.
    pub seq: u64,
}

impl Measurement {
    /// From a resection report (the camera pose is `(Rᵀ, centre)`).
    pub fn from_report(report: &ResectionReport, time_s: f64, seq: u64) -> Measurement {
        let e = &report.exterior;
        Measurement {
            plate_from_camera: pose::camera_pose(e),
            std_mm: report.std_center().max(),
            std_deg: report.std_rotation_deg().max(),
            n_targets: report.n_points as u32,
            time_s,
            seq,
        }
    }
}

/// An isometry from a rotation matrix and a translation.
pub fn isometry(r: &Matrix3<f64>, t: &Vector3<f64>) -> Isometry3<f64> {
    pose::isometry_from_matrix(r, t)
}

/// A KUKA pose `X, Y, Z, A, B, C` as an isometry (frame in its parent).
pub fn pose_to_isometry(p: &Pose6) -> Isometry3<f64> {
    pose::isometry_from_xyzabc(*p)
}

/// An isometry as a KUKA pose `X, Y, Z, A, B, C`.
pub fn isometry_to_pose(iso: &Isometry3<f64>) -> Pose6 {
    pose::xyzabc_from_isometry(iso)
}

/// Applies a correction `c` to a pose as the controller does in `frame`:
/// Base: `p + c_t`, `Rot(c) · R`; Tool: `p + R · c_t`, `R · Rot(c)`.
pub fn apply_correction(pose: &Isometry3<f64>, c: &Pose6, frame: CorrFrame) -> Isometry3<f64> {
    let rc = matrix_from_kuka_abc_deg(c[3], c[4], c[5]);
    let r = *pose.rotation.to_rotation_matrix().matrix();
    let t = pose.translation.vector;
    let ct = Vector3::new(c[0], c[1], c[2]);
    match frame {
        CorrFrame::Base => isometry(&(rc * r), &(t + ct)),
        CorrFrame::Tool => isometry(&(r * rc), &(t + r * ct)),
    }
}

/// Removes a correction applied by [`apply_correction`].
pub fn remove_correction(pose: &Isometry3<f64>, c: &Pose6, frame: CorrFrame) -> Isometry3<f64> {
    let rc = matrix_from_kuka_abc_deg(c[3], c[4], c[5]);
    let r = *pose.rotation.to_rotation_matrix().matrix();
    let t = pose.translation.vector;
    let ct = Vector3::new(c[0], c[1], c[2]);
    match frame {
        CorrFrame::Base => isometry(&(rc.transpose() * r), &(t - ct)),
        CorrFrame::Tool => {
            let r0 = r * rc.transpose();
            isometry(&r0, &(t - r0 * ct))
        }
    }
}

/// The correction (in `frame`, first order) that moves `measured` onto
/// `commanded`.
pub fn pose_error(
    commanded: &Isometry3<f64>,
    measured: &Isometry3<f64>,
    frame: CorrFrame,
) -> Pose6 {
    let rc = *commanded.rotation.to_rotation_matrix().matrix();
    let rm = *measured.rotation.to_rotation_matrix().matrix();
    let dt = commanded.translation.vector - measured.translation.vector;
    let (t, re) = match frame {
        CorrFrame::Base => (dt, rc * rm.transpose()),
        CorrFrame::Tool => (rm.transpose() * dt, rm.transpose() * rc),
    };
    let [a, b, c] = kuka_abc_deg_from_matrix(&re);
    [t.x, t.y, t.z, a, b, c]
}

/// Why a measurement was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StaleReason {
    /// Nothing was published yet.
    NoMeasurement,
    /// The latest measurement is older than the configured age.
    TooOld,
    /// The latest measurement used fewer targets than configured.
    TooFewTargets,
    /// The latest measurement's std exceeds the configured threshold.
    TooUncertain,
    /// The datagram carried no `RSol` (KR C2's first datagram, or `RSol`
    /// missing from the SEND list), or a cycle around the exposure did not.
    NoCommand,
    /// The measurement was exposed before the oldest cycle in the history
    /// (the controller session started after it, or it is older than the
    /// history holds).
    BeforeHistory,
    /// The measurement was exposed more than a cycle after the newest
    /// cycle: a clock or latency setting is wrong, or the controller
    /// paused; looked at again next cycle.
    AheadOfHistory,
}

/// The state of the law in a cycle (also the pose stream's status flag).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LawStatus {
    /// Correcting from a fresh measurement.
    Tracking,
    /// Frozen: absolute holds, relative sends zero.
    Stale(StaleReason),
    /// Measure-only mode: zero correction.
    MeasureOnly,
    /// Frozen because the computed correction was not finite or outside the
    /// limits (e.g. a broken hand-eye file): absolute holds, relative sends
    /// zero, and the value never enters the total.
    FrozenInvalid,
}

impl LawStatus {
    /// A short stable name (`tracking`, `stale_too_old`, ...).
    pub fn name(&self) -> &'static str {
        match self {
            LawStatus::Tracking => "tracking",
            LawStatus::MeasureOnly => "measure_only",
            LawStatus::FrozenInvalid => "frozen_invalid",
            LawStatus::Stale(StaleReason::NoMeasurement) => "stale_no_measurement",
            LawStatus::Stale(StaleReason::TooOld) => "stale_too_old",
            LawStatus::Stale(StaleReason::TooFewTargets) => "stale_too_few_targets",
            LawStatus::Stale(StaleReason::TooUncertain) => "stale_too_uncertain",
            LawStatus::Stale(StaleReason::NoCommand) => "stale_no_command",
            LawStatus::Stale(StaleReason::BeforeHistory) => "stale_before_history",
            LawStatus::Stale(StaleReason::AheadOfHistory) => "stale_ahead_of_history",
        }
    }

    /// A small integer code (0 tracking, 1 measure only, 2..=6 stale
    /// reasons, 7 frozen invalid, 8 and 9 the history's stale reasons), for
    /// an atomic status flag.
    pub fn code(&self) -> u8 {
        match self {
            LawStatus::Tracking => 0,
            LawStatus::MeasureOnly => 1,
            LawStatus::Stale(StaleReason::NoMeasurement) => 2,
            LawStatus::Stale(StaleReason::TooOld) => 3,
            LawStatus::Stale(StaleReason::TooFewTargets) => 4,
            LawStatus::Stale(StaleReason::TooUncertain) => 5,
            LawStatus::Stale(StaleReason::NoCommand) => 6,
            LawStatus::FrozenInvalid => 7,
            LawStatus::Stale(StaleReason::BeforeHistory) => 8,
            LawStatus::Stale(StaleReason::AheadOfHistory) => 9,
        }
    }

    /// The inverse of [`LawStatus::code`].
    pub fn from_code(code: u8) -> Option<LawStatus> {
        Some(match code {
            0 => LawStatus::Tracking,
            1 => LawStatus::MeasureOnly,
            2 => LawStatus::Stale(StaleReason::NoMeasurement),
            3 => LawStatus::Stale(StaleReason::TooOld),
            4 => LawStatus::Stale(StaleReason::TooFewTargets),
            5 => LawStatus::Stale(StaleReason::TooUncertain),
            6 => LawStatus::Stale(StaleReason::NoCommand),
            7 => LawStatus::FrozenInvalid,
            8 => LawStatus::Stale(StaleReason::BeforeHistory),
            9 => LawStatus::Stale(StaleReason::AheadOfHistory),
            _ => return None,
        })
    }
}

/// What the law decided in one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleOutput {
    /// The values to put in the reply's correction element.
    pub send: Pose6,
    /// The total correction in effect after this cycle.
    pub total: Pose6,
    /// The law's state.
    pub status: LawStatus,
    /// The error of the measurement used this cycle (new ones only), in the
    /// POSCORR frame.
    pub error: Option<Pose6>,
    /// The per-cycle slew limit cut this cycle's step.
    pub slew_limited: bool,
    /// The total clamp cut the target this cycle.
    pub clamped: bool,
    /// The programmed pose the measurement of this cycle was compared with
    /// (new measurements only): interpolated at its exposure instant.
    pub commanded: Option<Pose6>,
    /// The IPOCs of the two cycles it was interpolated between.
    pub commanded_ipoc: Option<(u64, u64)>,
}

/// One controller cycle as the history keeps it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Past {
    /// When the controller sampled `RIst`/`RSol`, s on the law's clock
    /// (arrival minus the controller latency).
    pub time_s: f64,
    /// The controller's IPOC (its own clock; 0 when not given).
    pub ipoc: u64,
    /// The commanded pose, if the datagram carried it.
    pub rsol: Option<Pose6>,
    /// The total correction in effect during this cycle (sent before it).
    pub total: Pose6,
}

/// The least history kept, cycles.
pub const HISTORY_MIN: usize = 64;
/// The most history kept, cycles (about 4.4 min at 4 ms): a `max_age`
/// beyond it is bounded by the history ([`StaleReason::BeforeHistory`]).
pub const HISTORY_MAX: usize = 1 << 16;

/// Cycles of history that cover `max_age_s` (plus a margin of a quarter and
/// eight cycles) at `cycle_s`, within [`HISTORY_MIN`]..=[`HISTORY_MAX`].
pub fn history_len(cfg: &LawConfig) -> usize {
    let n = (cfg.max_age_s * 1.25 / cfg.cycle_s).ceil() + 8.0;
    if n.is_finite() && n > 0.0 {
        (n.min(HISTORY_MAX as f64) as usize).max(HISTORY_MIN)
    } else {
        HISTORY_MIN
    }
}

/// What the history says about an exposure instant.
#[derive(Debug, Clone, Copy)]
struct Then {
    programmed: Isometry3<f64>,
    total: Pose6,
    ipocs: (u64, u64),
}

/// The correction law's state. Allocates its history once, at creation.
#[derive(Debug, Clone)]
pub struct CorrectionLaw {
    cfg: LawConfig,
    hand_eye: HandEye,
    /// The total in units of `1 / scale` (the printed grid).
    units: [i64; 6],
    /// `10^decimals`.
    scale: f64,
    /// Per-cycle slew limit in units.
    step_units: [i64; 6],
    /// Clamp in units.
    clamp_units: [i64; 6],
    target: Pose6,
    last_seq: Option<u64>,
    history: Vec<Past>,
    head: usize,
    filled: usize,
    /// The last used measurement's exposure and uncorrected error (error
    /// plus the total then), for the feed-forward's rate.
    last_error: Option<(f64, Pose6)>,
}

fn step_limits(cfg: &LawConfig) -> Pose6 {
    let (t, r) = (cfg.max_step_mm, cfg.max_step_deg);
    [t, t, t, r, r, r]
}

fn clamp_limits(cfg: &LawConfig) -> Pose6 {
    let (t, r) = (cfg.clamp_mm, cfg.clamp_deg);
    [t, t, t, r, r, r]
}

/// A limit in units of the grid, rounded down (never above the limit; a
/// non-finite or negative limit gives 0: nothing moves).
fn to_units(limit: f64, scale: f64) -> i64 {
    let u = (limit * scale * (1.0 + 1e-12)).floor();
    if u.is_finite() && u > 0.0 {
        u.min(1e15) as i64
    } else {
        0
    }
}

impl CorrectionLaw {
    /// A law with zero correction.
    pub fn new(cfg: LawConfig, hand_eye: HandEye) -> CorrectionLaw {
        let scale = 10f64.powi(cfg.decimals.min(9) as i32);
        CorrectionLaw {
            cfg,
            hand_eye,
            units: [0; 6],
            scale,
            step_units: step_limits(&cfg).map(|l| to_units(l, scale)),
            clamp_units: clamp_limits(&cfg).map(|l| to_units(l, scale)),
            target: [0.0; 6],
            last_seq: None,
            history: vec![
                Past {
                    time_s: f64::NEG_INFINITY,
                    ipoc: 0,
                    rsol: None,
                    total: [0.0; 6],
                };
                history_len(&cfg)
            ],
            head: 0,
            filled: 0,
            last_error: None,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &LawConfig {
        &self.cfg
    }

    /// The total correction in effect.
    pub fn total(&self) -> Pose6 {
        self.units.map(|u| u as f64 / self.scale)
    }

    /// Back to zero correction with no history: a new controller session
    /// (RSI restarted, its corrections start from zero).
    pub fn reset(&mut self) {
        self.units = [0; 6];
        self.target = [0.0; 6];
        self.last_seq = None;
        self.head = 0;
        self.filled = 0;
        self.last_error = None;
    }

    /// Cycles the history holds at most.
    pub fn history_capacity(&self) -> usize {
        self.history.len()
    }

    /// The `k`-th newest cycle of the history (0 = this cycle's).
    pub fn past(&self, k: usize) -> Option<Past> {
        (k < self.filled).then(|| {
            let n = self.history.len();
            self.history[(self.head + n - 1 - k) % n]
        })
    }

    /// What a frozen cycle sends: the held total (absolute) or zero
    /// (relative).
    pub fn hold(&self) -> Pose6 {
        match self.cfg.mode {
            CorrectionMode::Absolute => self.total(),
            CorrectionMode::Relative => [0.0; 6],
        }
    }

    /// Whether `send` may be written into a reply: every value finite and
    /// inside the clamp (absolute) or the slew limit (relative). The server
    /// checks it immediately before writing.
    pub fn admissible(&self, send: &Pose6) -> bool {
        let lim = match self.cfg.mode {
            CorrectionMode::Absolute => self.clamp_units,
            CorrectionMode::Relative => self.step_units,
        };
        send.iter()
            .zip(lim)
            .all(|(v, l)| v.is_finite() && v.abs() <= (l as f64 + 1e-6) / self.scale)
    }

    /// The programmed pose at `t` (interpolated between the cycles that
    /// bracket it, carried on from the last two up to a cycle after the
    /// newest) and the total correction in effect then.
    fn at(&self, t: f64) -> Result<Then, StaleReason> {
        let Some(newest) = self.past(0) else {
            return Err(StaleReason::NoCommand);
        };
        if t.is_nan() {
            return Err(StaleReason::TooOld);
        }
        if t > newest.time_s + self.cfg.cycle_s {
            return Err(StaleReason::AheadOfHistory);
        }
        // The newest cycle sampled at or before t (k), and the one after it:
        // a binary search (the samples are in time order; the history may
        // hold tens of thousands of cycles, the RSI thread has 4 ms).
        let (mut lo, mut hi) = (0, self.filled);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if self.past(mid).is_some_and(|p| p.time_s > t) {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        let k = lo;
        let earlier = match self.past(k) {
            Some(p) => p,
            // Less than a cycle before the oldest (a frame exposed just
            // before the session's first datagram): the oldest cycle's.
            None => match self.past(self.filled - 1) {
                Some(oldest) if t >= oldest.time_s - self.cfg.cycle_s => {
                    let Some(r) = oldest.rsol else {
                        return Err(StaleReason::NoCommand);
                    };
                    return Ok(Then {
                        programmed: self.programmed(&r, &oldest.total),
                        total: oldest.total,
                        ipocs: (oldest.ipoc, oldest.ipoc),
                    });
                }
                _ => return Err(StaleReason::BeforeHistory),
            },
        };
        let (a, b) = if k == 0 {
            // After the newest (less than a cycle): carried on from the
            // last two cycles, or held with only one.
            match self.past(1) {
                Some(p) if p.rsol.is_some() && p.time_s < newest.time_s => (p, newest),
                _ => (newest, newest),
            }
        } else {
            (earlier, self.past(k - 1).unwrap_or(newest))
        };
        let (Some(ra), Some(rb)) = (a.rsol, b.rsol) else {
            return Err(StaleReason::NoCommand);
        };
        let pa = self.programmed(&ra, &a.total);
        let pb = self.programmed(&rb, &b.total);
        let span = b.time_s - a.time_s;
        let f = if span > 0.0 {
            (t - a.time_s) / span
        } else {
            0.0
        };
        Ok(Then {
            programmed: interpolate(&pa, &pb, f),
            total: earlier.total,
            ipocs: (a.ipoc, b.ipoc),
        })
    }

    fn stale_reason(&self, now_s: f64, m: Option<&Measurement>) -> Option<StaleReason> {
        let Some(m) = m else {
            return Some(StaleReason::NoMeasurement);
        };
        let age = now_s - m.time_s;
        if age.is_nan() || age > self.cfg.max_age_s {
            return Some(StaleReason::TooOld);
        }
        if m.n_targets < self.cfg.min_targets {
            return Some(StaleReason::TooFewTargets);
        }
        if m.std_mm.is_nan()
            || m.std_deg.is_nan()
            || m.std_mm > self.cfg.max_std_mm
            || m.std_deg > self.cfg.max_std_deg
        {
            return Some(StaleReason::TooUncertain);
        }
        None
    }

    /// One RSI cycle whose datagram arrived at `now_s`, without an IPOC
    /// (tests and tools): [`CorrectionLaw::cycle_at`] with IPOC 0.
    pub fn cycle(
        &mut self,
        now_s: f64,
        rsol: Option<Pose6>,
        latest: Option<&Measurement>,
    ) -> CycleOutput {
        self.cycle_at(now_s, 0, rsol, latest)
    }

    /// One RSI cycle: the datagram with `ipoc` and `rsol` arrived at
    /// `arrival_s` (the controller sampled it `controller_latency_s`
    /// before), with the latest published measurement.
    pub fn cycle_at(
        &mut self,
        arrival_s: f64,
        ipoc: u64,
        rsol: Option<Pose6>,
        latest: Option<&Measurement>,
    ) -> CycleOutput {
        let now_s = arrival_s;
        // This cycle joins the history first: a frame may have been
        // exposed after the previous sample.
        self.record(arrival_s - self.cfg.controller_latency_s, ipoc, rsol);
        let mut out = CycleOutput {
            send: [0.0; 6],
            total: self.total(),
            status: LawStatus::Tracking,
            error: None,
            slew_limited: false,
            clamped: false,
            commanded: None,
            commanded_ipoc: None,
        };
        if self.cfg.measure_only {
            out.status = LawStatus::MeasureOnly;
            if let (Some(m), Some(_)) = (latest, rsol) {
                if self.last_seq != Some(m.seq) {
                    if let Ok(then) = self.at(self.compared_instant(m.time_s)) {
                        self.last_seq = Some(m.seq);
                        let measured = self.hand_eye.tcp_in_base(&m.plate_from_camera);
                        out.commanded = Some(isometry_to_pose(&then.programmed));
                        out.commanded_ipoc = Some(then.ipocs);
                        out.error = Some(pose_error(&then.programmed, &measured, self.cfg.frame));
                    }
                }
            }
            return out;
        }
        let stale = if rsol.is_none() {
            Some(StaleReason::NoCommand)
        } else {
            self.stale_reason(now_s, latest)
        };
        let (Some(m), Some(_), None) = (latest, rsol, stale) else {
            out.status = match stale {
                Some(reason) => LawStatus::Stale(reason),
                None => LawStatus::FrozenInvalid,
            };
            return self.freeze(out);
        };
        if self.last_seq != Some(m.seq) {
            let then = match self.at(self.compared_instant(m.time_s)) {
                Ok(then) => then,
                Err(reason) => {
                    out.status = LawStatus::Stale(reason);
                    return self.freeze(out);
                }
            };
            let total_then = then.total;
            let measured = self.hand_eye.tcp_in_base(&m.plate_from_camera);
            let e = pose_error(&then.programmed, &measured, self.cfg.frame);
            out.error = Some(e);
            out.commanded = Some(isometry_to_pose(&then.programmed));
            out.commanded_ipoc = Some(then.ipocs);
            let uncorrected: Pose6 = std::array::from_fn(|i| e[i] + total_then[i]);
            let lead = self.feed_forward_lead(m.time_s, &uncorrected, arrival_s);
            let lim = clamp_limits(&self.cfg);
            let mut target = [0.0; 6];
            let mut clamped = false;
            for i in 0..6 {
                let t = total_then[i] + self.cfg.gain * (e[i] + lead[i]);
                let c = t.clamp(-lim[i], lim[i]);
                clamped |= c != t;
                target[i] = c;
            }
            let plausible = e[..3].iter().all(|v| v.abs() <= MAX_ERROR_MM)
                && e[3..].iter().all(|v| v.abs() <= 360.0);
            if !plausible || target.iter().any(|v| !v.is_finite()) {
                // Not committed: the next cycle looks at it again (and
                // stays frozen while it is the latest measurement).
                out.status = LawStatus::FrozenInvalid;
                return self.freeze(out);
            }
            out.clamped = clamped;
            self.last_seq = Some(m.seq);
            self.last_error = Some((m.time_s, uncorrected));
            self.target = target;
        }
        // One step towards the target on the grid: the rounding remainder
        // stays in the distance to the target and is taken in later cycles.
        let mut units = self.units;
        for (i, u) in units.iter_mut().enumerate() {
            let want = (self.target[i] * self.scale).round();
            if !want.is_finite() {
                out.status = LawStatus::FrozenInvalid;
                return self.freeze(out);
            }
            let want = want.clamp(-1e15, 1e15) as i64;
            let want = want.clamp(-self.clamp_units[i], self.clamp_units[i]);
            let d = want - self.units[i];
            let step = d.clamp(-self.step_units[i], self.step_units[i]);
            out.slew_limited |= step != d;
            *u = self.units[i] + step;
        }
        let total = units.map(|u| u as f64 / self.scale);
        let send = match self.cfg.mode {
            CorrectionMode::Absolute => total,
            CorrectionMode::Relative => {
                std::array::from_fn(|i| (units[i] - self.units[i]) as f64 / self.scale)
            }
        };
        let inside = (0..6).all(|i| {
            units[i].abs() <= self.clamp_units[i]
                && (units[i] - self.units[i]).abs() <= self.step_units[i]
        });
        if !inside || !self.admissible(&send) {
            out.status = LawStatus::FrozenInvalid;
            return self.freeze(out);
        }
        self.units = units;
        out.total = total;
        out.send = send;
        out
    }

    /// The instant whose programmed pose a measurement exposed at `t` is
    /// compared with: `t` itself, or without latency compensation the
    /// newest cycle's sample instant (a naive system's "now").
    fn compared_instant(&self, t: f64) -> f64 {
        match self.past(0) {
            Some(newest) if !self.cfg.compensate_latency => newest.time_s,
            _ => t,
        }
    }

    /// The feed-forward term: the change of the uncorrected error from the
    /// exposure at `t` to this cycle's sample instant, at the rate between
    /// the last used measurement and this one (zeros when off, on the first
    /// measurement, or when the two are not in time order within
    /// `max_age_s`).
    fn feed_forward_lead(&self, t: f64, uncorrected: &Pose6, arrival_s: f64) -> Pose6 {
        let Some((t0, u0)) = self.last_error.filter(|_| self.cfg.feed_forward) else {
            return [0.0; 6];
        };
        let dt = t - t0;
        let ahead = arrival_s - self.cfg.controller_latency_s - t;
        if !(dt > 0.0 && dt <= self.cfg.max_age_s && ahead.is_finite()) {
            return [0.0; 6];
        }
        let ahead = ahead.clamp(0.0, self.cfg.max_age_s);
        std::array::from_fn(|i| (uncorrected[i] - u0[i]) / dt * ahead)
    }

    /// A frozen cycle: the target is the total, the reply holds.
    fn freeze(&mut self, mut out: CycleOutput) -> CycleOutput {
        self.target = self.total();
        out.send = self.hold();
        out.total = self.total();
        out.clamped = false;
        out.slew_limited = false;
        out
    }

    /// The programmed pose of a cycle from its `RSol` and the total then.
    fn programmed(&self, rsol: &Pose6, total_then: &Pose6) -> Isometry3<f64> {
        let p = pose_to_isometry(rsol);
        if self.cfg.rsol_includes_correction {
            remove_correction(&p, total_then, self.cfg.frame)
        } else {
            p
        }
    }

    /// A cycle into the history, with the total in effect during it (the
    /// one sent before it).
    fn record(&mut self, time_s: f64, ipoc: u64, rsol: Option<Pose6>) {
        let n = self.history.len();
        self.history[self.head] = Past {
            time_s,
            ipoc,
            rsol,
            total: self.total(),
        };
        self.head = (self.head + 1) % n;
        self.filled = (self.filled + 1).min(n);
    }
}

/// The pose a fraction `f` of the way from `a` to `b`: translation linear,
/// rotation along the shortest arc at constant rate (slerp); `f` outside
/// 0..=1 carries the motion on (or back) at the same rates.
pub fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, f: f64) -> Isometry3<f64> {
    let t = a.translation.vector + (b.translation.vector - a.translation.vector) * f;
    let delta = a.rotation.inverse() * b.rotation;
    let r = a.rotation * UnitQuaternion::from_scaled_axis(delta.scaled_axis() * f);
    Isometry3::from_parts(Translation3::from(t), r)
}

/// The largest translation (mm) and angle (degrees) component of a
/// correction.
pub fn magnitude(c: &Pose6) -> (f64, f64) {
    let t = c[..3].iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let r = c[3..].iter().fold(0.0f64, |a, v| a.max(v.abs()));
    (t, r)
}

#[cfg(test)]
mod tests;
