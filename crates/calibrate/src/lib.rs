//! photopose-calibrate: camera calibration by a self-calibrating bundle
//! adjustment on the planar test field — the "bundle adjustment using a
//! planar test field carried out before-hand" of the reference paper.
//!
//! From the blobs the detector found in 10–30 images of the plate and a
//! nominal camera (sensor, pixel size, principal distance), [`calibrate()`]
//! finds each image's start orientation from its coded targets, identifies
//! the uncoded ones by projection as the solution improves, and adjusts the
//! camera parameters of `docs/conventions.md` (`c, x0, y0, K1 K2 K3 P1 P2 b1 b2`,
//! any of them fixable), every image's exterior orientation and optionally
//! the target coordinates (free network), with sparse normal equations
//! (Schur complement of the per-image unknowns), Levenberg–Marquardt damping
//! and data snooping. [`Report`] gives σ0, every parameter with its
//! standard deviation, strong correlations and residuals per image; [`svg`]
//! draws the residuals.
//!
//! Invariant: no IO (no files, sockets, threads or clocks); the command
//! `photopose calibrate camera` reads the images and writes the files.

pub mod bundle;
pub mod calibrate;
pub mod cases;
pub mod error;
pub mod model;
pub mod params;
pub mod report;
pub mod svg;
pub mod views;

pub use bundle::{BundleOptions, BundleResult};
pub use calibrate::{
    calibrate, AdjustedImage, Blob, Calibration, CalibrationOptions, ImageDetections, Skipped,
};
pub use error::CalibrateError;
pub use params::{Fixed, Param};
pub use report::{natural_cmp, Report};
