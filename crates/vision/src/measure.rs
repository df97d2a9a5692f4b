//! Sub-pixel centre of a blob: background-subtracted, intensity-weighted
//! centroid over the blob's bounding box grown by 2 px, with the
//! intensity-weighted second moments (the ellipse) and a shape statistic.
//!
//! Every pixel of the window counts with weight `g − background`, not only
//! the pixels above the threshold: cutting the blurred edge at the threshold
//! biases the centre by several hundredths of a pixel. The window is the
//! grown box intersected with the blob's moment ellipse scaled up by the same
//! margin, so that the corners of the box never reach a coded target's ring.
//! The background is the 30th percentile of the dark pixels just outside the
//! window.
//!
//! Speed: each row visits only its span of the ellipses (from the roots of
//! the quadratic form), and the background ring and the window are
//! collected in one pass. The window's weighted moments and pixel counts
//! are exact integer sums about the pixel nearest the blob's centre
//! (`Σw·(1, k, k², j, j², k j)`), turned into moments about the centre in
//! `f64` once, with the background subtracted once it is known; so every
//! way of summing gives the same bits. An 8-bit frame (the linear weight)
//! forms every row's ring mask and window lanes from the spans of two
//! rows at a time as floats, picks its ring pixels by the masks, finds
//! the background, and then takes each row's window as one masked vector
//! with the background off every pixel, whose lanes are summed across
//! the rows (the moments in the row as running sums; no pixel counts
//! needed); other rows go through [`Pixel::moment_sums`] one row at a
//! time (in `i128` where a bound on the window does not rule out an
//! overflow of `i64`). A small ring is counted by grey value in bytes
//! instead of kept in a buffer.

use crate::label::Blob;
use crate::num::{
    ceil_i64, floor_i64, low_i32x2, max_or_f64x2, near_f64x2, pow2_f64x2, round_i64x2, ROUND,
};
use crate::pixel::{lanes16, lanes_from16, run16, scalar_moment_sums, Pixel, Plane};
use crate::threshold::Threshold;
use wide::{f64x2, i16x8, i32x4, u8x16, CmpGe, CmpLe};

/// Result of measuring a blob.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Centre column.
    pub col: f64,
    /// Centre row.
    pub row: f64,
    /// Intensity-weighted central second moments, px² (pixel area removed).
    pub cxx: f64,
    /// See `cxx`.
    pub cyy: f64,
    /// See `cxx`.
    pub cxy: f64,
    /// Background-subtracted grey-value sum.
    pub signal: f64,
    /// Local background level.
    pub background: f64,
    /// Normalised fourth moment of the binary shape along its major axis
    /// (2 for a filled ellipse, 1.8 for a bar, lower for two merged blobs,
    /// higher for a dot with a tail): the blob's [`Blob::kurtosis`].
    pub kurtosis: f64,
}

/// Semi-axes and angle of the ellipse with central moments `(cxx, cyy, cxy)`
/// (a uniform ellipse with semi-axes `a, b` has moments `a²/4, b²/4`): returns
/// `(a, b, angle)` with the angle of the major axis from `+col` towards `+row`.
pub fn ellipse(cxx: f64, cyy: f64, cxy: f64) -> (f64, f64, f64) {
    let (a, b) = axes(cxx, cyy, cxy);
    let angle = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
    (a, b, angle)
}

/// The semi-axes `(a, b)` of [`ellipse`] without its angle (no `atan2`:
/// the blob tests ask for the axes of every blob).
pub fn axes(cxx: f64, cyy: f64, cxy: f64) -> (f64, f64) {
    let tr = cxx + cyy;
    let d = ((cxx - cyy) * (cxx - cyy) / 4.0 + cxy * cxy).sqrt();
    let l1 = (tr / 2.0 + d).max(0.0);
    let l2 = (tr / 2.0 - d).max(0.0);
    (2.0 * l1.sqrt(), 2.0 * l2.sqrt())
}

/// The dot's own second moments with the blur removed, given its amplitude
/// (peak above background). Blurring adds the blur's variance `σ²` to both
/// principal moments and preserves the signal; the signal over the
/// amplitude is the dot's true area `π a b`. Solving
/// `(a_m² − 4σ²)(b_m² − 4σ²) = (a b)²` for `σ²` and subtracting it gives
/// moments that no longer depend on the blur (exact for a Gaussian blur of
/// a uniform ellipse whose centre reaches the full amplitude). Returns
/// `(cxx, cyy, cxy, σ²)`.
pub fn deblurred(m: &Measurement, amplitude: f64) -> (f64, f64, f64, f64) {
    let (cxx, cyy, cxy) = (m.cxx, m.cyy, m.cxy);
    if amplitude.is_nan() || amplitude <= 0.0 {
        return (cxx, cyy, cxy, 0.0);
    }
    let tr = cxx + cyy;
    let d = ((cxx - cyy) * (cxx - cyy) / 4.0 + cxy * cxy).sqrt();
    let (l1, l2) = ((tr / 2.0 + d).max(0.0), (tr / 2.0 - d).max(0.0));
    let (a2, b2) = (4.0 * l1, 4.0 * l2);
    let ab = m.signal / amplitude / std::f64::consts::PI;
    let p = a2 + b2;
    let q = a2 * b2 - ab * ab;
    let disc = (p * p - 4.0 * q).max(0.0);
    let s = ((p - disc.sqrt()) / 2.0).clamp(0.0, 0.6 * b2);
    let var = s / 4.0;
    (cxx - var, cyy - var, cxy, var)
}

/// Window margin, px.
pub const GROW: f64 = 2.0;
/// The window ellipse is at most this multiple of the blob's ellipse.
pub const MAX_SCALE: f64 = 1.5;
/// Window margin and scale for coded targets (the ring starts at 2).
pub const CODED_GROW: f64 = 1.5;
/// See [`CODED_GROW`].
pub const CODED_MAX_SCALE: f64 = 1.35;

/// A centroid window's margin, px, and the most multiple of the blob's
/// ellipse it may reach: any pair `(grow, max_scale)`, or a type whose
/// values are constants ([`DotMargin`], [`CodedMargin`]; the window's
/// bounds then fold to constants where they depend on the margin alone).
pub trait Margin: Copy {
    /// The margin, px.
    fn grow(self) -> f64;
    /// The most multiple of the blob's ellipse.
    fn max_scale(self) -> f64;
}

impl Margin for (f64, f64) {
    #[inline(always)]
    fn grow(self) -> f64 {
        self.0
    }
    #[inline(always)]
    fn max_scale(self) -> f64 {
        self.1
    }
}

/// A unit type whose [`Margin`] is a pair of constants.
macro_rules! constant_margin {
    ($(#[$doc:meta])* $name:ident, $grow:expr, $max_scale:expr) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy)]
        pub struct $name;

        impl Margin for $name {
            #[inline(always)]
            fn grow(self) -> f64 {
                $grow
            }
            #[inline(always)]
            fn max_scale(self) -> f64 {
                $max_scale
            }
        }
    };
}

constant_margin!(
    /// The window of a dot: [`GROW`] and [`MAX_SCALE`].
    DotMargin,
    GROW,
    MAX_SCALE
);

constant_margin!(
    /// The window of a coded target's dot: [`CODED_GROW`] and
    /// [`CODED_MAX_SCALE`].
    CodedMargin,
    CODED_GROW,
    CODED_MAX_SCALE
);

/// Background ring: from the window out to this multiple (inside a coded
/// target's gap, which ends at 2).
const BG_OUTER: f64 = 1.75;
/// Most background pixels kept for the median.
const BG_SAMPLES: usize = 512;

/// Rings of at most this many expected pixels are counted in a histogram
/// of bytes (see `measure_weighted`; less than [`BG_SAMPLES`], so that
/// every dark pixel counts).
const COUNTED_RING: f64 = 180.0;
const _: () = assert!(COUNTED_RING < BG_SAMPLES as f64);

/// A window's sums (see [`Moments::sums`]; without the pixel counts'
/// where the background is off every pixel already) and its background
/// from the ring (`None`: too few dark pixels).
type Counted = (([f64; 6], Option<[f64; 6]>), Option<u32>);

/// Where [`Window::sums`] puts the pixels of the background ring.
trait Ring {
    /// Takes a run of ring pixels.
    fn add<P: Pixel>(&mut self, part: &[P]);
    /// The 30th percentile of the dark pixels taken (threshold `level`),
    /// `None` for fewer than 4.
    fn quantile(&mut self, level: u32) -> Option<u32>;
}

/// Every ring pixel counted by grey value (values from 255 up in the last
/// count): the percentile is exact while at most 255 pixels are counted.
struct Counts<'a> {
    // (Apart from `total`, so that clearing it is a few stores, not a
    // library call.)
    count: &'a mut [u8; 256],
    total: usize,
}

impl Ring for Counts<'_> {
    #[inline(always)]
    fn add<P: Pixel>(&mut self, part: &[P]) {
        self.total += part.len();
        for p in part {
            let c = &mut self.count[p.value().min(255) as usize];
            *c = c.wrapping_add(1);
        }
    }

    #[inline]
    fn quantile(&mut self, level: u32) -> Option<u32> {
        let n = counted_up_to(self.count, level.min(255) as usize) as usize;
        (n >= 4).then(|| kth_counted(self.count, n * 3 / 10))
    }
}

impl Counts<'_> {
    /// Takes rows of 32 pixels, row `i` at `data[start + i stride..]`:
    /// its pixels `px[b]` of the bits `b` set in the low 32 bits of
    /// `masks[i]`. (A function of its own: its registers apart from those
    /// of the window's sums around it.)
    #[inline(never)]
    fn add_rows(&mut self, data: &[u8], start: usize, stride: usize, masks: &[u64]) {
        // (The pixels counted here: no store per row.)
        let mut taken = 0;
        let mut take = |px: &[u8; 32], m: u64| {
            let bits = m as u32;
            if bits != 0 {
                self.add_lanes(px, bits, &mut taken);
            }
        };
        each_row(data, start, stride, 32, masks, |row, at, &m| {
            let Ok(px) = <&[u8; 32]>::try_from(&row[at..][..32]) else {
                unreachable!("32 pixels")
            };
            take(px, m);
        });
        self.total += taken;
    }

    /// Takes the pixels `px[i]` of the bits `i` set in `bits` (not 0) but
    /// for `total`: adds how many to `n`.
    #[inline(always)]
    fn add_lanes(&mut self, px: &[u8; 32], mut bits: u32, n: &mut usize) {
        debug_assert!(bits != 0);
        // (Two at a time: one count of them per two, into the caller's
        // count as it goes: no count of its own to start and add a row.)
        loop {
            let c = &mut self.count[px[(bits.trailing_zeros() & 31) as usize] as usize];
            *c = c.wrapping_add(1);
            bits &= bits - 1;
            if bits == 0 {
                *n += 1;
                return;
            }
            let c = &mut self.count[px[(bits.trailing_zeros() & 31) as usize] as usize];
            *c = c.wrapping_add(1);
            *n += 2;
            bits &= bits - 1;
            if bits == 0 {
                return;
            }
        }
    }
}

