//! The pose result: one per processed frame, made by a detection worker and
//! handed in frame order to every sink. It keeps everything the adjustment
//! found — the exterior orientation with its full 6×6 covariance, σ0, the
//! targets used — with the frame's identity and times; each sink derives
//! what it needs from it (the wire message, the RSI measurement, a record).

use photopose_geometry::ResectionReport;
use photopose_locate::PoseStatus as LocateStatus;
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
        }
    }
}
