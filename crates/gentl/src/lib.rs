//! photopose-gentl: frames from Camera Link and CoaXPress frame grabbers
//! (and any other camera) through the vendor's GenTL producer, a `.cti`
//! shared library implementing the EMVA GenTL C interface.
//!
//! - [`abi`]: the GenTL declarations photopose uses (types, values, calls);
//! - [`pixel`]: PFNC pixel formats and their conversion to grey;
//! - [`system`]: the safe module chain system → interface → device → data
//!   stream, device listing ([`list_devices`]);
//! - [`source`]: [`GentlSource`], a `photopose-acquire` [`FrameSource`]
//!   (reopening with back-off off the frame path, camera timestamps, lost
//!   and incomplete frames counted);
//! - [`config`]: its settings ([`GentlConfig`]) and the producer search
//!   (`GENICAM_GENTL64_PATH`).
//!
//! The producer is loaded at run time with `libloading`; the only `unsafe`
//! code is the private `ffi` module. Photopose's libraries reach this crate
//! only through their `gentl` cargo feature.
//!
//! [`FrameSource`]: photopose_acquire::FrameSource

pub mod abi;
pub mod config;
pub mod error;
#[allow(unsafe_code)]
mod ffi;
pub mod genapi;
pub mod pixel;
pub mod source;
pub mod system;

pub use config::{find_producer, GentlConfig, PRODUCER_PATH_VAR};
pub use error::GentlError;
pub use ffi::{open_handles, OpenHandles};
pub use pixel::{ConvertError, PixelFormat};
pub use source::GentlSource;
pub use system::{list_devices, DeviceInfo, Opened, System};
