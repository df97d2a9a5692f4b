//! photopose-vision: finds the retro-reflective targets in a frame, measures
//! their centres to a few hundredths of a pixel and reads coded targets.
//!
//! The [`Detector`] runs on a window of a frame (an
//! [`ImageView`](photopose_frame::ImageView): the whole frame or a part of
//! it, up to the detector's capacity) and reports everything in full-frame
//! pixel coordinates. Its stages follow section 3.2 of the reference paper,
//! each a function of its own (`detector` module):
//!
//! 1. [`threshold`]: grey-value histogram, Otsu's threshold, bounded below by
//!    a noise floor; degenerate frames end here with a [`FrameStatus`]. The
//!    result is one [`Threshold`] value that the later stages ask; a
//!    threshold found before can be passed in instead
//!    ([`Detector::detect_with`]). Where the surroundings of a tile peak
//!    well below the frame's bright targets, the tile gets a lower level of
//!    its own ([`threshold::LocalLevels`]; `local_threshold`).
//! 2. [`label`]: run-length connected components with union-find, blob
//!    statistics in the same pass.
//! 3. Blob tests: area, border, saturation, and shape from second moments;
//!    rejected blobs are kept with a reason.
//! 4. [`measure`]: background-subtracted, intensity-weighted centroid and
//!    ellipse over the bounding box grown by 2 px, and the fourth-moment
//!    shape test.
//! 5. [`code`]: the 12-sector ring of coded targets; ids the field does not
//!    carry, and uncertain readings, stay unidentified. Blobs that are parts
//!    of a ring are suppressed.
//!
//! Centres are those of the bright dot's image (the centroid of the imaged
//! ellipse). For the plates and distances of photopose the perspective
//! offset between that and the image of the circle's centre stays below
//! 0.01 px.
//!
//! Invariant: no IO, threads or clocks; [`Detector`] allocates every buffer in
//! [`Detector::new`] and [`Detector::detect`] allocates nothing, whatever
//! window (up to the capacity) it is given.

pub mod code;
mod detector;
pub mod label;
pub mod measure;
mod num;
// The prefetch hint is an `unsafe fn` (its raw pointer); see the module.
pub mod pixel;
#[allow(unsafe_code)]
mod prefetch;
pub mod seed;
pub mod threshold;
pub mod window;

pub use code::{CodeSet, CodeStatus, Uncertainty};
pub use detector::{DetectStage, Detector};
pub use photopose_field::TargetKind;
pub use threshold::{FrameStatus, Threshold, ThresholdResult};
pub use window::{Expected, WindowMeasurer, WindowOutcome, WindowTarget};

use label::Blob;
use thiserror::Error;

/// Errors of the detector (a frame without targets is a result, not an error).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[non_exhaustive]
pub enum VisionError {
    /// The window is larger than the detector's capacity.
    #[error(
        "window is {got_width}×{got_height} px, larger than the detector's capacity of \
         {width}×{height} px"
    )]
    Size {
        /// Capacity: width.
        width: u32,
        /// Capacity: height.
        height: u32,
        /// Width of the window.
        got_width: u32,
        /// Height of the window.
        got_height: u32,
    },
    /// The detector was asked for an empty size.
    #[error("detector size {width}×{height} is too small (at least 8×8)")]
    TooSmall {
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
}

