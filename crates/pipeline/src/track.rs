//! Tracking mode in the daemon (`[tracking]`): the workers locate most
//! frames from the latest pose instead of reading the whole frame
//! (`photopose_locate::track`), and the whole frame every
//! `full_frame_every` frames, whenever tracking fails (too few targets, a
//! ring giving another id, a jump), or when the latest pose is too many
//! frames old.
//!
//! Off by default: which pose a worker tracks from depends on which frames
//! the other workers have finished, so two runs over the same recording
//! agree only to a fraction of σ, not bit for bit (a replay at speed `max`
//! is otherwise deterministic).
//!
//! The latest pose of the camera lives in one [`TrackSlot`] shared by the
//! workers. Workers finish frames out of order: a pose replaces the slot's
//! only when its frame is newer, and the one it replaces becomes the
//! "before" of the motion prediction; a frame older than the slot's pose
//! is tracked from it all the same (predicted back along the motion), not
//! located whole. Hand-over never waits: a worker that
//! finds the slot busy (another worker is publishing) locates the frame
//! whole, and a publication that finds it busy is skipped.

use crate::config::ConfigError;
use crate::source::Bad;
use photopose_field::Field;
use photopose_geometry::Camera;
use photopose_geometry::{Exterior, Matrix6, ResectionReport};
use photopose_locate::track::{Motion, Prior, TrackOptions};
use photopose_locate::{LocateError, LocateOptions, Locator, PoseStatus};
use photopose_vision::{Detector, DetectorOptions, ThresholdResult};
use serde::Deserialize;
use std::sync::{Arc, Mutex, TryLockError};

/// `[tracking]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub(crate) struct TrackingSection {
    enabled: bool,
    full_frame_every: u32,
    min_targets: u32,
    max_gap: u32,
}

impl Default for TrackingSection {
    fn default() -> Self {
        let t = Tracking::default();
        TrackingSection {
            enabled: t.enabled,
            full_frame_every: t.full_frame_every,
            min_targets: t.min_targets,
            max_gap: t.max_gap,
        }
    }
}

/// Tracking mode's configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tracking {
    /// Track frames from the latest pose.
    pub enabled: bool,
    /// Every frame whose sequence number is a multiple of this is located
    /// whole (1: every frame, i.e. tracking off).
    pub full_frame_every: u32,
    /// Targets a tracked frame must show; fewer: located whole.
    pub min_targets: u32,
    /// Largest number of frames between the latest pose and the frame to
    /// track from it.
    pub max_gap: u32,
}

impl Default for Tracking {
    fn default() -> Self {
        Tracking {
            enabled: false,
            full_frame_every: 50,
            min_targets: 12,
            max_gap: 8,
        }
    }
}

impl Tracking {
    /// Validates `[tracking]`.
    pub(crate) fn from_section(s: TrackingSection, bad: Bad<'_>) -> Result<Tracking, ConfigError> {
        if s.full_frame_every == 0 {
            return Err(bad(
                "tracking.full_frame_every",
                s.full_frame_every.to_string(),
                "must be at least 1",
            ));
        }
        if !(4..=10_000).contains(&s.min_targets) {
            return Err(bad(
                "tracking.min_targets",
                s.min_targets.to_string(),
                "must be 4..=10000",
            ));
        }
        if !(1..=1000).contains(&s.max_gap) {
            return Err(bad(
                "tracking.max_gap",
                s.max_gap.to_string(),
                "must be 1..=1000",
            ));
        }
        Ok(Tracking {
            enabled: s.enabled,
            full_frame_every: s.full_frame_every,
            min_targets: s.min_targets,
            max_gap: s.max_gap,
        })
    }
}

/// The camera's latest pose, what tracking starts from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Latest {
    /// The frame's sequence number.
    pub seq: u64,
    /// Its exterior orientation.
    pub exterior: Exterior,
    /// Its covariance.
    pub covariance: Matrix6<f64>,
    /// The threshold of the latest whole-frame pass.
    pub threshold: ThresholdResult,
    /// The pose before it (for the motion), when known.
    pub before: Option<(u64, Exterior)>,
}

/// The latest pose of one camera, shared by its workers.
#[derive(Debug, Clone, Default)]
pub struct TrackSlot {
    inner: Arc<Mutex<Option<Latest>>>,
}

impl TrackSlot {
    /// A copy of the latest pose; `None` when there is none or another
    /// worker is publishing right now.
    pub fn latest(&self) -> Option<Latest> {
        match self.inner.try_lock() {
            Ok(g) => *g,
            Err(TryLockError::Poisoned(p)) => *p.into_inner(),
            Err(TryLockError::WouldBlock) => None,
        }
    }

    /// Publishes the pose of frame `seq` if it is newer than the slot's
    /// (`threshold`: a whole-frame pass's, else the slot's is kept).
    pub fn publish(&self, seq: u64, pose: &ResectionReport, threshold: Option<ThresholdResult>) {
        let mut g = match self.inner.try_lock() {
            Ok(g) => g,
            Err(TryLockError::Poisoned(p)) => p.into_inner(),
            Err(TryLockError::WouldBlock) => return,
        };
        let old = *g;
        if old.is_some_and(|o| o.seq >= seq) {
            return;
        }
        let Some(threshold) = threshold.or(old.map(|o| o.threshold)) else {
            return;
        };
        *g = Some(Latest {
            seq,
            exterior: pose.exterior,
            covariance: pose.covariance,
            threshold,
            before: old.map(|o| (o.seq, o.exterior)),
        });
    }
}

