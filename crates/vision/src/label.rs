//! Connected components by run-length labelling with union-find
//! (8-connectivity), collecting each blob's statistics in the same pass:
//! area, bounding box, grey-value sum and peak, saturated pixels, and the
//! binary first and second moments (computed in closed form per run).
//!
//! All buffers belong to [`Labeller`] and are sized once; a frame that needs
//! more runs or blobs than the capacity is reported as overflowing instead of
//! growing them. Runs, bounding boxes and moments' origins are in full-frame
//! pixel coordinates, whatever window is labelled.

use crate::pixel::{Pixel, Plane};
use crate::threshold::{LocalLevels, Threshold, TileRow};
use wide::f64x2;

/// The levels the labeller compares a row's pixels with, a block of the
/// row at a time. A row's blocks lie on a grid of 64 pixels: block `k`
/// covers the row offsets `64 k − lead .. 64 (k + 1) − lead`, clipped to
/// the row (the first one is `lead` pixels short, the last one may be
/// short too); each block lies in one tile of the local levels.
pub trait BlockLevels: Copy {
    /// How many pixels the row's first block is short of 64 (`< 64`).
    fn lead(&self) -> usize;
    /// The threshold of block `k`.
    fn block(&self, k: usize) -> Threshold;
    /// The lowest threshold of blocks `k..k + 4`.
    fn lowest4(&self, k: usize) -> Threshold;
    /// The threshold of every block of the row, if they share one.
    fn uniform(&self) -> Option<Threshold>;
}

impl BlockLevels for Threshold {
    #[inline(always)]
    fn lead(&self) -> usize {
        0
    }
    #[inline(always)]
    fn block(&self, _: usize) -> Threshold {
        *self
    }
    #[inline(always)]
    fn lowest4(&self, _: usize) -> Threshold {
        *self
    }
    #[inline(always)]
    fn uniform(&self) -> Option<Threshold> {
        Some(*self)
    }
}

impl BlockLevels for TileRow<'_> {
    #[inline(always)]
    fn lead(&self) -> usize {
        TileRow::lead(self)
    }
    #[inline(always)]
    fn block(&self, k: usize) -> Threshold {
        self.tile(k)
    }
    #[inline(always)]
    fn lowest4(&self, k: usize) -> Threshold {
        TileRow::lowest4(self, k)
    }
    #[inline(always)]
    fn uniform(&self) -> Option<Threshold> {
        TileRow::uniform(self)
    }
}

/// A horizontal run of foreground pixels.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Run {
    pub(crate) row: u32,
    pub(crate) start: u32,
    /// One past the last column.
    pub(crate) end: u32,
    pub(crate) max: u16,
    pub(crate) saturated: u16,
}

impl Run {
    /// The run `line[start..end]` of row `row` (columns `col0 + start ..
    /// col0 + end`) with its grey-value statistics; pixels at or above
    /// `saturation` count as saturated.
    #[inline]
    pub(crate) fn of<P: Pixel>(
        line: &[P],
        row: u32,
        col0: u32,
        start: usize,
        end: usize,
        saturation: u32,
    ) -> Run {
        let (max, sat) = P::run_stats(line, start, end, saturation);
        Run {
            row,
            start: col0 + start as u32,
            end: col0 + end as u32,
            max: max.min(u16::MAX as u32) as u16,
            saturated: sat.min(u16::MAX as u32) as u16,
        }
    }
}

/// Statistics of one connected component.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Blob {
    /// Pixels in the blob.
    pub area: u32,
    /// Bounding box, inclusive: first column.
    pub col0: u32,
    /// First row.
    pub row0: u32,
    /// Last column.
    pub col1: u32,
    /// Last row.
    pub row1: u32,
    /// Largest grey value.
    pub max: u32,
    /// Pixels at or above the saturation level.
    pub saturated: u32,
    /// Binary moments Σx, Σy, Σx², Σy², Σxy relative to `(origin_col, row0)`.
    pub m: [f64; 5],
    /// Higher binary moments Σx³, Σx²y, Σxy², Σy³, Σx⁴, Σx³y, Σx²y², Σxy³,
    /// Σy⁴ about the same origin (for [`Blob::kurtosis`]).
    pub m4: [f64; 9],
    /// Column of the moments' origin (the start of the blob's first run).
    pub origin_col: u32,
}

impl Blob {
    pub(crate) fn empty() -> Self {
        Blob {
            area: 0,
            col0: u32::MAX,
            row0: u32::MAX,
            col1: 0,
            row1: 0,
            max: 0,
            saturated: 0,
            m: [0.0; 5],
            m4: [0.0; 9],
            origin_col: 0,
        }
    }

    /// Adds a run's pixels to the blob's statistics (the blob's first run
    /// fixes the moments' origin; runs come in row-major order).
    #[inline(always)]
    pub(crate) fn add_run(&mut self, run: &Run) {
        if self.area == 0 {
            self.origin_col = run.start;
            self.row0 = run.row;
        }
        // The moments' origin is fixed by the blob's first run (the
        // bounding box may later extend to its left).
        let ox = self.origin_col as f64;
        let oy = self.row0 as f64;
        let n = (run.end - run.start) as f64;
        let a = run.start as f64 - ox;
        let e = run.end as f64 - ox;
        let sx = (a + e - 1.0) * n / 2.0;
        // The power sums up to the run's ends (`a`, `e` as integers).
        let origin = self.origin_col as i64;
        let (pa, pe) = (
            pow_sums(run.start as i64 - origin),
            pow_sums(run.end as i64 - origin),
        );
        let sxx = pe[0] - pa[0];
        let y = run.row as f64 - oy;
        self.m[0] += sx;
        self.m[1] += n * y;
        self.m[2] += sxx;
        self.m[3] += n * y * y;
        self.m[4] += sx * y;
        // Σx³ and Σx⁴ over the run.
        let (p3, p4) = (pe[1] - pa[1], pe[2] - pa[2]);
        let (y2, y3) = (y * y, y * y * y);
        let m4 = &mut self.m4;
        m4[0] += p3;
        m4[1] += sxx * y;
        m4[2] += sx * y2;
        m4[3] += n * y3;
        m4[4] += p4;
        m4[5] += p3 * y;
        m4[6] += sxx * y2;
        m4[7] += sx * y3;
        m4[8] += n * y3 * y;
        self.area += run.end - run.start;
        self.max = self.max.max(run.max as u32);
        self.saturated += run.saturated as u32;
        self.col0 = self.col0.min(run.start);
        self.col1 = self.col1.max(run.end - 1);
        self.row1 = self.row1.max(run.row);
    }

    /// Binary centroid `(col, row)`.
    pub fn centre(&self) -> (f64, f64) {
        let n = self.area as f64;
        (
            self.origin_col as f64 + self.m[0] / n,
            self.row0 as f64 + self.m[1] / n,
        )
    }

