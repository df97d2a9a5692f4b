//! Exposure control for a camera source: the control law that holds the
//! brightest targets' peak grey value at a configured share of full scale
//! ([`ExposureLaw`], pure: the caller passes each measurement and the
//! exposure in effect; no IO, no clock), the per-frame measurement it is
//! fed (the 90th percentile of the identified targets' peaks,
//! [`frame_peak`]; each target's peak is its blob's brightest pixel, which
//! the detector measures),
//! and the lock-free link between the detection workers that measure and
//! the source that steers ([`ExposureLink`]: the newest frame's
//! measurement, the exposure in effect and the counts of feature writes,
//! exported as metrics).
//!
//! # The law
//! A retro-reflective target under a ring light returns a signal
//! proportional to the exposure time until it clips, so the law works on
//! ratios: with the frame's peak `p` (a fraction of full scale) and the
//! target `T`, the next exposure is the current one times `(T / p)^gain`,
//! the factor limited to `[1 / max_step_ratio, max_step_ratio]` and the
//! result clamped to `[min_us, max_us]`. On a linear sensor the log
//! distance to the target shrinks by `1 - gain` per step: the approach is
//! monotone and never overshoots for `0 < gain ≤ 1`. Inside the dead band
//! (`|p / T - 1| ≤ dead_band`) nothing changes, so a settled loop stays
//! put. A clipped peak (`p ≥ 1`) says only that the signal is too strong,
//! not by how much: the exposure steps down by the whole step limit. The
//! law acts on every `every_frames`-th measurement it is given; a frame
//! without targets gives no measurement, and a non-finite or absurd input
//! changes nothing (and is not counted).

use photopose_telemetry::{Collect, Counter, Gauge, Scrape};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use thiserror::Error;

/// The measurement a saturated (clipped) target counts as: above full
/// scale, so that a frame whose 90th-percentile target is clipped reads as
/// saturated.
pub const SATURATED_PEAK: f32 = 2.0;

/// The share of a frame's targets at or below the peak the law holds (the
/// brightest tenth may exceed it: one odd reflection does not steer).
pub const PEAK_QUANTILE: f64 = 0.9;

/// A change of less than this ratio is no change (cameras round the
/// exposure time; a write that moves nothing costs a register access).
const LEAST_CHANGE: f64 = 1e-3;

/// The settings of the loop (`[source.gige.exposure_control]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExposureSettings {
    /// The peak held, fraction of full scale, in (0, 1).
    pub target_peak: f64,
    /// Shortest exposure the loop sets, µs (> 0).
    pub min_us: f64,
    /// Longest exposure the loop sets, µs (≥ `min_us`).
    pub max_us: f64,
    /// Share of the (logarithmic) distance to the target corrected per
    /// step, in (0, 1]: 1 goes there in one step, less damps.
    pub gain: f64,
    /// Largest change of one step, as a ratio (> 1): 2 at most doubles or
    /// halves the exposure.
    pub max_step_ratio: f64,
    /// Relative deviation of the peak from `target_peak` left alone, in
    /// [0, 1): 0.1 holds the exposure while the peak is within ±10 % of
    /// the target.
    pub dead_band: f64,
    /// The law acts on every this many measured frames (≥ 1).
    pub every_frames: u32,
}

impl Default for ExposureSettings {
    fn default() -> Self {
        ExposureSettings {
            target_peak: 0.8,
            min_us: 20.0,
            max_us: 20_000.0,
            gain: 0.5,
            max_step_ratio: 2.0,
            dead_band: 0.1,
            every_frames: 4,
        }
    }
}

/// A setting of the loop out of its range.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum SettingsError {
    /// `key` (a key of `[source.gige.exposure_control]`) has `value`,
    /// which `reason` says is out of range.
    #[error("exposure_control.{key} = {value}: {reason}")]
    OutOfRange {
        /// The key, e.g. `max_us`.
        key: &'static str,
        /// The value given.
        value: f64,
        /// The range it must be in.
        reason: &'static str,
    },
}

