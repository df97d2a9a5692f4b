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
}
