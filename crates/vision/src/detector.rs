//! The [`Detector`]: its buffers, sized once for the largest window it
//! serves (its capacity), and the detection of one window as a sequence of
//! stages, each a function of its own: threshold → labelling → blob tests →
//! centroid → code ring, then the suppression of ring parts and the output.
//!
//! A window is any [`ImageView`] no larger than the capacity: the whole
//! frame, a part of it, or a region of a larger frame. Everything the
//! stages compute is in full-frame pixel coordinates, so a target fully
//! inside a window is measured exactly as in the whole frame when the same
//! threshold is used ([`Detector::detect_with`]).

use crate::code::{self, CodeParams, Gap, Reading, RingFrame, RingTables};
use crate::label::{Blob, LabelOutcome, Labeller};
use crate::measure::{self, Measurement};
use crate::pixel::{Pixel, Plane};
use crate::threshold::{
    self, FrameStatus, LocalLevels, Threshold, ThresholdParams, ThresholdResult, MAX_BINS,
};
use crate::{
    CodeStatus, Detection, Detections, DetectorOptions, RejectReason, TargetKind, Uncertainty,
    VisionError,
};
use photopose_frame::{ImageView, ViewPixels};
use wide::f64x2;

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

/// A blob that passed discrimination, with its measurement and reading.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    blob: u32,
    /// The blob's binary centre `(col, row)` (where the ring-part
    /// suppression places it).
    at: (f64, f64),
    m: Measurement,
    frame: Option<RingFrame>,
    /// Deblurred moments of the dot.
    moments: (f64, f64, f64),
    reading: Reading,
    suppressed: bool,
}

/// The target detector with all its buffers.
#[derive(Debug)]
pub struct Detector {
    max_width: u32,
    max_height: u32,
    options: DetectorOptions,
    hist: Vec<u32>,
    labeller: Labeller,
    candidates: Vec<Candidate>,
    order: Vec<u32>,
    /// The candidates' rows and indices by row (ring-part suppression).
    by_row: Vec<(f64, u32)>,
    /// The blobs that passed the blob tests, as sort keys (largest
    /// first), then the examined candidates' keys (in the blobs' order).
    pending: Vec<u64>,
    /// The candidates in the order they were examined.
    examined: Vec<Candidate>,
    /// The blobs rejected while examining them, with the reason.
    verdicts: Vec<(u32, RejectReason)>,
    /// The ring zones of the decoded targets examined so far
    /// ([`DecodedZone`]).
    zones: Vec<DecodedZone>,
    /// Whether ring parts are found before measuring (off: every blob is
    /// measured and read, the reference the tests compare with).
    #[cfg(test)]
    early_parts: bool,
    tables: RingTables,
    /// The window's local levels (all at the global level unless
    /// [`DetectorOptions::local_threshold`] found dim surroundings).
    levels: LocalLevels,
    /// The level held by [`DetectorOptions::threshold_hold`] and the
    /// saturation level of the frames it was found on.
    held: Option<(u32, Threshold)>,
    out: Detections,
}

/// The window of `image` as the stages read it.
fn plane<'a, P>(image: &ImageView<'_>, data: &'a [P]) -> Plane<'a, P> {
    let (col0, row0) = image.origin();
    Plane {
        data,
        width: image.width() as usize,
        height: image.height() as usize,
        stride: image.stride(),
        col0: col0 as usize,
        row0: row0 as usize,
    }
}

impl Detector {
    /// A detector for windows of up to `max_width × max_height` pixels
    /// (its capacity; at least 8 × 8); allocates all buffers.
    pub fn new(
        max_width: u32,
        max_height: u32,
        options: DetectorOptions,
    ) -> Result<Self, VisionError> {
        if max_width < 8 || max_height < 8 {
            return Err(VisionError::TooSmall {
                width: max_width,
                height: max_height,
            });
        }
        Ok(Detector {
            max_width,
            max_height,
            options,
            hist: vec![0; MAX_BINS],
            labeller: Labeller::new(options.max_runs, options.max_blobs),
            candidates: Vec::with_capacity(options.max_targets),
            order: Vec::with_capacity(options.max_targets),
            by_row: Vec::with_capacity(options.max_targets),
            pending: Vec::with_capacity(options.max_blobs),
            examined: Vec::with_capacity(options.max_targets),
            verdicts: Vec::with_capacity(options.max_blobs),
            zones: Vec::with_capacity(options.max_targets),
            #[cfg(test)]
            early_parts: true,
            tables: RingTables::default(),
            levels: LocalLevels::new(max_width as usize, max_height as usize),
            held: None,
            out: Detections::with_capacity(options.max_targets),
        })
    }

    /// The options.
    pub fn options(&self) -> &DetectorOptions {
        &self.options
    }

    /// The largest window `(width, height)` the detector serves.
    pub fn capacity(&self) -> (u32, u32) {
        (self.max_width, self.max_height)
    }

    /// The result of the last window.
    pub fn detections(&self) -> &Detections {
        &self.out
    }

