//! The pose result: one per processed frame, made by a detection worker and
//! handed in frame order to every sink. It keeps everything the adjustment
//! found — the exterior orientation with its full 6×6 covariance, σ0, the
//! targets used — with the frame's identity and times; each sink derives
//! what it needs from it (the wire message, the RSI measurement, a record).
//!
//! The identified targets of a frame travel with its result in
//! [`Targets`]: a list taken from a bounded [`TargetPool`] that goes back
//! to its pool when the result is dropped, so no frame allocates once the
//! pool is warm.

use crossbeam_queue::ArrayQueue;
use photopose_geometry::ResectionReport;
use photopose_locate::PoseStatus as LocateStatus;
use photopose_telemetry::Counter;
use std::sync::Arc;
use std::time::Instant;

/// The `[camera] id` of the daemon's camera (default `"camera"`): tags
/// every result, message and metric of its pipeline. Cloning it does not
/// allocate.
pub type CameraId = Arc<str>;

/// What became of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResultStatus {
    /// A pose was measured.
    Ok,
    /// Too few targets were identified for a pose (a result, not an error).
    TooFewTargets,
    /// The frame could not be processed.
    Error,
}

/// The times of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTimes {
    /// The camera's timestamp of the exposure, ns on the camera's clock (0
    /// when the source has none).
    pub camera_ns: u64,
    /// The hand-over of the frame to the pipeline, ns since the Unix epoch
    /// (host clock, UTC).
    pub handover_utc_ns: u64,
    /// The hand-over on the host's monotonic clock.
    pub handover: Instant,
    /// The hand-over on the host's monotonic clock (`CLOCK_MONOTONIC`), ns;
    /// 0 when the source did not stamp it.
    pub handover_mono_ns: u64,
    /// The middle of the exposure on the host's monotonic clock
    /// (`CLOCK_MONOTONIC`), ns; 0 when not known.
    pub exposure_mono_ns: u64,
    /// The middle of the exposure, ns since the Unix epoch (UTC), when known.
    pub exposure_utc_ns: Option<u64>,
    /// The standard uncertainty of the exposure instant, ns (0: not known).
    pub exposure_sigma_ns: u64,
    /// When the worker finished the frame, host monotonic clock.
    pub processed: Instant,
}

/// One frame's outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseResult {
    /// The camera that took the frame.
    pub camera: CameraId,
    /// The source's sequence number of the frame.
    pub seq: u64,
    /// The frame's times.
    pub times: FrameTimes,
    /// What became of the frame.
    pub status: ResultStatus,
    /// The adjustment: exterior orientation (`R`: field → camera, the
    /// projection centre), its covariance (`X, Y, Z` mm, `ωX, ωY, ωZ` rad,
    /// small rotations of the camera about the field axes), σ0, the targets
    /// used. `Some` exactly when the status is [`ResultStatus::Ok`].
    pub pose: Option<ResectionReport>,
    /// The identified targets of the frame (coded first, then uncoded);
    /// empty when the frame had none or the pool had no free list (counted
    /// by the pool, [`TargetPool::exhausted`]).
    pub targets: Targets,
}

/// One identified target of a frame: which field target it is and where
/// its centre was measured in the image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageTarget {
    /// The target's id in the field.
    pub id: u64,
    /// Whether it is a coded target (its id read from its code ring) or an
    /// uncoded one (identified by projection).
    pub coded: bool,
    /// The image of the target's centre, column, pixels (full-frame
    /// coordinates, origin at the centre of the top-left pixel).
    pub col_px: f64,
    /// The image of the target's centre, row, pixels.
    pub row_px: f64,
    /// Whether the final adjustment used it (not rejected as an outlier).
    pub used: bool,
}

type Lists = ArrayQueue<Vec<ImageTarget>>;

/// A frame's identified targets: a list from a [`TargetPool`], returned to
/// it on drop. Reads as a slice of [`ImageTarget`].
#[derive(Default)]
pub struct Targets {
    list: Vec<ImageTarget>,
    home: Option<Arc<Lists>>,
}

impl Targets {
    /// No targets, and no pool behind it (allocates nothing).
    pub fn none() -> Targets {
        Targets::default()
    }

    /// Appends a target; beyond the list's capacity (the field's size)
    /// nothing is added, so a pooled list never grows. Returns whether it
    /// was added.
    pub fn push(&mut self, target: ImageTarget) -> bool {
        if self.home.is_some() && self.list.len() == self.list.capacity() {
            return false;
        }
        self.list.push(target);
        true
    }

    /// Removes every target (keeps the list).
    pub fn clear(&mut self) {
        self.list.clear();
    }
}

impl std::ops::Deref for Targets {
    type Target = [ImageTarget];

    fn deref(&self) -> &[ImageTarget] {
        &self.list
    }
}

impl std::fmt::Debug for Targets {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.list.iter()).finish()
    }
}

/// A copy with a list of its own, outside any pool (not for the frame
/// path).
impl Clone for Targets {
    fn clone(&self) -> Targets {
        Targets {
            list: self.list.clone(),
            home: None,
        }
    }
}

impl PartialEq for Targets {
    fn eq(&self, other: &Targets) -> bool {
        self.list == other.list
    }
}

