//! The correction law: from the latest camera pose (in the plate frame) and
//! the controller's commanded TCP pose to the Cartesian correction sent in
//! this RSI cycle. Pure: the time of the cycle and of the measurement are
//! passed in (seconds on one monotonic clock chosen by the caller).
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
use nalgebra::{Isometry3, Matrix3, Vector3};
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
    /// missing from the SEND list).
    NoCommand,
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
        }
    }

    /// A small integer code (0 tracking, 1 measure only, 2..=6 stale
    /// reasons, 7 frozen invalid), for an atomic status flag.
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
}

#[derive(Debug, Clone, Copy)]
struct Past {
    time_s: f64,
    rsol: Option<Pose6>,
    total: Pose6,
}

/// Cycles of history kept to look up the commanded pose and the correction
/// in effect when a frame was exposed (2 s at 4 ms).
pub const HISTORY: usize = 512;

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
                    rsol: None,
                    total: [0.0; 6],
                };
                HISTORY
            ],
            head: 0,
            filled: 0,
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

    /// The past cycle at or just before `t` (or the oldest kept).
    fn at(&self, t: f64) -> Option<Past> {
        let mut best = None;
        for k in 0..self.filled {
            let i = (self.head + HISTORY - 1 - k) % HISTORY;
            let p = self.history[i];
            best = Some(p);
            if p.time_s <= t {
                break;
            }
        }
        best
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

    /// One RSI cycle at `now_s` with the datagram's `RSol` and the latest
    /// published measurement.
    pub fn cycle(
        &mut self,
        now_s: f64,
        rsol: Option<Pose6>,
        latest: Option<&Measurement>,
    ) -> CycleOutput {
        let mut out = CycleOutput {
            send: [0.0; 6],
            total: self.total(),
            status: LawStatus::Tracking,
            error: None,
            slew_limited: false,
            clamped: false,
        };
        if self.cfg.measure_only {
            out.status = LawStatus::MeasureOnly;
            if let (Some(m), Some(r)) = (latest, rsol) {
                if self.last_seq != Some(m.seq) {
                    self.last_seq = Some(m.seq);
                    let measured = self.hand_eye.tcp_in_base(&m.plate_from_camera);
                    out.error = Some(pose_error(
                        &self.programmed(&r, &[0.0; 6]),
                        &measured,
                        self.cfg.frame,
                    ));
                }
            }
            self.record(now_s, rsol);
            return out;
        }
        let stale = if rsol.is_none() {
            Some(StaleReason::NoCommand)
        } else {
            self.stale_reason(now_s, latest)
        };
        let (Some(m), Some(rsol_now), None) = (latest, rsol, stale) else {
            out.status = match stale {
                Some(reason) => LawStatus::Stale(reason),
                None => LawStatus::FrozenInvalid,
            };
            return self.freeze(now_s, rsol, out);
        };
        if self.last_seq != Some(m.seq) {
            let past = self.at(m.time_s);
            let (rsol_then, total_then) = match past {
                Some(Past {
                    rsol: Some(r),
                    total,
                    ..
                }) => (r, total),
                _ => (rsol_now, self.total()),
            };
            let measured = self.hand_eye.tcp_in_base(&m.plate_from_camera);
            let commanded = self.programmed(&rsol_then, &total_then);
            let e = pose_error(&commanded, &measured, self.cfg.frame);
            out.error = Some(e);
            let lim = clamp_limits(&self.cfg);
            let mut target = [0.0; 6];
            let mut clamped = false;
            for i in 0..6 {
                let t = total_then[i] + self.cfg.gain * e[i];
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
                return self.freeze(now_s, rsol, out);
            }
            out.clamped = clamped;
            self.last_seq = Some(m.seq);
            self.target = target;
        }
        // One step towards the target on the grid: the rounding remainder
        // stays in the distance to the target and is taken in later cycles.
        let mut units = self.units;
        for (i, u) in units.iter_mut().enumerate() {
            let want = (self.target[i] * self.scale).round();
            if !want.is_finite() {
                out.status = LawStatus::FrozenInvalid;
                return self.freeze(now_s, rsol, out);
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
            return self.freeze(now_s, rsol, out);
        }
        self.units = units;
        out.total = total;
        out.send = send;
        self.record(now_s, rsol);
        out
    }

    /// A frozen cycle: the target is the total, the reply holds.
    fn freeze(&mut self, now_s: f64, rsol: Option<Pose6>, mut out: CycleOutput) -> CycleOutput {
        self.target = self.total();
        out.send = self.hold();
        out.total = self.total();
        out.clamped = false;
        out.slew_limited = false;
        self.record(now_s, rsol);
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

    fn record(&mut self, now_s: f64, rsol: Option<Pose6>) {
        self.history[self.head] = Past {
            time_s: now_s,
            rsol,
            total: self.total(),
        };
        self.head = (self.head + 1) % HISTORY;
        self.filled = (self.filled + 1).min(HISTORY);
    }
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