    /// Detects the targets of a window (threshold from the window itself).
    /// Allocates nothing.
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
        self.dispatch(image, None, probe)
    }

    /// The threshold stage alone: the threshold of a window (for instance
    /// of a whole frame, to detect in windows of it with
    /// [`Detector::detect_with`]). Allocates nothing.
    pub fn threshold(&mut self, image: ImageView<'_>) -> Result<ThresholdResult, VisionError> {
        self.check(&image)?;
        let max_value = image.max_value() as u32;
        Ok(match image.pixels() {
            ViewPixels::Mono8(data) => {
                self.find_threshold(&plane(&image, data), max_value.min(255), false)
            }
            ViewPixels::Mono16(data) => self.find_threshold(&plane(&image, data), max_value, false),
        })
    }

    /// Detects the targets of a window with a threshold found before (on
    /// the whole frame, or on an earlier frame), skipping the threshold
    /// stage: a target fully inside the window is then reported exactly as
    /// in the frame the threshold came from. A threshold whose status is
    /// not normal ends the window with that status. Allocates nothing.
    pub fn detect_with(
        &mut self,
        image: ImageView<'_>,
        threshold: &ThresholdResult,
    ) -> Result<&Detections, VisionError> {
        self.detect_with_probed(image, threshold, &mut |_| {})
    }

    /// [`Detector::detect_with`] with a probe as in [`Detector::detect_probed`].
    pub fn detect_with_probed(
        &mut self,
        image: ImageView<'_>,
        threshold: &ThresholdResult,
        probe: &mut dyn FnMut(DetectStage),
    ) -> Result<&Detections, VisionError> {
        self.dispatch(image, Some(threshold), probe)
    }

    /// Refuses a window larger than the capacity.
    fn check(&self, image: &ImageView<'_>) -> Result<(), VisionError> {
        let (w, h) = (image.width(), image.height());
        if w > self.max_width || h > self.max_height {
            return Err(VisionError::Size {
                width: self.max_width,
                height: self.max_height,
                got_width: w,
                got_height: h,
            });
        }
        Ok(())
    }

    fn dispatch(
        &mut self,
        image: ImageView<'_>,
        given: Option<&ThresholdResult>,
        probe: &mut dyn FnMut(DetectStage),
    ) -> Result<&Detections, VisionError> {
        self.check(&image)?;
        let max_value = image.max_value() as u32;
        match image.pixels() {
            ViewPixels::Mono8(data) => {
                self.run(&plane(&image, data), max_value.min(255), given, probe)
            }
            ViewPixels::Mono16(data) => self.run(&plane(&image, data), max_value, given, probe),
        }
        probe(DetectStage::Finish);
        Ok(&self.out)
    }

    /// All stages on one window.
    fn run<P: Pixel>(
        &mut self,
        plane: &Plane<'_, P>,
        max_value: u32,
        given: Option<&ThresholdResult>,
        probe: &mut dyn FnMut(DetectStage),
    ) {
        self.out.clear();
        self.candidates.clear();
        self.order.clear();
        // 1. Threshold (and the tile peaks of the local levels, from the
        // same pass over the rows).
        let local = given.is_none() && self.options.local_threshold > 0.0;
        let t = match given {
            Some(t) => *t,
            None => {
                let t = self.find_threshold(plane, max_value, local);
                self.hold(t, max_value)
            }
        };
        self.out.threshold = t;
        self.out.status = t.status;
        probe(DetectStage::Threshold);
        if t.status != FrameStatus::Normal {
            return;
        }
        // Local levels: only for a threshold found on this window.
        if local {
            let o = &self.options;
            let floor = (o.local_noise_factor * t.noise).max(o.min_contrast * max_value as f64);
            self.levels.from_peaks(plane, &t, o.local_threshold, floor);
        } else {
            self.levels.set_global(plane, t.threshold);
        }
        self.out.local_levels = self.levels.any_local();
        // 2. Connected components.
        if !self.label(plane, t.threshold, max_value) {
            return;
        }
        probe(DetectStage::Label);
        if self.out.n_blobs == 0 {
            self.out.status = FrameStatus::Empty;
            return;
        }
        // 3.–5. Each blob: tests, centroid, code ring.
        self.examine_blobs(plane, &t, max_value, probe);
        // Parts of rings, then the output.
        self.suppress_ring_parts();
        self.emit();
    }

    /// The threshold hysteresis ([`DetectorOptions::threshold_hold`]): `t`
    /// with the held level while it lies within the band, else `t`, whose
    /// level is then held.
    fn hold(&mut self, mut t: ThresholdResult, max_value: u32) -> ThresholdResult {
        let hold = self.options.threshold_hold;
        if t.status != FrameStatus::Normal || hold.is_nan() || hold <= 0.0 {
            return t;
        }
        let band = (hold * t.noise).max((1u32 << threshold::bin_shift(max_value)) as f64);
        match self.held {
            Some((m, h))
                if m == max_value
                    && (h.level() as f64 - t.threshold.level() as f64).abs() <= band =>
            {
                t.threshold = h;
            }
            _ => self.held = Some((max_value, t.threshold)),
        }
        t
    }

    /// Stage 1: the sub-sampled histogram of the window and its threshold;
    /// with `peaks`, the tile peaks of the local levels as well (from the
    /// same pass over the rows).
    fn find_threshold<P: Pixel>(
        &mut self,
        plane: &Plane<'_, P>,
        max_value: u32,
        peaks: bool,
    ) -> ThresholdResult {
        let o = &self.options;
        let shift = threshold::bin_shift(max_value);
        let n = if peaks {
            self.levels.histogram_and_peaks(
                plane,
                o.histogram_step,
                shift,
                max_value,
                &mut self.hist,
            )
        } else {
            threshold::histogram(plane, o.histogram_step, shift, max_value, &mut self.hist)
        };
        let params = ThresholdParams {
            step: o.histogram_step,
            noise_factor: o.noise_factor,
            min_contrast: o.min_contrast,
            saturated_median: 0.9,
        };
        threshold::threshold(&self.hist, n, shift, max_value, &params)
    }

    /// Stage 2: connected components; false (with the frame's status set)
    /// if the window has more runs or blobs than the capacity.
    fn label<P: Pixel>(&mut self, plane: &Plane<'_, P>, t: Threshold, max_value: u32) -> bool {
        let outcome = if self.levels.any_local() {
            self.labeller.label_local(plane, &self.levels, max_value)
        } else {
            self.labeller.label(plane, t, max_value)
        };
        match outcome {
            LabelOutcome::Complete => {
                self.out.n_blobs = self.labeller.blobs().len();
                true
            }
            LabelOutcome::TooManyRuns | LabelOutcome::TooManyBlobs => {
                self.out.status = FrameStatus::Cluttered;
                false
            }
        }
    }

    /// Stages 3 to 5 for every blob: the blob tests, the centroid, the
    /// code ring; blobs that pass become candidates, the others rejections
    /// (with their reason), both in the order the blobs start.
    ///
    /// The blobs that pass the tests are measured largest first: a coded
    /// target's dot is larger than the parts of its ring that pass them,
    /// so once the dot is decoded, its ring parts are found from their
    /// binary centre ([`DecodedZone`]) and neither measured nor read (the
    /// suppression would remove them whatever they read). When more blobs
    /// pass than the detector holds candidates (`max_targets`), the
    /// smallest are the ones dropped.
    fn examine_blobs<P: Pixel>(
        &mut self,
        plane: &Plane<'_, P>,
        t: &ThresholdResult,
        max_value: u32,
        probe: &mut dyn FnMut(DetectStage),
    ) {
        #[cfg(test)]
        let early = self.early_parts;
        #[cfg(not(test))]
        let early = true;
        let Detector {
            options: o,
            labeller,
            candidates,
            tables,
            levels,
            pending,
            examined,
            verdicts,
            zones,
            out,
            ..
        } = self;
        let blobs = labeller.blobs();
        let min_read = (o.noise_factor * t.noise).max(o.min_contrast * max_value as f64);
        let min_local = (o.local_noise_factor * t.noise).max(o.min_contrast * max_value as f64);
        let mut code_params = CodeParams {
            min_contrast: min_read,
            min_isolation_contrast: min_read,
            sector_margin: o.sector_margin,
            sample_margin: o.sample_margin,
            dark_tolerance: o.dark_tolerance,
        };
        pending.clear();
        examined.clear();
        verdicts.clear();
        zones.clear();
        // 3. Tests on the binary statistics; the blobs that pass, keyed
        // largest first (ties in the blobs' order).
        for (i, blob) in blobs.iter().enumerate() {
            if blob.area < o.min_area {
                out.n_small += 1;
                continue;
            }
            match blob_tests(plane, blob, o) {
                Err(reason) => verdicts.push((i as u32, reason)),
                Ok(()) => pending.push(((u32::MAX - blob.area) as u64) << 32 | i as u64),
            }
        }
        pending.sort_unstable();
        for &key in pending.iter() {
            let i = key as u32;
            let blob = &blobs[i as usize];
            if early && zones.iter().any(|z| z.holds(blob)) {
                if examined.len() >= examined.capacity() {
                    out.n_dropped += 1;
                } else {
                    examined.push(Candidate::ring_part(i, blob));
                }
                continue;
            }
            // The blob's level: its tile's (the global one but in dim
            // surroundings).
            let local;
            // A dim blob (in a lowered tile) may be judged isolated with
            // the local floor's contrast; its ring is read only above the
            // global one.
            let t = if levels.any_local() {
                let (c, r) = blob.centre();
                local = ThresholdResult {
                    threshold: levels.at(c.max(0.0) as usize, r.max(0.0) as usize),
                    ..*t
                };
                code_params.min_isolation_contrast = if local.threshold == t.threshold {
                    min_read
                } else {
                    min_local
                };
                &local
            } else {
                t
            };
            // 4. Centroid and moments.
            let m = match centroid(plane, blob, t, o, max_value) {
                Ok(m) => m,
                Err(reason) => {
                    verdicts.push((i, reason));
                    continue;
                }
            };
            if examined.len() >= examined.capacity() {
                out.n_dropped += 1;
                continue;
            }
            probe(DetectStage::Measure);
            // 5. Code ring, sampled on the dot's ellipse with the blur removed.
            let ring = read_ring(plane, &m, &code_params, o, tables);
            probe(DetectStage::Decode);
            if let Err(reason) = ring_verdict(&ring.reading) {
                verdicts.push((i, reason));
                continue;
            }
            if let (Some(_), Some(f)) = (ring.reading.status.id(), ring.frame) {
                zones.push(DecodedZone::new(f));
            }
            let m = if ring.reading.ring_present {
                let m = coded_centre(plane, blob, t, o, max_value).unwrap_or(m);
                probe(DetectStage::Measure);
                m
            } else {
                m
            };
            examined.push(Candidate {
                blob: i,
                at: blob.centre(),
                m,
                frame: ring.frame,
                moments: ring.moments,
                reading: ring.reading,
                suppressed: false,
            });
        }
        // Back to the blobs' order.
        pending.clear();
        pending.extend(
            examined
                .iter()
                .enumerate()
                .map(|(k, c)| (c.blob as u64) << 32 | k as u64),
        );
        pending.sort_unstable();
        candidates.extend(pending.iter().map(|&key| examined[key as u32 as usize]));
        verdicts.sort_unstable_by_key(|v| v.0);
        for &(i, reason) in verdicts.iter() {
            out.reject(&blobs[i as usize], reason);
        }
    }

    /// Ring parts: blobs in the ring zone of a target with a ring
    /// ([`suppress_ring_parts`]).
    fn suppress_ring_parts(&mut self) {
        let Detector {
            labeller,
            candidates,
            order,
            by_row,
            out,
            ..
        } = self;
        suppress_ring_parts(
            labeller.blobs(),
            candidates,
            &mut out.rejected,
            order,
            Some(by_row),
        );
    }

    /// The output: every candidate not suppressed becomes a target.
    fn emit(&mut self) {
        let blobs = self.labeller.blobs();
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
                saturated: blob.saturated > 0,
            });
            self.out.n_saturated += (blob.saturated > 0) as usize;
        }
    }
}

