//! photopose-pipeline: the daemon's spine, from frame source to pose streams.
//!
//! ```text
//! source thread ──▶ ring of preallocated frames ──▶ detection workers (N)
//!   (grabber)        (overflow policy, counted)       (photopose-locate)
//!                                                          │ results
//!                                                          ▼
//!                                  output thread: re-orders by sequence
//!                                  number, encodes, UDP + TCP, watchdog
//! ```
//!
//! Frames move between threads in the ring of `photopose-acquire`: slots
//! allocated at start, a lock-free hand-over from the grabber to the
//! workers, the overflow policy applied by the grabber; a slot goes back to
//! the free pool when a worker is done with it. Sources (GigE camera,
//! replay, synthetic) all implement acquire's `FrameSource`. Nothing is
//! allocated per frame once warm. Each stage runs on a named thread; [`Pipeline::stop`] or the
//! end of the source shuts them down in order.

pub mod config;
pub mod health;
pub mod metrics;
pub mod notify;
pub mod result;
pub mod run;
pub mod sink;
pub mod source;
pub mod track;

pub use config::{Config, ConfigError};
pub use run::{Counters, Pipeline, Supervision};
pub use source::{FrameSource, Slot, SourceError};