/// Calls `f` with each row of a block of `data` and its item, row `i`
/// (of `items.len()`) starting at `data[start + i stride]`, given as a
/// slice and the row's first index in it (at least `width` elements are
/// read from there). Why: where a
/// whole stride follows the block's last row, the block splits into whole
/// strides with one bounds check for all of them; only a block that ends
/// the data goes row by row, each row checked.
#[inline(always)]
fn each_row<'d, T>(
    data: &'d [u8],
    start: usize,
    stride: usize,
    width: usize,
    items: &[T],
    mut f: impl FnMut(&'d [u8], usize, &T),
) {
    let block = start
        .checked_add(items.len() * stride)
        .and_then(|end| data.get(start..end));
    match block {
        Some(block) if stride >= width => {
            for (row, item) in block.chunks_exact(stride).zip(items) {
                f(row, 0, item);
            }
        }
        _ => {
            let mut at = start;
            for item in items {
                f(data, at, item);
                at += stride;
            }
        }
    }
}

/// The dark ring pixels kept in a buffer, every `stride`-th one, at most
/// [`BG_SAMPLES`].
struct Samples {
    buf: [u32; BG_SAMPLES],
    n: usize,
    seen: usize,
    next: usize,
    stride: usize,
    threshold: Threshold,
}

impl Ring for Samples {
    #[inline(always)]
    fn add<P: Pixel>(&mut self, part: &[P]) {
        let threshold = self.threshold;
        if self.stride == 1 && self.n + part.len() <= BG_SAMPLES {
            // Every dark pixel kept (`seen == next` throughout): store
            // each and count the dark ones, without a branch.
            let before = self.n;
            for p in part {
                let v = p.value();
                self.buf[self.n] = v;
                self.n += !threshold.is_foreground(v) as usize;
            }
            self.seen += self.n - before;
            self.next = self.seen;
            return;
        }
        for p in part {
            let v = p.value();
            if !threshold.is_foreground(v) {
                if self.seen == self.next {
                    if self.n < BG_SAMPLES {
                        self.buf[self.n] = v;
                        self.n += 1;
                    }
                    self.next += self.stride;
                }
                self.seen += 1;
            }
        }
    }

    #[inline]
    fn quantile(&mut self, level: u32) -> Option<u32> {
        let n = self.n;
        (n >= 4).then(|| quantile(&mut self.buf[..n], n * 3 / 10, level))
    }
}

/// The rows and columns [`measure_weighted`] visits (full-frame
/// coordinates; see there).
struct Window {
    q: Conic,
    by: f64,
    s_in: f64,
    s_out: f64,
    /// Rows and columns of the box that holds the ring.
    rows: (usize, usize),
    cols: (i64, i64),
    first_col: i64,
    /// Rows of the box proper (`wr.0 ≤ row ≤ wr.1`), for the background.
    wr: (f64, f64),
    /// Columns of the box proper, for the background.
    box_cols: (i64, i64),
    /// Rows and columns of the weighted window.
    wrows: (usize, usize),
    wcols: (i64, i64),
}

/// The spans of one row (full-frame columns, inclusive): the ring's outer
/// span `outer` (not empty) minus `hole` (inside it when not empty), and
/// the weighted window's span `window` (`None` if empty).
struct RowSpans {
    row: usize,
    outer: (i64, i64),
    hole: (i64, i64),
    window: Option<(i64, i64)>,
}

impl Window {
    /// The rows of the box with their spans, in order, into `f` (the rows
    /// whose outer span is empty left out): each row's spans from the
    /// roots of the quadratic form.
    #[inline(always)]
    fn rows(&self, mut f: impl FnMut(RowSpans)) {
        let (wr0, wr1) = self.wrows;
        self.blocks(|first, spans| {
            for (row, sp) in (first..).zip(spans) {
                let [oa, ob, xa, xb, a, b] = sp.map(i64::from);
                if oa > ob {
                    continue;
                }
                // Background: the outer span minus the window's span
                // inside the box.
                f(RowSpans {
                    row,
                    outer: (oa, ob),
                    hole: (xa, xb),
                    window: (a <= b && (wr0..=wr1).contains(&row)).then_some((a, b)),
                });
            }
        });
    }

    /// The spans of the box's rows a block at a time, into `f` with the
    /// block's first row: each row's `[oa, ob, xa, xb, a, b]` (see
    /// [`RowSpans`]; an empty outer span has `oa > ob`, the hole outside
    /// its rows is `(1, 0)`; the window's span `[a, b]` holds for the rows
    /// of the window only, which the callers pick: no blend per row pair,
    /// `measure_weighted` 49.17 M → 47.50 M).
    #[inline(always)]
    fn blocks(&self, f: impl FnMut(usize, &[[i32; 6]])) {
        let (one, zero) = (f64x2::splat(ROUND + 1.0), f64x2::splat(ROUND));
        self.blocks_of(
            |[oa, ob, xa, xb, a, b], hole| {
                // (Outside its rows the hole is `(1, 0)`.)
                let (xa, xb) = (hole.blend(xa, one), hole.blend(xb, zero));
                let ends = [oa, ob, xa, xb, a, b].map(low_i32x2);
                [0, 1].map(|lane| ends.map(|e| e[lane]))
            },
            f,
        );
    }

    /// The box's rows a block at a time: each pair of rows' spans (see
    /// [`PairSpans::at`]) made into a record of each row by `each`, then
    /// the block's records into `f` with the block's first row. (The
    /// spans' square roots overlap, and neither loop holds the other's
    /// values.)
    #[inline(always)]
    fn blocks_of<T: Copy + Default>(
        &self,
        mut each: impl FnMut([f64x2; 6], f64x2) -> [T; 2],
        mut f: impl FnMut(usize, &[T]),
    ) {
        let spans = self.pair_spans();
        let (r0, r1) = self.rows;
        let mut block = [T::default(); SPAN_BLOCK];
        let mut first = r0;
        while first <= r1 {
            let last = r1.min(first + SPAN_BLOCK - 1);
            for (pair, (ends, hole)) in block[..=last - first].chunks_mut(2).zip(spans.from(first))
            {
                for (r, e) in pair.iter_mut().zip(each(ends, hole)) {
                    *r = e;
                }
            }
            f(first, &block[..=last - first]);
            first = last + 1;
        }
    }

    /// What [`PairSpans::at`] needs, as floats.
    #[inline(always)]
    fn pair_spans(&self) -> PairSpans {
        // Clipping as floats (see `near_f64x2`).
        let at = |c: i64| f64x2::splat(c as f64 + ROUND);
        PairSpans {
            q: self.q,
            by: f64x2::splat(self.by),
            s: (self.s_in, self.s_out),
            hole_rows: (f64x2::splat(self.wr.0), f64x2::splat(self.wr.1)),
            cols: (at(self.cols.0), at(self.cols.1)),
            box_cols: (at(self.box_cols.0), at(self.box_cols.1)),
            wcols: (at(self.wcols.0), at(self.wcols.1)),
        }
    }

    /// One pass over the rows: the ring's pixels into `ring`, the window's
    /// pixels into `m`; returns `m`'s sums.
    #[inline(always)]
    fn sums<P: Pixel, M: Moments<P>, R: Ring>(
        &self,
        plane: &Plane<P>,
        mut m: M,
        ring: &mut R,
    ) -> ([f64; 6], [f64; 6]) {
        let first_col = self.first_col;
        self.rows(|s| {
            let ((oa, ob), (xa, xb)) = (s.outer, s.hole);
            // The row's pixels: element `i` is column `first_col + i`.
            let line = plane.row(s.row);
            // (One slice of the row, cut in two: `oa ≤ xa ≤ xb ≤ ob` when
            // `[xa, xb]` is not empty.)
            let outer = &line[(oa - first_col) as usize..=(ob - first_col) as usize];
            if xa > xb {
                ring.add(outer);
            } else {
                if xa > oa {
                    ring.add(&outer[..(xa - oa) as usize]);
                }
                if xb < ob {
                    ring.add(&outer[(xb + 1 - oa) as usize..]);
                }
            }
            if let Some((a, b)) = s.window {
                m.row(
                    line,
                    (a - first_col) as usize,
                    (b - first_col) as usize,
                    s.row,
                );
            }
        });
        m.sums()
    }

    /// [`Window::sums`] of an 8-bit window with the linear weight whose
    /// ring box is at most 32 columns wide and 32 rows high, its window at
    /// most 16 columns wide (`None` otherwise), the ring counted in `ring`,
    /// with the background (`level` the threshold's) as the caller would
    /// find it. In three passes: each pair of rows' spans made into a
    /// record of each row at once ([`PairSpans`]: the ring's bit mask of
    /// the box's 32 columns from the span ends as floats, [`run_bits`],
    /// and the window's mask offsets, one store a pair), then the ring's
    /// pixels picked by the masks ([`Counts::add_rows`]), then the window
    /// as one masked vector a row ([`Lanes`]); its loops apart, their
    /// registers do not compete. The background known before the window,
    /// the window's sums are taken with it off every pixel (then the pixel
    /// counts are not needed: their sums are returned as zeros), the same
    /// integers as [`Window::sums`] less the background times the counts.
    #[inline(always)]
    fn sums_8bit(
        &self,
        plane: &Plane<u8>,
        ring: &mut Counts,
        level: u32,
        origin: (i64, i64),
    ) -> Option<Counted> {
        let first_col = self.first_col;
        let (c0, c1) = self.cols;
        let (r0, r1) = self.rows;
        let (wr0, wr1) = self.wrows;
        let (wc0, wc1) = self.wcols;
        if c1 - c0 >= 32 || wc1 - wc0 >= 16 || r1 - r0 >= 32 || plane.width < 32 {
            return None;
        }
        // Lane 0 of the box's copy and of the window's vector (row indices).
        let pr = ((c0 - first_col) as usize).min(plane.width - 32);
        let pw = ((wc0 - first_col) as usize).min(plane.width - 16);
        // The span ends relative to the lanes: the ring's from `first_col +
        // pr` as `n + ROUND` less an integer (the last ends one past), the
        // window's from `first_col + pw` as plain integers.
        let at = |c: usize| f64x2::splat((first_col + c as i64) as f64);
        let one = f64x2::splat(1.0);
        let (ring_at, window_at) = (at(pr), at(pw) + f64x2::splat(ROUND));
        let (ring_past, window_past) = (ring_at - one, window_at - one);
        // The hole (the box proper's columns, inside the window's: the
        // window's lanes clipped to them) in the ring's lanes as `n + ROUND`.
        let (cw, cr) = (first_col + pw as i64, first_col + pr as i64);
        let to_ring = f64x2::splat((cw - cr) as f64 + ROUND);
        let hole_cols =
            [self.box_cols.0 - cw, self.box_cols.1 + 1 - cw].map(|c| f64x2::splat(c as f64));
        let rows = r1 - r0 + 1;
        let mut records = [0u64; 32];
        let lanes = RecordLanes {
            ring: (ring_at, ring_past),
            window: (window_at, window_past),
            to_ring,
            hole_cols,
        };
        let records_of = &mut records[..2 * rows.div_ceil(2)];
        // A window inside the box proper (a whole margin's: the same
        // columns) has its lanes inside the hole's: no clipping to them.
        if wc0 >= self.box_cols.0 && wc1 <= self.box_cols.1 {
            lanes.fill::<false>(self, r0, records_of);
        } else {
            lanes.fill::<true>(self, r0, records_of);
        }
        let (data, stride) = (plane.data, plane.stride);
        ring.add_rows(
            data,
            (r0 - plane.row0) * stride + pr,
            stride,
            &records[..rows],
        );
        // The background (the ring's percentile, when its counts are
        // exact), then the window's sums: with the background taken off
        // every pixel where it is known (exact integers: the pixel counts
        // are then not needed), else with the counts (for the caller's
        // fallback background; a ring of too many pixels is measured
        // again by the caller).
        let background = if ring.total <= u8::MAX as usize {
            ring.quantile(level)
        } else {
            None
        };
        let window = if wr0 <= wr1 {
            &records[wr0 - r0..wr1 + 1 - r0]
        } else {
            &[]
        };
        let at = (wr0 - plane.row0) * stride + pw;
        let sums = match background {
            Some(b) => {
                let m = Lanes::<1, true>::new(pw, wr0, origin, b as u8);
                (m.take_records(data, at, stride, window).0, None)
            }
            None => {
                let (g, n) =
                    Lanes::<1>::new(pw, wr0, origin, 0).take_records(data, at, stride, window);
                (g, Some(n))
            }
        };
        Some((sums, background))
    }
}

