//! Measuring one expected target in a small window of a frame (tracking
//! mode): the detector's stages 2–4 — labelling, blob tests, centroid — on
//! the pixels around a predicted position, with a threshold found before on
//! a whole frame, and no code reading: the target's identity comes from the
//! prediction, not from its ring.
//!
//! The blobs are grown ([`SeedLabeller`]) from the foreground pixels near
//! the prediction (within the gate and one pixel more: every blob that is
//! not hollow has a pixel there if its centre lies inside the gate),
//! inside a small core window (the gate plus the dot), and measured in a
//! larger one that holds the centroid's window and its dark surroundings:
//! the blob tests and the centroid then see exactly the pixels they see in
//! the whole frame, so a target measured here has the centre the
//! whole-frame detector gives it with the same threshold.
//!
//! Identification by prediction is only as safe as the gate: exactly one
//! blob whose binary centre lies inside the gate is taken, two are
//! [`WindowOutcome::Ambiguous`], and the caller keeps gates from
//! overlapping.

use crate::code::{CodeParams, Gap, RingTables};
use crate::detector::{
    blob_tests, centroid, coded_centre, coded_centroid, confirm_ring, read_ring,
};
use crate::label::Blob;
use crate::measure;
use crate::num::{ceil_i64, floor_i64, near_f64x2, round_i64, ROUND};
use crate::pixel::{Pixel, Plane, ShortRow};
use crate::seed::SeedLabeller;
use crate::{CodeStatus, DetectorOptions, RejectReason, ThresholdResult, Uncertainty};
use photopose_field::codes;
use photopose_frame::{ImageView, ViewPixels};
use wide::{f64x2, i64x2, CmpGt, CmpLt};

/// Runs the blobs grown in a core window may have (a dot and the parts of
/// a ring or of a neighbour that reach into the gate).
const MAX_RUNS: usize = 4096;
/// Blobs grown in a core window.
const MAX_BLOBS: usize = 512;
/// Rows of a core window served without growing a buffer.
const MAX_ROWS: usize = 1024;

/// Where to look for one target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Expected {
    /// Predicted centre, full-frame pixel column.
    pub col: f64,
    /// Predicted centre, full-frame pixel row.
    pub row: f64,
    /// The blob's binary centre must lie this close to the prediction, px.
    pub gate_px: f64,
    /// Expected semi-major axis of the dot's image, px (sizes the windows).
    pub radius_px: f64,
    /// A coded target (its centre is measured clear of its ring).
    pub coded: bool,
    /// Read the ring of a coded target too (to confirm its identity).
    pub read_code: bool,
    /// The id a coded target whose ring is read should carry, when known:
    /// away from the frame's edges its ring is then first checked against
    /// that code with fewer samples, and read in full only when the check
    /// does not plainly confirm it (the same outcome, at a fraction of
    /// the cost: see `WindowMeasurer::measure`).
    pub id: Option<u64>,
}

impl Expected {
    /// Half-width of the core window, px: every blob whose centre may lie
    /// inside the gate, whole.
    fn core_half(&self) -> f64 {
        self.gate_px + 1.5 * self.radius_px.max(1.0) + 3.0
    }
}

/// A target measured in its window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowTarget {
    /// Centre column (full-frame pixel coordinates).
    pub col: f64,
    /// Centre row.
    pub row: f64,
    /// Pixels above the threshold.
    pub area: u32,
    /// Largest grey value.
    pub peak: u32,
    /// Background-subtracted grey-value sum.
    pub signal: f64,
    /// Local background level.
    pub background: f64,
    /// The ring's reading, when asked for.
    pub code: Option<CodeStatus>,
    /// The dot has saturated pixels (measured as the whole frame measures
    /// it; to be weighted down).
    pub saturated: bool,
}

/// What came of one window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WindowOutcome {
    /// One blob inside the gate, measured.
    Found(WindowTarget),
    /// No blob inside the gate.
    Missing,
    /// More than one blob inside the gate: not identified.
    Ambiguous,
    /// The blob inside the gate is not a target (reason as in the detector).
    Rejected(RejectReason),
}

/// The measurer with its buffers (allocated once).
#[derive(Debug)]
pub struct WindowMeasurer {
    options: DetectorOptions,
    seeds: SeedLabeller,
    tables: RingTables,
}