/// The ring zone of a target with a ring, in units of its dot's radius.
const RING_ZONE: std::ops::RangeInclusive<f64> = 1.6..=3.8;

/// The ring zone of a decoded target, for finding its ring parts before
/// they are measured: the suppression ([`suppress_ring_parts`]) places a
/// blob at its binary centre, and a decoded target suppresses everything
/// in its zone but another decoded target, so a blob there is a ring part
/// whatever it would read (only a second decoded target in the first's
/// zone could act before it, which a plate never shows).
#[derive(Debug, Clone, Copy)]
struct DecodedZone {
    frame: RingFrame,
    /// How far the zone reaches from its centre in columns and rows.
    reach: (f64, f64),
}

impl DecodedZone {
    fn new(frame: RingFrame) -> Self {
        let [a, b, _] = frame.e;
        let cols = RING_ZONE.end() * (a * a + b * b).sqrt() * (1.0 + 1e-6) + 1e-6;
        DecodedZone {
            frame,
            reach: (cols, ring_reach(&frame)),
        }
    }

    /// Whether the binary centre of `blob` lies in the zone.
    fn holds(&self, blob: &Blob) -> bool {
        let (col, row) = blob.centre();
        let f = &self.frame;
        (col - f.col).abs() <= self.reach.0
            && (row - f.row).abs() <= self.reach.1
            && RING_ZONE.contains(&f.radius_of(col, row))
    }
}