/// Where [`Window::sums_8bit`]'s records put a row's spans: the ring's
/// lanes from `ring.0` (its span's first end as `n + ROUND` less it, the
/// last's less `ring.1`), the window's from `window.0` (as plain integers,
/// the last end less `window.1`), the hole's columns `hole_cols` in the
/// window's lanes and `to_ring` from them to the ring's (as `n + ROUND`).
struct RecordLanes {
    ring: (f64x2, f64x2),
    window: (f64x2, f64x2),
    to_ring: f64x2,
    hole_cols: [f64x2; 2],
}

impl RecordLanes {
    /// Each row's record of `w`'s rows from `r0` on into `records` (an
    /// even number), two rows at a time straight from their spans: the
    /// ring's bit mask in the low 32 bits, above it the window's mask
    /// offsets `32 − lo` and `32 − hi` (see `lanes_from16`), summed as
    /// integers below 2⁴⁶ (exact), the bits then from the float plus 2⁵².
    /// `CLIP`: the window's lanes clipped to the hole's columns (not
    /// needed, and the same, where the window lies inside them).
    #[inline(always)]
    fn fill<const CLIP: bool>(&self, w: &Window, r0: usize, records: &mut [u64]) {
        let above = f64x2::splat(32.0 * TWO_32 + 32.0 * 256.0 * TWO_32 + TWO_52);
        let ((ring_at, ring_past), (window_at, window_past)) = (self.ring, self.window);
        let (to_ring, hole_cols) = (self.to_ring, self.hole_cols);
        for (record, ([oa, ob, _, _, a, b], hole)) in
            records.chunks_exact_mut(2).zip(w.pair_spans().from(r0))
        {
            // The window's lanes `lo..hi` (an empty span as `lo = hi`;
            // `0 ≤ a − first_col − pw` and `b − first_col − pw ≤ 15`).
            let lo = (a - window_at).fast_min(f64x2::splat(16.0));
            let hi = (b - window_past).fast_max(lo);
            // The ring: the outer span less the hole (inside it when not
            // empty; its lanes `cw − cr` up from the window's, at most 32).
            // Unclipped, `lo ≤ hi` inside the hole's columns (or equal):
            // no negative run.
            let hole = if CLIP {
                (pow2_f64x2(hi.fast_min(hole_cols[1]) + to_ring)
                    - pow2_f64x2(lo.fast_max(hole_cols[0]) + to_ring))
                .fast_max(f64x2::ZERO)
            } else {
                pow2_f64x2(hi + to_ring) - pow2_f64x2(lo + to_ring)
            } & hole;
            let ring = run_bits(oa - ring_at, ob - ring_past) - hole;
            let r = (ring + above) - lo * f64x2::splat(TWO_32) - hi * f64x2::splat(256.0 * TWO_32);
            record.copy_from_slice(&r.to_array().map(f64::to_bits));
        }
    }
}

/// `2⁵²`: adding it to an integer-valued `x` with `0 ≤ x < 2⁵²` leaves `x`
/// in the low bits of the mantissa.
const TWO_52: f64 = 4_503_599_627_370_496.0;
/// `2³²`.
const TWO_32: f64 = 4_294_967_296.0;

/// For two rows (lanes), the bits `lo..hi` of a `u32` as the float
/// `2^hi − 2^lo` (`0` if `lo ≥ hi`), from `lo + ROUND` and `hi + ROUND`
/// with `lo ≥ 0` and `hi ≤ 32`: `lo` clamped to at most 32 and `hi` to at
/// least 0 (which keeps an empty run empty), then a power of two
/// ([`pow2_f64x2`]). Exact.
#[inline(always)]
fn run_bits(lo: f64x2, hi: f64x2) -> f64x2 {
    let (zero, top) = (f64x2::splat(ROUND), f64x2::splat(ROUND + 32.0));
    let (lo, hi) = (lo.fast_min(top), hi.fast_max(zero));
    (pow2_f64x2(hi) - pow2_f64x2(lo)).fast_max(f64x2::ZERO)
}

/// Where [`Window::sums`] puts the window's pixels: the exact integer sums
/// `Σw·(1, k, k², j, j², k j)` and `Σ1·(...)` of the weights `w` and the
/// pixel counts, `k` and `j` the column and row relative to a fixed pixel
/// near the blob's centre (the moments about the centre follow from them
/// once, in `measure_weighted`, with the background subtracted).
trait Moments<P: Pixel> {
    /// Takes `line[a..=b]` of frame row `row`.
    fn row(&mut self, line: &[P], a: usize, b: usize, row: usize);
    /// The sums (grey values, pixel counts) as `f64` (rounded once from
    /// the exact integers: the same from every implementation).
    fn sums(self) -> ([f64; 6], [f64; 6]);
}

/// Sums `(Σ1, Σk, Σk², Σj, Σj², Σk j)` about `(0, j)` moved to the origin
/// `(−dk, j)`, i.e. with `k + dk` in place of `k` (the rows are counted
/// from the origin's already), of two sets of sums at once (lanes): exact
/// while every sum, product and result is an integer below `2⁵³` in
/// magnitude.
#[inline(always)]
fn moved(s: [f64x2; 6], dk: f64) -> [f64x2; 6] {
    let (k, k2, kk) = (
        f64x2::splat(dk),
        f64x2::splat(2.0 * dk),
        f64x2::splat(dk * dk),
    );
    [
        s[0],
        s[1] + k * s[0],
        s[2] + k2 * s[1] + kk * s[0],
        s[3],
        s[4],
        s[5] + k * s[3],
    ]
}

/// An integer type the window's sums are exact in: `i64` where a bound on
/// the window shows that nothing overflows (every measurement of a
/// detector), `i128` else.
trait Exact:
    Copy
    + From<i32>
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::AddAssign
{
    /// Nearest `f64`.
    fn to_f64(self) -> f64;
    /// `[Σ w, Σ w k, Σ w k²]` over `line[a..a + n]`, `k` from `k0`.
    fn row_sums<P: Pixel, W: Weight>(w: W, line: &[P], a: usize, n: usize, k0: i64) -> [Self; 3];
    /// `n` as this type.
    fn of(n: i64) -> Self;
}

impl Exact for i64 {
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn row_sums<P: Pixel, W: Weight>(w: W, line: &[P], a: usize, n: usize, k0: i64) -> [i64; 3] {
        w.moment_sums(line, a, n, k0)
    }
    #[inline(always)]
    fn of(n: i64) -> i64 {
        n
    }
}

impl Exact for i128 {
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn row_sums<P: Pixel, W: Weight>(w: W, line: &[P], a: usize, n: usize, k0: i64) -> [i128; 3] {
        let (mut t0, mut t1, mut t2) = (0i128, 0i128, 0i128);
        for (k, &p) in (k0 as i128..).zip(&line[a..a + n]) {
            let v = w.weight(p.value()) as i128;
            t0 += v;
            t1 += v * k;
            t2 += v * k * k;
        }
        [t0, t1, t2]
    }
    #[inline(always)]
    fn of(n: i64) -> i128 {
        n as i128
    }
}

/// The window's sums one row at a time in `A` (any pixels, any weight):
/// each row's `Σw·(1, k, k²)` ([`Weight::moment_sums`]) and pixel counts
/// (closed forms), times the row's `j`.
struct RowByRow<W, A> {
    w: W,
    /// Index in a row of the origin's column, and the origin's row.
    k0: i64,
    j0: i64,
    g: [A; 6],
    n: [A; 6],
}

impl<W: Weight, A: Exact> RowByRow<W, A> {
    fn new(w: W, k0: i64, j0: i64) -> Self {
        let z = A::from(0);
        RowByRow {
            w,
            k0,
            j0,
            g: [z; 6],
            n: [z; 6],
        }
    }
}

impl<P: Pixel, W: Weight, A: Exact> Moments<P> for RowByRow<W, A> {
    #[inline(always)]
    fn row(&mut self, line: &[P], a: usize, b: usize, row: usize) {
        let n = b - a + 1;
        let ka = a as i64 - self.k0;
        let [t0, t1, t2] = A::row_sums(self.w, line, a, n, ka);
        let j = A::of(row as i64 - self.j0);
        // The pixel counts' sums in closed form, from `Σi` and `Σi²` over
        // `i = k − ka` in `0..n` (`n (n − 1)` is even, `n (n − 1)(2n − 1)`
        // a multiple of 6).
        let (n, ka) = (A::of(n as i64), A::of(ka));
        let (one, two) = (A::from(1), A::from(2));
        let i1 = n * (n - one) / two;
        let i2 = i1 * (two * n - one) / A::from(3);
        let k1 = n * ka + i1;
        let k2 = n * ka * ka + two * ka * i1 + i2;
        for (s, [x0, x1, x2]) in [(&mut self.g, [t0, t1, t2]), (&mut self.n, [n, k1, k2])] {
            s[0] += x0;
            s[1] += x1;
            s[2] += x2;
            s[3] += j * x0;
            s[4] += j * j * x0;
            s[5] += j * x1;
        }
    }

