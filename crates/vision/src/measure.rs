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
//! the quadratic form), the background ring and the window are collected in
//! one pass, and each row's grey-value moments are exact integer sums turned
//! into moments about the blob's centre in closed form (the background is
//! subtracted once it is known). The integer sums of 8-bit rows are taken
//! sixteen pixels at a time ([`Pixel::moment_sums`]); a small ring is
//! counted by grey value in bytes instead of kept in a buffer; the two
//! spans of a row and the moments' grey-value and pixel-count sums go in
//! pairs through the lanes of a vector. Every result is the same, bit for
//! bit, as one value at a time: the integer sums are exact, and each vector
//! lane does the floating-point operations of its scalar in their order.

use crate::label::Blob;
use crate::num::{ceil_i64, floor_i64, near_i32x2, round_i64};
use crate::pixel::{scalar_moment_sums, Pixel, Plane};
use crate::threshold::Threshold;
use wide::f64x2;

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
/// Background ring: from the window out to this multiple (inside a coded
/// target's gap, which ends at 2).
const BG_OUTER: f64 = 1.75;
/// Most background pixels kept for the median.
const BG_SAMPLES: usize = 512;

/// Rings of at most this many expected pixels are counted in a histogram
/// of bytes (see `measure_weighted`).
const COUNTED_RING: f64 = 180.0;

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
        let dark = &self.count[..=(level.min(255) as usize)];
        // (In bytes, sixteen at a time: no sum of counts passes 255.)
        let n = dark.iter().fold(0u8, |n, &c| n.wrapping_add(c)) as usize;
        if n < 4 {
            return None;
        }
        kth_counted(dark, n * 3 / 10)
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