    /// Normalised fourth moment of the blob's pixels along its major axis
    /// (the axis of [`Blob::covariance`]), `n Σu⁴ / (Σu²)²` with `u` the
    /// offset from the centre along it: 2 for a filled ellipse, 1.8 for a
    /// bar, lower for two merged blobs, higher for a dot with a tail; 0
    /// for a blob without extent.
    pub fn kurtosis(&self) -> f64 {
        let n = self.area as f64;
        if n == 0.0 {
            return 0.0;
        }
        // Central moments from the raw ones about the origin: Σ (x + a)^p
        // (y + b)^q with a, b the centre's negated offsets, expanded. The
        // moments in x and their mirror images in y (the same formula with
        // x and y swapped) two at a time, lane for lane the same
        // operations (the same bits as one at a time; in tracking 2.99 M
        // → 2.51 M instructions).
        let [s10, s01, s20, s02, s11] = self.m;
        let [s30, s21, s12, s03, s40, s31, s22, s13, s04] = self.m4;
        let (a, b) = (-s10 / n, -s01 / n);
        let (a2, b2) = (a * a, b * b);
        let pair = |x: f64, y: f64| f64x2::new([x, y]);
        let (ab, ba, nn) = (pair(a, b), pair(b, a), f64x2::splat(n));
        let ab2 = pair(a2, b2);
        let (m10, m20, m30, m40) = (
            pair(s10, s01),
            pair(s20, s02),
            pair(s30, s03),
            pair(s40, s04),
        );
        let (m21, m31, m01) = (pair(s21, s12), pair(s31, s13), pair(s01, s10));
        let [c20, c02] = (m20 + f64x2::splat(2.0) * ab * m10 + ab2 * nn).to_array();
        let c11 = s11 + a * s01 + b * s10 + a * b * n;
        let [c40, c04] = (m40
            + f64x2::splat(4.0) * ab * m30
            + f64x2::splat(6.0) * ab2 * m20
            + f64x2::splat(4.0) * ab2 * ab * m10
            + ab2 * ab2 * nn)
            .to_array();
        let [c31, c13] = (m31
            + ba * m30
            + f64x2::splat(3.0) * ab * (m21 + ba * m20)
            + f64x2::splat(3.0) * ab2 * (f64x2::splat(s11) + ba * m10)
            + ab2 * ab * (m01 + ba * nn))
            .to_array();
        let c22 = s22
            + 2.0 * b * s21
            + b2 * s20
            + 2.0 * a * (s12 + 2.0 * b * s11 + b2 * s10)
            + a2 * (s02 + 2.0 * b * s01 + b2 * n);
        let c2 = [c20, c11, c02];
        kurtosis_along(n, major_axis(c2), c2, [c40, c31, c22, c13, c04])
    }

    /// Binary central second moments `(cxx, cyy, cxy)`, px², including the
    /// pixel's own `1/12` so that a disc of radius `r` gives about `r²/4`.
    pub fn covariance(&self) -> (f64, f64, f64) {
        let n = self.area as f64;
        let (mx, my) = (self.m[0] / n, self.m[1] / n);
        (
            self.m[2] / n - mx * mx + 1.0 / 12.0,
            self.m[3] / n - my * my + 1.0 / 12.0,
            self.m[4] / n - mx * my,
        )
    }
}

/// Half-width of the run ends [`SmallMoments`] reads from [`POW_SUMS`]: a
/// blob at most this wide, about its origin.
pub(crate) const SMALL_SIDE: usize = 64;
const _: () = assert!(SMALL_SIDE < POW_HALF);

/// A small blob's binary moments (those of [`Blob::m`] and [`Blob::m4`])
/// summed a row at a time, two at once: the fast path of blobs grown on
/// row masks (tracking windows, at most [`SMALL_SIDE`] pixels each way).
/// The moments are sums of integers: every term and every partial sum of
/// a blob of at most 64 × 64 pixels lies below 2⁵³ (Σx⁴ at most
/// 4096 · 64⁴ ≈ 6.9 · 10¹⁰), so each `f64` addition and product here and
/// in [`Blob::add_run`] is exact, and both give the same values bit for
/// bit, whatever the order (a zero is +0 in both: the sums start at +0,
/// and a difference of equal values is +0).
///
/// The rows are added from the last (highest `y`) to the first, each
/// into a cascade of running sums: level `j` sums `C(y + j, j)` times a
/// row's sums (level 0 the row's sums, each level the one below it added
/// once per row). Per row nine vector additions instead of eleven products
/// and sums with the powers of `y` (tracking: SeedLabeller::grow 28.37 M
/// → 26.03 M with the rows kept in an array); the powers of `y` are formed
/// once per blob from the
/// levels (`y = C(y+1,1) − 1`, …, exact: every value below 2⁵³, at most
/// 24 · C(67, 4) · 64² ≈ 7.5 · 10¹⁰ in magnitude).
#[derive(Debug, Clone, Copy)]
pub(crate) struct SmallMoments {
    /// Level 0: `Σ (n, s1)`, `Σ (s2, s3)`, `Σ (s4, ·)` over the rows; the
    /// levels above as far as needed (`c2[1]`'s second lane unused).
    c0: [f64x2; 3],
    c1: [f64x2; 2],
    c2: [f64x2; 2],
    c3: f64x2,
    c4: f64x2,
}

/// `(n, Σx)`, `(Σx², Σx³)`, `(Σx⁴, 0)` of the pixels of a row's runs, `x`
/// about a blob's origin column.
pub(crate) type RowSums = [f64x2; 3];

/// The power sums of [`POW_SUMS`] at the run ends of a window's columns
/// about a blob's origin ([`SmallMoments::ends`]).
pub(crate) type RunEnds = [[f64; 8]; SMALL_SIDE + 1];

impl SmallMoments {
    pub(crate) const ZERO: Self = SmallMoments {
        c0: [f64x2::ZERO; 3],
        c1: [f64x2::ZERO; 2],
        c2: [f64x2::ZERO; 2],
        c3: f64x2::ZERO,
        c4: f64x2::ZERO,
    };

