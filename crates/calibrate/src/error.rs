//! The error type of the calibration: every variant a diagnosis that names
//! what is wrong with the input, never a number that looks like a result.

use thiserror::Error;

/// Why a calibration could not give a camera.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum CalibrateError {
    /// A parameter name (for `--fix`) is not one of the camera file's keys.
    #[error("unknown camera parameter `{0}` (one of c, x0, y0, k1, k2, k3, p1, p2, b1, b2)")]
    UnknownParameter(String),
    /// Fewer usable images than the adjustment needs.
    #[error("only {usable} usable image(s), need at least {need} (skipped: {skipped})")]
    TooFewImages {
        /// Images that could be used.
        usable: usize,
        /// Images needed.
        need: usize,
        /// The images skipped and why, `name: reason; …` (or `none`).
        skipped: String,
    },
    /// Every image looks straight onto the (planar) test field.
    #[error(
        "all {images} images look perpendicularly onto the plate (largest tilt {max_tilt_deg:.1}°, need at least \
         {min_tilt_deg:.1}°): the principal distance and the camera distances are inseparable; take images tilted \
         20–45° towards the plate from several sides and rolled by 90°"
    )]
    ParallelImages {
        /// Images used.
        images: usize,
        /// Largest angle between an optical axis and the plate's normal, degrees.
        max_tilt_deg: f64,
        /// The least tilt needed, degrees.
        min_tilt_deg: f64,
    },
    /// The normal equations are singular: the named combination of camera
    /// parameters is not determined by the images.
    #[error("the images do not determine the camera parameters: {combination} is free (fix one of them with --fix, or add tilted and rolled images)")]
    NotDeterminable {
        /// The undetermined combination, largest components first (`0.71 c - 0.70 k1`).
        combination: String,
    },
    /// The adjustment diverged or could not continue.
    #[error("the adjustment failed: {0}")]
    Diverged(String),
    /// A field target has a non-finite coordinate or the field is empty.
    #[error("bad test field: {0}")]
    BadField(String),
}