/// How far in rows the ring zone of `f` reaches from its centre: a point
/// at radius ρ lies at most ρ times the norm of E's second row away (with
/// a margin for rounding).
fn ring_reach(f: &RingFrame) -> f64 {
    let reach = RING_ZONE.end() * (f.e[1] * f.e[1] + f.e[2] * f.e[2]).sqrt();
    reach * (1.0 + 1e-6) + 1e-6
}

impl Candidate {
    /// A ring part found before measuring ([`DecodedZone`]): suppressed,
    /// never measured (its binary centre stands in for the centre).
    fn ring_part(blob: u32, b: &Blob) -> Self {
        let (col, row) = b.centre();
        Candidate {
            blob,
            at: (col, row),
            m: Measurement {
                col,
                row,
                cxx: 0.0,
                cyy: 0.0,
                cxy: 0.0,
                signal: 0.0,
                background: 0.0,
                kurtosis: 0.0,
            },
            frame: None,
            moments: (0.0, 0.0, 0.0),
            reading: Reading {
                gap: Gap::NotDark,
                status: CodeStatus::NoRing,
                ring_present: false,
                raw: 0,
                bright: 0.0,
                dark: 0.0,
            },
            suppressed: true,
        }
    }
}

/// Ring parts: blobs in the ring zone of a target with a ring. Decoded
/// targets come first, then rings with dark surroundings (whatever their
/// reading), then the rest by decreasing area; the first two suppress
/// whatever lies in their ring zone (but a decoded target only yields to a
/// decoded one), the rest only smaller blobs. Rejected blobs of odd shape
/// in a ring zone become ring parts as well.
///
/// With `by_row` (a buffer), the candidates a ring may suppress are looked
/// up among those whose rows lie within the ring zone's reach (candidates
/// sorted by row), not among all of them; the result is the same.
fn suppress_ring_parts(
    blobs: &[Blob],
    cands: &mut [Candidate],
    rejected: &mut [crate::Rejection],
    order: &mut Vec<u32>,
    mut by_row: Option<&mut Vec<(f64, u32)>>,
) {
    // Only a candidate with a ring suppresses: those, in their order.
    order.clear();
    order.extend(
        (0..cands.len() as u32).filter(|&i| {
            cands[i as usize].reading.ring_present && cands[i as usize].frame.is_some()
        }),
    );
    let rank = |c: &Candidate| -> u8 {
        if c.reading.status.id().is_some() {
            0
        } else if strong_ring(&c.reading) {
            1
        } else {
            2
        }
    };
    order.sort_unstable_by(|&x, &y| {
        let (cx, cy) = (&cands[x as usize], &cands[y as usize]);
        let (ax, ay) = (blobs[cx.blob as usize].area, blobs[cy.blob as usize].area);
        rank(cx).cmp(&rank(cy)).then(ay.cmp(&ax)).then(x.cmp(&y))
    });
    if let Some(b) = by_row.as_mut() {
        b.clear();
        b.extend(cands.iter().enumerate().map(|(j, c)| (c.at.1, j as u32)));
        b.sort_unstable_by(|x, y| x.0.total_cmp(&y.0));
    }
    for &i in order.iter() {
        let i = i as usize;
        let y = cands[i];
        if y.suppressed || !y.reading.ring_present {
            continue;
        }
        let Some(f) = y.frame else { continue };
        let y_area = blobs[y.blob as usize].area;
        let y_rank = rank(&y);
        let consider = |j: usize, x: &mut Candidate| {
            if j == i || x.suppressed {
                return;
            }
            if y_rank == 2 && blobs[x.blob as usize].area > y_area {
                return;
            }
            if x.reading.status.id().is_some() && y_rank > 0 {
                return;
            }
            if RING_ZONE.contains(&f.radius_of(x.at.0, x.at.1)) {
                x.suppressed = true;
            }
        };
        match by_row.as_deref() {
            Some(by_row) => {
                let reach = ring_reach(&f);
                let (lo, hi) = (f.row - reach, f.row + reach);
                let first = by_row.partition_point(|(r, _)| r.total_cmp(&lo).is_lt());
                let last = by_row.partition_point(|(r, _)| r.total_cmp(&hi).is_le());
                for &(_, j) in &by_row[first..last.max(first)] {
                    consider(j as usize, &mut cands[j as usize]);
                }
            }
            None => {
                for (j, x) in cands.iter_mut().enumerate() {
                    consider(j, x);
                }
            }
        }
        // Rejected blobs inside a ring zone are ring parts as well.
        for r in rejected.iter_mut() {
            if matches!(r.reason, RejectReason::Shape | RejectReason::Elongated)
                && RING_ZONE.contains(&f.radius_of(r.col, r.row))
            {
                r.reason = RejectReason::CodeRing;
            }
        }
    }
}