    /// The table of [`SmallMoments::run`] for a blob whose origin is
    /// column `origin` of its window (at most `SMALL_SIDE`): entry `x` the
    /// power sums below `x − origin`. Why: formed once per blob, a run's
    /// ends index it as the window's columns (no subtraction of the
    /// origin per end, no bounds check per run).
    #[inline(always)]
    pub(crate) fn ends(origin: usize) -> &'static RunEnds {
        debug_assert!(origin <= SMALL_SIDE);
        let first = POW_HALF - origin.min(SMALL_SIDE);
        match POW_SUMS[first..first + SMALL_SIDE + 1].try_into() {
            Ok(t) => t,
            Err(_) => unreachable!("SMALL_SIDE + 1 entries"),
        }
    }

    /// The sums of the run of window columns `a..e` (`a < e ≤
    /// SMALL_SIDE`) alone, about the origin of `ends`
    /// ([`SmallMoments::ends`]; never −0: a difference of exact integers).
    #[inline(always)]
    pub(crate) fn run(ends: &RunEnds, a: usize, e: usize) -> RowSums {
        let (pa, pe) = (&ends[a], &ends[e]);
        [0, 1, 2].map(|k| {
            f64x2::new([pe[2 * k], pe[2 * k + 1]]) - f64x2::new([pa[2 * k], pa[2 * k + 1]])
        })
    }

    /// Adds the run of window columns `a..e` (as [`SmallMoments::run`])
    /// to a row's sums.
    #[inline(always)]
    pub(crate) fn add_run(row: &mut RowSums, ends: &RunEnds, a: usize, e: usize) {
        for (sum, v) in row.iter_mut().zip(Self::run(ends, a, e)) {
            *sum += v;
        }
    }

    /// Adds a row's sums: the rows from the last to the first (`y` from
    /// the highest down to 0, each row once, no row skipped).
    #[inline(always)]
    pub(crate) fn add_row_up(&mut self, r: &RowSums) {
        for (q, &v) in self.c0.iter_mut().zip(r) {
            *q += v;
        }
        for (q1, &q0) in self.c1.iter_mut().zip(&self.c0) {
            *q1 += q0;
        }
        for (q2, &q1) in self.c2.iter_mut().zip(&self.c1) {
            *q2 += q1;
        }
        self.c3 += self.c2[0];
        self.c4 += self.c3;
    }

    /// The pixels summed: [`Blob::area`] (an exact integer).
    #[inline(always)]
    pub(crate) fn area(&self) -> u32 {
        self.c0[0].to_array()[0] as u32
    }

    /// The moments as [`Blob::m`] and [`Blob::m4`].
    #[inline]
    pub(crate) fn to_blob_moments(self) -> ([f64; 5], [f64; 9]) {
        let k = f64x2::splat;
        let [c0, c1, c2, c3, c4] = [self.c0[0], self.c1[0], self.c2[0], self.c3, self.c4];
        // Σ v·y, Σ v·y², Σ v·y³, Σ v·y⁴ (v = (n, s1)) from the levels.
        let q1 = c1 - c0;
        let q2 = k(2.0) * c2 - k(3.0) * c1 + c0;
        let q3 = k(6.0) * c3 - k(12.0) * c2 + k(7.0) * c1 - c0;
        let q4 = k(24.0) * c4 - k(60.0) * c3 + k(50.0) * c2 - k(15.0) * c1 + c0;
        // The same for v = (s2, s3) (y, y²).
        let p1 = self.c1[1] - self.c0[1];
        let p2 = k(2.0) * self.c2[1] - k(3.0) * self.c1[1] + self.c0[1];
        let [_, s10] = c0.to_array();
        let [s20, s30] = self.c0[1].to_array();
        let [s40, _] = self.c0[2].to_array();
        let [s01, s11] = q1.to_array();
        let [s21, s31] = p1.to_array();
        let [s02, s12] = q2.to_array();
        let [s22, _] = p2.to_array();
        let [s03, s13] = q3.to_array();
        let [s04, _] = q4.to_array();
        (
            [s10, s01, s20, s02, s11],
            [s30, s21, s12, s03, s40, s31, s22, s13, s04],
        )
    }
}

/// Outcome of labelling a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LabelOutcome {
    /// All runs and blobs fitted.
    Complete,
    /// More runs than the capacity.
    TooManyRuns,
    /// More blobs than the capacity.
    TooManyBlobs,
}

/// Run-length labeller with its buffers.
#[derive(Debug)]
pub struct Labeller {
    runs: Vec<Run>,
    parent: Vec<u32>,
    blobs: Vec<Blob>,
    max_runs: usize,
    max_blobs: usize,
}

/// The root of run `i` (path halving). Every run's parent is itself or
/// an older run (here and in [`union`]), which resolving relies on.
#[inline(always)]
fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let p = parent[i as usize];
        parent[i as usize] = parent[p as usize];
        i = p;
    }
    i
}

#[inline(always)]
fn union(parent: &mut [u32], a: u32, b: u32) {
    let ra = find(parent, a);
    let rb = find(parent, b);
    if ra != rb {
        // Keep the older run as root (stable, and roots come first).
        if ra < rb {
            parent[rb as usize] = ra;
        } else {
            parent[ra as usize] = rb;
        }
    }
}

/// `Σ_{x=0}^{k-1} x²`.
#[inline]
const fn sum_sq_below(k: f64) -> f64 {
    (k - 1.0) * k * (2.0 * k - 1.0) / 6.0
}

/// `Σ_{x=0}^{k-1} x³` (for negative `k` too: the polynomial telescopes).
#[inline]
const fn sum_pow3_below(k: f64) -> f64 {
    let h = (k - 1.0) * k / 2.0;
    h * h
}

/// `Σ_{x=0}^{k-1} x⁴` (for negative `k` too).
#[inline]
const fn sum_pow4_below(k: f64) -> f64 {
    let m = k - 1.0;
    m * (m + 1.0) * (2.0 * m + 1.0) * (3.0 * m * m + 3.0 * m - 1.0) / 30.0
}

/// [`POW_SUMS`] holds `k` from `−POW_HALF` to `POW_HALF − 1`.
const POW_HALF: usize = 128;
const _: () = assert!(2 * POW_HALF == 256);

/// `[k, Σx, Σx², Σx³, Σx⁴, 0, 0, 0]` for `x` from 0 below `k` (for negative `k`
/// the negated sums of `k..0`, which the polynomials give: the difference
/// of the entries at a run's ends is the run's sums) near a blob's origin,
/// entry `k + POW_HALF`: exact integers, evaluated at compile time (IEEE
/// arithmetic, the same operations: the same values bit for bit), so that
/// a run costs two look-ups instead of the polynomials. Read in pairs by
/// [`SmallMoments`] (a zero pads the third pair; an entry is 64 bytes, so
/// that its index is a shift).
static POW_SUMS: [[f64; 8]; 2 * POW_HALF] = {
    let mut t = [[0.0; 8]; 2 * POW_HALF];
    let mut i = 0;
    while i < 2 * POW_HALF {
        let k = i as f64 - POW_HALF as f64;
        t[i] = [
            k,
            k * (k - 1.0) / 2.0,
            sum_sq_below(k),
            sum_pow3_below(k),
            sum_pow4_below(k),
            0.0,
            0.0,
            0.0,
        ];
        i += 1;
    }
    t
};