/// Longest exposure the loop may be asked to set, µs (10 s).
pub const MAX_EXPOSURE_US: f64 = 1e7;

impl ExposureSettings {
    /// Checks every setting's range, naming the first one out of it.
    pub fn check(&self) -> Result<(), SettingsError> {
        let out = |key, value, reason| Err(SettingsError::OutOfRange { key, value, reason });
        let t = self.target_peak;
        if !(t.is_finite() && t > 0.0 && t < 1.0) {
            return out(
                "target_peak",
                t,
                "must be in (0, 1) (a fraction of full scale)",
            );
        }
        if !(self.min_us.is_finite() && self.min_us > 0.0 && self.min_us <= MAX_EXPOSURE_US) {
            return out("min_us", self.min_us, "must be in (0, 1e7] µs");
        }
        if !(self.max_us.is_finite()
            && self.max_us >= self.min_us
            && self.max_us <= MAX_EXPOSURE_US)
        {
            return out("max_us", self.max_us, "must be in [min_us, 1e7] µs");
        }
        if !(self.gain.is_finite() && self.gain > 0.0 && self.gain <= 1.0) {
            return out("gain", self.gain, "must be in (0, 1]");
        }
        let r = self.max_step_ratio;
        if !(r.is_finite() && r > 1.0 && r <= 100.0) {
            return out("max_step_ratio", r, "must be in (1, 100]");
        }
        if !(self.dead_band.is_finite() && (0.0..1.0).contains(&self.dead_band)) {
            return out("dead_band", self.dead_band, "must be in [0, 1)");
        }
        if !(1..=100_000).contains(&self.every_frames) {
            return out(
                "every_frames",
                f64::from(self.every_frames),
                "must be 1..=100000",
            );
        }
        Ok(())
    }
}

/// What the law asks of the camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Step {
    /// Leave the exposure as it is.
    Hold,
    /// Set the exposure to this many µs (finite, within the limits).
    Set(f64),
}

/// The control law (see the module docs): fed one measurement per frame,
/// it answers with the next exposure or [`Step::Hold`].
#[derive(Debug, Clone)]
pub struct ExposureLaw {
    settings: ExposureSettings,
    /// Measurements counted since the law last acted.
    counted: u32,
}

impl ExposureLaw {
    /// A law with `settings` (checked: [`ExposureSettings::check`]).
    pub fn new(settings: ExposureSettings) -> Result<ExposureLaw, SettingsError> {
        settings.check()?;
        Ok(ExposureLaw {
            settings,
            counted: 0,
        })
    }

    /// Its settings (limits narrowed by [`ExposureLaw::limit_to`]).
    pub fn settings(&self) -> &ExposureSettings {
        &self.settings
    }