/// Stage 3: the tests on a blob's binary statistics (area, distance from
/// the window's edge, saturation, elongation, fill of its ellipse).
#[inline(always)]
pub(crate) fn blob_tests<P: Pixel>(
    plane: &Plane<'_, P>,
    blob: &Blob,
    o: &DetectorOptions,
) -> Result<(), RejectReason> {
    if blob.area > o.max_area {
        return Err(RejectReason::TooLarge);
    }
    // The measuring window (the box grown by `GROW`) must lie inside.
    let margin = measure::GROW as u32;
    let (col0, row0) = (plane.col0 as u32, plane.row0 as u32);
    if blob.col0 < col0 + margin
        || blob.row0 < row0 + margin
        || blob.col1 + margin > plane.last_col() as u32
        || blob.row1 + margin > plane.last_row() as u32
    {
        return Err(RejectReason::Border);
    }
    if blob.saturated > 0 && !o.measure_saturated {
        return Err(RejectReason::Saturated);
    }
    // The semi-axes `a = 2√λ₁`, `b = 2√λ₂` of the principal moments
    // ([`measure::axes`]) compared without forming them: `a / b > ratio`
    // is `λ₁ > ratio² λ₂`, and the fill `area / (π a b)` is compared as
    // `area` against `π a b = 4π √(λ₁ λ₂)`. Why: one square root on the
    // path to the decision instead of three and two divisions (the blob's
    // measurement waited for that chain, about 80 cycles per target).
    let (cxx, cyy, cxy) = blob.covariance();
    let half = (cxx + cyy) / 2.0;
    let d = ((cxx - cyy) * (cxx - cyy) / 4.0 + cxy * cxy).sqrt();
    let (l1, l2) = ((half + d).max(0.0), (half - d).max(0.0));
    // (A NaN moment gives `l2 = 0`: `max` returns the number. The ratio
    // times its magnitude keeps its sign: a negative one rejects every
    // blob, as `a / b >` it did.)
    let ratio = o.max_axis_ratio;
    if l2 <= 0.0 || l1 > ratio * ratio.abs() * l2 {
        return Err(RejectReason::Elongated);
    }
    let ab = 4.0 * std::f64::consts::PI * (l1 * l2).sqrt();
    let area = blob.area as f64;
    if area < o.fill_range.0 * ab || area > o.fill_range.1 * ab {
        return Err(RejectReason::Shape);
    }
    Ok(())
}

/// Stage 4: the background-subtracted centroid and moments of a blob, and
/// the test of its fourth moment (a filled ellipse's).
pub(crate) fn centroid<P: Pixel>(
    plane: &Plane<'_, P>,
    blob: &Blob,
    t: &ThresholdResult,
    o: &DetectorOptions,
    max_value: u32,
) -> Result<Measurement, RejectReason> {
    shape_tested(
        centre_in(plane, blob, t, o, max_value, measure::DotMargin),
        blob,
        o,
    )
}

/// [`centroid`] in the window of a coded target's dot that keeps clear of
/// its ring ([`coded_centre`] with the fourth-moment test).
pub(crate) fn coded_centroid<P: Pixel>(
    plane: &Plane<'_, P>,
    blob: &Blob,
    t: &ThresholdResult,
    o: &DetectorOptions,
    max_value: u32,
) -> Result<Measurement, RejectReason> {
    shape_tested(coded_centre(plane, blob, t, o, max_value), blob, o)
}