    fn sums(self) -> ([f64; 6], [f64; 6]) {
        (self.g.map(A::to_f64), self.n.map(A::to_f64))
    }
}

/// The window's sums of 8-bit grey values in `B` blocks of sixteen lanes
/// (lane `l` of block `i` is column `p + 16 i + l` of every row; `j` the
/// row from the window's first): each row one masked load per block whose
/// lanes are summed across the rows (`Σ_j w` per lane), and the row's
/// `Σ_l w`, `Σ_l l w` in pairs of lanes (`P_j`, `Q_j`) summed as running
/// sums: after `T` rows `A₁ = Σ P_j`, `A₂ = Σ D_j P_j`, `A₃ = Σ D_j (D_j +
/// 1)/2 P_j`, `B₁ = Σ Q_j`, `B₂ = Σ D_j Q_j` with `D_j = T − j`, from which
/// the moments in `j` follow once at the end (no multiplication by `j` per
/// row, every accumulator in a register). The pixel counts the same way:
/// per lane from the masks, and the row's count `n_j` and `2 Σ_l l` as
/// running sums from the span's ends. The same integers as [`RowByRow`]
/// (tracking: `measure_weighted` 53.99 M → 53.83 M instructions against
/// multiplying by `j` per row). With at most 64 rows and 32 lanes no
/// 8-bit count passes 64, no 16-bit lane `64 · 255` and no 32-bit lane
/// `8 · 255 · 45760 < 2³¹` (`A₃`) or `8 · 255 · 31 · 2080` (`B₂`).
///
/// With `LESS` every pixel counts less a background known beforehand
/// (`w − b`, between −255 and 255: the same bounds): the sums less the
/// background times the pixel counts, the counts themselves not kept
/// (their sums are then zero).
struct Lanes<const B: usize, const LESS: bool = false> {
    /// Index in a row of lane 0, and the frame row of `j = 0`.
    p: usize,
    r0: usize,
    /// The frame row of the next step.
    next: usize,
    /// The origin's `k` and `j` (column and row).
    k0: i64,
    j0: i64,
    /// Per lane `Σ_j w`.
    col: [[i16x8; 2]; B],
    /// Per lane `Σ_j 1`, the pixels taken.
    count: [u8x16; B],
    /// The running sums (see above).
    a1: i32x4,
    a2: i32x4,
    a3: i32x4,
    b1: i32x4,
    b2: i32x4,
    /// The counts' running sums `(Σ n, Σ D n, Σ D (D + 1)/2 n, Σ 2 l,
    /// Σ D 2 l)` (see above).
    n: [i64; 5],
    /// With `LESS`, the background taken off every pixel (bytes).
    background: u8x16,
}

/// Lanes `0..8` and `8..16` of a block.
const LANE: [i16x8; 2] = [
    i16x8::new([0, 1, 2, 3, 4, 5, 6, 7]),
    i16x8::new([8, 9, 10, 11, 12, 13, 14, 15]),
];

impl<const B: usize, const LESS: bool> Lanes<B, LESS> {
    /// Most rows.
    const ROWS: usize = 64;

    /// With `LESS`, `background` taken off every pixel (else 0).
    fn new(p: usize, r0: usize, (k0, j0): (i64, i64), background: u8) -> Self {
        Lanes {
            p,
            r0,
            next: r0,
            k0,
            j0,
            col: [[i16x8::ZERO; 2]; B],
            count: [u8x16::ZERO; B],
            a1: i32x4::ZERO,
            a2: i32x4::ZERO,
            a3: i32x4::ZERO,
            b1: i32x4::ZERO,
            b2: i32x4::ZERO,
            n: [0; 5],
            background: u8x16::splat(background),
        }
    }
}

impl<const B: usize> Moments<u8> for Lanes<B> {
    #[inline(always)]
    fn row(&mut self, line: &[u8], a: usize, b: usize, row: usize) {
        debug_assert!(a >= self.p && b < self.p + 16 * B);
        let (lo, hi) = ((a - self.p) as isize, (b - self.p) as isize);
        // Rows left out (no pixel) still step the running sums.
        debug_assert!(row >= self.next);
        while self.next < row {
            self.a2 += self.a1;
            self.a3 += self.a2;
            self.b2 += self.b1;
            let n = &mut self.n;
            n[1] += n[0];
            n[2] += n[1];
            n[4] += n[3];
            self.next += 1;
        }
        let (l0, l1) = (lo as i64, hi as i64);
        let n = l1 - l0 + 1;
        self.take(
            line,
            self.p,
            |i| {
                let off = 16 * i as isize;
                run16(lo - off, hi - off)
            },
            (n, (l0 + l1) * n),
        );
    }

    fn sums(self) -> ([f64; 6], [f64; 6]) {
        self.sums()
    }
}

impl<const LESS: bool> Lanes<1, LESS> {
    /// Takes the rows of `records`, row `i` at `data[at + i stride..]`,
    /// its lanes from the mask offsets in bytes 4 and 5 of `records[i]`
    /// (see [`lanes_from16`]); returns the sums.
    #[inline(always)]
    fn take_records(
        mut self,
        data: &[u8],
        at: usize,
        stride: usize,
        records: &[u64],
    ) -> ([f64; 6], [f64; 6]) {
        each_row(data, at, stride, 16, records, |row, at, &r| {
            let (ge, gt) = ((r >> 32) as usize & 63, (r >> 40) as usize & 63);
            // The lanes `32 − ge..32 − gt`: `n = ge − gt`,
            // `2 Σ l = (63 − ge − gt) n`.
            let n = ge as i64 - gt as i64;
            let counts = (n, (63 - (ge + gt) as i64) * n);
            self.take(row, at, |_| lanes_from16(ge) & !lanes_from16(gt), counts);
        });
        self.sums()
    }
}

impl<const B: usize, const LESS: bool> Lanes<B, LESS> {
    /// Takes the next row's pixels in the lanes set in `mask(i)` of each
    /// block `i`, lane 0 at `data[at]`: `(n, 2 Σ l)` of them in `counts`.
    #[inline(always)]
    fn take(
        &mut self,
        data: &[u8],
        at: usize,
        mask: impl Fn(usize) -> u8x16,
        (count, l2): (i64, i64),
    ) {
        debug_assert!(self.next - self.r0 < Self::ROWS);
        self.next += 1;
        let ones = i16x8::splat(1);
        let (mut pw, mut qw) = (i32x4::ZERO, i32x4::ZERO);
        for (i, (col, cnt)) in self.col.iter_mut().zip(&mut self.count).enumerate() {
            let m = mask(i);
            let v = lanes16(&data[at + 16 * i..at + 16 * i + 16]) & m;
            let mut half = [i16x8::from_u8x16_low(v), i16x8::from_u8x16_high(v)];
            if LESS {
                // (The mask's lanes as 255: `& b` is `b` in them, 0 else;
                // taken in bytes, then widened like the pixels.)
                let b = m & self.background;
                half[0] -= i16x8::from_u8x16_low(b);
                half[1] -= i16x8::from_u8x16_high(b);
            } else {
                // (`0xff` is −1: one more pixel.)
                *cnt -= m;
            }
            col[0] += half[0];
            col[1] += half[1];
            // `Σ_l w` and `Σ_l l w` of the sixteen lanes from the sum of
            // the halves (lanes `l` and `l + 8` together, at most 510 in
            // magnitude): `l w` as `(l mod 8)` times both plus 8 times the
            // upper half (three products, not four).
            let both = half[0] + half[1];
            let l = if i == 0 {
                LANE[0]
            } else {
                LANE[0] + i16x8::splat(16 * i as i16)
            };
            pw += both.dot(ones);
            qw += both.dot(l) + half[1].dot(i16x8::splat(8));
        }
        self.a1 += pw;
        self.a2 += self.a1;
        self.a3 += self.a2;
        self.b1 += qw;
        self.b2 += self.b1;
        if !LESS {
            let n = &mut self.n;
            n[0] += count;
            n[1] += n[0];
            n[2] += n[1];
            n[3] += l2;
            n[4] += n[3];
        }
    }

    /// See [`Moments::sums`]. (Every sum about lane 0 and row `r0` is an
    /// integer far below `2⁵³`: exact as `f64`, and so are the moments in
    /// `j` and about the origin formed from them in floats.)
    #[inline(always)]
    fn sums(self) -> ([f64; 6], [f64; 6]) {
        // `Σ_l c_l l²` of the per-lane sums `c` (16-bit lanes); `Σ w` and
        // `Σ l w` are `A₁` and `B₁`.
        let (mut c2, mut n2) = (i32x4::ZERO, i32x4::ZERO);
        for (i, (col, count)) in self.col.iter().zip(&self.count).enumerate() {
            let count = [
                i16x8::from_u8x16_low(*count),
                i16x8::from_u8x16_high(*count),
            ];
            for h in 0..2 {
                let l = LANE[h] + i16x8::splat(16 * i as i16);
                // (`l²` up to 961 in 16 bits.)
                c2 += col[h].dot(l * l);
                if !LESS {
                    n2 += count[h].dot(l * l);
                }
            }
        }
        // (No array maps: not always inlined in a function this large.)
        let r = |v: i32x4| v.reduce_add() as f64;
        let (c0, c1, c2, n2) = (r(self.a1), r(self.b1), r(c2), r(n2));
        let (a2, a3, b2) = (r(self.a2), r(self.a3), r(self.b2));
        let f = |i: usize| if LESS { 0.0 } else { self.n[i] as f64 };
        let n = [f(0), f(1), f(2), f(3), f(4)];
        let pair = |g: f64, n: f64| f64x2::new([g, n]);
        // `Σ(1, l, l²)`, `Σ D`, `Σ D²`, `Σ D l` of the weights and counts.
        let s = [pair(c0, n[0]), pair(c1, 0.5 * n[3]), pair(c2, n2)];
        let d = pair(a2, n[1]);
        let d2 = pair(2.0 * a3 - a2, 2.0 * n[2] - n[1]);
        let dl = pair(b2, 0.5 * n[4]);
        // `j = T − D` from the origin's row (`T` the rows taken plus the
        // first's `j`: no moving in `j` at the end).
        let t = f64x2::splat((self.next as i64 - self.j0) as f64);
        let sums = [
            s[0],
            s[1],
            s[2],
            t * s[0] - d,
            t * t * s[0] - f64x2::splat(2.0) * t * d + d2,
            t * s[1] - dl,
        ];
        // From lane to the origin's column.
        let dk = (self.p as i64 - self.k0) as f64;
        let [m0, m1, m2, m3, m4, m5] = moved(sums, dk);
        let [m0, m1, m2, m3, m4, m5] = [
            m0.to_array(),
            m1.to_array(),
            m2.to_array(),
            m3.to_array(),
            m4.to_array(),
            m5.to_array(),
        ];
        (
            [m0[0], m1[0], m2[0], m3[0], m4[0], m5[0]],
            [m0[1], m1[1], m2[1], m3[1], m4[1], m5[1]],
        )
    }
}