impl WindowMeasurer {
    /// A measurer applying the detector's blob tests of `options`.
    pub fn new(options: DetectorOptions) -> Self {
        WindowMeasurer {
            options,
            seeds: SeedLabeller::new(MAX_RUNS, MAX_BLOBS, MAX_ROWS),
            tables: RingTables::default(),
        }
    }

    /// Measures the target expected at `e` in `image` (a whole frame or a
    /// window of one), with the threshold `t` of an earlier whole-frame
    /// pass. Allocates nothing.
    pub fn measure(
        &mut self,
        image: &ImageView<'_>,
        t: &ThresholdResult,
        e: &Expected,
    ) -> WindowOutcome {
        let max_value = image.max_value() as u32;
        match image.pixels() {
            ViewPixels::Mono8(data) => self.run(image, data, t, e, max_value.min(255)),
            ViewPixels::Mono16(data) => self.run(image, data, t, e, max_value),
        }
    }

    /// Asks the processor to fetch the cache lines that measuring `e` in
    /// `image` will read (the blob's rows and the centroid's box around
    /// them), without waiting for them. Tracking mode reads small
    /// windows scattered over a frame that is mostly not in the cache: asked
    /// for a few targets ahead of the one being measured, the fetches
    /// overlap the measurements instead of stalling them. Changes no result.
    pub fn prefetch(&self, image: &ImageView<'_>, e: &Expected) {
        // The rows and columns a measurement reads: the blob's (its centre
        // within the gate, about the dot's radius and a pixel of blur) and
        // the centroid's box around it (`measure::GROW` rounded up and two
        // more), at most the core.
        let half = (e.gate_px + e.radius_px.max(1.0) + 1.0 + 4.0).min(e.core_half());
        // (Nothing for a position or a square past ±2³⁰, NaN or infinite
        // ones included, nor for a negative gate: no window is measured
        // there.)
        let inside = e.col.abs() <= LIMIT && e.row.abs() <= LIMIT && half <= LIMIT;
        if !(inside && e.gate_px >= 0.0) {
            return;
        }
        match image.pixels() {
            ViewPixels::Mono8(data) => prefetch(image, data, e, half),
            ViewPixels::Mono16(data) => prefetch(image, data, e, half),
        }
    }