/// A centre of `blob` (`None`: no signal) with the test of its fourth
/// moment (a filled ellipse's).
fn shape_tested(
    m: Option<Measurement>,
    blob: &Blob,
    o: &DetectorOptions,
) -> Result<Measurement, RejectReason> {
    let m = m.ok_or(RejectReason::NoSignal)?;
    if (m.kurtosis - 2.0).abs() > o.kurtosis_tolerance + 5.0 / blob.area as f64 {
        return Err(RejectReason::Shape);
    }
    Ok(m)
}

/// The centre of a coded target's dot, measured again in a window that
/// keeps clear of its ring ([`measure::CODED_GROW`]); `None` if that
/// window holds no signal.
pub(crate) fn coded_centre<P: Pixel>(
    plane: &Plane<'_, P>,
    blob: &Blob,
    t: &ThresholdResult,
    o: &DetectorOptions,
    max_value: u32,
) -> Option<Measurement> {
    centre_in(plane, blob, t, o, max_value, measure::CodedMargin)
}

/// The centroid and moments of a blob in the window of `margin`, its
/// centre rolled off below saturation when most of it is saturated
/// ([`saturated_centre`]).
fn centre_in<P: Pixel>(
    plane: &Plane<'_, P>,
    blob: &Blob,
    t: &ThresholdResult,
    o: &DetectorOptions,
    max_value: u32,
    margin: impl measure::Margin,
) -> Option<Measurement> {
    let mut m = measure::measure(plane, blob, t.threshold, t.background, margin)?;
    if blob.saturated > 0 {
        saturated_centre(plane, blob, t, max_value, o.saturated_knee, margin, &mut m);
    }
    Some(m)
}

/// The centre of a blob at least half of whose pixels are saturated: the
/// centroid with the grey values rolled off smoothly below the saturation
/// level ([`measure::Knee`], from `knee` of the way between background and
/// saturation), replacing the centre of `m` (its moments and signal stay
/// those of the clipped profile). Blobs with fewer clipped pixels keep the
/// plain centroid: there the roll-off would throw away more signal than
/// the kink costs (see the detector's over-exposure test).
fn saturated_centre<P: Pixel>(
    plane: &Plane<'_, P>,
    blob: &Blob,
    t: &ThresholdResult,
    max_value: u32,
    knee: f64,
    margin: impl measure::Margin,
    m: &mut Measurement,
) {
    if 2 * blob.saturated < blob.area || knee >= 1.0 {
        return;
    }
    let knee = measure::Knee {
        knee: (m.background + knee * (max_value as f64 - m.background)) as u32,
        top: max_value,
    };
    if let Some(k) = measure::measure_weighted(plane, blob, t.threshold, t.background, margin, knee)
    {
        m.col = k.col;
        m.row = k.row;
    }
}

/// What stage 5 found around a dot.
pub(crate) struct Ring {
    /// The sampling frame of the ring (from the deblurred moments).
    frame: Option<RingFrame>,
    /// The dot's deblurred moments `(cxx, cyy, cxy)`.
    moments: (f64, f64, f64),
    pub(crate) reading: Reading,
}

/// Stage 5: the code ring around a measured dot, sampled on the dot's
/// ellipse with the blur removed.
pub(crate) fn read_ring<P: Pixel>(
    plane: &Plane<'_, P>,
    m: &Measurement,
    params: &CodeParams,
    o: &DetectorOptions,
    tables: &RingTables,
) -> Ring {
    let (centre, (cxx, cyy, cxy), frame) = ring_frame(plane, m);
    let reading = match &frame {
        Some(f) => code::read_centred(plane, f, centre, params, &o.codes, tables),
        None => Reading {
            gap: Gap::NotDark,
            status: CodeStatus::Uncertain(Uncertainty::LowContrast),
            ring_present: false,
            raw: 0,
            bright: 0.0,
            dark: 0.0,
        },
    };
    Ring {
        frame,
        moments: (cxx, cyy, cxy),
        reading,
    }
}

/// The grey value at the centre of the dot measured by `m` (`None`
/// outside the window: see [`dot_samples`]), its deblurred moments and
/// the sampling frame of its ring (`None`: no ellipse).
fn ring_frame<P: Pixel>(
    plane: &Plane<'_, P>,
    m: &Measurement,
) -> (Option<f64>, (f64, f64, f64), Option<RingFrame>) {
    // (The reader's bright level starts from the centre's value.)
    let (centre, amplitude) = dot_samples(plane, m.col, m.row);
    let amplitude = amplitude / 5.0 - m.background;
    let (cxx, cyy, cxy, _) = measure::deblurred(m, amplitude);
    let frame = RingFrame::from_moments(m.col, m.row, cxx, cyy, cxy);
    (centre, (cxx, cyy, cxy), frame)
}

/// Whether the ring around the dot measured by `m` plainly carries the
/// code of canonical value `value` ([`code::confirms`]: `false` says
/// nothing; read the ring then).
pub(crate) fn confirm_ring<P: Pixel>(
    plane: &Plane<'_, P>,
    m: &Measurement,
    params: &CodeParams,
    value: u16,
    tables: &RingTables,
) -> bool {
    let (centre, _, frame) = ring_frame(plane, m);
    frame.is_some_and(|f| code::confirms(plane, &f, centre, params, value, tables))
}