/// Options of the detector. Defaults suit 8- to 16-bit frames of
/// retro-reflective targets between a few and a few hundred pixels in area.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorOptions {
    /// The code ids that may be reported (the field's coded targets).
    pub codes: CodeSet,
    /// Smallest blob area, px (smaller blobs are counted, not listed).
    pub min_area: u32,
    /// Largest blob area, px.
    pub max_area: u32,
    /// Largest ratio of the ellipse's semi-axes (45° oblique gives 1.4).
    pub max_axis_ratio: f64,
    /// Accepted range of `area / (π a b)` of the thresholded blob.
    pub fill_range: (f64, f64),
    /// The fourth moment along the major axis (2 for a filled ellipse, 1.8
    /// for a bar, about 1.7 for two touching dots) may differ from 2 by this
    /// much plus `5 / area` (digitisation of small blobs).
    pub kurtosis_tolerance: f64,
    /// The threshold lies at least this many noise σ above the background.
    pub noise_factor: f64,
    /// ... and at least this fraction of the saturation level above it.
    pub min_contrast: f64,
    /// Histogram sub-sampling step: rows and columns `≡ 1 (mod step)` of
    /// the full frame. At [`threshold::PEAK_STEP`] (the default, 4) one pass
    /// over those rows gives the histogram and the local levels' tile peaks.
    pub histogram_step: usize,
    /// Capacity: runs per frame.
    pub max_runs: usize,
    /// Capacity: blobs per frame.
    pub max_blobs: usize,
    /// Capacity: targets and listed rejections per frame.
    pub max_targets: usize,
    /// Code reading: a sector's mean must be this fraction of the
    /// dot-to-gap contrast away from the threshold.
    pub sector_margin: f64,
    /// Code reading: every sample must be on its sector's side by this fraction.
    pub sample_margin: f64,
    /// Code reading: gap and quiet zone must stay below dark + this fraction.
    pub dark_tolerance: f64,
    /// Measure blobs with saturated (clipped) pixels as targets, flagged
    /// [`Detection::saturated`]; `false` rejects them
    /// ([`RejectReason::Saturated`]). The weighted centroid of a clipped
    /// symmetric dot stays on its centre, but the plateau carries no
    /// position information and the kink where the profile meets the
    /// saturation level moves the centroid with the dot's sub-pixel phase;
    /// see [`DetectorOptions::saturated_knee`].
    pub measure_saturated: bool,
    /// For blobs at least half of whose pixels are saturated, the centroid
    /// weights may roll off smoothly from this share of the way between
    /// background and saturation up to the saturation level
    /// ([`measure::Knee`]); 1 (the default) keeps the clipped plateau
    /// weighted uniformly. On the synthetic dots of the detector's
    /// over-exposure test (frontal, no distortion) a roll-off from 0.3
    /// halves the sub-pixel phase error at 2× full scale (RMS 0.026 →
    /// 0.013 px), but on frames of the renderer (exact pixel coverage,
    /// perspective, lens distortion) it pulls the centres of clipped dots
    /// towards the image centre (−0.004 px on a 2448 × 2048 frame, a 5σ
    /// error in distance) and raises σ0, while the uniform plateau stays
    /// unbiased (< 0.002 px; `photopose-locate`'s over-exposure test).
    pub saturated_knee: f64,
    /// Local threshold: in tiles of 64 × 64 px whose surroundings (the
    /// tile and its neighbours) peak well below the frame's bright targets,
    /// the level drops to this share of the local peak's height above the
    /// background (never below the noise floor, never above the global
    /// level), so that dim targets next to bright ones are found. 0: one
    /// global level. Only for thresholds found on the window itself
    /// ([`Detector::detect`]), not for given ones ([`Detector::detect_with`]).
    pub local_threshold: f64,
    /// The local levels lie at least this many noise σ above the
    /// background (and `min_contrast` of the saturation level); lower than
    /// `noise_factor`, as a tile is lowered only where its surroundings
    /// peak above it.
    pub local_noise_factor: f64,
    /// Threshold hysteresis, noise σ: a detector keeps the level it found
    /// on an earlier frame while the new frame's level lies within this
    /// many noise σ (at least one histogram bin) of it. Otsu's level
    /// jitters by a grey value or two from frame to frame with the noise;
    /// each jump moves the binary shapes, hence the centroid windows, and
    /// the centres by a tenth of their σ. Held, the level is the same for
    /// every frame of a steady scene, and for tracking mode, which reuses
    /// the level of the last whole frame. 0 (the default): a level per
    /// frame, so that a frame's result never depends on the frames the
    /// detector saw before (a replay over several workers gives the same
    /// output whichever worker locates which frame); tracking mode turns it
    /// on.
    pub threshold_hold: f64,
}

impl Default for DetectorOptions {
    fn default() -> Self {
        DetectorOptions {
            codes: CodeSet::all(),
            min_area: 6,
            max_area: 5_000,
            max_axis_ratio: 3.0,
            fill_range: (0.8, 1.2),
            kurtosis_tolerance: 0.1,
            noise_factor: 8.0,
            min_contrast: 0.04,
            histogram_step: 4,
            max_runs: 262_144,
            max_blobs: 32_768,
            max_targets: 4096,
            sector_margin: 0.25,
            sample_margin: 0.1,
            dark_tolerance: 0.3,
            measure_saturated: true,
            saturated_knee: 1.0,
            local_threshold: 0.3,
            local_noise_factor: 5.0,
            threshold_hold: 0.0,
        }
    }
}

impl DetectorOptions {
    /// Default options accepting the coded ids of `field`.
    pub fn for_field(field: &photopose_field::Field) -> Self {
        DetectorOptions {
            codes: CodeSet::from_field(field),
            ..Self::default()
        }
    }
}