    fn run<P: ShortRow>(
        &mut self,
        image: &ImageView<'_>,
        data: &[P],
        t: &ThresholdResult,
        e: &Expected,
        max_value: u32,
    ) -> WindowOutcome {
        if !(e.col.is_finite() && e.row.is_finite() && e.gate_px >= 0.0) {
            return WindowOutcome::Missing;
        }
        let radius = e.radius_px.max(1.0);
        // The core holds every blob whose centre may be inside the gate,
        // whole; the outer window the centroid's window (the box grown by
        // `GROW`, scaled ellipse) and its dark ring (up to 1.8 times it).
        let core = e.core_half();
        let outer = e.gate_px + 2.0 * (1.9 * radius * measure::MAX_SCALE) + measure::GROW + 4.0;
        let reach = e.gate_px + 1.0;
        let b = Bounds::of(e.col, e.row, outer, core, reach);
        let Some(outer_plane) = clipped(image, data, b.outer) else {
            return WindowOutcome::Missing;
        };
        let Some(core_plane) = clipped(image, data, b.core) else {
            return WindowOutcome::Missing;
        };
        // Every blob with a pixel within the gate and one pixel more: the
        // pixel nearest the prediction first (it mostly lies in the
        // target's blob, whose runs the scan of the gate then steps over).
        self.seeds.start(&core_plane);
        let (th, seeds) = (t.threshold, &mut self.seeds);
        let nearest = (b.nearest[0].max(0) as usize, b.nearest[1].max(0) as usize);
        if seeds
            .grow(&core_plane, th, max_value, nearest.0, nearest.1)
            .is_err()
        {
            return WindowOutcome::Ambiguous;
        }
        // The gate mostly lies inside the target's blob: when the square
        // around its disc is covered by the blobs grown, no other blob has
        // a pixel there and the scan has nothing to find (it cost about
        // 500 instructions per window).
        let [c_lo, r_lo, c_hi, r_hi] = b.gate;
        let covered = c_lo >= 0
            && r_lo >= 0
            && seeds.covers(c_lo as usize, c_hi as usize, r_lo as usize, r_hi as usize);
        let mut row = r_lo.max(0) as f64;
        while !covered && row <= e.row + reach {
            let dy = row - e.row;
            let half = (reach * reach - dy * dy).max(0.0).sqrt();
            let lo = ceil_i64(e.col - half).max(0) as usize;
            let hi = floor_i64(e.col + half) as f64;
            if hi >= 0.0
                && seeds
                    .grow_span(&core_plane, th, max_value, row as usize, lo, hi as usize)
                    .is_err()
            {
                return WindowOutcome::Ambiguous;
            }
            row += 1.0;
        }
        let gate2 = e.gate_px * e.gate_px;
        let mut found = None;
        for (i, blob) in self.seeds.blobs().iter().enumerate() {
            if blob.area < self.options.min_area {
                continue;
            }
            let (c, r) = blob.centre();
            if (c - e.col).powi(2) + (r - e.row).powi(2) > gate2 {
                continue;
            }
            if found.is_some() {
                return WindowOutcome::Ambiguous;
            }
            found = Some(i);
        }
        let Some(blob) = found.map(|i| &self.seeds.blobs()[i]) else {
            return WindowOutcome::Missing;
        };
        // A blob cut by the core's edge (not the frame's) is larger than
        // expected: the blob tests on the outer window would judge a part.
        let cut = |lo: u32, hi: u32, plo: usize, phi: usize, flo: u32, fhi: u32| {
            (lo as usize == plo && lo > flo) || (hi as usize == phi && hi < fhi)
        };
        let (fc0, fr0) = image.origin();
        let (fc1, fr1) = (fc0 + image.width() - 1, fr0 + image.height() - 1);
        if cut(
            blob.col0,
            blob.col1,
            core_plane.col0,
            core_plane.last_col(),
            fc0,
            fc1,
        ) || cut(
            blob.row0,
            blob.row1,
            core_plane.row0,
            core_plane.last_row(),
            fr0,
            fr1,
        ) {
            return WindowOutcome::Rejected(RejectReason::TooLarge);
        }
        if let Err(reason) = blob_tests(&outer_plane, blob, &self.options) {
            return WindowOutcome::Rejected(reason);
        }
        // Near the frame's edge the whole-frame detector keeps a target only
        // if its ring's samples (the ring's middle of an uncoded one, out
        // to the quiet zone of a coded one) lie inside: read the ring there
        // to judge alike. Elsewhere only when asked for.
        let (fc0, fr0) = (fc0 as f64, fr0 as f64);
        let (fc1, fr1) = (fc1 as f64, fr1 as f64);
        let edge = 3.5 * radius * measure::MAX_SCALE + e.gate_px + 3.0;
        let near_edge =
            e.col - edge < fc0 || e.row - edge < fr0 || e.col + edge > fc1 || e.row + edge > fr1;
        let read = near_edge || (e.coded && e.read_code);
        if e.coded && read && !near_edge {
            let params = self.code_params(t, max_value);
            if let Some(found) = self.confirmed(&outer_plane, blob, t, e, &params, max_value) {
                return found;
            }
        }
        if e.coded && !read {
            // A coded target whose ring is not read: its centre is measured
            // once, clear of the ring, where the whole frame measures it
            // first with the plain window to read the ring (its fourth
            // moment, tested here on this window, is the same but for the
            // rare pixel the smaller window leaves out).
            return match coded_centroid(&outer_plane, blob, t, &self.options, max_value) {
                Ok(m) => WindowOutcome::Found(found_target(&m, blob, None)),
                Err(reason) => WindowOutcome::Rejected(reason),
            };
        }
        let m = match centroid(&outer_plane, blob, t, &self.options, max_value) {
            Ok(m) => m,
            Err(reason) => return WindowOutcome::Rejected(reason),
        };
        let mut code = None;
        if read {
            let params = self.code_params(t, max_value);
            let reading = read_ring(&outer_plane, &m, &params, &self.options, &self.tables).reading;
            let outside = reading.status == CodeStatus::Uncertain(Uncertainty::OutsideImage);
            let cut = if e.coded {
                outside
            } else {
                (outside && !reading.ring_present) || reading.gap == Gap::Outside
            };
            if near_edge && cut {
                return WindowOutcome::Rejected(RejectReason::Border);
            }
            if e.coded && e.read_code {
                code = Some(reading.status);
            }
        }
        let m = if e.coded {
            coded_centre(&outer_plane, blob, t, &self.options, max_value).unwrap_or(m)
        } else {
            m
        };
        WindowOutcome::Found(found_target(&m, blob, code))
    }

