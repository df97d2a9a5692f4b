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
//! subtracted once it is known).

use crate::label::Blob;
use crate::num::{ceil_i64, floor_i64, near_i64, round_i64};
use crate::pixel::{Pixel, Plane};
use crate::threshold::Threshold;

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

impl Conic {
    /// The columns with `ρ²(col − bx, dy) ≤ s_in` and `≤ s_out`
    /// (`s_in ≤ s_out`), as inclusive ranges, unclipped. The ends are the
    /// ceiling and floor of the roots, taken as the nearest integers to
    /// `root ± 0.5` (exact but for a root that is exactly an integer, where
    /// a column on the ellipse itself may be left out).
    #[inline(always)]
    fn spans(&self, dy: f64, s_in: f64, s_out: f64) -> ((i64, i64), (i64, i64)) {
        let b = self.qxy * dy;
        let base = b * b - self.qxx * self.qyy * dy * dy;
        let disc_out = base + self.qxx * s_out;
        // (NaN counts as negative.)
        if disc_out.is_nan() || disc_out < 0.0 {
            return (EMPTY, EMPTY);
        }
        let mid = self.bx - b * self.inv_qxx;
        let h_out = disc_out.sqrt() * self.inv_qxx;
        let out = (near_i64(mid - h_out + 0.5), near_i64(mid + h_out - 0.5));
        let disc_in = base + self.qxx * s_in;
        if disc_in.is_nan() || disc_in < 0.0 {
            return (EMPTY, out);
        }
        let h_in = disc_in.sqrt() * self.inv_qxx;
        (
            (near_i64(mid - h_in + 0.5), near_i64(mid + h_in - 0.5)),
            out,
        )
    }
}

/// `Σ_{k=1}^{m} k²`, valid for every integer `m` (telescoping).
#[inline(always)]
fn sum_sq_to(m: i64) -> i64 {
    m * (m + 1) * (2 * m + 1) / 6
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
        let mut acc = 0usize;
        for (v, &c) in count.iter().enumerate() {
            acc += c as usize;
            if acc > k {
                return v as u32;
            }
        }
    }
    let (_, &mut q, _) = values.select_nth_unstable(k);
    q
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
    let q = Conic {
        qxx,
        qyy,
        qxy,
        inv_qxx: 1.0 / qxx,
        bx,
    };

    // One pass over the rows collects
    // - the background: 30th percentile of the dark pixels in the ring just
    //   outside the window (robust against a coded target's ring reaching
    //   into it; the small downward bias for pure noise moves the centre by
    //   nothing, as the window is centred on the blob), every `stride`-th
    //   one kept;
    // - the window's grey-value moments: exact integer sums of `g`, `g k`
    //   and `g k²` per row (`k` the column relative to the blob's nearest
    //   integer column), turned into moments about the blob's centre in
    //   closed form, with the matching pixel-count moments so that the
    //   background is subtracted once it is known.
    // (The fourth moment is the blob's own: `Blob::kurtosis`.)
    let mut bg_buf = [0u32; BG_SAMPLES];
    let est = std::f64::consts::PI * (s_out - s_in) * 4.0 * det.sqrt();
    let stride = ceil_i64(est / BG_SAMPLES as f64).max(1) as usize;
    let (mut bg_n, mut seen, mut next) = (0usize, 0usize, 0usize);
    // Σg·(1, dx, dx², dy, dy², dx dy) and Σ1·(...).
    let mut gm = [0.0f64; 6];
    let mut nm = [0.0f64; 6];
    let cc = round_i64(bx);
    let d0 = cc as f64 - bx;
    // The rows' spans a block of rows ahead, in a loop of their own: each
    // needs two square roots, whose latency the long row loop below would
    // wait for one row after the other; computed together, the rows'
    // roots overlap.
    let mut spans = [[0i32; 4]; SPAN_BLOCK];
    for row in r0..=r1 {
        let k = (row - r0) % SPAN_BLOCK;
        if k == 0 {
            for (sp, ahead) in spans.iter_mut().zip(row..=r1) {
                let ((ia, ib), (oa, ob)) = q.spans(ahead as i64 as f64 - by, s_in, s_out);
                *sp = [ia as i32, ib as i32, oa as i32, ob as i32];
            }
        }
        // (Through i64: one instruction on x86-64, unlike usize → f64.)
        let row_f = row as i64 as f64;
        let dy = row_f - by;
        let [ia, ib, oa, ob] = spans[k].map(i64::from);
        let (oa, ob) = (oa.max(c0), ob.min(c1));
        if oa > ob {
            continue;
        }
        // The row's pixels: element `i` is column `first_col + i`.
        let line = plane.row(row);
        // Background: the outer span minus the window's span inside the box.
        let in_rows = row_f >= wr0 && row_f <= wr1;
        let (xa, xb) = if in_rows {
            (ia.max(bc0).max(oa), ib.min(bc1).min(ob))
        } else {
            EMPTY
        };
        let parts = if xa > xb {
            [(oa, ob), EMPTY]
        } else {
            [(oa, xa - 1), (xb + 1, ob)]
        };
        for (a, b) in parts {
            if a > b {
                continue;
            }
            let part = &line[(a - first_col) as usize..=(b - first_col) as usize];
            if stride == 1 && bg_n + part.len() <= BG_SAMPLES {
                // Every dark pixel kept (`seen == next` throughout): store
                // each and count the dark ones, without a branch.
                let before = bg_n;
                for p in part {
                    let v = p.value();
                    bg_buf[bg_n] = v;
                    bg_n += !threshold.is_foreground(v) as usize;
                }
                seen += bg_n - before;
                next = seen;
                continue;
            }
            for p in part {
                let v = p.value();
                if !threshold.is_foreground(v) {
                    if seen == next {
                        if bg_n < BG_SAMPLES {
                            bg_buf[bg_n] = v;
                            bg_n += 1;
                        }
                        next += stride;
                    }
                    seen += 1;
                }
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
        let px = &line[(a - first_col) as usize..=(b - first_col) as usize];
        let (mut t0, mut t1, mut t2) = (0i64, 0i64, 0i64);
        for (k, p) in (a - cc..).zip(px) {
            let vi = w.weight(p.value());
            t0 += vi;
            t1 += vi * k;
            t2 += vi * k * k;
        }
        let (ka, kb) = (a - cc, b - cc);
        let n = (b - a + 1) as f64;
        let k1 = ((ka + kb) * (kb - ka + 1) / 2) as f64;
        let k2 = (sum_sq_to(kb) - sum_sq_to(ka - 1)) as f64;
        let (t0, t1, t2) = (t0 as f64, t1 as f64, t2 as f64);
        let gx = t1 + d0 * t0;
        let nx = k1 + n * d0;
        gm[0] += t0;
        gm[1] += gx;
        gm[2] += t2 + 2.0 * d0 * t1 + d0 * d0 * t0;
        gm[3] += dy * t0;
        gm[4] += dy * dy * t0;
        gm[5] += dy * gx;
        nm[0] += n;
        nm[1] += nx;
        nm[2] += k2 + 2.0 * d0 * k1 + n * d0 * d0;
        nm[3] += dy * n;
        nm[4] += dy * dy * n;
        nm[5] += dy * nx;
    }
    let background = if bg_n >= 4 {
        quantile(&mut bg_buf[..bg_n], bg_n * 3 / 10, threshold.level()) as f64
    } else {
        fallback_background
    };
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
