//! photopose-gentl-producer: a GenTL producer for tests. Built as a
//! `cdylib`, it is a `.cti` any GenTL consumer can load: one system, one
//! interface, one device (`DEVICE_ID`, serial `SERIAL`) with one data
//! stream that fills the consumer's announced buffers with Mono8 frames of
//! the default plate, rendered by `photopose-render` through the default
//! camera at the pose [`truth_pose`] gives for the frame id, stamped
//! [`timestamp_ns`] (ns). Frames are rendered when the consumer waits for
//! one (`EventGetData`), so none is ever lost.
//!
//! The rlib gives tests the truth. Set `PHOTOPOSE_TEST_PRODUCER_PFNC` (a
//! number, e.g. `0x01080009`) before `GCInitLib` to make the device report
//! another pixel format (a consumer must refuse it), and
//! `PHOTOPOSE_TEST_PRODUCER_UNPLUG_AFTER` (a count) to make the stream fail
//! once after that many frames, as an unplugged camera does, until the
//! device is opened again.

#[allow(unsafe_code)]
mod exports;

/// The device's id.
pub const DEVICE_ID: &str = "photopose-render-0";
/// The device's serial number.
pub const SERIAL: &str = "PPR0001";
/// The interface's id.
pub const INTERFACE_ID: &str = "photopose-render-if";
/// Frame period of the timestamps, ns (20 frames/s).
pub const PERIOD_NS: u64 = 50_000_000;
/// The variable that overrides the reported pixel format.
pub const PFNC_VAR: &str = "PHOTOPOSE_TEST_PRODUCER_PFNC";
/// The variable that makes the device fail once after that many frames.
pub const UNPLUG_VAR: &str = "PHOTOPOSE_TEST_PRODUCER_UNPLUG_AFTER";

/// The camera pose (KUKA `X, Y, Z` in mm, `A, B, C` in degrees, camera in
/// the plate frame) of frame `frame_id`: a deterministic walk over
/// distances 950–1050 mm and tilts of a few degrees.
pub fn truth_pose(frame_id: u64) -> [f64; 6] {
    let k = |m: u64| (frame_id % m) as f64;
    [
        -40.0 + 20.0 * k(5),
        30.0 - 15.0 * k(4),
        950.0 + 50.0 * k(3),
        -15.0 + 5.0 * k(7),
        3.0 - 3.0 * k(3),
        -2.0 + k(5),
    ]
}

/// The device timestamp of frame `frame_id`, ns.
pub fn timestamp_ns(frame_id: u64) -> u64 {
    1_000_000_000 + frame_id * PERIOD_NS
}

/// The frame id whose timestamp is `ns`, if it is one.
pub fn frame_of_timestamp(ns: u64) -> Option<u64> {
    let t = ns.checked_sub(1_000_000_000)?;
    (t % PERIOD_NS == 0).then_some(t / PERIOD_NS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_map_back_to_frame_ids() {
        for id in [1, 2, 17, 1000] {
            assert_eq!(frame_of_timestamp(timestamp_ns(id)), Some(id));
        }
        assert_eq!(frame_of_timestamp(5), None);
        assert_ne!(truth_pose(1), truth_pose(2));
    }
}