    /// The ring reader's parameters with threshold `t` in a frame of
    /// saturation `max_value` (formed only for a ring that is read).
    fn code_params(&self, t: &ThresholdResult, max_value: u32) -> CodeParams {
        let o = &self.options;
        let min_read = (o.noise_factor * t.noise).max(o.min_contrast * max_value as f64);
        CodeParams {
            min_contrast: min_read,
            min_isolation_contrast: min_read,
            sector_margin: o.sector_margin,
            sample_margin: o.sample_margin,
            dark_tolerance: o.dark_tolerance,
        }
    }

    /// A coded target expected with its id, its ring read away from the
    /// frame's edges: measured as one whose ring is not read (its centre
    /// clear of the ring, where a reading leaves it too), and found with
    /// that id when its ring plainly carries the id's code
    /// ([`confirm_ring`]). `None`: no id, an id the detector does not
    /// accept, no centre there, or a ring not plainly confirmed: read it in
    /// full (the check says nothing about another code).
    fn confirmed<P: Pixel>(
        &self,
        plane: &Plane<'_, P>,
        blob: &Blob,
        t: &ThresholdResult,
        e: &Expected,
        params: &CodeParams,
        max_value: u32,
    ) -> Option<WindowOutcome> {
        let id = e.id.filter(|&id| self.options.codes.contains(id))?;
        let value = codes::value_of(id)?;
        let m = coded_centroid(plane, blob, t, &self.options, max_value).ok()?;
        confirm_ring(plane, &m, params, value, &self.tables).then(|| {
            let code = CodeStatus::Read { id, value };
            WindowOutcome::Found(found_target(&m, blob, Some(code)))
        })
    }
}

/// The target measured in a window.
fn found_target(m: &measure::Measurement, blob: &Blob, code: Option<CodeStatus>) -> WindowTarget {
    WindowTarget {
        col: m.col,
        row: m.row,
        area: blob.area,
        peak: blob.max,
        signal: m.signal,
        background: m.background,
        code,
        saturated: blob.saturated > 0,
    }
}

/// [`Plane::prefetch`] of the square of half-width `half` around `e`.
fn prefetch<P: Pixel>(image: &ImageView<'_>, data: &[P], e: &Expected, half: f64) {
    let square = square_near(f64x2::new([e.col, e.row]), half);
    let Some(plane) = clipped(image, data, square) else {
        return;
    };
    let ask = |p: &P| crate::prefetch::line(std::slice::from_ref(p));
    if !row_ends(&plane, |first, last| {
        ask(first);
        ask(last);
    }) {
        plane.prefetch(plane.col0, plane.row0, plane.last_col(), plane.last_row());
    }
}

/// Calls `f` with the first and the last pixel of each row of `plane`, top
/// to bottom, when each row spans at most 64 bytes (a tracking window's:
/// those two pixels' lines are all its lines) and the frame holds a whole
/// stride past the last row; `false` (and no call) otherwise. Why: per row
/// a split and two calls, no index checked (`Plane::prefetch` checks each
/// row's slice; tracking 4.09 M → 3.06 M instructions in
/// `WindowMeasurer::prefetch`).
#[inline(always)]
fn row_ends<P: Pixel>(plane: &Plane<'_, P>, mut f: impl FnMut(&P, &P)) -> bool {
    let last = plane.width.wrapping_sub(1);
    if plane.width * std::mem::size_of::<P>() > 64 || last >= plane.stride {
        return false;
    }
    let Some(mut rows) = plane.data.get(..plane.height * plane.stride) else {
        return false;
    };
    while let Some((row, rest)) = rows.split_at_checked(plane.stride) {
        f(&row[0], &row[last]);
        rows = rest;
    }
    true
}

/// Positions and half-widths whose bounds two at a time are exact: within
/// ±2³⁰ (see [`Bounds::of`]).
const LIMIT: f64 = (1u64 << 30) as f64;

/// The square of half-width `half` px around `at` (column, row):
/// `[floor(col − half), floor(row − half), ceil(col + half), ceil(row +
/// half)]`, two at a time; `at` and `half` within ±2³⁰ ([`LIMIT`], checked
/// by the callers).
#[inline(always)]
fn square_near(at: f64x2, half: f64) -> [i64; 4] {
    let half = f64x2::splat(half);
    let (lo, hi) = (floor2(at - half), ceil2(at + half));
    [lo[0], lo[1], hi[0], hi[1]]
}