/// How a frame was located.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// From the whole frame.
    Whole,
    /// Tracked from the latest pose.
    Tracked,
}

/// The threshold hysteresis of a worker's detector with tracking on, noise
/// σ (`photopose_vision::DetectorOptions::threshold_hold`).
pub const THRESHOLD_HOLD: f64 = 1.0;

/// A worker's locator for `camera` and `field`. With tracking on, its
/// detector holds its threshold level within [`THRESHOLD_HOLD`] noise σ, so
/// that whole-frame and tracked poses agree within a tenth of their σ; off,
/// every frame gets its own level, and a replay gives the same output
/// whichever worker locates which frame.
pub fn locator(camera: Camera, field: Field, tracking: &Tracking) -> Result<Locator, LocateError> {
    let mut options = DetectorOptions::for_field(&field);
    if tracking.enabled {
        options.threshold_hold = THRESHOLD_HOLD;
    }
    let detector = Detector::new(camera.sensor.width, camera.sensor.height, options)?;
    Locator::with_detector(camera, field, LocateOptions::default(), detector)
}

/// One worker's side of tracking mode.
#[derive(Debug)]
pub struct Tracker {
    config: Tracking,
    options: TrackOptions,
    slot: TrackSlot,
}

impl Tracker {
    /// A worker's tracker on the camera's slot.
    pub fn new(config: Tracking, slot: TrackSlot) -> Tracker {
        Tracker {
            options: TrackOptions {
                min_targets: config.min_targets as usize,
                ..TrackOptions::default()
            },
            config,
            slot,
        }
    }

    /// Locates frame `seq`: tracked when it may be, else whole (also when
    /// tracking fails). Returns how, the status and the pose; publishes the
    /// pose to the slot.
    pub fn locate<'l>(
        &self,
        locator: &'l mut Locator,
        seq: u64,
        image: photopose_frame::ImageView<'_>,
    ) -> Result<(Mode, &'l PoseStatus, Option<&'l ResectionReport>), LocateError> {
        if let Some(prior) = self.prior(locator, seq) {
            if locator.track(image, &prior, &self.options).is_ok() {
                let pose = *locator.pose().expect("a tracked frame has a pose");
                self.slot.publish(seq, &pose, None);
                return Ok((Mode::Tracked, locator.status(), locator.pose()));
            }
        }
        let location = locator.locate(image)?;
        if let (PoseStatus::Ok, Some(pose)) = (location.status, location.pose) {
            if self.config.enabled {
                self.slot
                    .publish(seq, pose, Some(location.detections.threshold));
            }
        }
        Ok((Mode::Whole, locator.status(), locator.pose()))
    }

    /// The prior of frame `seq`, when it is to be tracked.
    fn prior(&self, locator: &Locator, seq: u64) -> Option<Prior> {
        if !self.config.enabled || seq.is_multiple_of(u64::from(self.config.full_frame_every)) {
            return None;
        }
        let latest = self.slot.latest()?;
        // A frame older than the latest pose (another worker finished a
        // later one first) is predicted back along the same motion.
        if seq == latest.seq || seq.abs_diff(latest.seq) > u64::from(self.config.max_gap) {
            return None;
        }
        let camera = locator.camera();
        let motion = Motion {
            last: (latest.seq, latest.exterior),
            before: latest.before,
        };
        let distance = latest.exterior.center.norm();
        let (exterior, motion_px) =
            motion.predict(seq, camera.interior.c, camera.sensor.pixel_size, distance);
        Some(Prior {
            exterior,
            covariance: latest.covariance,
            motion_px,
            threshold: latest.threshold,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use photopose_geometry::Vector3;
    use photopose_vision::{FrameStatus, Threshold};

    fn report(x: f64) -> ResectionReport {
        ResectionReport {
            exterior: Exterior::from_kuka_pose([x, 0.0, 1000.0, 0.0, 0.0, 0.0]),
            covariance: Matrix6::identity() * 1e-4,
            sigma0: 1e-4,
            sigma0_px: 0.02,
            rms_px: 0.02,
            n_points: 200,
            n_rejected: 0,
            iterations: 2,
            hypotheses: 0,
        }
    }

    #[test]
    fn a_frame_older_than_the_latest_pose_is_tracked_from_it() {
        let slot = TrackSlot::default();
        let config = Tracking {
            enabled: true,
            ..Tracking::default()
        };
        let tracker = Tracker::new(config, slot.clone());
        let locator = Locator::new(
            photopose_formats::default_camera(),
            photopose_field::design::default_plate(),
            LocateOptions::default(),
        )
        .unwrap();
        let threshold = ThresholdResult {
            threshold: Threshold::global(90),
            otsu: 90,
            floor: 40,
            background: 13.0,
            noise: 2.0,
            max_sampled: 220,
            status: FrameStatus::Normal,
        };
        slot.publish(10, &report(0.0), Some(threshold));
        slot.publish(12, &report(2.0), None);
        // Frame 11 went to a worker that started it after frame 12's pose
        // was published.
        let prior = tracker.prior(&locator, 11).expect("a prior for frame 11");
        let want = Vector3::new(1.0, 0.0, 1000.0);
        let got = prior.exterior.center;
        assert!((got - want).norm() < 1e-9, "{got:?}");
        assert!(prior.motion_px > 0.0);
        assert!(tracker.prior(&locator, 13).is_some());
        // The latest pose's own frame, and frames too far either side.
        assert!(tracker.prior(&locator, 12).is_none());
        assert!(tracker.prior(&locator, 12 + 9).is_none());
        assert!(tracker.prior(&locator, 3).is_none());
    }
}