/// The grey value at a dot's centre `(col, row)` (`None` outside the
/// window) and the sum of the values there and half a pixel to the right,
/// left, below and above (in that order; 0 for one outside): without range
/// checks and two at a time when all five lie inside (the same values, the
/// centre in both the first and the last pair).
fn dot_samples<P: Pixel>(plane: &Plane<'_, P>, col: f64, row: f64) -> (Option<f64>, f64) {
    let inside = plane.width >= 2
        && plane.height >= 2
        && col - 0.5 >= plane.col0 as f64
        && row - 0.5 >= plane.row0 as f64
        && col + 0.5 <= plane.last_col() as f64
        && row + 0.5 <= plane.last_row() as f64;
    if inside {
        let (c2, r2) = (f64x2::splat(col), f64x2::splat(row));
        // (An offset of 0 leaves a positive coordinate as it is.)
        let step = |d: [f64; 2]| f64x2::new(d);
        let [c, right] = plane
            .bilinear_inside_x2(c2 + step([0.0, 0.5]), r2)
            .to_array();
        let [left, down] = plane
            .bilinear_inside_x2(c2 + step([-0.5, 0.0]), r2 + step([0.0, 0.5]))
            .to_array();
        let [up, _] = plane
            .bilinear_inside_x2(c2, r2 + step([-0.5, 0.0]))
            .to_array();
        return (Some(c), c + right + left + down + up);
    }
    let centre = plane.bilinear(col, row);
    let mut sum = centre.unwrap_or(0.0);
    for (dx, dy) in [(0.5, 0.0), (-0.5, 0.0), (0.0, 0.5), (0.0, -0.5)] {
        sum += plane.bilinear(col + dx, row + dy).unwrap_or(0.0);
    }
    (centre, sum)
}

/// Whether a ring's reading leaves the dot a target: its dark gap must be
/// seen all round.
fn ring_verdict(reading: &Reading) -> Result<(), RejectReason> {
    if reading.status == CodeStatus::Uncertain(Uncertainty::OutsideImage) && !reading.ring_present {
        // Its ring zone leaves the window and nothing bright is seen in the
        // part inside: it may be a part of the ring of a coded target whose
        // dot is outside the window.
        return Err(RejectReason::Border);
    }
    match reading.gap {
        Gap::Dark => Ok(()),
        Gap::NotDark => Err(RejectReason::NotIsolated),
        Gap::Outside => Err(RejectReason::Border),
    }
}

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
mod tests {
    use super::*;
    use photopose_field::design::default_plate;
    use photopose_geometry::{Camera, Exterior, Vector3};
    use photopose_render::{RenderOptions, Renderer};

    /// A dot's five samples two at a time (inside the window) are those
    /// one at a time: 8 and 16 bits, windows at odd origins, centres on
    /// and off the grid, and near the edges (one at a time there).
    #[test]
    fn dot_samples_two_at_a_time_are_the_plain_ones() {
        use crate::testutil::window;
        let (w, h) = (40usize, 30usize);
        let d16: Vec<u16> = (0..w * h).map(|i| ((i * 7919) % 65536) as u16).collect();
        let d8: Vec<u8> = (0..w * h).map(|i| ((i * 7919) % 256) as u8).collect();
        fn check<P: Pixel>(win: &Plane<P>, col: f64, row: f64) -> bool {
            let plain = win.bilinear(col, row);
            let mut sum = plain.unwrap_or(0.0);
            for (dx, dy) in [(0.5, 0.0), (-0.5, 0.0), (0.0, 0.5), (0.0, -0.5)] {
                sum += win.bilinear(col + dx, row + dy).unwrap_or(0.0);
            }
            let (centre, got) = dot_samples(win, col, row);
            assert_eq!(
                centre.map(f64::to_bits),
                plain.map(f64::to_bits),
                "{col} {row}"
            );
            assert_eq!(got.to_bits(), sum.to_bits(), "{col} {row}");
            plain.is_some()
        }
        let mut n = 0;
        for (c0, r0, ww, hh) in [(0, 0, w, h), (3, 1, 31, 25)] {
            let (win8, win16) = (
                window(&d8, w, (c0, r0, ww, hh)),
                window(&d16, w, (c0, r0, ww, hh)),
            );
            for k in 0..4000 {
                let col = c0 as f64 - 1.0 + (k % 97) as f64 * (ww as f64 + 1.0) / 96.0;
                let row = r0 as f64 - 1.0 + (k / 97) as f64 * (hh as f64 + 1.0) / 41.0;
                let (col, row) = if k % 3 == 0 {
                    (col.round() + 0.5, row.round())
                } else {
                    (col, row)
                };
                n += check(&win8, col, row) as usize;
                check(&win16, col, row);
            }
        }
        assert!(n > 4000, "{n}");
    }