/// A detected target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// Centre column (pixel coordinates, integer = pixel centre).
    pub col: f64,
    /// Centre row.
    pub row: f64,
    /// Semi-major axis of the dot's ellipse, px (from the intensity moments,
    /// pixel area and blur removed).
    pub semi_major: f64,
    /// Semi-minor axis, px.
    pub semi_minor: f64,
    /// Angle of the major axis from `+col` towards `+row`, radians.
    pub angle: f64,
    /// Pixels above the threshold.
    pub area: u32,
    /// Largest grey value.
    pub peak: u32,
    /// Background-subtracted grey-value sum.
    pub signal: f64,
    /// Local background level.
    pub background: f64,
    /// Coded if a ring is present (read or not), else uncoded.
    pub kind: TargetKind,
    /// The code id, only for certain readings of ids in the field.
    pub id: Option<u64>,
    /// The outcome of reading the ring.
    pub code: CodeStatus,
    /// The dot has pixels at the saturation level (over-exposed): its
    /// centre is measured from a clipped profile and is less precise.
    pub saturated: bool,
}

/// Why a blob is not a target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RejectReason {
    /// Larger than `max_area`.
    TooLarge,
    /// Touches the window's border, or its measuring window or dark
    /// surroundings leave the window.
    Border,
    /// Has saturated pixels (only with
    /// [`DetectorOptions::measure_saturated`] off).
    Saturated,
    /// Too elongated (`max_axis_ratio`).
    Elongated,
    /// Not an ellipse (fill ratio or fourth moment out of range: merged
    /// blobs, odd-shaped reflections).
    Shape,
    /// No signal above the local background.
    NoSignal,
    /// The dark zone around the dot (1 to 2 radii) is not dark: a part of
    /// a code ring, or a dot merged with something.
    NotIsolated,
    /// Part of a coded target's ring.
    CodeRing,
}

/// A rejected blob.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rejection {
    /// Binary centroid, column.
    pub col: f64,
    /// Binary centroid, row.
    pub row: f64,
    /// Pixels above the threshold.
    pub area: u32,
    /// Largest grey value.
    pub peak: u32,
    /// Bounding box `[col0, row0, col1, row1]`, inclusive.
    pub bbox: [u32; 4],
    /// Why.
    pub reason: RejectReason,
}

/// The result of one window (the whole frame or a part of it).
#[derive(Debug, Clone, PartialEq)]
pub struct Detections {
    /// Targets, in the order their blobs start (row-major).
    pub targets: Vec<Detection>,
    /// Rejected blobs of at least `min_area` pixels.
    pub rejected: Vec<Rejection>,
    /// The threshold stage.
    pub threshold: ThresholdResult,
    /// What happened to the frame.
    pub status: FrameStatus,
    /// Blobs found.
    pub n_blobs: usize,
    /// Blobs below `min_area` (not listed).
    pub n_small: usize,
    /// Targets or rejections not listed for lack of capacity.
    pub n_dropped: usize,
    /// Targets with saturated pixels (over-exposed, measured less precisely).
    pub n_saturated: usize,
    /// Some tiles were labelled below the global level (local threshold).
    pub local_levels: bool,
}

impl Detections {
    pub(crate) fn with_capacity(n: usize) -> Self {
        Detections {
            targets: Vec::with_capacity(n),
            rejected: Vec::with_capacity(n),
            threshold: ThresholdResult {
                threshold: Threshold::global(0),
                otsu: 0,
                floor: 0,
                background: 0.0,
                noise: 0.0,
                max_sampled: 0,
                status: FrameStatus::Empty,
            },
            status: FrameStatus::Empty,
            n_blobs: 0,
            n_small: 0,
            n_dropped: 0,
            n_saturated: 0,
            local_levels: false,
        }
    }

    pub(crate) fn clear(&mut self) {
        self.targets.clear();
        self.rejected.clear();
        self.status = FrameStatus::Empty;
        self.n_blobs = 0;
        self.n_small = 0;
        self.n_dropped = 0;
        self.n_saturated = 0;
        self.local_levels = false;
    }

    pub(crate) fn reject(&mut self, blob: &Blob, reason: RejectReason) {
        if self.rejected.len() >= self.rejected.capacity() {
            self.n_dropped += 1;
            return;
        }
        let (col, row) = blob.centre();
        self.rejected.push(Rejection {
            col,
            row,
            area: blob.area,
            peak: blob.max,
            bbox: [blob.col0, blob.row0, blob.col1, blob.row1],
            reason,
        });
    }
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod testutil;