impl Drop for Targets {
    fn drop(&mut self) {
        if let Some(home) = self.home.take() {
            let mut list = std::mem::take(&mut self.list);
            list.clear();
            // The pool holds every list it made, so there is room.
            let _ = home.push(list);
        }
    }
}

/// A bounded pool of target lists, each with room for a field's targets,
/// all allocated at creation: the workers take one per frame, the result
/// gives it back when dropped. When none is free the frame's result
/// carries no targets and [`TargetPool::exhausted`] counts it.
#[derive(Clone)]
pub struct TargetPool {
    lists: Arc<Lists>,
    exhausted: Arc<Counter>,
}

impl std::fmt::Debug for TargetPool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TargetPool")
            .field("free", &self.lists.len())
            .field("capacity", &self.lists.capacity())
            .finish()
    }
}

impl TargetPool {
    /// `lists` lists (at least one) of room for `per_list` targets each.
    pub fn new(lists: usize, per_list: usize) -> TargetPool {
        Self::counted(lists, per_list, Arc::new(Counter::new()))
    }

    /// [`TargetPool::new`] counting empty takes in `exhausted` (e.g. the
    /// pipeline's metric).
    pub fn counted(lists: usize, per_list: usize, exhausted: Arc<Counter>) -> TargetPool {
        let queue = ArrayQueue::new(lists.max(1));
        for _ in 0..lists.max(1) {
            let _ = queue.push(Vec::with_capacity(per_list));
        }
        TargetPool {
            lists: Arc::new(queue),
            exhausted,
        }
    }

    /// An empty list from the pool; [`Targets::none`] (counted) when every
    /// list is in use.
    pub fn take(&self) -> Targets {
        match self.lists.pop() {
            Some(list) => Targets {
                list,
                home: Some(Arc::clone(&self.lists)),
            },
            None => {
                self.exhausted.inc();
                Targets::none()
            }
        }
    }

    /// Lists free now.
    pub fn free(&self) -> usize {
        self.lists.len()
    }

    /// The count of results that went without targets because no list was
    /// free.
    pub fn exhausted(&self) -> &Arc<Counter> {
        &self.exhausted
    }
}

impl PoseResult {
    /// The result of locating one frame (`None`: the locator failed on it).
    pub fn from_location(
        camera: &CameraId,
        meta: &photopose_frame::FrameMeta,
        handover: Instant,
        located: Option<(&LocateStatus, Option<&ResectionReport>)>,
    ) -> PoseResult {
        let (status, pose) = match located {
            Some((LocateStatus::Ok, Some(p))) => (ResultStatus::Ok, Some(*p)),
            Some((LocateStatus::TooFewTargets { .. } | LocateStatus::Frame(_), _)) => {
                (ResultStatus::TooFewTargets, None)
            }
            _ => (ResultStatus::Error, None),
        };
        PoseResult {
            camera: Arc::clone(camera),
            seq: meta.seq,
            times: FrameTimes {
                camera_ns: meta.camera_time_ns,
                handover_utc_ns: meta.host_time_ns,
                handover,
                handover_mono_ns: meta.host_mono_ns,
                exposure_mono_ns: meta.exposure_mono_ns,
                exposure_utc_ns: meta.exposure_utc_ns(),
                exposure_sigma_ns: meta.exposure_sigma_ns,
                processed: Instant::now(),
            },
            status,
            pose,
            targets: Targets::none(),
        }
    }

    /// Puts the identified targets of a location into `targets` (a list
    /// from a [`TargetPool`]) and that into the result.
    pub fn with_targets(
        mut self,
        mut targets: Targets,
        identified: &[photopose_locate::Identified],
    ) -> PoseResult {
        targets.clear();
        for t in identified {
            let added = targets.push(ImageTarget {
                id: t.id,
                coded: t.kind == photopose_field::TargetKind::Coded,
                col_px: t.col,
                row_px: t.row,
                used: t.used,
            });
            if !added {
                break;
            }
        }
        self.targets = targets;
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn target(id: u64) -> ImageTarget {
        ImageTarget {
            id,
            coded: id < 100,
            col_px: id as f64,
            row_px: 2.0 * id as f64,
            used: true,
        }
    }

    #[test]
    fn a_list_goes_back_to_its_pool_and_an_empty_pool_is_counted() {
        let pool = TargetPool::new(2, 4);
        let mut a = pool.take();
        let b = pool.take();
        assert_eq!(pool.free(), 0);
        for id in 0..6 {
            a.push(target(id));
        }
        // The list never grows past its room.
        assert_eq!(a.len(), 4);
        assert_eq!(a[3], target(3));
        let none = pool.take();
        assert!(none.is_empty());
        assert_eq!(pool.exhausted().get(), 1);
        drop(a);
        assert_eq!(pool.free(), 1);
        let again = pool.take();
        assert!(again.is_empty(), "a returned list comes back empty");
        drop((b, again, none));
        assert_eq!(pool.free(), 2);
    }

    #[test]
    fn a_clone_is_outside_the_pool() {
        let pool = TargetPool::new(1, 2);
        let mut a = pool.take();
        a.push(target(7));
        let copy = a.clone();
        drop(a);
        assert_eq!(pool.free(), 1);
        assert_eq!(&copy[..], &[target(7)]);
        drop(copy);
        assert_eq!(pool.free(), 1);
    }
}