impl Window {
    /// One pass over the rows: the ring's pixels into `ring`, and the
    /// window's weighted moments `Σw·(1, dx, dx², dy, dy², dx dy)` and pixel
    /// counts `Σ1·(...)` about the blob's centre. Each row's sums of `w`,
    /// `w k` and `w k²` (`k` the column relative to the blob's nearest
    /// integer column) are exact integers, turned into moments about the
    /// centre in closed form; the background is subtracted once it is
    /// known.
    #[inline(always)]
    fn sums<P: Pixel, W: Weight, R: Ring>(
        &self,
        plane: &Plane<P>,
        w: W,
        ring: &mut R,
    ) -> ([f64; 6], [f64; 6]) {
        let q = &self.q;
        let (r0, r1) = self.rows;
        let (c0, c1) = self.cols;
        let first_col = self.first_col;
        let (wr0, wr1) = self.wr;
        let (bc0, bc1) = self.box_cols;
        let (wr0i, wr1i) = self.wrows;
        let (wc0i, wc1i) = self.wcols;
        // Σw·(1, dx, dx², dy, dy², dx dy) and Σ1·(...), in the two lanes of
        // each: the same sums, operation for operation, as one at a time.
        let mut acc = [f64x2::ZERO; 6];
        let cc = round_i64(q.bx);
        let d0 = cc as f64 - q.bx;
        // The rows' spans a block of rows ahead, in a loop of their own:
        // each needs two square roots, whose latency the long row loop
        // below would wait for one row after the other; computed together,
        // the rows' roots overlap.
        let mut spans = [[0i32; 4]; SPAN_BLOCK];
        for row in r0..=r1 {
            let k = (row - r0) % SPAN_BLOCK;
            if k == 0 {
                for (sp, ahead) in spans.iter_mut().zip(row..r1 + 1) {
                    let ((ia, ib), (oa, ob)) =
                        q.spans(ahead as i64 as f64 - self.by, self.s_in, self.s_out);
                    *sp = [ia, ib, oa, ob];
                }
            }
            // (Through i64: one instruction on x86-64, unlike usize → f64.)
            let row_f = row as i64 as f64;
            let dy = row_f - self.by;
            let [ia, ib, oa, ob] = spans[k].map(i64::from);
            let (oa, ob) = (oa.max(c0), ob.min(c1));
            if oa > ob {
                continue;
            }
            // The row's pixels: element `i` is column `first_col + i`.
            let line = plane.row(row);
            // Background: the outer span minus the window's span inside
            // the box.
            let in_rows = row_f >= wr0 && row_f <= wr1;
            let (xa, xb) = if in_rows {
                (ia.max(bc0).max(oa), ib.min(bc1).min(ob))
            } else {
                EMPTY
            };
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
            // Window.
            if row < wr0i || row > wr1i {
                continue;
            }
            let (a, b) = (ia.max(wc0i), ib.min(wc1i));
            if a > b {
                continue;
            }
            let n = b - a + 1;
            let ka = a - cc;
            let [t0, t1, t2] = w.moment_sums(line, (a - first_col) as usize, n as usize, ka);
            // The pixel counts' sums in closed form, from `Σj` and `Σj²` over
            // `j = k − ka` in `0..n` (`n (n − 1)` is even, `n (n − 1)(2n − 1)`
            // a multiple of 6; unsigned, as the divisions by constants are
            // cheaper so).
            let nu = n as u64;
            let j1 = nu * (nu - 1) / 2;
            let j2 = (j1 * (2 * nu - 1) / 3) as i64;
            let j1 = j1 as i64;
            let k1 = (n * ka + j1) as f64;
            let k2 = (n * ka * ka + 2 * ka * j1 + j2) as f64;
            // Lanes (grey values, pixel counts): `x = (t0, n)`,
            // `y1 = (t1, k1)`, `y2 = (t2, k2)`; `gx` and `nx` the first
            // moments about the centre.
            let t0 = t0 as f64;
            let x = f64x2::new([t0, n as f64]);
            let y1 = f64x2::new([t1 as f64, k1]);
            let y2 = f64x2::new([t2 as f64, k2]);
            let d0x = f64x2::splat(d0) * x;
            let gnx = y1 + d0x;
            // (t2 + 2 d0 t1 + d0² t0, k2 + 2 d0 k1 + n d0 d0).
            let sq = f64x2::new([d0 * d0, d0x.to_array()[1]]) * f64x2::new([t0, d0]);
            let dy = f64x2::splat(dy);
            acc[0] += x;
            acc[1] += gnx;
            acc[2] += y2 + f64x2::splat(2.0 * d0) * y1 + sq;
            acc[3] += dy * x;
            acc[4] += dy * dy * x;
            acc[5] += dy * gnx;
        }
        let gm = acc.map(|a| a.to_array()[0]);
        let nm = acc.map(|a| a.to_array()[1]);
        (gm, nm)
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

/// Rows whose spans [`measure_weighted`] computes ahead at a time.
const SPAN_BLOCK: usize = 8;

/// An empty inclusive range.
const EMPTY: (i64, i64) = (1, 0);
/// See [`EMPTY`].
const EMPTY32: (i32, i32) = (1, 0);

impl Conic {
    /// The columns with `ρ²(col − bx, dy) ≤ s_in` and `≤ s_out`
    /// (`s_in ≤ s_out`), as inclusive ranges, unclipped. The ends are the
    /// ceiling and floor of the roots, taken as the nearest integers to
    /// `root ± 0.5` (exact but for a root that is exactly an integer, where
    /// a column on the ellipse itself may be left out).
    #[inline(always)]
    fn spans(&self, dy: f64, s_in: f64, s_out: f64) -> ((i32, i32), (i32, i32)) {
        // (Both spans at once in the two lanes of a vector: each lane the
        // same operations as alone.)
        let b = self.qxy * dy;
        let base = b * b - self.qxx * self.qyy * dy * dy;
        let disc = f64x2::splat(base) + f64x2::new([self.qxx * s_in, self.qxx * s_out]);
        let [disc_in, disc_out] = disc.to_array();
        // (NaN counts as negative.)
        if disc_out.is_nan() || disc_out < 0.0 {
            return (EMPTY32, EMPTY32);
        }
        let mid = f64x2::splat(self.bx - b * self.inv_qxx);
        let h = disc.sqrt() * f64x2::splat(self.inv_qxx);
        let [lo_in, lo_out] = near_i32x2(mid - h + f64x2::splat(0.5));
        let [hi_in, hi_out] = near_i32x2(mid + h - f64x2::splat(0.5));
        if disc_in.is_nan() || disc_in < 0.0 {
            return (EMPTY32, (lo_out, hi_out));
        }
        ((lo_in, hi_in), (lo_out, hi_out))
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
        if let Some(q) = kth_counted(&count, k) {
            return q;
        }
    }
    let (_, &mut q, _) = values.select_nth_unstable(k);
    q
}

/// The `k`-th smallest (from 0) of the values counted in `count` (`count[v]`
/// values equal `v`); `None` if fewer than `k + 1` are counted.
#[inline]
fn kth_counted(count: &[u8], k: usize) -> Option<u32> {
    let mut acc = 0usize;
    for (v, &c) in count.iter().enumerate() {
        acc += c as usize;
        if acc > k {
            return Some(v as u32);
        }
    }
    None
}

/// The weight a grey value gets in the centroid sums (in units of
/// `1 / SCALE` grey values).
pub trait Weight: Copy {
    /// Weight units per grey value.
    const SCALE: f64;
    /// The weight of grey value `v`.
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
/// only); `None` if the window holds no signal.
pub fn measure<P: Pixel>(
    plane: &Plane<P>,
    blob: &Blob,
    threshold: Threshold,
    fallback_background: f64,
    grow: f64,
    max_scale: f64,
) -> Option<Measurement> {
    measure_weighted(
        plane,
        blob,
        threshold,
        fallback_background,
        grow,
        max_scale,
        Linear,
    )
}

/// [`measure`] with the grey values weighted by `w` in the centroid and
/// moment sums (the signal is in the weight's units).
pub fn measure_weighted<P: Pixel, W: Weight>(
    plane: &Plane<P>,
    blob: &Blob,
    threshold: Threshold,
    fallback_background: f64,
    grow: f64,
    max_scale: f64,
    w: W,
) -> Option<Measurement> {
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
    let g = ceil_i64(grow) + 2;
    let (first_col, first_row) = (plane.col0 as i64, plane.row0 as i64);
    let (last_col, last_row) = (plane.last_col() as i64, plane.last_row());
    let c0 = (blob.col0 as i64 - g).max(first_col);
    let r0 = (blob.row0 as i64 - g).max(first_row) as usize;
    let c1 = (blob.col1 as i64 + g).min(last_col);
    let r1 = ((blob.row1 as i64 + g) as usize).min(last_row);
    let (wc0, wr0) = (blob.col0 as f64 - grow, blob.row0 as f64 - grow);
    let (wc1, wr1) = (blob.col1 as f64 + grow, blob.row1 as f64 + grow);
    // Columns of the box proper (`wc0 ≤ col ≤ wc1`), for the background.
    let (bc0, bc1) = (c0.max(ceil_i64(wc0)), c1.min(floor_i64(wc1)));
    // Rows and columns of the weighted window.
    let wr0i = wr0.max(first_row as f64) as usize;
    let wr1i = (wr1 as usize).min(last_row);
    let wc0i = wc0.max(first_col as f64) as i64;
    let wc1i = (wc1 as i64).min(last_col);
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
    let stride = ceil_i64(est / BG_SAMPLES as f64).max(1) as usize;
    let level = threshold.level();
    let mut counted = None;
    if stride == 1 && est <= COUNTED_RING && (P::MAX <= 255 || level < 255) {
        let mut count = [0; 256];
        let mut ring = Counts {
            count: &mut count,
            total: 0,
        };
        let sums = window.sums(plane, w, &mut ring);
        if ring.total <= u8::MAX as usize {
            counted = Some((sums, ring.quantile(level)));
        }
    }
    let ((gm, nm), bg) = counted.unwrap_or_else(|| {
        let mut ring = Samples {
            buf: [0; BG_SAMPLES],
            n: 0,
            seen: 0,
            next: 0,
            stride,
            threshold,
        };
        let sums = window.sums(plane, w, &mut ring);
        (sums, ring.quantile(level))
    });
    let background = bg.map_or(fallback_background, |b| b as f64);
    let bw = w.level(background);
    let m = |i: usize| gm[i] - bw * nm[i];
    let (sw, sx, sxx, sy, syy, sxy) = (m(0), m(1), m(2), m(3), m(4), m(5));
    if sw.is_nan() || sw <= 0.0 {
        return None;
    }
    let (mx, my) = (sx / sw, sy / sw);
    let kurtosis = blob.kurtosis();
    Some(Measurement {
        col: bx + mx,
        row: by + my,
        cxx: sxx / sw - mx * mx - 1.0 / 12.0,
        cyy: syy / sw - my * my - 1.0 / 12.0,
        cxy: sxy / sw - mx * my,
        signal: sw / W::SCALE,
        background,
        kurtosis,
    })
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