    /// Narrows the limits to what a camera accepts, `[lo, hi]` µs;
    /// `false` (limits unchanged) when the two ranges do not meet or the
    /// camera's is not a range.
    pub fn limit_to(&mut self, lo: f64, hi: f64) -> bool {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return false;
        }
        let (min, max) = (self.settings.min_us.max(lo), self.settings.max_us.min(hi));
        if !(min.is_finite() && max.is_finite() && min > 0.0 && min <= max) {
            return false;
        }
        self.settings.min_us = min;
        self.settings.max_us = max;
        true
    }

    /// `us` clamped to the limits (a non-finite or non-positive value
    /// gives the lower limit).
    pub fn clamp(&self, us: f64) -> f64 {
        if us.is_finite() && us > 0.0 {
            us.clamp(self.settings.min_us, self.settings.max_us)
        } else {
            self.settings.min_us
        }
    }

    /// Forgets the measurements counted towards the next action (after
    /// the camera was reopened).
    pub fn reset(&mut self) {
        self.counted = 0;
    }

    /// One frame's measurement: `peak`, its targets' peak as a fraction of
    /// full scale (clipped targets counted as [`SATURATED_PEAK`]), taken
    /// with the exposure `current_us` in effect. Acts on every
    /// `every_frames`-th valid measurement; an input that is not finite,
    /// a peak outside `(0, SATURATED_PEAK]` or an exposure that is not
    /// positive changes nothing and is not counted.
    pub fn observe(&mut self, peak: f64, current_us: f64) -> Step {
        if !valid(peak, current_us) {
            return Step::Hold;
        }
        self.counted += 1;
        if self.counted < self.settings.every_frames {
            return Step::Hold;
        }
        self.counted = 0;
        let next = self.next_exposure(peak, current_us);
        if (next / current_us - 1.0).abs() < LEAST_CHANGE {
            Step::Hold
        } else {
            Step::Set(next)
        }
    }

    /// The exposure the law would set after a frame with `peak` taken at
    /// `current_us` (the current one, clamped, when the input is not
    /// valid).
    pub fn next_exposure(&self, peak: f64, current_us: f64) -> f64 {
        if !valid(peak, current_us) {
            return self.clamp(current_us);
        }
        let s = &self.settings;
        let r = s.max_step_ratio;
        let factor = if peak >= 1.0 {
            // Clipped: how far above full scale is not known.
            1.0 / r
        } else if (peak / s.target_peak - 1.0).abs() <= s.dead_band {
            1.0
        } else {
            (s.target_peak / peak).powf(s.gain).clamp(1.0 / r, r)
        };
        self.clamp(current_us * factor)
    }
}

fn valid(peak: f64, current_us: f64) -> bool {
    peak.is_finite()
        && peak > 0.0
        && peak <= f64::from(SATURATED_PEAK)
        && current_us.is_finite()
        && current_us > 0.0
}

/// The frame's measurement from its targets' peaks (fractions of full
/// scale, clipped ones as [`SATURATED_PEAK`]): their [`PEAK_QUANTILE`]
/// quantile (the nearest rank), `None` without targets. Reorders `peaks`;
/// allocates nothing. Non-finite entries count as clipped.
pub fn frame_peak(peaks: &mut [f32]) -> Option<f32> {
    if peaks.is_empty() {
        return None;
    }
    for p in peaks.iter_mut() {
        if !p.is_finite() {
            *p = SATURATED_PEAK;
        }
    }
    let n = peaks.len();
    let rank = ((PEAK_QUANTILE * n as f64).ceil() as usize).clamp(1, n) - 1;
    let (_, q, _) = peaks.select_nth_unstable_by(rank, f32::total_cmp);
    Some(*q)
}

/// No measurement (the peak's bits are a NaN).
const EMPTY: u64 = 0x7FC0_0000;

/// The link between the workers that measure frames and the source that
/// steers the exposure, shared through an `Arc`: the newest frame's
/// measurement (lock-free: frame number and peak packed in one atomic
/// word), whether the source steers, and the exposure in effect with the
/// counts of the source's feature writes (exported as metrics).
#[derive(Debug)]
pub struct ExposureLink {
    /// Low 32 bits of the frame's `seq` above, the peak's `f32` bits below.
    sample: AtomicU64,
    steering: AtomicBool,
    /// The exposure in effect, seconds (0: not known).
    pub exposure_s: Gauge,
    /// Exposure writes the camera took.
    pub writes: Counter,
    /// Exposure writes that failed (logged, never fatal).
    pub write_failures: Counter,
}

impl Default for ExposureLink {
    fn default() -> Self {
        ExposureLink {
            sample: AtomicU64::new(EMPTY),
            steering: AtomicBool::new(false),
            exposure_s: Gauge::default(),
            writes: Counter::new(),
            write_failures: Counter::new(),
        }
    }
}

/// Whether frame number `a` comes after `b`, both the low 32 bits of a
/// `seq` (wrapping: 2^31 frames either side).
pub fn seq_after(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) > 0
}