    /// The ring-part suppression looking up candidates by row suppresses
    /// exactly what the plain one over all candidates does, on rendered
    /// frames of the default plate (near, far, oblique) with ring parts.
    #[test]
    fn suppression_by_row_equals_the_plain_one() {
        let cam = Camera::reference();
        let field = default_plate();
        let mut renderer = Renderer::new(cam, &field, RenderOptions::default()).unwrap();
        let mut image = renderer.new_image();
        let mut det = Detector::new(1300, 1030, DetectorOptions::for_field(&field)).unwrap();
        let mut suppressed = 0;
        for (k, &(d, tilt, az)) in [
            (600.0, 45.0, 30.0),
            (900.0, 10.0, 200.0),
            (1300.0, 30.0, 100.0),
        ]
        .iter()
        .enumerate()
        {
            let (t, a) = (f64::to_radians(tilt), f64::to_radians(az));
            let eye = Vector3::new(t.sin() * a.cos(), t.sin() * a.sin(), t.cos()) * d;
            let e = Exterior::look_at(eye, Vector3::zeros(), Vector3::new(-a.sin(), a.cos(), 0.0))
                .unwrap();
            renderer
                .set_options(RenderOptions {
                    seed: k as u64 + 3,
                    ..RenderOptions::default()
                })
                .unwrap();
            renderer.render(&e, &mut image).unwrap();
            det.detect(image.view()).unwrap();
            // The candidates as they were before the suppression, and the
            // rejections with odd shapes turned back.
            let mut cands = det.candidates.clone();
            cands.iter_mut().for_each(|c| c.suppressed = false);
            let mut rejected = det.out.rejected.clone();
            for r in rejected.iter_mut() {
                if r.reason == RejectReason::CodeRing {
                    r.reason = RejectReason::Shape;
                }
            }
            let (mut plain, mut plain_rejected) = (cands.clone(), rejected.clone());
            let blobs = det.labeller.blobs();
            let mut order = Vec::new();
            let mut by_row = Vec::new();
            suppress_ring_parts(
                blobs,
                &mut cands,
                &mut rejected,
                &mut order,
                Some(&mut by_row),
            );
            suppress_ring_parts(blobs, &mut plain, &mut plain_rejected, &mut order, None);
            let flags = |c: &[Candidate]| c.iter().map(|c| c.suppressed).collect::<Vec<_>>();
            assert_eq!(flags(&cands), flags(&plain), "frame {k}");
            assert_eq!(rejected, plain_rejected, "frame {k}");
            suppressed += flags(&plain).iter().filter(|&&s| s).count();
        }
        assert!(suppressed > 20, "ring parts were suppressed: {suppressed}");
    }

    /// Finding ring parts before measuring them changes no target, and no
    /// rejection but to a ring part (whose reading would have rejected it
    /// otherwise), on rendered frames of the default plate: near, far,
    /// oblique, 8- and 16-bit, with motion blur.
    #[test]
    fn ring_parts_found_before_measuring_change_no_target() {
        let cam = Camera::reference();
        let field = default_plate();
        let mut early = Detector::new(1300, 1030, DetectorOptions::for_field(&field)).unwrap();
        let mut reference = Detector::new(1300, 1030, DetectorOptions::for_field(&field)).unwrap();
        reference.early_parts = false;
        let (mut parts, mut targets) = (0, 0);
        let mut renderer = Renderer::new(cam, &field, RenderOptions::default()).unwrap();
        // Distance, tilt, azimuth, motion during the exposure (mm), 16-bit.
        for (k, &(d, tilt, az, shift, sixteen)) in [
            (600.0, 45.0, 30.0, 0.0, false),
            (900.0, 10.0, 200.0, 0.0, false),
            (1300.0, 30.0, 100.0, 0.0, true),
            (1000.0, 5.0, 300.0, 1.5, false),
            (750.0, 25.0, 0.0, 0.7, true),
        ]
        .iter()
        .enumerate()
        {
            renderer
                .set_options(RenderOptions {
                    seed: k as u64 + 11,
                    ..RenderOptions::default()
                })
                .unwrap();
            let mut image = if sixteen {
                photopose_frame::Image::new_mono16(1300, 1030, 4095)
            } else {
                renderer.new_image()
            };
            let (t, a) = (f64::to_radians(tilt), f64::to_radians(az));
            let eye = Vector3::new(t.sin() * a.cos(), t.sin() * a.sin(), t.cos()) * d;
            let up = Vector3::new(-a.sin(), a.cos(), 0.0);
            let e = Exterior::look_at(eye, Vector3::zeros(), up).unwrap();
            let moved = Vector3::new(shift, 0.0, 0.0);
            let end = Exterior::look_at(eye + moved, moved, up).unwrap();
            renderer.render_moving(&e, &end, &mut image).unwrap();
            let got = early.detect(image.view()).unwrap().clone();
            let want = reference.detect(image.view()).unwrap().clone();
            assert_eq!(got.targets, want.targets, "frame {k}");
            assert_eq!(got.status, want.status, "frame {k}");
            // The same rejected blobs; a blob's reason differs only where
            // it was found as a ring part before its reading.
            assert_eq!(got.rejected.len(), want.rejected.len(), "frame {k}");
            for w in &want.rejected {
                let g = got
                    .rejected
                    .iter()
                    .find(|g| g.bbox == w.bbox && g.area == w.area)
                    .unwrap_or_else(|| panic!("frame {k}: {w:?} not rejected"));
                assert!(
                    g.reason == w.reason || g.reason == RejectReason::CodeRing,
                    "frame {k}: {g:?} against {w:?}"
                );
            }
            parts += early
                .candidates
                .iter()
                .filter(|c| c.frame.is_none() && c.suppressed)
                .count();
            targets += got.targets.len();
        }
        assert!(targets > 800, "targets: {targets}");
        assert!(parts > 150, "ring parts found before measuring: {parts}");
    }
}