/// A blob's ellipse as the quadratic form
/// `ρ²(dx, dy) = qxx dx² + 2 qxy dx dy + qyy dy²` about `(bx, ·)`: the
/// columns of a row inside `ρ² ≤ s` come from the roots of the quadratic,
/// so that only the pixels that count are visited.
#[derive(Debug, Clone, Copy)]
struct Conic {
    qxx: f64,
    qyy: f64,
    qxy: f64,
    inv_qxx: f64,
    bx: f64,
}

/// A [`Window`]'s span ends of two rows at a time (see [`PairSpans::at`]).
struct PairSpans {
    q: Conic,
    by: f64x2,
    s: (f64, f64),
    /// The rows of the box proper (`wr.0 ≤ row ≤ wr.1`), for the hole.
    hole_rows: (f64x2, f64x2),
    /// The columns of the ring's box, the box proper and the window as
    /// `c + ROUND`.
    cols: (f64x2, f64x2),
    box_cols: (f64x2, f64x2),
    wcols: (f64x2, f64x2),
}

/// [`PairSpans::at`] of the rows from `rows` on, two at a time (without
/// end).
struct Pairs<'a> {
    spans: &'a PairSpans,
    rows: f64x2,
}

impl Iterator for Pairs<'_> {
    type Item = ([f64x2; 6], f64x2);

    #[inline(always)]
    fn next(&mut self) -> Option<Self::Item> {
        let at = self.spans.at(self.rows);
        // (The rows as floats stepped by 2: exact integers.)
        self.rows += f64x2::splat(2.0);
        Some(at)
    }
}

impl PairSpans {
    /// The pairs of rows from `first` on (see [`Pairs`]).
    #[inline(always)]
    fn from(&self, first: usize) -> Pairs<'_> {
        let top = first as f64;
        Pairs {
            spans: self,
            rows: f64x2::new([top, top + 1.0]),
        }
    }

    /// The spans of the rows `rows` (lanes): `[oa, ob, xa, xb, a, b]` as
    /// in [`Window::blocks`] but the hole in every row (inside the outer
    /// span when not empty), with the mask of the rows that have it (the
    /// box proper); each end the integer `n` as the float `n + ROUND` (see
    /// [`near_f64x2`]), clipped as floats.
    #[inline(always)]
    fn at(&self, rows: f64x2) -> ([f64x2; 6], f64x2) {
        let [ia, ib, oa, ob] = self.q.spans(rows - self.by, self.s.0, self.s.1);
        let ends = [
            oa.fast_max(self.cols.0),
            ob.fast_min(self.cols.1),
            // (Inside the outer span as it is: the inner roots are inside
            // the outer ones, `s_in ≤ s_out`, and every step from `s` to
            // the ends is monotonic in floats.)
            ia.fast_max(self.box_cols.0),
            ib.fast_min(self.box_cols.1),
            ia.fast_max(self.wcols.0),
            ib.fast_min(self.wcols.1),
        ];
        let (hr0, hr1) = self.hole_rows;
        (ends, rows.cmp_ge(hr0) & rows.cmp_le(hr1))
    }
}

/// Rows whose spans [`Window::blocks`] computes ahead at a time.
const SPAN_BLOCK: usize = 24;
const _: () = assert!(SPAN_BLOCK.is_multiple_of(2));

impl Conic {
    /// The columns with `ρ²(col − bx, dy) ≤ s_in` and `≤ s_out`
    /// (`s_in ≤ s_out`) of the rows `dy` (lanes), as inclusive ranges
    /// `[lo_in, hi_in, lo_out, hi_out]` (unclipped, see [`near_f64x2`];
    /// empty ones with `lo > hi`). The ends are the ceiling and floor of
    /// the roots, taken as the nearest integers to `root ± 0.5` (exact but
    /// for a root that is exactly an integer, where a column on the
    /// ellipse itself may be left out).
    #[inline(always)]
    fn spans(&self, dy: f64x2, s_in: f64, s_out: f64) -> [f64x2; 4] {
        let b = f64x2::splat(self.qxy) * dy;
        let base = b * b - f64x2::splat(self.qxx * self.qyy) * dy * dy;
        let mid = f64x2::splat(self.bx) - b * f64x2::splat(self.inv_qxx);
        let inv = f64x2::splat(self.inv_qxx);
        let ends = |s: f64| {
            let disc = base + f64x2::splat(self.qxx * s);
            // (No root, or NaN: `h = −1` gives `lo > hi`. The square root
            // of a negative `disc` is NaN, and `inv > 0`: one `max`, no
            // comparison and blend.)
            let h = max_or_f64x2(disc.sqrt() * inv, f64x2::splat(-1.0));
            let lo = near_f64x2(mid - h + f64x2::splat(0.5));
            let hi = near_f64x2(mid + h - f64x2::splat(0.5));
            (lo, hi)
        };
        let ((lo_in, hi_in), (lo_out, hi_out)) = (ends(s_in), ends(s_out));
        [lo_in, hi_in, lo_out, hi_out]
    }
}

/// The `k`-th smallest of `values` (all `≤ max`): by counting when the
/// values are small (8-bit frames), else by selection (reorders `values`).
#[inline]
fn quantile(values: &mut [u32], k: usize, max: u32) -> u32 {
    const SMALL: usize = 256;
    // (Counts in bytes while no count can pass 255: a table of 256 bytes
    // is cleared with a few stores, 512 would be a library call.)
    if (max as usize) < SMALL && values.len() <= u8::MAX as usize {
        let mut count = [0u8; SMALL];
        for &v in values.iter() {
            count[v as usize & (SMALL - 1)] += 1;
        }
        return kth_counted(&count, k);
    }
    let (_, &mut q, _) = values.select_nth_unstable(k);
    q
}

/// How many values `count` holds up to `last` (`count[v]` values equal
/// `v`; at most 255 in all, so that no sum of counts wraps): sixteen
/// counts at a time, the last sixteen masked.
#[inline(always)]
fn counted_up_to(count: &[u8; 256], last: usize) -> u8 {
    let whole = (last + 1) / 16;
    let mut n = u8x16::ZERO;
    for c in count.chunks_exact(16).take(whole) {
        n += lanes16(c);
    }
    if whole < 16 {
        // (The lanes `< (last + 1) % 16` of the next sixteen.)
        let next = lanes16(&count[16 * whole..16 * whole + 16]);
        n += next & !lanes_from16(32 - (last + 1) % 16);
    }
    n.to_array().iter().fold(0, |n, &c| n.wrapping_add(c))
}

/// The `k`-th smallest (from 0) of the values counted in `count` (`count[v]`
/// values equal `v`; more than `k` in all, at most 255): eight counts at
/// a time as the bytes of a `u64`, whose product with `0x0101…01` holds
/// their running sums (no carry: at most 255), the chunk that passes `k`
/// then searched in those sums without a loop.
#[inline]
fn kth_counted(count: &[u8; 256], k: usize) -> u32 {
    const BYTES: u64 = 0x0101_0101_0101_0101;
    const LANES: u64 = 0x0001_0001_0001_0001;
    const EVEN: u64 = 0x00ff_00ff_00ff_00ff;
    let mut acc = 0;
    for (i, c) in count.chunks_exact(8).enumerate() {
        let Ok(c) = <[u8; 8]>::try_from(c) else {
            unreachable!("eight counts")
        };
        // Byte `j`: the counts `0..=j` of the eight summed.
        let sums = u64::from_le_bytes(c).wrapping_mul(BYTES);
        let eight = (sums >> 56) as usize;
        if acc + eight > k {
            // The first byte of at least `t = k + 1 − acc` (1 to 255): the
            // bytes of at least `t` counted in 16-bit lanes, even bytes
            // and odd ones (`v + 256 − t` reaches bit 8 where `v ≥ t`).
            let below = (256 - (k + 1 - acc) as u64) * LANES;
            let even = ((sums & EVEN) + below) >> 8 & LANES;
            let odd = ((sums >> 8 & EVEN) + below) >> 8 & LANES;
            let at_least = ((even + odd).wrapping_mul(LANES) >> 48) as u32;
            return 8 * i as u32 + 8 - at_least;
        }
        acc += eight;
    }
    debug_assert!(false, "fewer than {} counted", k + 1);
    255
}

/// The weight a grey value gets in the centroid sums (in units of
/// `1 / SCALE` grey values).
pub trait Weight: Copy {
    /// Weight units per grey value.
    const SCALE: f64;
    /// Whether the weight is the grey value itself (so that 8-bit weights
    /// are bytes).
    const LINEAR: bool = false;
    /// The weight of grey value `v`, from 0 to `v · SCALE` (the bound
    /// that keeps the window's integer sums in `i64` relies on it).
    fn weight(&self, v: u32) -> i64;
    /// The weight of a level between grey values (the background), unrounded.
    fn level(&self, v: f64) -> f64;
    /// `[Σ w, Σ w k, Σ w k²]` over the weights `w` of the pixels
    /// `line[a..a + n]`, `k` running from `k0`.
    #[inline(always)]
    fn moment_sums<P: Pixel>(&self, line: &[P], a: usize, n: usize, k0: i64) -> [i64; 3] {
        scalar_moment_sums(&line[a..a + n], k0, |p| self.weight(p.value()))
    }
}

/// The grey value itself (the default centroid).
#[derive(Debug, Clone, Copy)]
pub struct Linear;

impl Weight for Linear {
    const SCALE: f64 = 1.0;
    const LINEAR: bool = true;
    #[inline(always)]
    fn weight(&self, v: u32) -> i64 {
        v as i64
    }
    #[inline(always)]
    fn level(&self, v: f64) -> f64 {
        v
    }
    #[inline(always)]
    fn moment_sums<P: Pixel>(&self, line: &[P], a: usize, n: usize, k0: i64) -> [i64; 3] {
        P::moment_sums(line, a, n, k0)
    }
}

/// The grey value rolled off smoothly to a constant before the
/// saturation level: linear up to `knee`, then a parabola that meets the
/// constant `knee + (top − knee) / 2` with zero slope at `top` (the
/// saturation level). A clipped profile has a kink where it meets the
/// saturation level; sampled at pixel centres, that kink moves the
/// centroid with the dot's sub-pixel phase. Through this roll-off the
/// weight of the clipped profile is smooth (its slope is zero where the
/// clipping sets in), so the phase error of a saturated dot shrinks.
#[derive(Debug, Clone, Copy)]
pub struct Knee {
    /// End of the linear part, grey value.
    pub knee: u32,
    /// The saturation level.
    pub top: u32,
}

