//! photopose-vision: finds the retro-reflective targets in a frame, measures
//! their centres to a few hundredths of a pixel and reads coded targets.
//!
//! The stages follow section 3.2 of the reference paper:
//!
//! 1. [`threshold`]: grey-value histogram, Otsu's threshold, bounded below by
//!    a noise floor; degenerate frames end here with a [`FrameStatus`].
//! 2. [`label`]: run-length connected components with union-find, blob
//!    statistics in the same pass.
//! 3. Blob discrimination (this module): area, border, saturation, and shape
//!    from second and fourth moments; rejected blobs are kept with a reason.
//! 4. [`measure`]: background-subtracted, intensity-weighted centroid and
//!    ellipse over the bounding box grown by 2 px.
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
//! [`Detector::new`] and [`Detector::detect`] allocates nothing.

pub mod code;
pub mod label;
pub mod measure;
pub mod pixel;
pub mod threshold;

pub use code::{CodeSet, CodeStatus, Uncertainty};
pub use photopose_field::TargetKind;
pub use threshold::{FrameStatus, ThresholdResult};

use code::{CodeParams, Gap, Reading, RingFrame};
use label::{Blob, LabelOutcome, Labeller};
use measure::Measurement;
use photopose_frame::ImageView;
use pixel::{Pixel, Plane};
use thiserror::Error;
use threshold::{ThresholdParams, MAX_BINS};

/// Errors of the detector (a frame without targets is a result, not an error).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum VisionError {
    /// The image does not have the size the detector was built for.
    #[error("image is {got_width}×{got_height} px, the detector expects {width}×{height} px")]
    Size {
        /// Expected width.
        width: u32,
        /// Expected height.
        height: u32,
        /// Width of the image.
        got_width: u32,
        /// Height of the image.
        got_height: u32,
    },
    /// The image buffer is shorter than its size says.
    #[error("image buffer holds {got} pixels, {need} needed")]
    Buffer {
        /// Pixels needed.
        need: usize,
        /// Pixels present.
        got: usize,
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
    /// Histogram sub-sampling step.
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
            histogram_step: 2,
            max_runs: 262_144,
            max_blobs: 32_768,
            max_targets: 4096,
            sector_margin: 0.25,
            sample_margin: 0.1,
            dark_tolerance: 0.3,
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
}

/// Why a blob is not a target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RejectReason {
    /// Larger than `max_area`.
    TooLarge,
    /// Touches the image border, or its window or dark surroundings leave the image.
    Border,
    /// Has saturated pixels.
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

/// The result of one frame.
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
}

impl Detections {
    fn with_capacity(n: usize) -> Self {
        Detections {
            targets: Vec::with_capacity(n),
            rejected: Vec::with_capacity(n),
            threshold: ThresholdResult {
                threshold: 0,
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
        }
    }

    fn clear(&mut self) {
        self.targets.clear();
        self.rejected.clear();
        self.status = FrameStatus::Empty;
        self.n_blobs = 0;
        self.n_small = 0;
        self.n_dropped = 0;
    }

    fn reject(&mut self, blob: &Blob, reason: RejectReason) {
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

/// A blob that passed discrimination, with its measurement and reading.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    blob: u32,
    m: Measurement,
    frame: Option<RingFrame>,
    /// Deblurred moments of the dot.
    moments: (f64, f64, f64),
    reading: Reading,
    suppressed: bool,
}

/// The stages of [`Detector::detect_probed`]; each is reported when it ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DetectStage {
    /// Histogram and Otsu threshold.
    Threshold,
    /// Connected components with their statistics.
    Label,
    /// Blob tests and centroid/moment measurement (of one blob).
    Measure,
    /// Code-ring reading (of one blob).
    Decode,
    /// Ring-part suppression and output.
    Finish,
}

/// The target detector with all its buffers.
#[derive(Debug)]
pub struct Detector {
    width: u32,
    height: u32,
    options: DetectorOptions,
    hist: Vec<u32>,
    labeller: Labeller,
    candidates: Vec<Candidate>,
    order: Vec<u32>,
    tables: code::RingTables,
    out: Detections,
}

impl Detector {
    /// A detector for `width × height` frames; allocates all buffers.
    pub fn new(width: u32, height: u32, options: DetectorOptions) -> Result<Self, VisionError> {
        if width < 8 || height < 8 {
            return Err(VisionError::TooSmall { width, height });
        }
        Ok(Detector {
            width,
            height,
            options,
            hist: vec![0; MAX_BINS],
            labeller: Labeller::new(options.max_runs, options.max_blobs),
            candidates: Vec::with_capacity(options.max_targets),
            order: Vec::with_capacity(options.max_targets),
            tables: code::RingTables::default(),
            out: Detections::with_capacity(options.max_targets),
        })
    }

