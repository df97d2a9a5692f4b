//! The GenTL consumer's error: what went wrong, naming the producer file,
//! the call and its code, or the device asked for and those found.

use std::path::PathBuf;
use thiserror::Error;

/// Why a producer, a device or a stream could not be used.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum GentlError {
    /// No producer named and none found through `GENICAM_GENTL64_PATH`.
    #[error("no GenTL producer: set `{key}` to a .cti file, or GENICAM_GENTL64_PATH to a directory holding one ({searched})")]
    NoProducer {
        /// The configuration key that names a producer.
        key: String,
        /// What was searched (the variable's value, or that it is unset).
        searched: String,
    },
    /// `GENICAM_GENTL64_PATH` holds several producers and none was named.
    #[error("GENICAM_GENTL64_PATH holds several GenTL producers ({found}): name one with `{key}`")]
    AmbiguousProducer {
        /// The configuration key that names a producer.
        key: String,
        /// The producers found.
        found: String,
    },
    /// The producer file is not there or not a regular file.
    #[error("GenTL producer {}: {reason}", path.display())]
    MissingProducer {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// The file is not a loadable GenTL producer.
    #[error("GenTL producer {} is not usable: {reason}", path.display())]
    InvalidProducer {
        /// The file.
        path: PathBuf,
        /// The loader's word, or the missing symbol.
        reason: String,
    },
    /// A GenTL call failed.
    #[error("GenTL producer {}: {call} failed: {name} ({code}){}", path.display(), if text.is_empty() { String::new() } else { format!(": {text}") })]
    Call {
        /// The producer file.
        path: PathBuf,
        /// The call.
        call: &'static str,
        /// The `GC_ERROR` it returned.
        code: i32,
        /// The standard's name of the code.
        name: &'static str,
        /// The producer's text (`GCGetLastError`).
        text: String,
    },
    /// No device matches the configured id or serial number.
    #[error("GenTL producer {}: no device {wanted} (found: {found})", path.display())]
    NoDevice {
        /// The producer file.
        path: PathBuf,
        /// The id or serial asked for (or "at all").
        wanted: String,
        /// The devices found (id and serial).
        found: String,
    },
    /// The device has no data stream, or the stream does not say its
    /// payload size.
    #[error("GenTL device {device}: {reason}")]
    Stream {
        /// The device id.
        device: String,
        /// What is missing.
        reason: String,
    },
}

impl GentlError {
    pub(crate) fn call(path: &std::path::Path, e: crate::ffi::CallError) -> GentlError {
        GentlError::Call {
            path: path.to_path_buf(),
            call: e.call,
            code: e.code,
            name: crate::abi::error_name(e.code),
            text: e.text,
        }
    }
}