impl Weight for Knee {
    const SCALE: f64 = 16.0;
    #[inline(always)]
    fn weight(&self, v: u32) -> i64 {
        self.level(v as f64).round() as i64
    }
    fn level(&self, v: f64) -> f64 {
        let (k, t) = (self.knee as f64, self.top.max(self.knee + 1) as f64);
        let w = if v <= k {
            v
        } else if v >= t {
            k + (t - k) / 2.0
        } else {
            let x = v - k;
            k + x - x * x / (2.0 * (t - k))
        };
        w * Self::SCALE
    }
}

/// Measures a blob (full-frame coordinates, pixels read inside `plane`
/// only) in the window of `margin`; `None` if the window holds no signal.
pub fn measure<P: Pixel>(
    plane: &Plane<P>,
    blob: &Blob,
    threshold: Threshold,
    fallback_background: f64,
    margin: impl Margin,
) -> Option<Measurement> {
    measure_weighted(plane, blob, threshold, fallback_background, margin, Linear)
}

/// [`measure`] with the grey values weighted by `w` in the centroid and
/// moment sums (the signal is in the weight's units).
pub fn measure_weighted<P: Pixel, W: Weight>(
    plane: &Plane<P>,
    blob: &Blob,
    threshold: Threshold,
    fallback_background: f64,
    margin: impl Margin,
    w: W,
) -> Option<Measurement> {
    // The blob's own fourth moment first: a chain of a division, a square
    // root and a division that depends on nothing below, so the processor
    // overlaps it with the window's sums instead of waiting for it at the
    // end (tracking: 4.8 % of the time for 2.9 % of the instructions there).
    let kurtosis = blob.kurtosis();
    let (grow, max_scale) = (margin.grow(), margin.max_scale());
    let (bx, by) = blob.centre();
    let (cxx, cyy, cxy) = blob.covariance();
    // Semi-minor axis as in `ellipse` (without its angle).
    let d = ((cxx - cyy) * (cxx - cyy) / 4.0 + cxy * cxy).sqrt();
    let b = 2.0 * ((cxx + cyy) / 2.0 - d).max(0.0).sqrt();
    if b.is_nan() || b <= 0.0 {
        return None;
    }
    let scale = ((b + grow) / b).min(max_scale);
    let bg_outer = (scale + 0.3).min(BG_OUTER).max(scale + 0.15);
    // Normalised radius² of an offset: dᵀ (4C)⁻¹ d.
    let det = cxx * cyy - cxy * cxy;
    if det.is_nan() || det <= 0.0 {
        return None;
    }
    let (qxx, qyy, qxy) = (cyy / (4.0 * det), cxx / (4.0 * det), -cxy / (4.0 * det));
    let (s_in, s_out) = (scale * scale, bg_outer * bg_outer);
    // Window: the box grown by GROW (and one more pixel for the background).
    // (The window's integer bounds from `⌈grow⌉` and `⌊grow⌋` instead of
    // eight conversions of floats: `⌈n − grow⌉ = n − ⌊grow⌋` and so on.)
    let (cg, fg) = (ceil_i64(grow), floor_i64(grow));
    let g = cg + 2;
    let (first_col, first_row) = (plane.col0 as i64, plane.row0 as i64);
    let (last_col, last_row) = (plane.last_col() as i64, plane.last_row());
    let c0 = (blob.col0 as i64 - g).max(first_col);
    let r0 = (blob.row0 as i64 - g).max(first_row) as usize;
    let c1 = (blob.col1 as i64 + g).min(last_col);
    let r1 = ((blob.row1 as i64 + g) as usize).min(last_row);
    let (wr0, wr1) = (blob.row0 as f64 - grow, blob.row1 as f64 + grow);
    // Columns of the box proper (`col0 − grow ≤ col ≤ col1 + grow`), for
    // the background.
    let [bc0, bc1, wc0i, wc1i] = grown(
        (blob.col0 as i64, blob.col1 as i64),
        grow,
        (cg, fg),
        (first_col, last_col),
    );
    let (bc0, bc1) = (c0.max(bc0), c1.min(bc1));
    // Rows of the weighted window.
    let [_, _, wr0i, wr1i] = grown(
        (blob.row0 as i64, blob.row1 as i64),
        grow,
        (cg, fg),
        (first_row, last_row as i64),
    );
    let (wr0i, wr1i) = (wr0i as usize, wr1i.max(0) as usize);
    let window = Window {
        q: Conic {
            qxx,
            qyy,
            qxy,
            inv_qxx: 1.0 / qxx,
            bx,
        },
        by,
        s_in,
        s_out,
        rows: (r0, r1),
        cols: (c0, c1),
        first_col,
        wr: (wr0, wr1),
        box_cols: (bc0, bc1),
        wrows: (wr0i, wr1i),
        wcols: (wc0i, wc1i),
    };
    // Background: the 30th percentile of the dark pixels in the ring just
    // outside the window (robust against a coded target's ring reaching
    // into it; the small downward bias for pure noise moves the centre by
    // nothing, as the window is centred on the blob), every `stride`-th one
    // kept. The pixels of a small ring are counted by grey value in bytes,
    // without a branch, and the percentile read from the counts up to the
    // threshold (no 2 KB buffer to clear; exact while the ring holds at
    // most 255 pixels, else measured again with the buffer). (The fourth
    // moment is the blob's own: `Blob::kurtosis`.)
    let est = std::f64::consts::PI * (s_out - s_in) * 4.0 * det.sqrt();
    let level = threshold.level();
    // The window's sums are exact integers about the pixel nearest the
    // blob's centre.
    let [cc, rr] = round_i64x2(f64x2::new([bx, by]));
    let mut counted = None;
    // (`est ≤ COUNTED_RING < BG_SAMPLES` keeps every dark pixel: stride 1.)
    if est <= COUNTED_RING && (P::MAX <= 255 || level < 255) {
        let mut count = [0; 256];
        let mut ring = Counts {
            count: &mut count,
            total: 0,
        };
        let fast = match plane.bytes() {
            Some(bytes) if W::LINEAR => {
                window.sums_8bit(&bytes, &mut ring, level, (cc - first_col, rr))
            }
            _ => None,
        };
        let (sums, background) = fast.unwrap_or_else(|| {
            let (g, n) = window_sums(&window, plane, w, &mut ring, (cc, rr));
            let exact = ring.total <= u8::MAX as usize;
            (
                (g, Some(n)),
                if exact { ring.quantile(level) } else { None },
            )
        });
        if ring.total <= u8::MAX as usize {
            counted = Some((sums, background));
        }
    }
    let ((gm, nm), bg) = counted.unwrap_or_else(|| {
        let mut ring = Samples {
            buf: [0; BG_SAMPLES],
            n: 0,
            seen: 0,
            next: 0,
            stride: ceil_i64(est / BG_SAMPLES as f64).max(1) as usize,
            threshold,
        };
        let (g, n) = window_sums(&window, plane, w, &mut ring, (cc, rr));
        ((g, Some(n)), ring.quantile(level))
    });
    let background = bg.map_or(fallback_background, |b| b as f64);
    // The moments with the background subtracted (unless off already),
    // then about the centre.
    let bw = w.level(background);
    let [sw, sx, sxx, sy, syy, sxy] = match nm {
        Some(n) => [0, 1, 2, 3, 4, 5].map(|i| gm[i] - bw * n[i]),
        None => gm,
    };
    if sw.is_nan() || sw <= 0.0 {
        return None;
    }
    let (mx, my) = (sx / sw, sy / sw);
    Some(Measurement {
        col: cc as f64 + mx,
        row: rr as f64 + my,
        cxx: sxx / sw - mx * mx - 1.0 / 12.0,
        cyy: syy / sw - my * my - 1.0 / 12.0,
        cxy: sxy / sw - mx * my,
        signal: sw / W::SCALE,
        background,
        kurtosis,
    })
}

/// For a blob's extent `lo..=hi` (columns or rows) grown by `grow`, with
/// `⌈grow⌉, ⌊grow⌋` in `cg, fg`, in a plane's `first..=last`: `[⌈lo −
/// grow⌉, ⌊hi + grow⌋]` and the window's `[max(lo − grow, first), min(hi
/// + grow, last)]` rounded towards 0, in integers (`⌈n − x⌉ = n − ⌊x⌋`;
/// `lo ≥ first ≥ 0`).
#[inline(always)]
fn grown(
    (lo, hi): (i64, i64),
    grow: f64,
    (cg, fg): (i64, i64),
    (first, last): (i64, i64),
) -> [i64; 4] {
    let top = if grow >= 0.0 {
        hi + fg
    } else {
        // (Rounded towards 0, not down.)
        (hi as f64 + grow) as i64
    };
    [lo - fg, hi + fg, (lo - cg).max(first), top.min(last)]
}