    /// The options.
    pub fn options(&self) -> &DetectorOptions {
        &self.options
    }

    /// Frame width.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Frame height.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The result of the last frame.
    pub fn detections(&self) -> &Detections {
        &self.out
    }

    /// Detects the targets of a frame. Allocates nothing.
    pub fn detect(&mut self, image: ImageView<'_>) -> Result<&Detections, VisionError> {
        self.detect_probed(image, &mut |_| {})
    }

    /// [`Detector::detect`], calling `probe` each time a [`DetectStage`]
    /// ends (per blob for measuring and decoding). The caller may read a
    /// clock there; this crate reads none.
    pub fn detect_probed(
        &mut self,
        image: ImageView<'_>,
        probe: &mut dyn FnMut(DetectStage),
    ) -> Result<&Detections, VisionError> {
        let (w, h) = (image.width(), image.height());
        if (w, h) != (self.width, self.height) {
            return Err(VisionError::Size {
                width: self.width,
                height: self.height,
                got_width: w,
                got_height: h,
            });
        }
        let need = w as usize * h as usize;
        let max_value = image.max_value() as u32;
        match image {
            ImageView::Mono8 { data, .. } => {
                if data.len() < need {
                    return Err(VisionError::Buffer {
                        need,
                        got: data.len(),
                    });
                }
                self.run(&data[..need], max_value.min(255), probe);
            }
            ImageView::Mono16 { data, .. } => {
                if data.len() < need {
                    return Err(VisionError::Buffer {
                        need,
                        got: data.len(),
                    });
                }
                self.run(&data[..need], max_value, probe);
            }
        }
        probe(DetectStage::Finish);
        Ok(&self.out)
    }

