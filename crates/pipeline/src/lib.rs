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
//! Frames move between threads as boxed slots through bounded channels: the
//! ring is the set of slots allocated at start; a slot goes back to the
//! free queue when a worker is done with it. Nothing is allocated per frame
//! once warm. Each stage runs on a named thread; [`Pipeline::stop`] or the
//! end of the source shuts them down in order.

pub mod config;
pub mod metrics;
pub mod notify;
pub mod run;
pub mod source;

pub use config::{Config, ConfigError};
pub use run::{Counters, Pipeline};
pub use source::{Frame, FrameSource, SourceError, SourceEvent};