/// The box `[first column, first row, last column, last row]` (full-frame
/// pixels) clipped to `image`; `None` when nothing of it lies inside. The
/// bounds are clamped as integers (conversions from `f64` to `usize` cost
/// a branch and a dozen instructions each on x86-64; integer clamping is
/// the same).
fn clipped<'a, P>(image: &ImageView<'_>, data: &'a [P], b: [i64; 4]) -> Option<Plane<'a, P>> {
    let (c0, r0) = image.origin();
    let (c0, r0) = (c0 as i64, r0 as i64);
    let (c1, r1) = (
        c0 + image.width() as i64 - 1,
        r0 + image.height() as i64 - 1,
    );
    let lo_c = b[0].max(c0);
    let lo_r = b[1].max(r0);
    let hi_c = b[2].min(c1);
    let hi_r = b[3].min(r1);
    if !(lo_c <= hi_c && lo_r <= hi_r) {
        return None;
    }
    // Here c0 <= lo_c <= hi_c <= c1 (and the same for rows): all fit.
    let stride = image.stride();
    let first = (lo_r - r0) as usize * stride + (lo_c - c0) as usize;
    Some(Plane {
        data: &data[first..],
        width: (hi_c - lo_c) as usize + 1,
        height: (hi_r - lo_r) as usize + 1,
        stride,
        col0: lo_c as usize,
        row0: lo_r as usize,
    })
}

/// The integer bounds of a window's measurement around `(col, row)`:
/// `[column, row, column, row]` of the outer and the core windows' squares
/// (`floor(x − half)`, `ceil(x + half)`), the square inside the gate's
/// disc (`ceil(x − reach)`, `floor(x + reach)`), the nearest pixel
/// (`floor(x + 0.5)`), each of the same `f64` value as one at a time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Bounds {
    outer: [i64; 4],
    core: [i64; 4],
    gate: [i64; 4],
    nearest: [i64; 2],
}

impl Bounds {
    /// Why: fourteen roundings per window one at a time (each a
    /// saturating conversion and a compare, ~12 instructions) cost
    /// 1.84 M instructions in tracking (two at a time: 0.67 M less in
    /// all); here column and row two at a time, exact where every value
    /// lies within ±2³⁰ (then the nearest integer by adding and
    /// subtracting 1.5 · 2⁵², corrected by one compare), one at a time
    /// elsewhere.
    #[inline(always)]
    fn of(col: f64, row: f64, outer: f64, core: f64, reach: f64) -> Self {
        if !(col.abs() <= LIMIT && row.abs() <= LIMIT && outer <= LIMIT && core <= outer) {
            return Self::plain(col, row, outer, core, reach);
        }
        // (One check for all: `core` and `reach` lie between 0 and `outer`
        // in a window's measurement.)
        debug_assert!(core >= 0.0 && (0.0..=outer).contains(&reach));
        let at = f64x2::new([col, row]);
        let k = f64x2::splat;
        let (lo, hi) = (ceil2(at - k(reach)), floor2(at + k(reach)));
        Bounds {
            outer: square_near(at, outer),
            core: square_near(at, core),
            gate: [lo[0], lo[1], hi[0], hi[1]],
            nearest: floor2(at + k(0.5)),
        }
    }

    /// [`Bounds::of`] one value at a time.
    #[inline(never)]
    fn plain(col: f64, row: f64, outer: f64, core: f64, reach: f64) -> Self {
        let square = |half: f64| {
            [
                floor_i64(col - half),
                floor_i64(row - half),
                ceil_i64(col + half),
                ceil_i64(row + half),
            ]
        };
        Bounds {
            outer: square(outer),
            core: square(core),
            gate: [
                ceil_i64(col - reach),
                ceil_i64(row - reach),
                floor_i64(col + reach),
                floor_i64(row + reach),
            ],
            nearest: [round_i64(col), round_i64(row)],
        }
    }
}