impl ExposureLink {
    /// A link for a source that steers (`true`) or only reports its
    /// exposure.
    pub fn new(steering: bool) -> ExposureLink {
        let link = ExposureLink::default();
        link.steering.store(steering, Ordering::Relaxed);
        link
    }

    /// Whether the source steers its exposure from the measurements (the
    /// workers measure only then).
    pub fn steering(&self) -> bool {
        self.steering.load(Ordering::Relaxed)
    }

    /// Offers frame `seq`'s measurement: kept when it is newer than the
    /// one held (workers finish frames out of order). Lock-free, never
    /// waits; a non-finite peak is not offered.
    pub fn offer(&self, seq: u64, peak: f32) {
        if !peak.is_finite() {
            return;
        }
        let word = ((seq & 0xFFFF_FFFF) << 32) | u64::from(peak.to_bits());
        let mut held = self.sample.load(Ordering::Acquire);
        loop {
            if let Some((s, _)) = unpack(held) {
                if !seq_after(seq as u32, s) {
                    return;
                }
            }
            match self
                .sample
                .compare_exchange_weak(held, word, Ordering::AcqRel, Ordering::Acquire)
            {
                Ok(_) => return,
                Err(now) => held = now,
            }
        }
    }

    /// The newest measurement: the low 32 bits of its frame's `seq` and
    /// its peak; `None` before the first.
    pub fn latest(&self) -> Option<(u32, f32)> {
        unpack(self.sample.load(Ordering::Acquire))
    }
}

fn unpack(word: u64) -> Option<(u32, f32)> {
    let peak = f32::from_bits(word as u32);
    peak.is_finite().then_some(((word >> 32) as u32, peak))
}

