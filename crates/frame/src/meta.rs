//! Frame metadata: what a source knows about a frame besides its pixels
//! (sequence number, camera frame id, camera and host timestamps). Plain
//! data, so that sources, recordings and vision can share it without
//! depending on each other.

/// What a source knows about one frame besides its pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameMeta {
    /// The source's sequence number: strictly increasing over the source's
    /// life (across reconnects), advanced past frames the source knows it
    /// missed, so a gap in `seq` is a lost frame.
    pub seq: u64,
    /// The camera's own frame (block) id, as sent; 0 when the source has none.
    pub camera_frame_id: u64,
    /// The camera's timestamp of the exposure, ns on the camera's clock
    /// (0 when the source has none).
    pub camera_time_ns: u64,
    /// Host time of reception, ns since the Unix epoch.
    pub host_time_ns: u64,
    /// Host time of reception on the host's monotonic clock
    /// (`CLOCK_MONOTONIC`), ns; 0 when the source did not stamp it.
    pub host_mono_ns: u64,
    /// The middle of the exposure on the host's monotonic clock
    /// (`CLOCK_MONOTONIC`), ns: the instant the measurement belongs to; 0
    /// when not known.
    pub exposure_mono_ns: u64,
    /// The standard uncertainty of `exposure_mono_ns`, ns (0 when not known).
    pub exposure_sigma_ns: u64,
    /// The exposure time (shutter open), ns; 0 when not known.
    pub exposure_ns: u64,
}

impl FrameMeta {
    /// The middle of the exposure in UTC (ns since the Unix epoch), from the
    /// reception's UTC and the two monotonic instants; `None` when the
    /// exposure instant or the monotonic reception time is not known.
    pub fn exposure_utc_ns(&self) -> Option<u64> {
        if self.exposure_mono_ns == 0 || self.host_mono_ns == 0 || self.host_time_ns == 0 {
            return None;
        }
        let back = self.host_mono_ns.checked_sub(self.exposure_mono_ns)?;
        self.host_time_ns.checked_sub(back)
    }
}