/// [`Window::sums`] with the window's sums about the pixel `origin`
/// (column, row) taken the cheapest exact way: 8-bit grey values (the
/// linear weight) of a window at most 32 columns wide and 64 rows high in
/// [`Lanes`]; else
/// row by row in `i64` when a bound shows that no sum can overflow, in
/// `i128` otherwise.
#[inline(always)]
fn window_sums<P: Pixel, W: Weight, R: Ring>(
    window: &Window,
    plane: &Plane<P>,
    w: W,
    ring: &mut R,
    (cc, rr): (i64, i64),
) -> ([f64; 6], [f64; 6]) {
    let (wr0, wr1) = window.wrows;
    let (wc0, wc1) = window.wcols;
    let first_col = window.first_col;
    let k0 = cc - first_col;
    if wr0 > wr1 || wc0 > wc1 {
        // No pixel in the window.
        return window.sums(plane, RowByRow::<W, i64>::new(w, k0, rr), ring);
    }
    let (cols, rows) = ((wc1 - wc0 + 1) as usize, wr1 - wr0 + 1);
    if W::LINEAR && rows <= Lanes::<1>::ROWS && cols <= 32 && plane.width >= 32 {
        if let Some(bytes) = plane.bytes() {
            let a = (wc0 - first_col) as usize;
            return if cols <= 16 {
                let p = a.min(plane.width - 16);
                window.sums(&bytes, Lanes::<1>::new(p, wr0, (k0, rr), 0), ring)
            } else {
                let p = a.min(plane.width - 32);
                window.sums(&bytes, Lanes::<2>::new(p, wr0, (k0, rr), 0), ring)
            };
        }
    }
    // Every sum (and every intermediate of a row's sums) is at most a few
    // times `pixels · w_max · d²` with `d` the largest of the window's
    // extents and distances from the origin (Knee weights are at most the
    // grey value times the scale).
    let d = [wc0 - cc, wc1 - cc, wr0 as i64 - rr, wr1 as i64 - rr]
        .map(i64::abs)
        .into_iter()
        .chain([cols as i64, rows as i64])
        .max()
        .unwrap_or(0) as f64
        + 1.0;
    let bound = (cols * rows) as f64 * P::MAX as f64 * W::SCALE.max(1.0) * d * d;
    if bound < (1u64 << 58) as f64 {
        window.sums(plane, RowByRow::<W, i64>::new(w, k0, rr), ring)
    } else {
        window.sums(plane, RowByRow::<W, i128>::new(w, k0, rr), ring)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::Rng;

    #[test]
    fn vectorised_moment_sums_are_the_scalar_ones() {
        // Rows shorter and longer than a block, runs ending at the row's end
        // (the last block shifted back), `k` at the ends of its range and
        // past them (the scalar fallback).
        let mut rng = Rng::new(5);
        for len in [3usize, 15, 16, 17, 40, 150] {
            let line: Vec<u8> = (0..len).map(|_| (rng.next_u64() % 256) as u8).collect();
            let runs = (0..len).flat_map(|a| (1..=len - a).map(move |n| (a, n)));
            for (a, n) in runs {
                for k0 in [-200, -127, -5, 0, 3, 127 - n as i64, 120] {
                    let want = scalar_moment_sums(&line[a..a + n], k0, |p| p as i64);
                    assert_eq!(u8::moment_sums(&line, a, n, k0), want, "{len} {a} {n} {k0}");
                    assert_eq!(Linear.moment_sums(&line, a, n, k0), want);
                }
            }
        }
    }

    /// 1 to 64 rows of random pixels `width` wide after `above` more, and
    /// an origin near them.
    fn random_rows(rng: &mut Rng, width: usize, above: usize) -> (usize, Vec<u8>, (i64, i64)) {
        let rows = 1 + (rng.next_u64() % 64) as usize;
        let data = (0..width * (rows + above))
            .map(|_| (rng.next_u64() % 256) as u8)
            .collect();
        let origin = (
            (rng.next_u64() % 40) as i64 - 6,
            (rng.next_u64() % 70) as i64,
        );
        (rows, data, origin)
    }

    /// The window's sums of random rows and spans from every
    /// implementation: the same integers, so the same `f64`s.
    #[test]
    fn window_sums_agree() {
        let mut rng = Rng::new(21);
        let width = 48;
        for case in 0..300 {
            let (rows, data, (k0, j0)) = random_rows(&mut rng, width, 3);
            let r0 = 3usize;
            let lanes = if case % 2 == 0 { 16 } else { 32 };
            let p = (rng.next_u64() % (width - 31) as u64) as usize;
            let mut one = Lanes::<1>::new(p, r0, (k0, j0), 0);
            let mut two = Lanes::<2>::new(p, r0, (k0, j0), 0);
            let mut by64 = RowByRow::<Linear, i64>::new(Linear, k0, j0);
            let mut by128 = RowByRow::<Linear, i128>::new(Linear, k0, j0);
            for row in r0..r0 + rows {
                if rng.next_u64().is_multiple_of(5) {
                    continue;
                }
                let line = &data[row * width..(row + 1) * width];
                let a = p + (rng.next_u64() % lanes as u64) as usize;
                let b = a + (rng.next_u64() % (p + lanes - a) as u64) as usize;
                if lanes == 16 {
                    one.row(line, a, b, row);
                }
                two.row(line, a, b, row);
                by64.row(line, a, b, row);
                by128.row(line, a, b, row);
            }
            let want = Moments::<u8>::sums(by64);
            assert_eq!(Moments::<u8>::sums(by128), want, "{case}");
            assert_eq!(two.sums(), want, "{case}");
            if lanes == 16 {
                assert_eq!(one.sums(), want, "{case}");
            }
        }
    }

    /// The window's rows from records (the 8-bit path's lanes from mask
    /// offsets, rows without pixels as empty offsets) against the plain
    /// sums: with the pixel counts, and with a background taken off every
    /// pixel (the weights' sums less the background times the counts',
    /// the counts' zero).
    #[test]
    fn window_records_are_the_plain_sums() {
        let mut rng = Rng::new(23);
        let width = 40;
        for case in 0..400 {
            let (rows, data, origin) = random_rows(&mut rng, width, 2);
            let (r0, p) = (2usize, (rng.next_u64() % (width - 15) as u64) as usize);
            let mut plain = RowByRow::<Linear, i64>::new(Linear, origin.0, origin.1);
            let records: Vec<u64> = (r0..r0 + rows)
                .map(|row| {
                    let lo = (rng.next_u64() % 17) as usize;
                    if lo == 16 || rng.next_u64().is_multiple_of(4) {
                        // (Empty: the two offsets equal.)
                        return ((32 - lo as u64) << 32) | ((32 - lo as u64) << 40);
                    }
                    let hi = lo + (rng.next_u64() % (16 - lo) as u64) as usize;
                    plain.row(&data[row * width..], p + lo, p + hi, row);
                    ((32 - lo as u64) << 32) | ((31 - hi as u64) << 40)
                })
                .collect();
            let at = r0 * width + p;
            let want = Moments::<u8>::sums(plain);
            // The rows ending the data (row by row but for `p = 0`), and
            // with a row after them (whole strides).
            let mut longer = data.clone();
            longer.extend_from_slice(&data[..width]);
            for data in [&data, &longer] {
                let with_counts = Lanes::<1>::new(p, r0, origin, 0);
                assert_eq!(
                    with_counts.take_records(data, at, width, &records),
                    want,
                    "{case}"
                );
                let b = (rng.next_u64() % 256) as u8;
                let less = Lanes::<1, true>::new(p, r0, origin, b);
                let (g, n) = less.take_records(data, at, width, &records);
                assert_eq!(n, [0.0; 6], "{case}");
                for (i, (g, (w, n))) in g.iter().zip(want.0.iter().zip(want.1)).enumerate() {
                    assert_eq!(*g, w - b as f64 * n, "{case} {i}");
                }
            }
        }
    }

    /// The 8-bit paths (the counted ring picked by bit masks, the window
    /// in lanes) against the plain path of the same frame in 16 bits:
    /// blobs of many sizes and shapes, at the window's edges too.
    #[test]
    fn eight_bit_measurement_is_the_plain_one() {
        let mut rng = Rng::new(33);
        let (width, height) = (160usize, 120usize);
        let mut fallbacks = 0;
        for frame in 0..12 {
            let mut img = vec![0f64; width * height];
            for v in img.iter_mut() {
                *v = 20.0 + 6.0 * rng.uniform();
            }
            for _ in 0..14 {
                let (cx, cy) = (
                    rng.range(2.0, width as f64 - 2.0),
                    rng.range(2.0, height as f64 - 2.0),
                );
                let (sa, sb) = (rng.range(1.0, 2.0 + frame as f64), rng.range(1.0, 4.0));
                let ang = rng.range(0.0, std::f64::consts::PI);
                let amp = rng.range(60.0, 260.0);
                let (c, s) = (ang.cos(), ang.sin());
                for r in 0..height {
                    for col in 0..width {
                        let (dx, dy) = (col as f64 - cx, r as f64 - cy);
                        let (u, v) = ((c * dx + s * dy) / sa, (-s * dx + c * dy) / sb);
                        img[r * width + col] += amp * (-(u * u + v * v) / 2.0).exp();
                    }
                }
            }
            let px8: Vec<u8> = img.iter().map(|&v| v.min(255.0) as u8).collect();
            let px16: Vec<u16> = px8.iter().map(|&v| v as u16).collect();
            let threshold = Threshold::global(60);
            let whole8 = Plane::whole(&px8, width, height);
            let mut labeller = crate::label::Labeller::new(100_000, 10_000);
            labeller.label(&whole8, threshold, 255);
            // The whole frame and a window inside it.
            fn crop<P: Pixel>(w: &[P], width: usize, height: usize) -> Plane<'_, P> {
                Plane {
                    data: &w[(7 * width + 5)..],
                    width: width - 12,
                    height: height - 10,
                    stride: width,
                    col0: 5,
                    row0: 7,
                }
            }
            let mut n = 0;
            for blob in labeller.blobs() {
                for margin in [(GROW, MAX_SCALE), (CODED_GROW, CODED_MAX_SCALE)] {
                    let m8 = measure(&whole8, blob, threshold, 20.0, margin);
                    let whole16 = Plane::whole(&px16, width, height);
                    let m16 = measure(&whole16, blob, threshold, 20.0, margin);
                    assert_eq!(m8, m16, "{frame} {blob:?}");
                    let c8 = measure(&crop(&px8, width, height), blob, threshold, 20.0, margin);
                    let c16 = measure(&crop(&px16, width, height), blob, threshold, 20.0, margin);
                    assert_eq!(c8, c16, "{frame} {blob:?}");
                    // The margins as constants: the same.
                    let constant = if margin.0 == GROW {
                        measure(&whole8, blob, threshold, 20.0, DotMargin)
                    } else {
                        measure(&whole8, blob, threshold, 20.0, CodedMargin)
                    };
                    assert_eq!(constant, m8, "{frame} {blob:?}");
                    n += m8.is_some() as usize;
                    // A level below most of the ring: rings of too few
                    // dark pixels (the fallback background) too.
                    let low = Threshold::global(22);
                    let l8 = measure(&whole8, blob, low, 20.5, margin);
                    assert_eq!(l8, measure(&whole16, blob, low, 20.5, margin), "{frame}");
                    fallbacks += l8.is_some_and(|m| m.background == 20.5) as usize;
                }
            }
            assert!(n >= 10, "{frame}: {n}");
        }
        assert!(fallbacks >= 10, "{fallbacks}");
    }

    /// The spans of the conic's rows against the quadratic form at every
    /// column (two rows per call, rows without roots empty).
    #[test]
    fn conic_spans_hold_the_columns_inside() {
        let mut rng = Rng::new(12);
        for case in 0..2000 {
            let (cxx, cyy) = (rng.range(0.5, 30.0), rng.range(0.5, 30.0));
            let cxy = rng.range(-0.95, 0.95) * (cxx * cyy).sqrt();
            let det = cxx * cyy - cxy * cxy;
            let (qxx, qyy, qxy) = (cyy / (4.0 * det), cxx / (4.0 * det), -cxy / (4.0 * det));
            let q = Conic {
                qxx,
                qyy,
                qxy,
                inv_qxx: 1.0 / qxx,
                bx: rng.range(10.0, 1000.0),
            };
            let s_in = rng.range(0.5, 2.5);
            let s_out = s_in + rng.range(0.0, 1.5);
            let dy0 = rng.range(-25.0, 25.0);
            let ends = q
                .spans(f64x2::new([dy0, dy0 + 1.0]), s_in, s_out)
                .map(low_i32x2);
            for (lane, dy) in [dy0, dy0 + 1.0].into_iter().enumerate() {
                for (s, lo, hi) in [
                    (s_in, ends[0][lane], ends[1][lane]),
                    (s_out, ends[2][lane], ends[3][lane]),
                ] {
                    let c0 = q.bx as i32 - 40;
                    for col in c0..c0 + 80 {
                        let dx = col as f64 - q.bx;
                        let rho = qxx * dx * dx + 2.0 * qxy * dx * dy + qyy * dy * dy;
                        if (rho - s).abs() < 1e-9 {
                            continue;
                        }
                        assert_eq!(rho <= s, lo <= col && col <= hi, "{case} {lane} {col}");
                    }
                }
            }
        }
    }

    /// The ring's rows picked by bit masks: blocks with whole strides
    /// after them and blocks that end the data (the row by row branch),
    /// strides too short for the fast branch, against the pixels counted
    /// one at a time.
    #[test]
    fn ring_rows_are_counted_by_their_masks() {
        let mut rng = Rng::new(43);
        for case in 0..400 {
            let stride = 32 + (rng.next_u64() % 9) as usize;
            let rows = 1 + (rng.next_u64() % 32) as usize;
            let start = (rng.next_u64() % 40) as usize;
            // The last row's 32 pixels end the data, or a stride or more
            // follows.
            let tail = [0, stride - 32, stride - 31, stride + 5][case % 4];
            let len = start + (rows - 1) * stride + 32 + tail;
            let data: Vec<u8> = (0..len).map(|_| (rng.next_u64() % 256) as u8).collect();
            let masks: Vec<u64> = (0..rows)
                .map(|_| match rng.next_u64() % 4 {
                    0 => rng.next_u64() & !0xffff_ffff,
                    1 => u64::MAX,
                    _ => rng.next_u64(),
                })
                .collect();
            let mut count = [0u8; 256];
            let mut ring = Counts {
                count: &mut count,
                total: 0,
            };
            ring.add_rows(&data, start, stride, &masks);
            let total = ring.total;
            let mut want = [0u8; 256];
            let mut n = 0;
            for (i, m) in masks.iter().enumerate() {
                for b in 0..32 {
                    if m >> b & 1 == 1 {
                        let v = data[start + i * stride + b];
                        want[v as usize] = want[v as usize].wrapping_add(1);
                        n += 1;
                    }
                }
            }
            assert_eq!((count, total), (want, n), "{case}");
        }
    }

    #[test]
    fn counted_ring_has_the_sampled_percentile() {
        let mut rng = Rng::new(9);
        for case in 0..400 {
            let len = 1 + (rng.next_u64() % 255) as usize;
            let top = 1 + rng.next_u64() % 256;
            let px: Vec<u8> = (0..len).map(|_| (rng.next_u64() % top) as u8).collect();
            let wide: Vec<u16> = px
                .iter()
                .map(|&v| v as u16 * (1 + v as u16 / 200))
                .collect();
            let level = (rng.next_u64() % 256) as u32;
            let mut count = [0; 256];
            let mut counts = Counts {
                count: &mut count,
                total: 0,
            };
            let mut samples = Samples {
                buf: [0; BG_SAMPLES],
                n: 0,
                seen: 0,
                next: 0,
                stride: 1,
                threshold: Threshold::global(level),
            };
            for part in px.chunks(1 + case % 7) {
                counts.add(part);
                samples.add(part);
            }
            assert_eq!(counts.total, len);
            assert_eq!(counts.quantile(level), samples.quantile(level), "{case}");
            // 16-bit values from 255 up share the last count.
            if level < 255 {
                let mut count = [0; 256];
                let mut counts = Counts {
                    count: &mut count,
                    total: 0,
                };
                samples.n = 0;
                for part in wide.chunks(1 + case % 5) {
                    counts.add(part);
                    samples.add(part);
                }
                assert_eq!(counts.quantile(level), samples.quantile(level), "{case}");
            }
        }
    }

    /// The rows [`Window::blocks`] gives (stepped as floats, blocks of
    /// [`SPAN_BLOCK`]) against each row's spans on its own.
    #[test]
    fn blocks_give_every_row_its_spans() {
        let mut rng = Rng::new(4);
        for case in 0..200 {
            let (cxx, cyy) = (rng.range(0.5, 200.0), rng.range(0.5, 200.0));
            let cxy = rng.range(-0.9, 0.9) * (cxx * cyy).sqrt();
            let det = cxx * cyy - cxy * cxy;
            let qxx = cyy / (4.0 * det);
            let q = Conic {
                qxx,
                qyy: cxx / (4.0 * det),
                qxy: -cxy / (4.0 * det),
                inv_qxx: 1.0 / qxx,
                bx: rng.range(100.0, 140.0),
            };
            let by = rng.range(100.0, 140.0);
            let r0 = 60 + (rng.next_u64() % 20) as usize;
            let r1 = r0 + (rng.next_u64() % 70) as usize;
            let window = Window {
                q,
                by,
                s_in: 1.5,
                s_out: 2.5,
                rows: (r0, r1),
                cols: (60, 180),
                first_col: 0,
                wr: (r0 as f64 + 2.5, r1 as f64 - 2.5),
                box_cols: (70, 170),
                wrows: (r0 + 1, r1 - 1),
                wcols: (80, 160),
            };
            let mut next = r0;
            window.blocks(|first, spans| {
                assert_eq!(first, next, "{case}");
                for (row, sp) in (first..).zip(spans) {
                    let dy = row as f64 - by;
                    let [ia, ib, oa, ob] = q.spans(f64x2::splat(dy), 1.5, 2.5).map(low_i32x2);
                    let (oa, ob) = (oa[0].max(60), ob[0].min(180));
                    assert_eq!([sp[0], sp[1]], [oa, ob], "{case} {row}");
                    // The hole inside the outer span (clipped to it or not).
                    let (xa, xb) = (ia[0].max(70).max(oa), ib[0].min(170).min(ob));
                    if (r0 as f64 + 2.5..=r1 as f64 - 2.5).contains(&(row as f64)) {
                        assert_eq!(sp[2] <= sp[3], xa <= xb, "{case} {row}");
                        if xa <= xb {
                            assert_eq!([sp[2], sp[3]], [xa, xb], "{case} {row}");
                        }
                    } else {
                        assert_eq!([sp[2], sp[3]], [1, 0], "{case} {row}");
                    }
                    assert_eq!([sp[4], sp[5]], [ia[0].max(80), ib[0].min(160)]);
                }
                next = first + spans.len();
            });
            assert_eq!(next, r1 + 1, "{case}");
        }
    }

    /// The window's integer bounds against the floats they stand for.
    #[test]
    fn grown_bounds_are_the_float_ones() {
        for grow in [-3.0f64, -1.5, -0.25, 0.0, 0.5, 1.5, 2.0, 2.75, 4.0] {
            let (cg, fg) = (grow.ceil() as i64, grow.floor() as i64);
            for first in [0i64, 3] {
                for lo in first..first + 8 {
                    for hi in lo..lo + 6 {
                        let last = first + 9;
                        let (wlo, whi) = (lo as f64 - grow, hi as f64 + grow);
                        let want = [
                            wlo.ceil() as i64,
                            whi.floor() as i64,
                            wlo.max(first as f64) as i64,
                            (whi as i64).min(last),
                        ];
                        let got = grown((lo, hi), grow, (cg, fg), (first, last));
                        assert_eq!(got, want, "{grow} {first} {lo} {hi}");
                        // Rows: rounded towards 0 as `usize`.
                        assert_eq!(got[3].max(0) as usize, (whi as usize).min(last as usize));
                    }
                }
            }
        }
    }

    /// The counted percentile's parts against plain loops: the counts up
    /// to every level (the last sixteen masked) and every `k`-th value,
    /// tables sparse and full (sums up to 255).
    #[test]
    fn counted_sums_and_order_statistics_are_the_plain_ones() {
        let mut rng = Rng::new(17);
        for case in 0..300 {
            let mut count = [0u8; 256];
            let n = 1 + (rng.next_u64() % 255) as usize;
            let spread = 1 + (rng.next_u64() % 256) as usize;
            let base = (rng.next_u64() % (257 - spread as u64)) as usize;
            for _ in 0..n {
                count[base + (rng.next_u64() as usize % spread)] += 1;
            }
            for last in 0..256 {
                let want: usize = count[..=last].iter().map(|&c| c as usize).sum();
                assert_eq!(counted_up_to(&count, last) as usize, want, "{case} {last}");
            }
            for k in 0..n {
                let mut acc = 0;
                let want = (0..256)
                    .find(|&v| {
                        acc += count[v] as usize;
                        acc > k
                    })
                    .unwrap() as u32;
                assert_eq!(kth_counted(&count, k), want, "{case} {k}");
            }
        }
    }

    /// The ring's runs as floats against bit masks built one bit at a
    /// time: every run in and past the 32 lanes, empty ones too.
    #[test]
    fn run_bits_are_the_lanes() {
        for lo in -3i64..40 {
            for hi in -3i64..36 {
                if lo < 0 || hi > 32 {
                    continue;
                }
                let r = |x: i64| f64x2::splat(x as f64 + ROUND);
                let got = (run_bits(r(lo), r(hi)) + f64x2::splat(TWO_52)).to_array()[0];
                let want = (lo..hi.min(32)).fold(0u32, |m, b| m | 1 << b);
                assert_eq!(got.to_bits() as u32, want, "{lo} {hi}");
                assert_eq!(got.to_bits() >> 32, TWO_52.to_bits() >> 32, "{lo} {hi}");
            }
        }
    }

    #[test]
    fn quantile_by_counting_is_the_order_statistic() {
        // 255 values or fewer are counted in bytes; more are selected.
        let mut few: Vec<u32> = (0..255).map(|i| (i * 37 % 7) as u32).collect();
        for k in [0, 1, 77, 150, 254] {
            let mut sorted = few.clone();
            sorted.sort_unstable();
            assert_eq!(quantile(&mut few, k, 100), sorted[k]);
        }
        let mut v: Vec<u32> = (0..300).map(|i| (i * 37 % 101) as u32).collect();
        for k in [0, 1, 77, 150, 299] {
            let mut sorted = v.clone();
            sorted.sort_unstable();
            assert_eq!(quantile(&mut v, k, 100), sorted[k]);
            assert_eq!(quantile(&mut v.clone(), k, 4000), sorted[k]);
        }
    }

    #[test]
    fn ellipse_of_moments() {
        let (a, b, ang) = ellipse(9.0, 4.0, 0.0);
        assert!((a - 6.0).abs() < 1e-12 && (b - 4.0).abs() < 1e-12 && ang.abs() < 1e-12);
        let (a, b, ang) = ellipse(4.0, 9.0, 0.0);
        assert!((a - 6.0).abs() < 1e-12 && (b - 4.0).abs() < 1e-12);
        assert!((ang - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        // 45°: moments of a = 6, b = 4 rotated.
        let (l1, l2) = (9.0, 4.0);
        let (a, b, ang) = ellipse((l1 + l2) / 2.0, (l1 + l2) / 2.0, (l1 - l2) / 2.0);
        assert!((a - 6.0).abs() < 1e-12 && (b - 4.0).abs() < 1e-12);
        assert!((ang - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
    }
}