/// `[Σx², Σx³, Σx⁴]` for `x` below `k` (from [`POW_SUMS`] near 0).
#[inline(always)]
fn pow_sums(k: i64) -> [f64; 3] {
    match POW_SUMS.get(k.wrapping_add(POW_HALF as i64) as usize) {
        Some(s) => [s[2], s[3], s[4]],
        None => {
            let k = k as f64;
            [sum_sq_below(k), sum_pow3_below(k), sum_pow4_below(k)]
        }
    }
}

/// The foreground mask of the block `line[base..base + n]` (`n ≤ 64`) at
/// `threshold`. A block shorter than 64 pixels (at a row's ends) is read
/// as the 64 pixels that start at it, or else end with it, when the row
/// has them (the vector path, not one pixel at a time), and the bits of
/// the other pixels dropped.
#[inline(always)]
fn block_mask<P: Pixel>(line: &[P], base: usize, n: usize, threshold: Threshold) -> u64 {
    let width = line.len();
    if n == 64 || width < 64 {
        threshold.foreground_mask(&line[base..base + n])
    } else if base + 64 <= width {
        threshold.foreground_mask(&line[base..base + 64]) & ((1u64 << n) - 1)
    } else {
        threshold.foreground_mask(&line[width - 64..]) >> (64 - n)
    }
}

/// Which of the blocks `first..last` (at most 64) of a row hold
/// foreground (bit `k − first` for block `k`; blocks as in
/// [`BlockLevels`]). Four whole blocks at a time are tested against the
/// lowest of their levels ([`Pixel::lit_quarters`]): a stretch of four
/// dark blocks (most of a frame) costs one test, and a block dark at the
/// lowest of the levels is dark at its own. The other blocks (a short
/// one at either end of the row, whole ones short of four at its end)
/// one at a time.
#[inline(always)]
fn lit_blocks<P: Pixel, L: BlockLevels>(line: &[P], levels: L, first: usize, last: usize) -> u64 {
    let (width, lead) = (line.len(), levels.lead());
    debug_assert!(first < last && last - first <= 64);
    // Block `k` starts at `base` and sets bit `bit`.
    let (mut lit, mut k, mut bit) = (0u64, first, 0);
    let mut base = (64 * k).saturating_sub(lead);
    if k == 0 && lead > 0 {
        let end = (64 - lead).min(width);
        lit = (block_mask(line, 0, end, levels.block(0)) != 0) as u64;
        (k, base, bit) = (1, end, 1);
    }
    // Whole blocks from `k` on, four at a time while four end inside the
    // row and among the blocks asked for.
    let stretches = (last - k) / 4;
    for stretch in line[base..].chunks_exact(256).take(stretches) {
        let Ok(stretch) = <&[P; 256]>::try_from(stretch) else {
            unreachable!("256 pixels")
        };
        lit |= (P::lit_quarters(stretch, levels.lowest4(k)) as u64) << bit;
        (k, base, bit) = (k + 4, base + 256, bit + 4);
    }
    while k < last {
        let end = (base + 64).min(width);
        lit |= ((block_mask(line, base, end - base, levels.block(k)) != 0) as u64) << bit;
        (k, base, bit) = (k + 1, end, bit + 1);
    }
    lit
}

impl Labeller {
    /// A labeller for at most `max_runs` runs and `max_blobs` blobs per frame.
    pub fn new(max_runs: usize, max_blobs: usize) -> Self {
        Labeller {
            runs: Vec::with_capacity(max_runs),
            parent: Vec::with_capacity(max_runs),
            blobs: Vec::with_capacity(max_blobs),
            max_runs,
            max_blobs,
        }
    }

    /// The blobs of the last frame.
    pub fn blobs(&self) -> &[Blob] {
        &self.blobs
    }

    /// Labels the foreground pixels of the window `plane`; pixels at or
    /// above `saturation` count as saturated.
    pub fn label<P: Pixel>(
        &mut self,
        plane: &Plane<'_, P>,
        threshold: Threshold,
        saturation: u32,
    ) -> LabelOutcome {
        self.label_rows(plane, |_| threshold, saturation)
    }

    /// [`Labeller::label`] with a level per tile ([`LocalLevels`] laid out
    /// for this window).
    pub fn label_local<P: Pixel>(
        &mut self,
        plane: &Plane<'_, P>,
        levels: &LocalLevels,
        saturation: u32,
    ) -> LabelOutcome {
        self.label_rows(plane, |row| levels.row(plane, row), saturation)
    }

    fn label_rows<P: Pixel, L: BlockLevels>(
        &mut self,
        plane: &Plane<'_, P>,
        levels_of: impl Fn(usize) -> L,
        saturation: u32,
    ) -> LabelOutcome {
        self.runs.clear();
        self.parent.clear();
        self.blobs.clear();
        let mut prev_start = 0usize; // runs of the previous row: prev_start..row_start
        let mut prev_end = 0usize;
        let col0 = plane.col0 as u32;
        for row in plane.row0..=plane.last_row() {
            let line = plane.row(row);
            let row_start = self.runs.len();
            // A row whose blocks share one level is labelled as with one
            // level for the frame (the same runs: blocks serve only to
            // skip the dark ones), without a level per block.
            let levels = levels_of(row);
            let complete = match levels.uniform() {
                Some(t) => self.extract_runs(line, row as u32, col0, t, saturation),
                None => self.extract_runs(line, row as u32, col0, levels, saturation),
            };
            if !complete {
                return LabelOutcome::TooManyRuns;
            }
            let row_end = self.runs.len();
            // Connect with the previous row (8-connectivity: overlap or touch diagonally).
            if prev_end > prev_start && row_end > row_start {
                let (prev, cur) = self.runs[prev_start..row_end].split_at(row_start - prev_start);
                let (mut i, mut j) = (0, 0);
                while let (Some(a), Some(b)) = (prev.get(i), cur.get(j)) {
                    if a.start <= b.end && b.start <= a.end {
                        union(
                            &mut self.parent,
                            (prev_start + i) as u32,
                            (row_start + j) as u32,
                        );
                    }
                    // Advance the run that ends first.
                    if a.end < b.end {
                        i += 1;
                    } else {
                        j += 1;
                    }
                }
            }
            prev_start = row_start;
            prev_end = row_end;
        }
        // Resolve labels and accumulate statistics. A run's parent is
        // itself (the first run of its component) or an older run of the
        // same component (union and find only ever point to older runs),
        // whose entry already holds its blob: so blob indices replace the
        // parents in one pass, with no find.
        // (The buffers taken apart first: a blob's statistics are not
        // seen to move the buffers, which stay in registers.)
        let (runs, parent, blobs) = (&self.runs[..], &mut self.parent[..], &mut self.blobs);
        for (k, run) in runs.iter().enumerate() {
            let p = parent[k] as usize;
            let b = if p == k {
                if blobs.len() >= self.max_blobs {
                    return LabelOutcome::TooManyBlobs;
                }
                blobs.push(Blob::empty());
                blobs.len() - 1
            } else {
                parent[p] as usize
            };
            parent[k] = b as u32;
            blobs[b].add_run(run);
        }
        LabelOutcome::Complete
    }