/// `floor` of both lanes as integers, `|x| ≤ 2³¹` (an integer's `f64`;
/// the value modulo 2³² beyond `i32`): the nearest integer's low bits
/// (`near_f64x2`) less one where it lies above `x`. Why: the compare's
/// lane of ones is −1 as an integer, so the correction is one integer
/// addition, not a float step and a second rounding to read the integer.
#[inline(always)]
fn floor2(x: f64x2) -> [i64; 2] {
    let r = near_f64x2(x);
    low_bits(bits(r) + bits((r - f64x2::splat(ROUND)).cmp_gt(x)))
}

/// `ceil` of both lanes as integers, as [`floor2`].
#[inline(always)]
fn ceil2(x: f64x2) -> [i64; 2] {
    let r = near_f64x2(x);
    low_bits(bits(r) - bits((r - f64x2::splat(ROUND)).cmp_lt(x)))
}

/// The lanes' bits as integers.
#[inline(always)]
fn bits(x: f64x2) -> i64x2 {
    i64x2::from(x.to_array().map(|x| x.to_bits() as i64))
}

/// The low 32 bits of both lanes, signed.
#[inline(always)]
fn low_bits(x: i64x2) -> [i64; 2] {
    x.to_array().map(|x| i64::from(x as i32))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{window, Drawn, Rng, Scene, View};
    use crate::{CodeSet, Detector, TargetKind};
    use photopose_field::codes;

    /// Three uncoded dots and two coded targets, blurred and noisy.
    fn scene() -> photopose_frame::Image {
        let mut s = Scene::new(320, 240, 15.0);
        let dot = |col, row| Drawn {
            col,
            row,
            radius: 5.0,
            view: View::frontal(1.0),
            code: None,
            phase: 0.0,
        };
        let ids: Vec<u64> = codes::even_ids().step_by(5).take(2).collect();
        let coded = |col, row, id| Drawn {
            code: codes::value_of(id),
            phase: 0.3,
            ..dot(col, row)
        };
        for t in [
            dot(40.3, 50.7),
            dot(70.1, 52.2),
            dot(250.6, 190.4),
            coded(120.4, 120.9, ids[0]),
            coded(220.7, 70.2, ids[1]),
        ] {
            s.draw(&t, 190.0);
        }
        s.blur(0.6);
        s.noise(2.0, &mut Rng::new(5));
        s.to_mono8()
    }

    #[test]
    fn a_target_in_its_window_has_the_whole_frame_centre() {
        let img = scene();
        let options = DetectorOptions {
            codes: CodeSet::all(),
            ..DetectorOptions::default()
        };
        let mut det = Detector::new(img.width(), img.height(), options).unwrap();
        let view = img.view();
        let found = det.detect(view).unwrap().clone();
        assert_eq!(found.targets.len(), 5, "{:?}", found.targets);
        let mut w = WindowMeasurer::new(options);
        // Every ring read in full, and those of the coded targets checked
        // against their ids first (the same centres and ids).
        let expected = found.targets.iter().flat_map(|d| {
            let e = Expected {
                col: d.col + 0.7,
                row: d.row - 0.4,
                gate_px: 3.0,
                radius_px: d.semi_major,
                coded: d.kind == TargetKind::Coded,
                read_code: true,
                id: None,
            };
            [(d, e), (d, Expected { id: d.id, ..e })]
        });
        for (d, e) in expected {
            match w.measure(&view, &found.threshold, &e) {
                WindowOutcome::Found(m) => {
                    assert_eq!((m.col, m.row), (d.col, d.row));
                    assert_eq!(m.area, d.area);
                    if d.kind == TargetKind::Coded {
                        assert_eq!(m.code.and_then(|c| c.id()), d.id);
                        assert!(d.id.is_some());
                    } else {
                        assert_eq!(m.code, None);
                    }
                }
                other => panic!("{other:?} at {} {}", d.col, d.row),
            }
        }
    }

    /// The gate's scan is skipped only where the target's blob covers the
    /// square around the gate: a neighbour whose centre lies inside the
    /// gate is still found (ambiguous), a prediction off the dot's middle
    /// (its square reaching past the dot) still measures the dot.
    #[test]
    fn the_gate_is_scanned_unless_the_target_covers_it() {
        let mut s = Scene::new(120, 90, 15.0);
        for (col, row) in [(40.2, 40.3), (50.6, 40.9)] {
            let dot = Drawn {
                col,
                row,
                radius: 3.5,
                view: View::frontal(1.0),
                code: None,
                phase: 0.0,
            };
            s.draw(&dot, 190.0);
        }
        s.blur(0.6);
        let img = s.to_mono8();
        let options = DetectorOptions::default();
        let mut det = Detector::new(img.width(), img.height(), options).unwrap();
        let view = img.view();
        // (The whole frame rejects these dots: too close to read their
        // rings. Its threshold is what the windows need.)
        let t = det.detect(view).unwrap().threshold;
        let first = (40.2, 40.3);
        let mut w = WindowMeasurer::new(options);
        let covered = |w: &WindowMeasurer, e: &Expected| {
            let reach = e.gate_px + 1.0;
            w.seeds.covers(
                ceil_i64(e.col - reach) as usize,
                floor_i64(e.col + reach) as usize,
                ceil_i64(e.row - reach) as usize,
                floor_i64(e.row + reach) as usize,
            )
        };
        let at = |col: f64, row: f64, gate_px: f64| Expected {
            col,
            row,
            gate_px,
            radius_px: 3.5,
            coded: false,
            read_code: false,
            id: None,
        };
        // On the dot, a narrow gate: covered, the dot found.
        let e = at(first.0 + 0.3, first.1 - 0.2, 1.0);
        let WindowOutcome::Found(dot) = w.measure(&view, &t, &e) else {
            panic!("{:?}", w.measure(&view, &t, &e));
        };
        assert!((dot.col - first.0).abs() < 0.1 && (dot.row - first.1).abs() < 0.1);
        assert!(covered(&w, &e));
        // Off the dot's middle: the square reaches past the dot, the gate
        // is scanned and holds the dot alone.
        let e = at(first.0 + 2.2, first.1 + 0.4, 2.5);
        assert_eq!(w.measure(&view, &t, &e), WindowOutcome::Found(dot));
        assert!(!covered(&w, &e));
        // A gate that holds the neighbour's centre too: ambiguous.
        let e = at(first.0, first.1, 12.0);
        assert_eq!(w.measure(&view, &t, &e), WindowOutcome::Ambiguous);
        assert!(!covered(&w, &e));
    }

    /// The bounds two at a time are the plain ones one at a time: random
    /// and near-integer positions (at, just off and half-way between
    /// integers), negative ones, half-widths that meet integers, values
    /// up to and past the limit of the vector path, infinite ones.
    #[test]
    fn bounds_two_at_a_time_are_the_plain_ones() {
        let mut rng = Rng::new(17);
        let mut unit = || (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        let limit = (1u64 << 30) as f64;
        for round in 0..20_000 {
            let base = match round % 5 {
                0 => (unit() - 0.3) * 2000.0,
                1 => ((unit() - 0.5) * 400.0).round(),
                2 => ((unit() - 0.5) * 400.0).round() + 0.5,
                3 => {
                    ((unit() - 0.5) * 400.0).round() + [1e-12, -1e-12, 2.0f64.powi(-40)][round % 3]
                }
                _ => (unit() - 0.5) * 2.0 * limit * [0.5, 1.0, 1.0 + 1e-9, 4.0][round % 4],
            };
            let col = base;
            let row = if round % 2 == 0 {
                -base
            } else {
                base * 0.7 + 3.0
            };
            let gate = [0.0, 1.5, unit() * 4.0, 2.0][round % 4];
            let radius = [4.5, 1.0, unit() * 8.0, 0.25][round % 4];
            let e = Expected {
                col,
                row,
                gate_px: gate,
                radius_px: radius,
                coded: false,
                read_code: false,
                id: None,
            };
            let outer =
                gate + 2.0 * (1.9 * radius.max(1.0) * measure::MAX_SCALE) + measure::GROW + 4.0;
            let (core, reach) = (e.core_half(), gate + 1.0);
            assert_eq!(
                Bounds::of(col, row, outer, core, reach),
                Bounds::plain(col, row, outer, core, reach),
                "{col} {row} {outer} {core} {reach}"
            );
        }
        for (col, row, outer) in [
            (f64::INFINITY, 3.0, 10.0),
            (3.0, 5.0, f64::INFINITY),
            (-1e300, 2.0, 10.0),
            (1073741823.5, -1073741823.5, 0.5),
        ] {
            assert_eq!(
                Bounds::of(col, row, outer, 5.0, 2.0),
                Bounds::plain(col, row, outer, 5.0, 2.0)
            );
        }
    }

    /// The rows' ends the prefetch asks for are each row's first and last
    /// pixel, top to bottom, in 8- and 16-bit windows anywhere in a frame;
    /// windows wider than 64 bytes or on the frame's last rows are left to
    /// `Plane::prefetch`. Expected positions anywhere, finite or not, ask
    /// for nothing outside the frame.
    #[test]
    fn the_prefetch_asks_for_the_ends_of_every_row() {
        fn ends<P: Pixel>(plane: &Plane<'_, P>) -> Option<Vec<(*const P, *const P)>> {
            let mut got = Vec::new();
            let fast = row_ends(plane, |a, b| got.push((a as *const P, b as *const P)));
            fast.then_some(got)
        }
        fn check<P: Pixel>(data: &[P], stride: usize, rows: usize, rng: &mut Rng) -> [usize; 2] {
            let mut paths = [0, 0];
            for _ in 0..400 {
                let (c0, r0) = (
                    (rng.next_u64() % stride as u64) as usize,
                    (rng.next_u64() % rows as u64) as usize,
                );
                let w = 1 + (rng.next_u64() % (stride - c0) as u64) as usize;
                let h = 1 + (rng.next_u64() % (rows - r0) as u64) as usize;
                let plane = window(data, stride, (c0, r0, w, h));
                let want: Vec<_> = (r0..r0 + h)
                    .map(|r| {
                        let row = plane.row(r);
                        (&row[0] as *const P, &row[w - 1] as *const P)
                    })
                    .collect();
                // (The frame holds a stride past the last row unless that
                // is the frame's and the window starts right of column 0.)
                let fast = w * std::mem::size_of::<P>() <= 64 && (r0 + h < rows || c0 == 0);
                match ends(&plane) {
                    Some(got) => {
                        assert!(fast, "{c0} {r0} {w} {h}");
                        assert_eq!(got, want, "{c0} {r0} {w} {h}");
                        paths[0] += 1;
                    }
                    None => {
                        assert!(!fast, "{c0} {r0} {w} {h}");
                        paths[1] += 1;
                    }
                }
            }
            paths
        }
        let mut rng = Rng::new(23);
        let bytes = vec![0u8; 90 * 12];
        let words = vec![0u16; 90 * 12];
        for paths in [
            check(&bytes, 90, 12, &mut rng),
            check(&words, 90, 12, &mut rng),
        ] {
            assert!(paths[0] > 50 && paths[1] > 50, "{paths:?}");
        }
        // Positions anywhere (at the corners, outside, past ±2³⁰, not
        // finite), gates of any size: asked for or left, never a panic.
        let w = WindowMeasurer::new(DetectorOptions::default());
        let views = [
            ImageView::mono8(&bytes, 90, 12, 90).unwrap(),
            ImageView::mono16(&words, 90, 12, 90, 4095).unwrap(),
        ];
        for view in &views {
            for col in [0.0, 89.4, -3.0, 95.0, 2e9, -2e9, f64::NAN, f64::INFINITY] {
                for gate_px in [0.0, 3.0, 1e12, -1.0, f64::NAN] {
                    let e = Expected {
                        col,
                        row: col / 10.0,
                        gate_px,
                        radius_px: 4.0,
                        coded: false,
                        read_code: false,
                        id: None,
                    };
                    w.prefetch(view, &e);
                }
            }
        }
    }

    #[test]
    fn nothing_inside_the_gate_is_missing_and_two_are_ambiguous() {
        let img = scene();
        let options = DetectorOptions::default();
        let mut det = Detector::new(img.width(), img.height(), options).unwrap();
        let view = img.view();
        let t = det.detect(view).unwrap().threshold;
        let mut w = WindowMeasurer::new(options);
        let e = Expected {
            col: 40.3 + 8.0,
            row: 50.7,
            gate_px: 2.0,
            radius_px: 5.0,
            coded: false,
            read_code: false,
            id: None,
        };
        assert_eq!(w.measure(&view, &t, &e), WindowOutcome::Missing);
        let far = Expected {
            col: -100.0,
            row: -100.0,
            ..e
        };
        assert_eq!(w.measure(&view, &t, &far), WindowOutcome::Missing);
        // Half-way between the two close dots, with a gate reaching both.
        let both = Expected {
            col: 55.2,
            row: 51.4,
            gate_px: 16.0,
            ..e
        };
        assert_eq!(w.measure(&view, &t, &both), WindowOutcome::Ambiguous);
    }
}