impl Collect for ExposureLink {
    fn collect(&self, out: &mut Scrape<'_>) -> std::fmt::Result {
        out.gauge(
            "photopose_exposure_time_seconds",
            "The camera's exposure time in effect (0 when not known).",
            self.exposure_s.get(),
        )?;
        out.gauge(
            "photopose_exposure_control_enabled",
            "1 while the exposure control loop steers the camera, else 0.",
            f64::from(u8::from(self.steering())),
        )?;
        out.counter(
            "photopose_exposure_control_writes_total",
            "Exposure times the control loop wrote to the camera.",
            self.writes.get(),
        )?;
        out.counter(
            "photopose_exposure_control_write_failures_total",
            "Exposure writes the camera refused or that failed (logged, not fatal).",
            self.write_failures.get(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A linear sensor with clipping: the peak is `k` × exposure, read as
    /// [`SATURATED_PEAK`] from full scale on.
    fn sensor(k: f64, us: f64) -> f64 {
        let p = k * us;
        if p >= 1.0 {
            f64::from(SATURATED_PEAK)
        } else {
            p
        }
    }

    fn every_frame() -> ExposureSettings {
        ExposureSettings {
            every_frames: 1,
            ..ExposureSettings::default()
        }
    }

    /// Runs the loop on `sensor(k, ·)` from `start` µs: the exposures set.
    fn run(settings: ExposureSettings, k: f64, start: f64, frames: usize) -> Vec<f64> {
        let mut law = ExposureLaw::new(settings).unwrap();
        let mut us = start;
        let mut set = vec![us];
        for _ in 0..frames {
            if let Step::Set(next) = law.observe(sensor(k, us), us) {
                us = next;
                set.push(us);
            }
        }
        set
    }

    fn in_band(s: &ExposureSettings, k: f64, us: f64) -> bool {
        (sensor(k, us) / s.target_peak - 1.0).abs() <= s.dead_band
    }

    /// Steps needed at most from `from` to `to` µs with settings `s`: the
    /// step limit's share, then the damped approach into the dead band.
    fn bound(s: &ExposureSettings, from: f64, to: f64) -> usize {
        let far = (to / from).ln().abs();
        let limited = (far / s.max_step_ratio.ln()).ceil();
        let damped = ((s.max_step_ratio.ln() / (1.0 + s.dead_band).ln()).ln()
            / (1.0 / (1.0 - s.gain)).ln())
        .ceil();
        (limited + damped.max(0.0)) as usize + 2
    }

    #[test]
    fn converges_from_too_dark_monotonely_and_stays() {
        let s = every_frame();
        // Full scale at 5000 µs: the target (0.8) at 4000 µs.
        let k = 1.0 / 5000.0;
        let set = run(s, k, 30.0, 200);
        let last = *set.last().unwrap();
        assert!(in_band(&s, k, last), "ends at {last} µs: {set:?}");
        assert!(
            set.len() - 1 <= bound(&s, 30.0, 4000.0),
            "{} steps: {set:?}",
            set.len() - 1
        );
        assert!(
            set.windows(2).all(|w| w[1] > w[0]),
            "monotone approach from below: {set:?}"
        );
        assert!(
            set.iter().all(|&us| sensor(k, us) < 1.0),
            "never clipped on the way: {set:?}"
        );
        // Settled: many more frames change nothing.
        let mut law = ExposureLaw::new(s).unwrap();
        for _ in 0..100 {
            assert_eq!(law.observe(sensor(k, last), last), Step::Hold);
        }
    }

    #[test]
    fn converges_from_saturated_within_bounded_steps() {
        let s = every_frame();
        let k = 1.0 / 500.0;
        // 20 ms on a sensor that clips at 0.5 ms: 40× too long.
        let set = run(s, k, 20_000.0, 200);
        let last = *set.last().unwrap();
        assert!(in_band(&s, k, last), "ends at {last} µs: {set:?}");
        assert!(set.len() - 1 <= bound(&s, 20_000.0, 400.0) + 1, "{set:?}");
        // Down by the whole step while clipped, then a monotone approach.
        let first_unclipped = set.iter().position(|&us| sensor(k, us) < 1.0).unwrap();
        for w in set[..=first_unclipped].windows(2) {
            assert!((w[0] / w[1] - s.max_step_ratio).abs() < 1e-9, "{set:?}");
        }
        let tail = &set[first_unclipped..];
        let up = tail.windows(2).all(|w| w[1] > w[0]);
        let down = tail.windows(2).all(|w| w[1] < w[0]);
        assert!(up || down, "no oscillation once unclipped: {set:?}");
    }

    #[test]
    fn stays_within_the_limits() {
        let s = ExposureSettings {
            min_us: 100.0,
            max_us: 1000.0,
            ..every_frame()
        };
        // Too dark even at the longest exposure: it stops there.
        let set = run(s, 1e-5, 500.0, 50);
        assert_eq!(*set.last().unwrap(), 1000.0);
        assert!(set.iter().all(|&us| (100.0..=1000.0).contains(&us)));
        // Clipped even at the shortest: it stops there.
        let set = run(s, 1.0, 500.0, 50);
        assert_eq!(*set.last().unwrap(), 100.0);
        // A camera outside the limits is brought inside at the first action,
        // even with its peak in the dead band.
        let mut law = ExposureLaw::new(s).unwrap();
        assert_eq!(law.observe(0.8, 5000.0), Step::Set(1000.0));
        // At the limit, asking for more changes nothing.
        assert_eq!(law.observe(0.1, 1000.0), Step::Hold);
    }

    #[test]
    fn acts_every_n_frames_and_frames_without_a_peak_do_not_count() {
        let s = ExposureSettings {
            every_frames: 3,
            ..ExposureSettings::default()
        };
        let mut law = ExposureLaw::new(s).unwrap();
        assert_eq!(law.observe(0.2, 1000.0), Step::Hold);
        assert_eq!(law.observe(f64::NAN, 1000.0), Step::Hold);
        assert_eq!(law.observe(0.2, 1000.0), Step::Hold);
        assert_eq!(law.observe(0.2, 1000.0), Step::Set(2000.0));
        assert_eq!(law.observe(0.2, 2000.0), Step::Hold);
    }

    #[test]
    fn absurd_inputs_change_nothing() {
        let mut law = ExposureLaw::new(every_frame()).unwrap();
        for (peak, us) in [
            (f64::NAN, 1000.0),
            (f64::INFINITY, 1000.0),
            (-0.5, 1000.0),
            (0.0, 1000.0),
            (1e30, 1000.0),
            (0.2, f64::NAN),
            (0.2, -1.0),
            (0.2, 0.0),
            (0.2, f64::INFINITY),
        ] {
            assert_eq!(law.observe(peak, us), Step::Hold, "{peak} at {us} µs");
        }
        // A saturated measurement steps down by the limit.
        assert_eq!(
            law.observe(f64::from(SATURATED_PEAK), 1000.0),
            Step::Set(500.0)
        );
    }

    #[test]
    fn settings_are_checked_naming_the_key() {
        assert!(ExposureSettings::default().check().is_ok());
        let cases: [(&str, ExposureSettings); 8] = [
            (
                "target_peak",
                ExposureSettings {
                    target_peak: 1.0,
                    ..Default::default()
                },
            ),
            (
                "target_peak",
                ExposureSettings {
                    target_peak: f64::NAN,
                    ..Default::default()
                },
            ),
            (
                "min_us",
                ExposureSettings {
                    min_us: 0.0,
                    ..Default::default()
                },
            ),
            (
                "max_us",
                ExposureSettings {
                    max_us: 10.0,
                    ..Default::default()
                },
            ),
            (
                "gain",
                ExposureSettings {
                    gain: 1.5,
                    ..Default::default()
                },
            ),
            (
                "max_step_ratio",
                ExposureSettings {
                    max_step_ratio: 1.0,
                    ..Default::default()
                },
            ),
            (
                "dead_band",
                ExposureSettings {
                    dead_band: -0.1,
                    ..Default::default()
                },
            ),
            (
                "every_frames",
                ExposureSettings {
                    every_frames: 0,
                    ..Default::default()
                },
            ),
        ];
        for (key, s) in cases {
            match s.check() {
                Err(SettingsError::OutOfRange { key: k, .. }) => assert_eq!(k, key),
                other => panic!("{key}: {other:?}"),
            }
        }
    }

    #[test]
    fn limits_narrow_to_the_cameras() {
        let mut law = ExposureLaw::new(ExposureSettings::default()).unwrap();
        assert!(law.limit_to(10.0, 1e7));
        assert_eq!(
            (law.settings().min_us, law.settings().max_us),
            (20.0, 20_000.0)
        );
        assert!(law.limit_to(100.0, 5000.0));
        assert_eq!(
            (law.settings().min_us, law.settings().max_us),
            (100.0, 5000.0)
        );
        assert!(!law.limit_to(6000.0, 9000.0));
        assert!(!law.limit_to(f64::NAN, 9000.0));
        assert_eq!(
            (law.settings().min_us, law.settings().max_us),
            (100.0, 5000.0)
        );
    }

    #[test]
    fn the_frame_peak_is_a_robust_high_quantile() {
        assert_eq!(frame_peak(&mut []), None);
        assert_eq!(frame_peak(&mut [0.4]), Some(0.4));
        // One odd bright reflection among twenty does not steer.
        let mut p: Vec<f32> = (0..19).map(|k| 0.3 + 0.01 * k as f32).collect();
        p.push(SATURATED_PEAK);
        let q = frame_peak(&mut p).unwrap();
        assert!((q - 0.47).abs() < 1e-6, "{q}");
        // More than a tenth clipped: the frame reads as clipped.
        let mut p = vec![0.5f32; 17];
        p.extend([SATURATED_PEAK, f32::NAN, SATURATED_PEAK]);
        assert_eq!(frame_peak(&mut p), Some(SATURATED_PEAK));
    }

    #[test]
    fn the_link_keeps_the_newest_frame() {
        let link = ExposureLink::new(true);
        assert!(link.steering());
        assert_eq!(link.latest(), None);
        link.offer(10, 0.5);
        link.offer(9, 0.9);
        assert_eq!(link.latest(), Some((10, 0.5)));
        link.offer(11, f32::NAN);
        assert_eq!(link.latest(), Some((10, 0.5)));
        link.offer(12, SATURATED_PEAK);
        assert_eq!(link.latest(), Some((12, SATURATED_PEAK)));
        // Across the 32-bit wrap of the frame number.
        link.offer(u64::from(u32::MAX), 0.3);
        let link = ExposureLink::new(false);
        link.offer(u64::from(u32::MAX), 0.3);
        link.offer(u64::from(u32::MAX) + 1, 0.4);
        assert_eq!(link.latest(), Some((0, 0.4)));
        assert!(seq_after(0, u32::MAX) && !seq_after(u32::MAX, 0));
    }

    proptest! {
        #[test]
        fn outputs_are_finite_and_within_the_limits(
            min_us in 1.0f64..1000.0,
            span in 1.0f64..1000.0,
            target_peak in 0.05f64..0.95,
            gain in 0.01f64..=1.0,
            max_step_ratio in 1.01f64..20.0,
            dead_band in 0.0f64..0.5,
            every_frames in 1u32..5,
            inputs in proptest::collection::vec(
                (prop_oneof![
                    -1.0f64..3.0,
                    Just(f64::NAN),
                    Just(f64::INFINITY),
                    Just(f64::from(SATURATED_PEAK)),
                    Just(0.0),
                ],
                prop_oneof![
                    0.0f64..1e8,
                    Just(f64::NAN),
                    Just(-1.0),
                    Just(f64::INFINITY),
                ]),
                1..64,
            ),
        ) {
            let s = ExposureSettings {
                target_peak,
                min_us,
                max_us: min_us * span,
                gain,
                max_step_ratio,
                dead_band,
                every_frames,
            };
            let mut law = ExposureLaw::new(s).unwrap();
            for (peak, us) in inputs {
                if let Step::Set(next) = law.observe(peak, us) {
                    prop_assert!(next.is_finite());
                    prop_assert!(next >= s.min_us && next <= s.max_us, "{next} outside [{}, {}]", s.min_us, s.max_us);
                    // Never more than one step limit from a current value in range.
                    if us >= s.min_us && us <= s.max_us {
                        prop_assert!(next / us <= max_step_ratio * (1.0 + 1e-12));
                        prop_assert!(us / next <= max_step_ratio * (1.0 + 1e-12));
                    }
                }
            }
        }

        #[test]
        fn a_linear_sensor_is_approached_without_oscillation(
            target_us in 200.0f64..5000.0,
            start_us in 20.0f64..20_000.0,
            gain in 0.2f64..=1.0,
            max_step_ratio in 1.5f64..4.0,
            dead_band in 0.02f64..0.3,
        ) {
            let s = ExposureSettings {
                gain,
                max_step_ratio,
                dead_band,
                every_frames: 1,
                ..ExposureSettings::default()
            };
            let k = s.target_peak / target_us;
            let set = run(s, k, start_us, 500);
            let last = *set.last().unwrap();
            prop_assert!(in_band(&s, k, last), "ends at {} µs: {:?}", last, set);
            let first_unclipped = set.iter().position(|&us| sensor(k, us) < 1.0).unwrap();
            let tail = &set[first_unclipped..];
            let up = tail.windows(2).all(|w| w[1] > w[0]);
            let down = tail.windows(2).all(|w| w[1] < w[0]);
            prop_assert!(up || down, "oscillates: {:?}", set);
        }
    }
}