    /// Appends the runs of one row of a window whose first column is
    /// `col0`; false if the capacity is exceeded. The row's blocks (64
    /// pixels, [`BlockLevels`]) that hold foreground are found first, up
    /// to 64 blocks at a time ([`lit_blocks`]); only those are turned into
    /// bit masks of their foreground pixels (16 at a time for 8-bit
    /// frames), and runs are the masks' stretches of ones. A run still
    /// open at the end of a block ends there unless the next block holds
    /// foreground (a dark block's first pixel is background).
    #[inline(always)]
    fn extract_runs<P: Pixel, L: BlockLevels>(
        &mut self,
        line: &[P],
        row: u32,
        col0: u32,
        levels: L,
        saturation: u32,
    ) -> bool {
        const NONE: usize = usize::MAX;
        let (width, lead) = (line.len(), levels.lead());
        let blocks = (width + lead).div_ceil(64);
        let mut open = NONE;
        // The end of the last block that held foreground.
        let mut lit_end = 0;
        let mut first = 0;
        while first < blocks {
            let last = blocks.min(first + 64);
            let mut lit = lit_blocks(line, levels, first, last);
            while lit != 0 {
                let k = first + lit.trailing_zeros() as usize;
                lit &= lit - 1;
                let base = (64 * k).saturating_sub(lead);
                let end = (64 * k + 64 - lead).min(width);
                if open != NONE && base != lit_end {
                    if !self.push_run(line, row, col0, open, lit_end, saturation) {
                        return false;
                    }
                    open = NONE;
                }
                lit_end = end;
                let n = end - base;
                let m = match <&[P; 64]>::try_from(&line[base..end]) {
                    // A block known to hold foreground: no dark test.
                    Ok(block) => P::lit_mask(block, levels.block(k)),
                    Err(_) => block_mask(line, base, n, levels.block(k)),
                };
                let valid = u64::MAX >> (64 - n);
                let mut pos = 0u32;
                loop {
                    if open == NONE {
                        let lit = m & (u64::MAX << pos);
                        if lit == 0 {
                            break;
                        }
                        pos = lit.trailing_zeros();
                        open = base + pos as usize;
                    } else {
                        let dark = !m & valid & (u64::MAX << pos);
                        if dark == 0 {
                            break;
                        }
                        pos = dark.trailing_zeros();
                        let end = base + pos as usize;
                        if !self.push_run(line, row, col0, open, end, saturation) {
                            return false;
                        }
                        open = NONE;
                    }
                }
            }
            first = last;
        }
        if open != NONE && !self.push_run(line, row, col0, open, lit_end, saturation) {
            return false;
        }
        true
    }

    /// Appends the run `line[start..end]` (columns `col0 + start ..
    /// col0 + end`); false if the capacity is exceeded.
    #[inline]
    fn push_run<P: Pixel>(
        &mut self,
        line: &[P],
        row: u32,
        col0: u32,
        start: usize,
        end: usize,
        saturation: u32,
    ) -> bool {
        if self.runs.len() >= self.max_runs {
            return false;
        }
        // Each run its own root until connected.
        self.parent.push(self.runs.len() as u32);
        self.runs
            .push(Run::of(line, row, col0, start, end, saturation));
        true
    }
}

/// The direction of the major axis of central second moments `[c20,
/// c11, c02]` as the products `[ux², ux·uy, uy²]` of a vector along it,
/// scaled by an arbitrary positive factor (here `2r`, with `r` the
/// difference of the two principal moments): `[r + t, 2 c11, r − t]` with
/// `t = c20 − c02`; `[1, 0, 0]` for a round blob. Why: the fourth moment
/// is a ratio of forms of degree 2 and 4 in `u`, so the scale cancels, and
/// the products need one square root where the unit vector took three and
/// two divisions (a chain of about 80 cycles per target that the blob's
/// measurement waited for).
#[inline(always)]
fn major_axis([c20, c11, c02]: [f64; 3]) -> [f64; 3] {
    let (t, t2) = (c20 - c02, 2.0 * c11);
    let r = (t * t + t2 * t2).sqrt();
    if r > 0.0 {
        [r + t, t2, r - t]
    } else {
        [1.0, 0.0, 0.0]
    }
}

