//! photopose-acquire: the acquisition layer of the daemon.
//!
//! - [`ring`]: a pool of preallocated frame slots and the bounded,
//!   lock-free single-producer / multi-consumer hand-over between a grabber
//!   and detection workers, with an explicit overflow policy;
//! - [`source`]: the [`FrameSource`] seam and its error;
//! - [`gige`]: the GigE Vision source over aravis, reconnecting with back-off;
//! - [`reopen`]: keeping a device open with back-off on helper threads
//!   (opener, reaper), shared by the camera sources;
//! - [`grabber`]: the grabber thread that runs a source into a ring;
//! - [`exposure`]: the exposure control law (pure), the per-frame peak
//!   measurement it is fed and the lock-free link from the detection
//!   workers to the source that steers;
//! - [`clock_map`]: the camera-clock → host-clock estimate (pure: pairs
//!   passed in);
//! - [`mono`]: the host's monotonic clock in ns, the daemon's time base;
//! - [`fake`]: an in-process GigE Vision fake camera serving given images
//!   (test support).
//!
//! Invariants: no allocation per frame once the ring is built; the camera
//! is never touched on the frame path once lost; the only `unsafe` code is
//! in the private `ffi` module. This is the only crate that links aravis,
//! and only with its `gige` feature (on by default): without it the crate
//! builds with no system library, and the GigE source is not there.

pub mod clock_map;
pub mod exposure;
#[cfg(feature = "gige")]
pub mod fake;
#[cfg(feature = "gige")]
#[allow(unsafe_code)]
mod ffi;
#[cfg(feature = "gige")]
pub mod gige;
pub mod grabber;
pub mod mono;
pub mod reopen;
pub mod ring;
pub mod source;

pub use clock_map::{ClockMap, ClockMapConfig, Mapped};
pub use exposure::{ExposureLaw, ExposureLink, ExposureSettings};
#[cfg(feature = "gige")]
pub use gige::{list_cameras, CameraInfo, FeatureValue, GigeConfig, GigeSource, PixelDepth, Roi};
pub use grabber::{
    spawn_grabber, spawn_grabber_counted, spawn_grabber_with, Grabber, GrabberCounters, GrabberExit,
};
pub use ring::{Consumer, FrameHandle, Overflow, Producer, Published, Ring, Slot};
pub use source::{FrameSource, SourceCounters, SourceError, SourceStats};