    fn run<P: Pixel>(&mut self, data: &[P], max_value: u32, probe: &mut dyn FnMut(DetectStage)) {
        let o = self.options;
        let (w, h) = (self.width as usize, self.height as usize);
        let plane = Plane {
            data,
            width: w,
            height: h,
        };
        self.out.clear();
        self.candidates.clear();
        self.order.clear();

        // 1. Threshold.
        let shift = threshold::bin_shift(max_value);
        let n = threshold::histogram(
            data,
            w,
            h,
            o.histogram_step,
            shift,
            max_value,
            &mut self.hist,
        );
        let tp = ThresholdParams {
            step: o.histogram_step,
            noise_factor: o.noise_factor,
            min_contrast: o.min_contrast,
            saturated_median: 0.9,
        };
        let t = threshold::threshold(&self.hist, n, shift, max_value, &tp);
        self.out.threshold = t;
        self.out.status = t.status;
        probe(DetectStage::Threshold);
        if t.status != FrameStatus::Normal {
            return;
        }

        // 2. Connected components.
        match self.labeller.label(data, w, h, t.threshold, max_value) {
            LabelOutcome::Complete => {}
            LabelOutcome::TooManyRuns | LabelOutcome::TooManyBlobs => {
                self.out.status = FrameStatus::Cluttered;
                return;
            }
        }
        let blobs = self.labeller.blobs();
        self.out.n_blobs = blobs.len();
        probe(DetectStage::Label);
        if blobs.is_empty() {
            self.out.status = FrameStatus::Empty;
            return;
        }

        // 3. Discrimination and 4. measurement.
        let margin = measure::GROW as u32;
        let code_params = CodeParams {
            min_contrast: (o.noise_factor * t.noise).max(o.min_contrast * max_value as f64),
            sector_margin: o.sector_margin,
            sample_margin: o.sample_margin,
            dark_tolerance: o.dark_tolerance,
        };
        for (i, blob) in blobs.iter().enumerate() {
            if blob.area < o.min_area {
                self.out.n_small += 1;
                continue;
            }
            if blob.area > o.max_area {
                self.out.reject(blob, RejectReason::TooLarge);
                continue;
            }
            if blob.col0 < margin
                || blob.row0 < margin
                || blob.col1 + margin >= self.width
                || blob.row1 + margin >= self.height
            {
                self.out.reject(blob, RejectReason::Border);
                continue;
            }
            if blob.saturated > 0 {
                self.out.reject(blob, RejectReason::Saturated);
                continue;
            }
            let (cxx, cyy, cxy) = blob.covariance();
            let (a, b, _) = measure::ellipse(cxx, cyy, cxy);
            if b.is_nan() || b <= 0.0 || a / b > o.max_axis_ratio {
                self.out.reject(blob, RejectReason::Elongated);
                continue;
            }
            let fill = blob.area as f64 / (std::f64::consts::PI * a * b);
            if fill < o.fill_range.0 || fill > o.fill_range.1 {
                self.out.reject(blob, RejectReason::Shape);
                continue;
            }
            let Some(mut m) = measure::measure(
                &plane,
                blob,
                t.threshold,
                t.background,
                measure::GROW,
                measure::MAX_SCALE,
            ) else {
                self.out.reject(blob, RejectReason::NoSignal);
                continue;
            };
            if (m.kurtosis - 2.0).abs() > o.kurtosis_tolerance + 5.0 / blob.area as f64 {
                self.out.reject(blob, RejectReason::Shape);
                continue;
            }
            if self.candidates.len() >= self.candidates.capacity() {
                self.out.n_dropped += 1;
                continue;
            }
            probe(DetectStage::Measure);
            // 5. Code ring, sampled on the dot's ellipse with the blur removed.
            let mut amplitude = plane.bilinear(m.col, m.row).unwrap_or(0.0);
            for (dx, dy) in [(0.5, 0.0), (-0.5, 0.0), (0.0, 0.5), (0.0, -0.5)] {
                amplitude += plane.bilinear(m.col + dx, m.row + dy).unwrap_or(0.0);
            }
            amplitude = amplitude / 5.0 - m.background;
            let (cxx, cyy, cxy, _) = measure::deblurred(&m, amplitude);
            let frame = RingFrame::from_moments(m.col, m.row, cxx, cyy, cxy);
            let reading = match &frame {
                Some(f) => code::read(&plane, f, &code_params, &o.codes, &self.tables),
                None => Reading {
                    gap: Gap::NotDark,
                    status: CodeStatus::Uncertain(Uncertainty::LowContrast),
                    ring_present: false,
                    raw: 0,
                    bright: 0.0,
                    dark: 0.0,
                },
            };
            probe(DetectStage::Decode);
            if reading.status == CodeStatus::Uncertain(Uncertainty::OutsideImage)
                && !reading.ring_present
            {
                // Its ring zone leaves the image and nothing bright is seen
                // in the part inside: it may be a part of the ring of a
                // coded target whose dot is outside the frame.
                self.out.reject(blob, RejectReason::Border);
                continue;
            }
            match reading.gap {
                Gap::Dark => {}
                Gap::NotDark => {
                    self.out.reject(blob, RejectReason::NotIsolated);
                    continue;
                }
                Gap::Outside => {
                    self.out.reject(blob, RejectReason::Border);
                    continue;
                }
            }
            if reading.ring_present {
                // Measure again with a window that keeps clear of the ring.
                if let Some(m2) = measure::measure(
                    &plane,
                    blob,
                    t.threshold,
                    t.background,
                    measure::CODED_GROW,
                    measure::CODED_MAX_SCALE,
                ) {
                    m = m2;
                }
                probe(DetectStage::Measure);
            }
            self.candidates.push(Candidate {
                blob: i as u32,
                m,
                frame,
                moments: (cxx, cyy, cxy),
                reading,
                suppressed: false,
            });
        }

        // Ring parts: blobs in the ring zone of a target with a ring.
        // Decoded targets come first, then rings with dark surroundings
        // (whatever their reading), then the rest by decreasing area; the
        // first two suppress whatever lies in their ring zone (but a decoded
        // target only yields to a decoded one), the rest only smaller blobs.
        for k in 0..self.candidates.len() {
            self.order.push(k as u32);
        }
        let cands = &mut self.candidates;
        let rank = |c: &Candidate| -> u8 {
            if c.reading.status.id().is_some() {
                0
            } else if strong_ring(&c.reading) {
                1
            } else {
                2
            }
        };
        self.order.sort_unstable_by(|&x, &y| {
            let (cx, cy) = (&cands[x as usize], &cands[y as usize]);
            let (ax, ay) = (blobs[cx.blob as usize].area, blobs[cy.blob as usize].area);
            rank(cx).cmp(&rank(cy)).then(ay.cmp(&ax)).then(x.cmp(&y))
        });
        for oi in 0..self.order.len() {
            let i = self.order[oi] as usize;
            let y = cands[i];
            if y.suppressed || !y.reading.ring_present {
                continue;
            }
            let Some(f) = y.frame else { continue };
            let y_area = blobs[y.blob as usize].area;
            let y_rank = rank(&y);
            for (j, x) in cands.iter_mut().enumerate() {
                if j == i || x.suppressed {
                    continue;
                }
                if y_rank == 2 && blobs[x.blob as usize].area > y_area {
                    continue;
                }
                if x.reading.status.id().is_some() && y_rank > 0 {
                    continue;
                }
                let rho = f.radius_of(x.m.col, x.m.row);
                if (1.6..=3.8).contains(&rho) {
                    x.suppressed = true;
                }
            }
            // Rejected blobs inside a ring zone are ring parts as well.
            for r in self.out.rejected.iter_mut() {
                if matches!(r.reason, RejectReason::Shape | RejectReason::Elongated)
                    && (1.6..=3.8).contains(&f.radius_of(r.col, r.row))
                {
                    r.reason = RejectReason::CodeRing;
                }
            }
        }

        // Output.
        for c in self.candidates.iter() {
            let blob = &blobs[c.blob as usize];
            if c.suppressed {
                self.out.reject(blob, RejectReason::CodeRing);
                continue;
            }
            if self.out.targets.len() >= self.out.targets.capacity() {
                self.out.n_dropped += 1;
                continue;
            }
            let (a, b, angle) = measure::ellipse(c.moments.0, c.moments.1, c.moments.2);
            self.out.targets.push(Detection {
                col: c.m.col,
                row: c.m.row,
                semi_major: a,
                semi_minor: b,
                angle,
                area: blob.area,
                peak: blob.max,
                signal: c.m.signal,
                background: c.m.background,
                kind: if c.reading.ring_present {
                    TargetKind::Coded
                } else {
                    TargetKind::Uncoded
                },
                id: c.reading.status.id(),
                code: c.reading.status,
            });
        }
    }
}

#[cfg(test)]
mod tests;
/// Whether a reading found a ring with dark gap and quiet zone (a coded
/// target, read or not).
fn strong_ring(r: &Reading) -> bool {
    r.ring_present
        && r.gap == Gap::Dark
        && !matches!(
            r.status,
            CodeStatus::Uncertain(
                Uncertainty::OutsideImage
                    | Uncertainty::QuietZoneNotDark
                    | Uncertainty::LowContrast
            )
        )
}

#[cfg(test)]
mod testutil;