/// `n Σu⁴ / (Σu²)²` along the direction `[ux², ux·uy, uy²]` (any scale)
/// of the central moments `c2 = [c20, c11, c02]`, `c4 = [c40, c31, c22,
/// c13, c04]` of `n` pixels; 0 for a blob without extent along it.
fn kurtosis_along(n: f64, [xx, xy, yy]: [f64; 3], c2: [f64; 3], c4: [f64; 5]) -> f64 {
    let ([c20, c11, c02], [c40, c31, c22, c13, c04]) = (c2, c4);
    let su2 = xx * c20 + 2.0 * xy * c11 + yy * c02;
    let su4 = xx * xx * c40
        + 4.0 * xx * xy * c31
        + 6.0 * xx * yy * c22
        + 4.0 * yy * xy * c13
        + yy * yy * c04;
    if su2 > 0.0 {
        n * su4 / (su2 * su2)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::window;

    fn label(img: &[&str]) -> Vec<Blob> {
        let h = img.len();
        let w = img[0].len();
        let data: Vec<u8> = img
            .iter()
            .flat_map(|r| r.bytes().map(|b| if b == b'#' { 200 } else { 0 }))
            .collect();
        let mut l = Labeller::new(1000, 100);
        let plane = Plane::whole(&data, w, h);
        assert_eq!(
            l.label(&plane, Threshold::global(100), 255),
            LabelOutcome::Complete
        );
        l.blobs().to_vec()
    }

    #[test]
    fn components_with_8_connectivity() {
        let b = label(&[
            "##....#.", //
            ".#...#..", //
            "........", //
            "#......#", //
            "##....##", //
            "#.#..#..", //
        ]);
        assert_eq!(b.len(), 4, "{b:?}");
        assert_eq!(b[0].area, 3);
        assert_eq!(b[1].area, 2); // diagonal pair top right
        assert_eq!(b[2].area, 5);
        assert_eq!((b[2].col0, b[2].row0, b[2].col1, b[2].row1), (0, 3, 2, 5));
        assert_eq!(b[3].area, 4);
    }

    #[test]
    fn u_shape_merges_and_moments_are_exact() {
        let b = label(&[
            "#...#", //
            "#...#", //
            "#####", //
        ]);
        assert_eq!(b.len(), 1);
        let (cx, cy) = b[0].centre();
        // Pixels: (0,0),(4,0),(0,1),(4,1),(0..=4,2): Σx = 0+4+0+4+10 = 18, n = 9.
        assert!((cx - 2.0).abs() < 1e-12, "{cx}");
        assert!(
            (cy - (0.0 + 0.0 + 1.0 + 1.0 + 10.0) / 9.0).abs() < 1e-12,
            "{cy}"
        );
        let (cxx, _, _) = b[0].covariance();
        let want = (0.0 + 16.0 + 0.0 + 16.0 + 30.0) / 9.0 - 4.0 + 1.0 / 12.0;
        assert!((cxx - want).abs() < 1e-12);
    }

    /// `n Σu⁴ / (Σu²)²` of the pixels of a mask, straight from its pixels,
    /// along the major axis of `(cxx, cyy, cxy)` (the blob's: a disc's
    /// axis is an accident of rounding).
    fn kurtosis_of(pixels: &[(f64, f64)], (cxx, cyy, cxy): (f64, f64, f64)) -> f64 {
        let n = pixels.len() as f64;
        let (mx, my) = pixels
            .iter()
            .fold((0.0, 0.0), |(a, b), &(x, y)| (a + x / n, b + y / n));
        let theta = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
        let (ux, uy) = (theta.cos(), theta.sin());
        let (mut s2, mut s4) = (0.0, 0.0);
        for &(x, y) in pixels {
            let u = ux * (x - mx) + uy * (y - my);
            s2 += u * u;
            s4 += u * u * u * u;
        }
        n * s4 / (s2 * s2)
    }

    #[test]
    fn kurtosis_is_that_of_the_pixels_and_tells_shapes_apart() {
        // A filled disc (r = 6), a bar, two touching discs, a tilted
        // ellipse with a tail: the closed form against the pixels.
        let shapes: [&dyn Fn(f64, f64) -> bool; 4] = [
            &|x, y| (x - 10.0).powi(2) + (y - 9.0).powi(2) <= 36.0,
            &|x, y| (3.0..=17.0).contains(&x) && (7.0..=9.0).contains(&y),
            &|x, y| {
                (x - 6.0).powi(2) + (y - 9.0).powi(2) <= 12.0
                    || (x - 13.0).powi(2) + (y - 9.0).powi(2) <= 12.0
            },
            &|x, y| {
                let (u, v) = (
                    0.8 * (x - 9.0) + 0.6 * (y - 9.0),
                    -0.6 * (x - 9.0) + 0.8 * (y - 9.0),
                );
                (u / 7.0).powi(2) + (v / 3.5).powi(2) <= 1.0
                    || (u > 0.0 && u < 9.5 && v.abs() < 1.0)
            },
        ];
        let mut got = Vec::new();
        for inside in shapes {
            let (w, h) = (22usize, 19usize);
            let mut data = vec![0u8; w * h];
            let mut pixels = Vec::new();
            for y in 0..h {
                for x in 0..w {
                    if inside(x as f64, y as f64) {
                        data[y * w + x] = 200;
                        pixels.push((x as f64, y as f64));
                    }
                }
            }
            let mut l = Labeller::new(1000, 10);
            let plane = Plane::whole(&data, w, h);
            assert_eq!(
                l.label(&plane, Threshold::global(100), 255),
                LabelOutcome::Complete
            );
            assert_eq!(l.blobs().len(), 1);
            let k = l.blobs()[0].kurtosis();
            let want = kurtosis_of(&pixels, l.blobs()[0].covariance());
            assert!((k - want).abs() < 1e-9, "{k} against {want}");
            got.push(k);
        }
        assert!((got[0] - 2.0).abs() < 0.05, "disc {}", got[0]);
        assert!((got[1] - 1.8).abs() < 0.05, "bar {}", got[1]);
        assert!(got[2] < 1.75, "two discs {}", got[2]);
        assert!(got[3] > 2.1, "a dot with a tail {}", got[3]);
    }

    /// [`Blob::kurtosis`] with its central moments one at a time (the
    /// form the paired one replaced) and the unit vector along the major
    /// axis (the half angle of `(cxx − cyy, 2 cxy)` of the covariance, the
    /// form [`major_axis`]'s scaled products replaced).
    fn kurtosis_one_at_a_time(blob: &Blob) -> f64 {
        let n = blob.area as f64;
        let (cxx, cyy, cxy) = blob.covariance();
        let (t, t2) = (cxx - cyy, 2.0 * cxy);
        let r = (t * t + t2 * t2).sqrt();
        let (ux, uy) = if r > 0.0 {
            let c2 = t / r;
            (
                ((1.0 + c2) / 2.0).max(0.0).sqrt(),
                ((1.0 - c2) / 2.0).max(0.0).sqrt().copysign(t2),
            )
        } else {
            (1.0, 0.0)
        };
        let [s10, s01, s20, s02, s11] = blob.m;
        let [s30, s21, s12, s03, s40, s31, s22, s13, s04] = blob.m4;
        let (a, b) = (-s10 / n, -s01 / n);
        let (a2, b2) = (a * a, b * b);
        let c20 = s20 + 2.0 * a * s10 + a2 * n;
        let c02 = s02 + 2.0 * b * s01 + b2 * n;
        let c11 = s11 + a * s01 + b * s10 + a * b * n;
        let c40 = s40 + 4.0 * a * s30 + 6.0 * a2 * s20 + 4.0 * a2 * a * s10 + a2 * a2 * n;
        let c04 = s04 + 4.0 * b * s03 + 6.0 * b2 * s02 + 4.0 * b2 * b * s01 + b2 * b2 * n;
        let c31 = s31
            + b * s30
            + 3.0 * a * (s21 + b * s20)
            + 3.0 * a2 * (s11 + b * s10)
            + a2 * a * (s01 + b * n);
        let c13 = s13
            + a * s03
            + 3.0 * b * (s12 + a * s02)
            + 3.0 * b2 * (s11 + a * s01)
            + b2 * b * (s10 + a * n);
        let c22 = s22
            + 2.0 * b * s21
            + b2 * s20
            + 2.0 * a * (s12 + 2.0 * b * s11 + b2 * s10)
            + a2 * (s02 + 2.0 * b * s01 + b2 * n);
        let dir = [ux * ux, ux * uy, uy * uy];
        kurtosis_along(n, dir, [c20, c11, c02], [c40, c31, c22, c13, c04])
    }

    /// The paired central moments and the scaled axis give the kurtosis of
    /// one at a time with the unit axis (to rounding), on the blobs of
    /// random frames (every shape, orientation and offset from the
    /// moments' origin).
    #[test]
    fn kurtosis_in_pairs_is_the_one_at_a_time() {
        use crate::testutil::Rng;
        let mut rng = Rng::new(17);
        let (w, h) = (120usize, 90usize);
        let mut checked = 0;
        for _ in 0..20 {
            let mut data = vec![0u8; w * h];
            for _ in 0..40 {
                let (c, r) = (
                    (rng.next_u64() % w as u64) as usize,
                    (rng.next_u64() % h as u64) as usize,
                );
                let (rw, rh) = (1 + rng.next_u64() % 12, 1 + rng.next_u64() % 12);
                let skew = (rng.next_u64() % 5) as usize;
                for y in r..(r + rh as usize).min(h) {
                    for x in (c + (y - r) * skew / 4)..(c + (y - r) * skew / 4 + rw as usize).min(w)
                    {
                        data[y * w + x] = 200;
                    }
                }
            }
            let mut l = Labeller::new(100_000, 10_000);
            let plane = Plane::whole(&data, w, h);
            assert_eq!(
                l.label(&plane, Threshold::global(100), 255),
                LabelOutcome::Complete
            );
            for b in l.blobs() {
                let (got, want) = (b.kurtosis(), kurtosis_one_at_a_time(b));
                assert!(
                    (got - want).abs() <= 1e-9 * want.abs(),
                    "{got} {want} {b:?}"
                );
                checked += 1;
            }
        }
        assert!(checked > 200, "{checked}");
    }

    /// The plain labelling: each pixel against its own level, runs read
    /// one pixel at a time, components by flood fill (8-connectivity),
    /// blobs in the order of their first pixel, their statistics added
    /// run by run in raster order.
    fn plain<P: Pixel>(
        plane: &Plane<'_, P>,
        level: impl Fn(usize, usize) -> u32,
        saturation: u32,
    ) -> (Vec<Run>, Vec<Blob>) {
        let (w, h) = (plane.width, plane.height);
        let fg = |c: usize, r: usize| {
            let (col, row) = (plane.col0 + c, plane.row0 + r);
            plane.row(row)[c].value() > level(col, row)
        };
        let mut runs = Vec::new();
        for r in 0..h {
            let mut c = 0;
            while c < w {
                if !fg(c, r) {
                    c += 1;
                    continue;
                }
                let s = c;
                while c < w && fg(c, r) {
                    c += 1;
                }
                let px = &plane.row(plane.row0 + r)[s..c];
                let max = px.iter().map(|p| p.value()).max().unwrap_or(0);
                let sat = px.iter().filter(|p| p.value() >= saturation).count();
                runs.push(Run {
                    row: (plane.row0 + r) as u32,
                    start: (plane.col0 + s) as u32,
                    end: (plane.col0 + c) as u32,
                    max: max.min(u16::MAX as u32) as u16,
                    saturated: sat.min(u16::MAX as usize) as u16,
                });
            }
        }
        let mut label = vec![usize::MAX; w * h];
        let mut n = 0;
        for start in 0..w * h {
            if label[start] != usize::MAX || !fg(start % w, start / w) {
                continue;
            }
            let mut stack = vec![start];
            label[start] = n;
            while let Some(i) = stack.pop() {
                let (c, r) = ((i % w) as isize, (i / w) as isize);
                for (dc, dr) in [
                    (-1, -1),
                    (0, -1),
                    (1, -1),
                    (-1, 0),
                    (1, 0),
                    (-1, 1),
                    (0, 1),
                    (1, 1),
                ] {
                    let (cc, rr) = (c + dc, r + dr);
                    if cc < 0 || rr < 0 || cc >= w as isize || rr >= h as isize {
                        continue;
                    }
                    let j = rr as usize * w + cc as usize;
                    if label[j] == usize::MAX && fg(cc as usize, rr as usize) {
                        label[j] = n;
                        stack.push(j);
                    }
                }
            }
            n += 1;
        }
        let mut blobs = vec![Blob::empty(); n];
        for run in &runs {
            let (c, r) = (
                run.start as usize - plane.col0,
                run.row as usize - plane.row0,
            );
            blobs[label[r * w + c]].add_run(run);
        }
        (runs, blobs)
    }

    fn same_runs(a: &[Run], b: &[Run]) -> bool {
        a.len() == b.len()
            && a.iter().zip(b).all(|(x, y)| {
                (x.row, x.start, x.end, x.max, x.saturated)
                    == (y.row, y.start, y.end, y.max, y.saturated)
            })
    }

    /// The labeller on the window `win` of a frame `fw` pixels wide, with
    /// one random level and with random levels per tile, against the
    /// plain labelling: the same runs, the same blobs in the same order.
    fn check_against_plain<P: Pixel>(
        data: &[P],
        fw: usize,
        win: (usize, usize, usize, usize),
        rng: &mut crate::testutil::Rng,
        top: u32,
    ) {
        let plane = window(data, fw, win);
        let sat = top - (rng.next_u64() % 3) as u32;
        let global = (rng.next_u64() % (top as u64 / 2)) as u32 + top / 4;
        let fh = data.len() / fw;
        // Levels per tile, every second row of tiles at one level (the
        // labeller takes such rows as with one level for the frame).
        let mut level = || global - (rng.next_u64() % (top as u64 / 4)) as u32;
        let mut tiles = vec![vec![0u32; fh.div_ceil(64)]; fw.div_ceil(64)];
        for tr in 0..fh.div_ceil(64) {
            let one = (tr % 2 == 1).then(&mut level);
            for column in tiles.iter_mut() {
                column[tr] = one.unwrap_or_else(&mut level);
            }
        }
        let mut l = Labeller::new(100_000, 100_000);
        assert_eq!(
            l.label(&plane, Threshold::global(global), sat),
            LabelOutcome::Complete
        );
        let (runs, blobs) = plain(&plane, |_, _| global, sat);
        assert!(same_runs(&l.runs, &runs), "{win:?}");
        assert_eq!(l.blobs(), &blobs[..], "{win:?}");
        let mut levels = LocalLevels::new(fw, fh);
        levels.set_each(&plane, |tc, tr| tiles[tc][tr]);
        let level = |c: usize, r: usize| tiles[c / 64][r / 64];
        assert_eq!(l.label_local(&plane, &levels, sat), LabelOutcome::Complete);
        let (runs, blobs) = plain(&plane, level, sat);
        assert!(same_runs(&l.runs, &runs), "{win:?}");
        assert_eq!(l.blobs(), &blobs[..], "{win:?}");
    }

    /// Rows of more than 64 blocks (4096 pixels) are taken 64 blocks at a
    /// time: runs across the edge between two such groups, and a dark
    /// group between lit ones, give the plain labelling's runs and blobs.
    #[test]
    fn rows_of_more_than_64_blocks_equal_the_plain_labelling() {
        use crate::testutil::Rng;
        let mut rng = Rng::new(9);
        let (fw, fh) = (8400usize, 5usize);
        for round in 0..4 {
            let mut v: Vec<u32> = (0..fw * fh).map(|_| (rng.next_u64() % 40) as u32).collect();
            for (r, a, b) in [
                (0, 4000, 4200),
                (1, 4050, 4060),
                (1, 4090, 4135),
                (2, 4130, 4140),
                (3, 8100, 8300),
                (4, 0, 70),
                (4, 8350, 8400),
            ] {
                for x in &mut v[r * fw + a..r * fw + b] {
                    *x = 100 + (rng.next_u64() % 156) as u32;
                }
            }
            for _ in 0..200 {
                let i = (rng.next_u64() % (fw * fh) as u64) as usize;
                v[i] = 255;
            }
            let win = [
                (0, 0, fw, fh),
                (37, 1, fw - 37, 4),
                (5, 0, 8200, 5),
                (64, 0, 4200, 5),
            ][round];
            let d8: Vec<u8> = v.iter().map(|&x| x as u8).collect();
            check_against_plain(&d8, fw, win, &mut rng, 255);
            let d16: Vec<u16> = v.iter().map(|&x| (x * 257) as u16).collect();
            check_against_plain(&d16, fw, win, &mut rng, 65535);
        }
    }

    /// The labeller (dark stretches, masks, partial blocks at both ends of
    /// a row, known-dark blocks) equals the plain labelling on random
    /// frames: 8 and 16 bits, one level and a level per tile, whole frames
    /// and windows at odd origins, runs across block edges and through
    /// the last pixel of a row, sparse and dense foreground.
    #[test]
    fn equals_the_plain_labelling_on_random_frames() {
        use crate::testutil::Rng;
        let mut rng = Rng::new(5);
        let (fw, fh) = (333usize, 90usize);
        for round in 0..24 {
            // Background noise, dots, and bright columns at the edges of blocks.
            let density = [0.0005, 0.003, 0.02][round % 3];
            let mut v = vec![0u32; fw * fh];
            for x in v.iter_mut() {
                *x = (rng.next_u64() % 40) as u32;
            }
            for _ in 0..(density * (fw * fh) as f64) as usize {
                let (c, r) = (
                    (rng.next_u64() % fw as u64) as usize,
                    (rng.next_u64() % fh as u64) as usize,
                );
                let len = 1 + (rng.next_u64() % 9) as usize;
                for k in 0..len.min(fw - c) {
                    for rr in r..(r + 1 + (rng.next_u64() % 3) as usize).min(fh) {
                        v[rr * fw + c + k] = 100 + (rng.next_u64() % 156) as u32;
                    }
                }
            }
            for &c in &[0usize, 63, 64, 127, 128, 255, 256, 320, 331, 332] {
                let r = (rng.next_u64() % fh as u64) as usize;
                for rr in r..(r + 4).min(fh) {
                    v[rr * fw + c] = 255;
                }
            }
            let win = [
                (0, 0, fw, fh),
                (1 + round, 3, fw - 1 - round - round % 5, fh - 5),
                (64, 2, 256, 40),
                (70, 0, 63, fh),
            ][round % 4];
            let d8: Vec<u8> = v.iter().map(|&x| x as u8).collect();
            check_against_plain(&d8, fw, win, &mut rng, 255);
            let d16: Vec<u16> = v.iter().map(|&x| (x * 257) as u16).collect();
            check_against_plain(&d16, fw, win, &mut rng, 65535);
        }
    }

    /// The table of power sums equals the functions evaluated at run time
    /// bit for bit, and beyond it they are evaluated.
    #[test]
    fn power_sums_from_the_table_are_the_functions() {
        for k in -3 * POW_HALF as i64..3 * POW_HALF as i64 {
            let x = k as f64;
            let want = [sum_sq_below(x), sum_pow3_below(x), sum_pow4_below(x)];
            assert_eq!(pow_sums(k).map(f64::to_bits), want.map(f64::to_bits), "{k}");
        }
        assert_eq!(pow_sums(3)[0], 5.0);
        assert_eq!(pow_sums(-2)[2], -17.0); // −(1 + 16): telescoped
    }

    /// A run's sums read from the table about a blob's origin
    /// (`SmallMoments::ends`, indexed by window columns) are the sums
    /// `Blob::add_run` forms about the origin, bit for bit: every origin
    /// of a 64-pixel window and every run in it, both ends included.
    #[test]
    fn a_runs_sums_about_the_origin_are_those_of_add_run() {
        for origin in 0..=SMALL_SIDE {
            let ends = SmallMoments::ends(origin);
            for a in 0..SMALL_SIDE {
                for e in a + 1..=SMALL_SIDE {
                    let [p0, p1, p2] = SmallMoments::run(ends, a, e).map(|v| v.to_array());
                    let (a0, e0) = (a as i64 - origin as i64, e as i64 - origin as i64);
                    let (pa, pe) = (pow_sums(a0), pow_sums(e0));
                    let n = (e - a) as f64;
                    let sx = (a0 as f64 + e0 as f64 - 1.0) * n / 2.0;
                    let want = [n, sx, pe[0] - pa[0], pe[1] - pa[1], pe[2] - pa[2], 0.0];
                    let got = [p0[0], p0[1], p1[0], p1[1], p2[0], p2[1]];
                    assert_eq!(
                        got.map(f64::to_bits),
                        want.map(f64::to_bits),
                        "{origin} {a} {e}"
                    );
                }
            }
        }
    }

    #[test]
    fn capacity_is_reported() {
        let data = [200u8, 0, 200, 0, 200, 0];
        let plane = Plane::whole(&data, 6, 1);
        let t = Threshold::global(100);
        let mut l = Labeller::new(2, 10);
        assert_eq!(l.label(&plane, t, 255), LabelOutcome::TooManyRuns);
        let mut l = Labeller::new(10, 2);
        assert_eq!(l.label(&plane, t, 255), LabelOutcome::TooManyBlobs);
    }

    #[test]
    fn a_window_labels_in_full_frame_coordinates() {
        let img = [
            "..........", //
            "...##.....", //
            "..###...#.", //
            "...#....##", //
            "..........", //
        ];
        let data: Vec<u8> = img
            .iter()
            .flat_map(|r| r.bytes().map(|b| if b == b'#' { 200 } else { 0 }))
            .collect();
        let t = Threshold::global(100);
        let mut whole = Labeller::new(100, 10);
        assert_eq!(
            whole.label(&Plane::whole(&data, 10, 5), t, 255),
            LabelOutcome::Complete
        );
        // Columns 1..=6, rows 1..=3: the left blob whole, the right one cut off.
        let plane = window(&data, 10, (1, 1, 6, 3));
        let mut win = Labeller::new(100, 10);
        assert_eq!(win.label(&plane, t, 255), LabelOutcome::Complete);
        assert_eq!(win.blobs().len(), 1);
        assert_eq!(win.blobs()[0], whole.blobs()[0]);
        assert_eq!(
            (
                win.blobs()[0].col0,
                win.blobs()[0].row0,
                win.blobs()[0].area
            ),
            (2, 1, 6)
        );
    }
}
