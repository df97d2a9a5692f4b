//! Pixel access shared by the stages: one generic code path for 8-bit and
//! 16-bit frames, the window the detector runs on ([`Plane`]: its pixels,
//! row stride and origin in the full frame) and bilinear interpolation at
//! sub-pixel positions (integer coordinates are pixel centres). Every
//! position a [`Plane`] takes is in full-frame pixel coordinates.

use crate::threshold::Threshold;
use wide::{f64x2, i16x8, i32x4, i32x8, u16x8, u8x16, CmpGt};

/// A grey value type the detector reads.
pub trait Pixel: Copy + Send + Sync + 'static {
    /// Largest value of the type.
    const MAX: u32;
    /// The grey value.
    fn value(self) -> u32;
    /// Largest value of a slice (vectorises).
    fn max_of(chunk: &[Self]) -> u32;
    /// Bit `i` set if `block[i]` is foreground, for a block of at most 64
    /// pixels (see [`Threshold::foreground_mask`]).
    #[inline]
    fn above_mask(block: &[Self], threshold: Threshold) -> u64 {
        debug_assert!(block.len() <= 64);
        let mut m = 0u64;
        for (i, p) in block.iter().enumerate() {
            m |= (threshold.is_foreground(p.value()) as u64) << i;
        }
        m
    }
    /// [`Pixel::above_mask`] of a whole block that likely holds foreground
    /// (no test for a dark block first).
    #[inline]
    fn lit_mask(block: &[Self; 64], threshold: Threshold) -> u64 {
        Self::above_mask(block, threshold)
    }
    /// The largest value of `line[start..end]` (0 if empty) and how
    /// many of its pixels are at or above `saturation`: a run's statistics.
    #[inline]
    fn run_stats(line: &[Self], start: usize, end: usize, saturation: u32) -> (u32, u32) {
        scalar_run_stats(&line[start..end], saturation)
    }
    /// Bit `k` (of four) set unless the 64 pixels `block[64 k..64 k + 64]`
    /// are all background: which quarters of a stretch of 256 pixels of a
    /// row hold foreground.
    #[inline]
    fn lit_quarters(block: &[Self; 256], threshold: Threshold) -> u32 {
        let mut lit = 0;
        for (k, q) in block.chunks_exact(64).enumerate() {
            lit |= (!threshold.all_background(q) as u32) << k;
        }
        lit
    }
    /// The largest values of the `N` tiles of 64 pixels from `a` on
    /// (`a + 64 k .. a + 64 (k + 1)`) over all of `rows` (each holds the
    /// pixels up to `a + 64 N`; 0 if no rows): the peaks of `N` tiles over
    /// their sampled rows.
    #[inline]
    fn tile_peaks<const N: usize>(rows: &[&[Self]], a: usize) -> [u32; N] {
        std::array::from_fn(|k| max_of_rows(rows, a + 64 * k, a + 64 * k + 64))
    }
    /// `[Σ v, Σ v k, Σ v k²]` over the `n` pixels `line[a..a + n]`, `k`
    /// running from `k0`: a row's grey-value moments.
    #[inline]
    fn moment_sums(line: &[Self], a: usize, n: usize, k0: i64) -> [i64; 3] {
        scalar_moment_sums(&line[a..a + n], k0, |p| p.value() as i64)
    }
    /// The corners `[p00, p01, p10, p11]` of two cells of bilinear
    /// interpolation, lane 0 from `a`, lane 1 from `b`, each cell as the
    /// pixels from its top-left corner and from its bottom-left one (at
    /// least two each).
    #[inline(always)]
    fn corners_x2(a: [&[Self]; 2], b: [&[Self]; 2]) -> [f64x2; 4] {
        corners_x2(a, b)
    }
    /// A bound of the pixels of pairs of cells (each pair as
    /// [`Pixel::corners_x2`] takes it): their bitwise or (at least the
    /// largest, one operation a pixel), 0 for none.
    #[inline(always)]
    fn cells_bound<'p>(cells: impl Iterator<Item = [[&'p [Self]; 2]; 2]>) -> u32
    where
        Self: 'p,
    {
        cells.fold(0, |m, [[a0, a1], [b0, b1]]| {
            let [a0, a1, b0, b1] = [a0, a1, b0, b1].map(|p| p[0].value() | p[1].value());
            m | a0 | a1 | b0 | b1
        })
    }
    /// The pixels as bytes if they are 8-bit (for the paths that take an
    /// 8-bit row sixteen pixels at a time).
    #[inline(always)]
    fn bytes(_px: &[Self]) -> Option<&[u8]> {
        None
    }
}

/// The largest value of the pixels `a..b` of each of `rows` (0 if
/// none), a row at a time ([`Pixel::max_of`] of each): a tile's peak over
/// its sampled rows.
#[inline(always)]
pub(crate) fn max_of_rows<P: Pixel>(rows: &[&[P]], a: usize, b: usize) -> u32 {
    rows.iter().fold(0, |m, r| m.max(P::max_of(&r[a..b])))
}

/// [`Pixel::run_stats`] one pixel at a time.
#[inline(always)]
fn scalar_run_stats<P: Pixel>(px: &[P], saturation: u32) -> (u32, u32) {
    let (mut max, mut sat) = (0u32, 0u32);
    for p in px {
        let v = p.value();
        max = max.max(v);
        sat += (v >= saturation) as u32;
    }
    (max, sat)
}

/// `[Σ w, Σ w k, Σ w k²]` over `px` with `w` the weight of a pixel and `k`
/// running from `k0` (see [`Pixel::moment_sums`]).
#[inline(always)]
pub(crate) fn scalar_moment_sums<P: Pixel>(px: &[P], k0: i64, w: impl Fn(P) -> i64) -> [i64; 3] {
    let (mut t0, mut t1, mut t2) = (0i64, 0i64, 0i64);
    for (k, &p) in (k0..).zip(px) {
        let v = w(p);
        t0 += v;
        t1 += v * k;
        t2 += v * k * k;
    }
    [t0, t1, t2]
}

/// [`Pixel::corners_x2`] one pixel at a time.
#[inline(always)]
fn corners_x2<P: Pixel>([a0, a1]: [&[P]; 2], [b0, b1]: [&[P]; 2]) -> [f64x2; 4] {
    let v = |p: P| p.value() as f64;
    [
        f64x2::new([v(a0[0]), v(b0[0])]),
        f64x2::new([v(a0[1]), v(b0[1])]),
        f64x2::new([v(a1[0]), v(b1[0])]),
        f64x2::new([v(a1[1]), v(b1[1])]),
    ]
}

/// Sixteen pixels of an 8-bit row as one vector.
#[inline(always)]
pub(crate) fn lanes16(c: &[u8]) -> u8x16 {
    let Ok(&c) = <&[u8; 16]>::try_from(c) else {
        unreachable!("sixteen pixels")
    };
    u8x16::new(c)
}

/// The 8-bit level of `threshold` as sixteen lanes; `None` when no 8-bit
/// value lies above it.
#[inline(always)]
fn level16(threshold: Threshold) -> Option<u8x16> {
    let level = threshold.level();
    (level < u8::MAX as u32).then(|| u8x16::splat(level as u8))
}

/// Bit `i` set for each lane of `v` above `t` (the foreground lanes).
#[inline(always)]
fn above16(v: u8x16, t: u8x16) -> u32 {
    !(v.saturating_sub(t).cmp_eq(u8x16::splat(0)).move_mask() as u32) & 0xffff
}

/// The largest lane of `v`.
#[inline(always)]
fn reduce_max16(v: u8x16) -> u32 {
    // (Through `u8`: the callers see a value below 256.)
    i16x8::from_u8x16_low(v)
        .max(i16x8::from_u8x16_high(v))
        .reduce_max() as u8 as u32
}

/// [`Pixel::lit_mask`] of 8-bit pixels given as four vectors.
#[inline(always)]
fn mask64(v: [u8x16; 4], t: u8x16) -> u64 {
    let mut m = 0u64;
    for (k, &x) in v.iter().enumerate() {
        m |= (above16(x, t) as u64) << (16 * k);
    }
    m
}

/// `[p00, p01, p10, p11]` of an 8-bit cell (its top pair and its bottom
/// pair, [`Pixel::corners_x2`]) as the low bytes of a vector, two pixels a
/// load.
#[inline(always)]
fn cell_bytes([top, bottom]: [&[u8]; 2]) -> u8x16 {
    let pair = |c: &[u8]| u16::from_le_bytes([c[0], c[1]]) as u32;
    let [x0, x1, x2, x3] = (pair(top) | pair(bottom) << 16).to_le_bytes();
    u8x16::new([x0, x1, x2, x3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
}

impl Pixel for u8 {
    const MAX: u32 = u8::MAX as u32;
    #[inline(always)]
    fn value(self) -> u32 {
        self as u32
    }
    #[inline(always)]
    fn bytes(px: &[Self]) -> Option<&[u8]> {
        Some(px)
    }
    #[inline(always)]
    fn max_of(chunk: &[Self]) -> u32 {
        chunk.iter().fold(0u8, |m, &p| m.max(p)) as u32
    }
    /// Two pixels a load (a 16-bit or), the halves or-ed at the end.
    #[inline(always)]
    fn cells_bound<'p>(cells: impl Iterator<Item = [[&'p [Self]; 2]; 2]>) -> u32 {
        let pair = |p: &[u8]| u16::from_le_bytes([p[0], p[1]]);
        let w = cells.fold(0u16, |m, [[a0, a1], [b0, b1]]| {
            m | pair(a0) | pair(a1) | pair(b0) | pair(b1)
        });
        ((w | w >> 8) & 0xff) as u32
    }
    /// Two pixels at a time (a 16-bit load), the eight bytes interleaved
    /// and widened to 32 bits in vectors, converted two at a time: the
    /// same values.
    #[inline(always)]
    fn corners_x2(a: [&[Self]; 2], b: [&[Self]; 2]) -> [f64x2; 4] {
        let v = u8x16::unpack_low(cell_bytes(a), cell_bytes(b));
        let d = i32x8::from_u16x8(u16x8::from_u8x16_low(v)).to_array();
        let f = |i: usize| f64x2::new([d[i] as f64, d[i + 1] as f64]);
        [f(0), f(2), f(4), f(6)]
    }
    /// Sixteen pixels at a time (SSE2 on x86-64): a pixel is foreground
    /// where it is not `≤ level`, i.e. where `v − level` (saturating) is not 0.
    #[inline]
    fn above_mask(block: &[Self], threshold: Threshold) -> u64 {
        debug_assert!(block.len() <= 64);
        let Some(t) = level16(threshold) else {
            return 0;
        };
        if let Ok(b) = <&[u8; 64]>::try_from(block) {
            let v = [
                lanes16(&b[..16]),
                lanes16(&b[16..32]),
                lanes16(&b[32..48]),
                lanes16(&b[48..]),
            ];
            // A dark block (most of a frame) costs one test.
            if above16(v[0].max(v[1]).max(v[2].max(v[3])), t) == 0 {
                return 0;
            }
            return mask64(v, t);
        }
        let mut chunks = block.chunks_exact(16);
        let mut m = 0u64;
        let mut shift = 0;
        for c in &mut chunks {
            m |= (above16(lanes16(c), t) as u64) << shift;
            shift += 16;
        }
        for (i, &p) in chunks.remainder().iter().enumerate() {
            m |= (threshold.is_foreground(p as u32) as u64) << (shift + i);
        }
        m
    }

    #[inline]
    fn lit_mask(block: &[Self; 64], threshold: Threshold) -> u64 {
        let Some(t) = level16(threshold) else {
            return 0;
        };
        // (A loop over the four vectors: `[0, 1, 2, 3].map` was left a
        // call in the labeller.)
        let mut m = 0u64;
        for (k, c) in block.chunks_exact(16).enumerate() {
            m |= (above16(lanes16(c), t) as u64) << (16 * k);
        }
        m
    }

    /// Sixteen pixels at a time: each tile's lanes' maxima over all the
    /// rows, reduced once per tile (for `N = 4` a row's 256 pixels with
    /// one range check).
    #[inline]
    fn tile_peaks<const N: usize>(rows: &[&[Self]], a: usize) -> [u32; N] {
        let mut m = [u8x16::splat(0); N];
        for r in rows {
            let tiles = &r[a..a + 64 * N];
            for (k, m) in m.iter_mut().enumerate() {
                let v = |j: usize| lanes16(&tiles[64 * k + 16 * j..64 * k + 16 * j + 16]);
                *m = m.max(v(0).max(v(1)).max(v(2).max(v(3))));
            }
        }
        m.map(reduce_max16)
    }

    /// Sixteen pixels at a time (`run_lanes`): their maximum as one
    /// vector, reduced once at the end. The saturated pixels are counted
    /// only when that maximum reaches the saturation level (a run below
    /// it has none; most runs), from bit masks in a second pass (a lane
    /// set to 0 is not saturated unless every value is, at saturation 0,
    /// where the count is the run's length).
    #[inline]
    fn run_stats(line: &[Self], start: usize, end: usize, saturation: u32) -> (u32, u32) {
        if line.len() < 16 {
            return scalar_run_stats(&line[start..end], saturation);
        }
        let mut max = u8x16::splat(0);
        run_lanes(line, start, end, |v| max = max.max(v));
        let max = reduce_max16(max);
        if max < saturation {
            return (max, 0);
        }
        if saturation == 0 {
            return (max, (end - start) as u32);
        }
        // `v ≥ saturation` where `max(v, saturation) = v` (here ≤ 255).
        let (sat_level, mut sat) = (u8x16::splat(saturation as u8), 0);
        run_lanes(line, start, end, |v| {
            sat += v.max(sat_level).cmp_eq(v).move_mask().count_ones()
        });
        (max, sat)
    }

    /// Sixteen pixels at a time: the largest value of each quarter, and of
    /// those four, compared with the level once each (no horizontal maximum);
    /// a dark stretch (most of a frame) costs the first comparison only.
    #[inline]
    fn lit_quarters(block: &[Self; 256], threshold: Threshold) -> u32 {
        let Some(t) = level16(threshold) else {
            return 0;
        };
        // Nonzero where some lane is above `t`.
        let lit = |v: u8x16| above16(v, t);
        let v = |k: usize| lanes16(&block[16 * k..16 * k + 16]);
        let q = |k: usize| {
            v(4 * k)
                .max(v(4 * k + 1))
                .max(v(4 * k + 2).max(v(4 * k + 3)))
        };
        let (q0, q1, q2, q3) = (q(0), q(1), q(2), q(3));
        if lit(q0.max(q1).max(q2.max(q3))) == 0 {
            return 0;
        }
        (lit(q0) != 0) as u32
            | ((lit(q1) != 0) as u32) << 1
            | ((lit(q2) != 0) as u32) << 2
            | ((lit(q3) != 0) as u32) << 3
    }

    /// Sixteen pixels at a time in 16-bit lanes (SSE2 `pmaddwd` sums the
    /// products in pairs into 32-bit lanes) about the run's first pixel
    /// (`j = k − k0`), moved to `k0` exactly in integers; so the same as one
    /// pixel at a time. A run of at most sixteen pixels is one block from
    /// its first pixel; otherwise the last block is the sixteen pixels
    /// ending at the row's end when fewer are left (lanes outside the
    /// pixels not yet summed masked off). For `n ≤ 128` every lane's `j²`
    /// (`|j| < 144`) fits 16 bits and the 32-bit lane sums cannot overflow.
    #[inline]
    fn moment_sums(line: &[Self], a: usize, n: usize, k0: i64) -> [i64; 3] {
        const LANES: usize = 16;
        if n > 128 || line.len() < LANES {
            return scalar_moment_sums(&line[a..a + n], k0, |p| p as i64);
        }
        const LO: i16x8 = i16x8::new([0, 1, 2, 3, 4, 5, 6, 7]);
        const HI: i16x8 = i16x8::new([8, 9, 10, 11, 12, 13, 14, 15]);
        let (mut s0, mut s1, mut s2) = (i16x8::ZERO, i32x4::ZERO, i32x4::ZERO);
        let end = i16x8::splat(n as i16);
        let mut s = 0;
        if n <= LANES && a + LANES <= line.len() {
            // One block from the row's first pixel (most rows): `j` is the
            // lane, `j²` a constant too.
            const LO2: i16x8 = i16x8::new([0, 1, 4, 9, 16, 25, 36, 49]);
            const HI2: i16x8 = i16x8::new([64, 81, 100, 121, 144, 169, 196, 225]);
            let v = lanes16(&line[a..a + LANES]);
            let lo = i16x8::from_u8x16_low(v) & end.cmp_gt(LO);
            let hi = i16x8::from_u8x16_high(v) & end.cmp_gt(HI);
            s0 = lo + hi;
            s1 = lo.dot(LO) + hi.dot(HI);
            s2 = lo.dot(LO2) + hi.dot(HI2);
            s = n;
        }
        while s < n {
            let p = (a + s).min(line.len() - LANES);
            let v = lanes16(&line[p..p + LANES]);
            // `j` of lane 0; the lanes with `j < s` were summed before.
            let j0 = i16x8::splat((p as isize - a as isize) as i16);
            let first = i16x8::splat(s as i16 - 1);
            for (v, lane) in [
                (i16x8::from_u8x16_low(v), LO),
                (i16x8::from_u8x16_high(v), HI),
            ] {
                let j = j0 + lane;
                let v = v & (j.cmp_gt(first) & end.cmp_gt(j));
                s0 += v;
                s1 += v.dot(j);
                s2 += v.dot(j * j);
            }
            s += LANES;
        }
        let s0 = s0.dot(i16x8::splat(1)).reduce_add() as i64;
        let s1 = s1.reduce_add() as i64;
        let s2 = s2.reduce_add() as i64;
        [s0, s1 + k0 * s0, s2 + 2 * k0 * s1 + k0 * k0 * s0]
    }
}

impl Pixel for u16 {
    const MAX: u32 = u16::MAX as u32;
    #[inline(always)]
    fn value(self) -> u32 {
        self as u32
    }
    #[inline(always)]
    fn max_of(chunk: &[Self]) -> u32 {
        chunk.iter().fold(0u16, |m, &p| m.max(p)) as u32
    }
}

/// The window the detector reads: `width × height` pixels whose top-left
/// pixel is `(col0, row0)` of the full frame, rows `stride` elements apart.
/// Positions are full-frame pixel coordinates; the window's own offsets
/// appear only in the index arithmetic (once per row or per sample, never
/// per pixel of a row).
#[derive(Debug, Clone, Copy)]
pub struct Plane<'a, P> {
    /// Pixels: the window's first pixel is element 0, its row `r` starts at
    /// element `r * stride` and holds `width` pixels.
    pub data: &'a [P],
    /// Width.
    pub width: usize,
    /// Height.
    pub height: usize,
    /// Distance between the starts of two rows, elements.
    pub stride: usize,
    /// Full-frame column of the first pixel.
    pub col0: usize,
    /// Full-frame row of the first pixel.
    pub row0: usize,
}

impl<'a, P: Pixel> Plane<'a, P> {
    /// A whole frame: row-major, unpadded, at the origin.
    pub fn whole(data: &'a [P], width: usize, height: usize) -> Self {
        Plane {
            data,
            width,
            height,
            stride: width,
            col0: 0,
            row0: 0,
        }
    }

    /// The last column inside the window (full frame).
    #[inline(always)]
    pub fn last_col(&self) -> usize {
        self.col0 + self.width - 1
    }

    /// The last row inside the window (full frame).
    #[inline(always)]
    pub fn last_row(&self) -> usize {
        self.row0 + self.height - 1
    }

    /// The `width` pixels of full-frame row `row` (inside the window);
    /// element `i` is column `col0 + i`.
    #[inline(always)]
    pub fn row(&self, row: usize) -> &'a [P] {
        let start = (row - self.row0) * self.stride;
        &self.data[start..start + self.width]
    }

    /// Asks the processor to fetch every cache line of the full-frame box
    /// `col0..=col1 × row0..=row1` (clipped to the window) without waiting
    /// for them (a prefetch hint): the box is then read from the cache
    /// when it is measured a little later. Changes nothing.
    #[inline]
    pub fn prefetch(&self, col0: usize, row0: usize, col1: usize, row1: usize) {
        let (c0, r0) = (col0.max(self.col0), row0.max(self.row0));
        let (c1, r1) = (col1.min(self.last_col()), row1.min(self.last_row()));
        if c0 > c1 || r0 > r1 {
            return;
        }
        // Each row's first pixel, one every cache line after it, and its
        // last pixel, straight from the buffer: per row an index step and a
        // slice check (a row of a tracking window mostly spans one or two
        // lines).
        let step = (64 / std::mem::size_of::<P>()).max(1);
        let (width, last) = (c1 - c0 + 1, c1 - c0);
        let mut start = (r0 - self.row0) * self.stride + (c0 - self.col0);
        for _ in 0..r1 - r0 + 1 {
            let Some(row) = self.data.get(start..start + width) else {
                return;
            };
            crate::prefetch::line(row);
            let mut k = step;
            while k < last {
                crate::prefetch::line(&row[k..]);
                k += step;
            }
            crate::prefetch::line(&row[last..]);
            start += self.stride;
        }
    }

    /// Grey value at a full-frame integer position (must be inside).
    #[inline(always)]
    pub fn at(&self, col: usize, row: usize) -> f64 {
        self.data[(row - self.row0) * self.stride + (col - self.col0)].value() as f64
    }

    /// Bilinear interpolation at the full-frame position `(col, row)`;
    /// `None` outside the hull of the window's pixel centres.
    #[inline]
    pub fn bilinear(&self, col: f64, row: f64) -> Option<f64> {
        let (w, h) = (self.width, self.height);
        // Inside the hull of the pixel centres (false for NaN).
        // (Signed conversions: a single instruction each on x86-64.)
        let (c0, r0) = (self.col0 as i64, self.row0 as i64);
        let (cl, rl) = (c0 + w as i64 - 1, r0 + h as i64 - 1);
        if !(col >= c0 as f64 && row >= r0 as f64 && col <= cl as f64 && row <= rl as f64) {
            return None;
        }
        if w < 2 || h < 2 {
            return Some(self.at(col as usize, row as usize));
        }
        // Truncation is the floor for non-negative values (and needs no
        // libm call on baseline x86-64). On the last column or row, the
        // cell to the left or above is used with a fraction of exactly 1.
        let (ci, ri) = ((col as i64).min(cl - 1), (row as i64).min(rl - 1));
        let fx = col - ci as f64;
        let fy = row - ri as f64;
        let i = (ri - r0) as usize * self.stride + (ci - c0) as usize;
        let top = &self.data[i..i + 2];
        let bottom = &self.data[i + self.stride..i + self.stride + 2];
        let (p00, p01) = (top[0].value() as f64, top[1].value() as f64);
        let (p10, p11) = (bottom[0].value() as f64, bottom[1].value() as f64);
        let top = p00 + fx * (p01 - p00);
        let bottom = p10 + fx * (p11 - p10);
        Some(top + fy * (bottom - top))
    }

    /// [`Plane::bilinear`] at a position the caller knows to lie inside the
    /// hull of the window's pixel centres (`col0 ≤ col ≤ col0 + width − 1`,
    /// likewise for rows, at least 2 × 2 pixels); outside it, the value is
    /// that of a nearby position (never a panic for finite positions).
    #[inline(always)]
    pub fn bilinear_inside(&self, col: f64, row: f64) -> f64 {
        let (w, h) = (self.width, self.height);
        // The cell's corner: `col − 0.5` rounded to an integer by adding
        // 1.5 · 2⁵² (the sum is that integer plus 1.5 · 2⁵², and its low
        // mantissa bits are the integer). That is the floor of `col`, or
        // one less for an integer `col`, where the fraction is then 1 and
        // the interpolation gives the same value. Clamped to the window's
        // cells while still offset (two float instructions, no branches),
        // then taken apart: the integer from the low bits, its value as a
        // float by taking the offset off again (both exact).
        const ROUND: f64 = 6_755_399_441_055_744.0;
        // (`if` rather than `f64::max`: one instruction each; NaN gives
        // the lower bound.)
        let clamp = |v: f64, lo: f64, hi: f64| {
            let v = if v > lo { v } else { lo };
            if v < hi {
                v
            } else {
                hi
            }
        };
        let (c0, r0) = (self.col0 as u32 as f64, self.row0 as u32 as f64);
        let cc = clamp(
            (col - 0.5) + ROUND,
            ROUND + c0,
            ROUND + c0 + w.saturating_sub(2) as u32 as f64,
        );
        let rc = clamp(
            (row - 0.5) + ROUND,
            ROUND + r0,
            ROUND + r0 + h.saturating_sub(2) as u32 as f64,
        );
        let ci = (cc.to_bits() as u32).wrapping_sub(self.col0 as u32) as usize;
        let ri = (rc.to_bits() as u32).wrapping_sub(self.row0 as u32) as usize;
        let fx = col - (cc - ROUND);
        let fy = row - (rc - ROUND);
        let s = self.stride;
        let i = ri * s + ci;
        // One range check for the 2 × 2 cell.
        let cell = &self.data[i..i + s + 2];
        let (p00, p01) = (cell[0].value() as f64, cell[1].value() as f64);
        let (p10, p11) = (cell[s].value() as f64, cell[s + 1].value() as f64);
        let top = p00 + fx * (p01 - p00);
        let bottom = p10 + fx * (p11 - p10);
        top + fy * (bottom - top)
    }

    /// [`Plane::bilinear_inside`] at two positions at once (lane `l` of
    /// `col` and `row` is a position): each lane does exactly the scalar's
    /// floating-point operations in the same order, so the two values are
    /// those of two scalar calls bit for bit. Only the index of the cell is
    /// formed otherwise, exactly in floating point, and taken from the low
    /// mantissa bits of both lanes.
    #[inline(always)]
    pub fn bilinear_inside_x2(&self, col: f64x2, row: f64x2) -> f64x2 {
        const LOW_51: u64 = (1 << 51) - 1;
        let (w, h) = (self.width, self.height);
        let (c0, r0) = (self.col0 as u32 as f64, self.row0 as u32 as f64);
        let (cc, rc) = rounded_x2(col, row);
        // `fast_max`/`fast_min` are SSE2's `maxpd`/`minpd`: `v > lo ? v :
        // lo` and `v < hi ? v : hi`, the scalar's clamp (also for NaN; on
        // targets without SSE2 the same except for NaN).
        let (c_lo, r_lo) = (ROUND + c0, ROUND + r0);
        let c_hi = ROUND + c0 + w.saturating_sub(2) as u32 as f64;
        let r_hi = ROUND + r0 + h.saturating_sub(2) as u32 as f64;
        let cc = cc.fast_max(f64x2::splat(c_lo)).fast_min(f64x2::splat(c_hi));
        let rc = rc.fast_max(f64x2::splat(r_lo)).fast_min(f64x2::splat(r_hi));
        let s = self.stride;
        let (i, fx, fy) = cell_x2(col, row, cc, rc, s as f64, ROUND - self.origin(0));
        let [ia, ib] = i.to_array().map(|v| (v.to_bits() & LOW_51) as usize);
        // Two range checks per cell (its start, then its length; the
        // length not wrapping is checked once, out of the loops).
        let n = s.checked_add(2).expect("stride");
        let a = &self.data[ia..][..n];
        let b = &self.data[ib..][..n];
        interpolate(P::corners_x2([a, &a[s..]], [b, &b[s..]]), fx, fy)
    }

    /// The full-frame offset of element `start` of the buffer, `row0 ·
    /// stride + col0 + start` (an integer below 2⁵¹ for any frame, exact).
    fn origin(&self, start: usize) -> f64 {
        (self.row0 as u32 as u64 * self.stride as u64 + self.col0 as u32 as u64 + start as u64)
            as f64
    }

    /// The cells whose top-left pixels lie in the full-frame box `col0..=
    /// col1 × row0..=row1` (inside the window, short of its last column
    /// and row), for [`Cells::bilinear_x2`]; `None` if the box spans more
    /// than [`CELLS`] pixels of the buffer or the buffer holds too few
    /// pixels around it (a stride of 2¹⁶ or more, a window's last rows).
    pub fn cells(
        &self,
        (col0, row0): (usize, usize),
        (col1, row1): (usize, usize),
    ) -> Option<Cells<'a, P>> {
        let inside = self.col0 <= col0
            && col0 <= col1
            && col1 + 1 < self.col0 + self.width
            && self.row0 <= row0
            && row0 <= row1
            && row1 + 1 < self.row0 + self.height;
        let s = self.stride;
        if !inside || s >= CELLS {
            return None;
        }
        let first = (row0 - self.row0) * s + (col0 - self.col0);
        let last = (row1 - self.row0) * s + (col1 - self.col0);
        let len = self.data.len();
        if last - first >= CELLS || last + s + 2 > len {
            return None;
        }
        // The blocks from the box's first cell, or from as far before it
        // as the buffer's end requires (the box's last cell still among
        // the first CELLS: `last + s + 2 ≤ len`).
        let start = first.min(len.checked_sub(s + CELLS + 1)?);
        Some(Cells {
            top: self.data[start..].first_chunk()?,
            bottom: self.data[start + s..].first_chunk()?,
            k: ROUND - self.origin(start),
            stride: s as f64,
        })
    }
}

/// `1.5 · 2⁵²`: adding it rounds a float of magnitude below 2⁵¹ to an
/// integer (ties to even), whose value is then the low mantissa bits.
const ROUND: f64 = 6_755_399_441_055_744.0;

/// How many cells a [`Cells`] holds (their top-left pixels).
pub const CELLS: usize = 1 << 16;

/// The cells of a part of a window ([`Plane::cells`]) as two blocks of
/// fixed size, the pixels from its first cell's top-left pixel and those a
/// stride on (the cells' bottom rows): a cell's index, masked into the
/// block, needs no range checks.
#[derive(Debug, Clone, Copy)]
pub struct Cells<'a, P> {
    top: &'a [P; CELLS + 1],
    bottom: &'a [P; CELLS + 1],
    /// `1.5 · 2⁵²` less the full-frame offset of the blocks' first pixel.
    k: f64,
    stride: f64,
}

impl<'a, P: Pixel> Cells<'a, P> {
    /// [`Plane::bilinear_inside_x2`] at positions whose cells lie in the
    /// box the blocks were made for and half a pixel clear of the window's
    /// edges (`col0 + 0.5 ≤ col ≤ col0 + width − 1.5`, likewise for rows):
    /// there the cells need no clamping to the window (a corner, `col −
    /// 0.5` rounded, lies between the first and the last but one column),
    /// and the values are the same bit for bit. Elsewhere the value of
    /// some cell of the blocks (never a panic).
    #[inline(always)]
    pub fn bilinear_x2(&self, col: f64x2, row: f64x2) -> f64x2 {
        let ([a, b], fx, fy) = self.cells_x2(col, row);
        interpolate(P::corners_x2(a, b), fx, fy)
    }

    /// A bound `m` of the pixels of the cells of `positions` (two at a
    /// time, as [`Cells::bilinear_x2`] takes them; [`Pixel::cells_bound`]),
    /// and so of the values there: an interpolated value is at most the
    /// float after its cell's largest pixel (the fractions lie in `[0,
    /// 1]`, rounding is monotonic, and only the last step's difference
    /// may round up, by half an ulp of at most that pixel), below any
    /// limit above `m`.
    #[inline(always)]
    pub fn corners_bound(&self, positions: impl IntoIterator<Item = (f64x2, f64x2)>) -> u32 {
        P::cells_bound(
            positions
                .into_iter()
                .map(|(col, row)| self.cells_x2(col, row).0),
        )
    }

    /// The cells of two positions (their top and bottom pairs of pixels)
    /// and the positions' fractions in them.
    #[inline(always)]
    fn cells_x2(&self, col: f64x2, row: f64x2) -> ([[&'a [P]; 2]; 2], f64x2, f64x2) {
        let (cc, rc) = rounded_x2(col, row);
        let (i, fx, fy) = cell_x2(col, row, cc, rc, self.stride, self.k);
        let [ia, ib] = i.to_array().map(|v| v.to_bits() as usize & (CELLS - 1));
        let (top, bottom): (&'a [P; CELLS + 1], &'a [P; CELLS + 1]) = (self.top, self.bottom);
        let cell = |i: usize| [&top[i..i + 2], &bottom[i..i + 2]];
        ([cell(ia), cell(ib)], fx, fy)
    }
}

/// The corners of the cells of two positions, `col − 0.5` and `row − 0.5`
/// rounded to integers, offset by [`ROUND`] (not yet clamped).
#[inline(always)]
fn rounded_x2(col: f64x2, row: f64x2) -> (f64x2, f64x2) {
    let (round, half) = (f64x2::splat(ROUND), f64x2::splat(0.5));
    ((col - half) + round, (row - half) + round)
}

/// The index of two cells with their corners `(cc, rc)` (offset by
/// [`ROUND`]) and the fractions of the positions in them. The index, `ri
/// · stride + ci` less an origin, is formed in floating point as `ri ·
/// stride + (ci + k)` with `k = 1.5 · 2⁵² − origin`: every term an integer
/// below 2⁵³ (exact), the sum `1.5 · 2⁵²` plus the index, which its low
/// mantissa bits hold (three operations on the cell's corner, which the
/// fractions need anyway).
#[inline(always)]
fn cell_x2(
    col: f64x2,
    row: f64x2,
    cc: f64x2,
    rc: f64x2,
    stride: f64,
    k: f64,
) -> (f64x2, f64x2, f64x2) {
    let round = f64x2::splat(ROUND);
    // The cell's corner in full-frame coordinates (exact).
    let (ci, ri) = (cc - round, rc - round);
    let i = ri * f64x2::splat(stride) + (ci + f64x2::splat(k));
    (i, col - ci, row - ri)
}

/// Bilinear interpolation of two cells (lane by lane) from their corners
/// and fractions: the same operations as [`Plane::bilinear`].
#[inline(always)]
fn interpolate([p00, p01, p10, p11]: [f64x2; 4], fx: f64x2, fy: f64x2) -> f64x2 {
    let top = p00 + fx * (p01 - p00);
    let bottom = p10 + fx * (p11 - p10);
    top + fy * (bottom - top)
}

impl<'a, P: Pixel> Plane<'a, P> {
    /// The same window of an 8-bit frame with its pixels as bytes; `None`
    /// for wider pixels.
    #[inline(always)]
    pub(crate) fn bytes(&self) -> Option<Plane<'a, u8>> {
        Some(Plane {
            data: P::bytes(self.data)?,
            width: self.width,
            height: self.height,
            stride: self.stride,
            col0: self.col0,
            row0: self.row0,
        })
    }
}

/// `0xff` at the indices `lo..hi` of `N` bytes, 0 elsewhere: a table whose
/// sixteen bytes from an offset are the lanes of a mask.
const fn lanes_set<const N: usize>(lo: usize, hi: usize) -> [u8; N] {
    let mut t = [0u8; N];
    let mut i = lo;
    while i < hi {
        t[i] = 0xff;
        i += 1;
    }
    t
}

/// `0xff` from index 32 on: sixteen of them from `32 − lo` are the lanes
/// `≥ lo` (see [`lanes_from16`]).
const FROM_32: [u8; 80] = lanes_set(32, 80);

/// Calls `f` with the pixels `line[start..end]` (a run; `line` holds at
/// least 16) sixteen at a time, as the vectors of the run's next pixels or
/// of the row's last sixteen ([`masked16`]), the lanes outside the run or
/// already given set to 0.
#[inline(always)]
fn run_lanes(line: &[u8], start: usize, end: usize, mut f: impl FnMut(u8x16)) {
    const LANES: usize = 16;
    let len = line.len();
    debug_assert!(start <= end && end <= len && len >= LANES);
    let mut s = start;
    while s < end {
        let p = s.min(len - LANES);
        // The run's lanes: `lo..hi`.
        let (lo, hi) = (s - p, (end - p).min(LANES));
        f(masked16(line, p, lo as isize, hi as isize - 1));
        s = p + hi;
    }
}

/// The lanes `≥ 32 − i` of sixteen as `0xff` bytes (`i` modulo 64; every
/// lane for `48 ≤ i < 64`): the lanes from `lo` at `i = 32 − lo`, one
/// unaligned load from a table instead of a loop.
#[inline(always)]
pub(crate) fn lanes_from16(i: usize) -> u8x16 {
    lanes16(&FROM_32[i & 63..][..16])
}

/// The lanes `lo..=hi` of sixteen as `0xff` bytes (`−16 ≤ lo ≤ 32`,
/// `−17 ≤ hi ≤ 31`; none for `lo > hi`): a run of a row as a mask.
#[inline(always)]
pub(crate) fn run16(lo: isize, hi: isize) -> u8x16 {
    debug_assert!((-16..=32).contains(&lo) && (-17..=31).contains(&hi));
    lanes_from16((32 - lo) as usize) & !lanes_from16((31 - hi) as usize)
}

/// The sixteen pixels `line[p..p + 16]` with the lanes outside `lo..=hi`
/// (lane `i` is `line[p + i]`; [`run16`]'s ranges) set to 0: a run of a
/// row as one vector.
#[inline(always)]
pub(crate) fn masked16(line: &[u8], p: usize, lo: isize, hi: isize) -> u8x16 {
    lanes16(&line[p..p + 16]) & run16(lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::window;

    /// The vector paths for 8-bit rows equal the plain ones: a run's
    /// statistics for every run of rows of 16 to 70 pixels (loads clamped
    /// to the row's end, runs over several blocks) at saturation levels
    /// from 0 to above 255; which quarters of 256 pixels hold foreground,
    /// and the masks of blocks of 64, at levels from 0 to 255.
    #[test]
    fn u8_runs_and_quarters_equal_the_plain_ones() {
        let mut x = 3u64;
        let mut next = move || {
            x = x
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1442695040888963407);
            (x >> 33) as u32
        };
        for len in [16usize, 17, 31, 40, 70] {
            let line: Vec<u8> = (0..len)
                .map(|_| {
                    if next() % 4 == 0 {
                        255
                    } else {
                        (next() % 256) as u8
                    }
                })
                .collect();
            for saturation in [0u32, 1, 100, 200, 254, 255, 256, 1000] {
                for start in 0..len {
                    for end in start..=len {
                        assert_eq!(
                            u8::run_stats(&line, start, end, saturation),
                            scalar_run_stats(&line[start..end], saturation),
                            "{len} {start} {end} {saturation}"
                        );
                    }
                }
            }
        }
        for round in 0..200 {
            let mut block = [0u8; 256];
            for v in block.iter_mut() {
                *v = (next() % 60) as u8;
            }
            for _ in 0..round % 4 {
                block[(next() % 256) as usize] = (next() % 256) as u8;
            }
            for level in [0u32, 30, 59, 60, 100, 200, 254, 255] {
                let t = Threshold::global(level);
                let plain = block
                    .chunks_exact(64)
                    .enumerate()
                    .map(|(k, q)| (q.iter().any(|&v| t.is_foreground(v as u32)) as u32) << k)
                    .sum::<u32>();
                assert_eq!(u8::lit_quarters(&block, t), plain, "{level}");
                for q in block.chunks_exact(64) {
                    let q: &[u8; 64] = q.try_into().unwrap();
                    let plain = (0..64)
                        .map(|i| (t.is_foreground(q[i] as u32) as u64) << i)
                        .sum::<u64>();
                    assert_eq!(u8::lit_mask(q, t), plain, "{level}");
                    assert_eq!(u8::above_mask(q, t), plain, "{level}");
                }
            }
        }
    }

    #[test]
    fn bilinear_interpolates_between_centres() {
        let data = [0u8, 10, 20, 30, 40, 50];
        let p = Plane::whole(&data, 3, 2);
        assert_eq!(p.bilinear(0.0, 0.0), Some(0.0));
        assert_eq!(p.bilinear(0.5, 0.0), Some(5.0));
        assert_eq!(p.bilinear(1.0, 0.5), Some(25.0));
        assert_eq!(p.bilinear(2.0, 1.0), Some(50.0));
        assert_eq!(p.bilinear(2.0, 0.5), Some(35.0));
        assert_eq!(p.bilinear(1.5, 1.0), Some(45.0));
        assert_eq!(p.bilinear(0.0, 1.1), None);
        assert_eq!(p.bilinear(f64::NAN, 0.0), None);
        for (c, r) in [
            (0.0, 0.0),
            (0.5, 0.0),
            (1.0, 0.5),
            (2.0, 1.0),
            (1.7, 0.2),
            (1.0, 1.0),
            (0.25, 0.75),
        ] {
            assert_eq!(Some(p.bilinear_inside(c, r)), p.bilinear(c, r));
        }
        assert_eq!(p.bilinear(2.1, 0.0), None);
        assert_eq!(p.bilinear(-0.1, 0.0), None);
        assert_eq!(u16::max_of(&[3, 900, 7]), 900);
    }

    /// The unchecked sampling equals the checked one bit for bit anywhere
    /// in the hull of the pixel centres (integer, half-integer and other
    /// positions; windows at even and odd origins), and outside it stays
    /// a value, never a panic.
    #[test]
    fn bilinear_inside_equals_bilinear_in_the_hull() {
        let (w, h) = (23usize, 17usize);
        let data: Vec<u16> = (0..w * h).map(|i| ((i * 7919) % 4096) as u16).collect();
        let mut x = 99u64;
        let mut unit = move || {
            x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        for (c0, r0, ww, hh) in [(0, 0, w, h), (1, 2, 20, 13), (2, 1, 7, 9), (3, 3, 2, 2)] {
            let win = window(&data, w, (c0, r0, ww, hh));
            let (cl, rl) = (win.last_col() as f64, win.last_row() as f64);
            for k in 0..4000 {
                let (mut c, mut r) = (
                    c0 as f64 + unit() * (cl - c0 as f64),
                    r0 as f64 + unit() * (rl - r0 as f64),
                );
                // Every fourth on the grid of half pixels.
                if k % 4 == 0 {
                    c = (2.0 * c).round() / 2.0;
                    r = (2.0 * r).round() / 2.0;
                }
                let want = win.bilinear(c, r).unwrap();
                assert_eq!(
                    win.bilinear_inside(c, r).to_bits(),
                    want.to_bits(),
                    "{c} {r}"
                );
            }
            for (c, r) in [
                (-3.0, 0.5),
                (cl + 4.0, rl + 9.0),
                (f64::NAN, 1.0),
                (1e12, -1e12),
            ] {
                let _ = win.bilinear_inside(c, r);
            }
        }
    }

    /// Two positions at a time equal one at a time bit for bit (8 and 16
    /// bits, windows at even and odd origins, integer, half-integer and
    /// other positions, the hull's edges); outside the hull, still values.
    #[test]
    fn bilinear_inside_x2_equals_bilinear_in_the_hull() {
        let (w, h) = (23usize, 17usize);
        let d16: Vec<u16> = (0..w * h).map(|i| ((i * 7919) % 65536) as u16).collect();
        let d8: Vec<u8> = (0..w * h).map(|i| ((i * 7919) % 256) as u8).collect();
        let mut x = 7u64;
        let mut unit = move || {
            x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        fn check<P: Pixel>(win: &Plane<P>, a: (f64, f64), b: (f64, f64)) {
            let v = win.bilinear_inside_x2(f64x2::new([a.0, b.0]), f64x2::new([a.1, b.1]));
            let [va, vb] = v.to_array();
            assert_eq!(
                va.to_bits(),
                win.bilinear(a.0, a.1).unwrap().to_bits(),
                "{a:?}"
            );
            assert_eq!(
                vb.to_bits(),
                win.bilinear(b.0, b.1).unwrap().to_bits(),
                "{b:?}"
            );
        }
        for (c0, r0, ww, hh) in [(0, 0, w, h), (1, 2, 20, 13), (2, 1, 7, 9), (3, 3, 2, 2)] {
            let (win8, win16) = (
                window(&d8, w, (c0, r0, ww, hh)),
                window(&d16, w, (c0, r0, ww, hh)),
            );
            let (cl, rl) = (win8.last_col() as f64, win8.last_row() as f64);
            let (c0, r0) = (c0 as f64, r0 as f64);
            let mut pos = |k: usize| {
                let (c, r) = (c0 + unit() * (cl - c0), r0 + unit() * (rl - r0));
                match k % 4 {
                    0 => ((2.0 * c).round() / 2.0, (2.0 * r).round() / 2.0),
                    1 => ([c0, cl][k / 4 % 2], r),
                    2 => (c, [r0, rl][k / 4 % 2]),
                    _ => (c, r),
                }
            };
            for k in 0..4000 {
                let (a, b) = (pos(k), pos(k + 1));
                check(&win8, a, b);
                check(&win16, a, b);
            }
            for (c, r) in [
                (-3.0, 0.5),
                (cl + 4.0, rl + 9.0),
                (f64::NAN, 1.0),
                (1e12, -1e12),
            ] {
                let _ = win16.bilinear_inside_x2(f64x2::new([c, c0]), f64x2::new([r, r0]));
            }
        }
    }

    /// Cells in fixed-size blocks (no clamping, no range checks) give two
    /// positions at a time as one at a time bit for bit wherever their
    /// cells lie in the box and half a pixel clear of the window's edges (8
    /// and 16 bits, windows at even and odd origins, boxes at the buffer's
    /// start and end, integer, half-integer and other positions, the
    /// box's edges); boxes too large or too near the buffer's end have
    /// none.
    #[test]
    fn cells_interpolate_two_at_a_time_as_one_at_a_time() {
        let (w, h) = (301usize, 260usize);
        let d16: Vec<u16> = (0..w * h).map(|i| ((i * 7919) % 65536) as u16).collect();
        let d8: Vec<u8> = (0..w * h).map(|i| ((i * 7919) % 256) as u8).collect();
        let mut rng = crate::testutil::Rng::new(11);
        let mut next = move || rng.next_u64() >> 11;
        fn check<P: Pixel>(win: &Plane<P>, cells: &Cells<P>, a: (f64, f64), b: (f64, f64)) {
            let v = cells.bilinear_x2(f64x2::new([a.0, b.0]), f64x2::new([a.1, b.1]));
            let [va, vb] = v.to_array();
            let want = |(c, r): (f64, f64)| win.bilinear(c, r).unwrap().to_bits();
            assert_eq!(va.to_bits(), want(a), "{a:?}");
            assert_eq!(vb.to_bits(), want(b), "{b:?}");
        }
        let (mut edges, mut ends) = (0, 0);
        for (c0, r0, ww, hh) in [
            (0, 0, w, h),
            (1, 2, 290, 250),
            (2, 1, 77, 256),
            (5, 40, 80, 79),
        ] {
            let (win8, win16) = (
                window(&d8, w, (c0, r0, ww, hh)),
                window(&d16, w, (c0, r0, ww, hh)),
            );
            for k in 0..60 {
                // A box inside the window short of its last column and
                // row, at most 150 rows (the last ones now and then).
                let (bw, bh) = (
                    1 + next() as usize % (ww - 1),
                    1 + next() as usize % (hh - 1).min(150),
                );
                let bc = c0 + next() as usize % (ww - bw);
                let br = if k % 4 == 0 {
                    r0 + hh - 1 - bh
                } else {
                    r0 + next() as usize % (hh - bh)
                };
                let (lo, hi) = ((bc, br), (bc + bw - 1, br + bh - 1));
                let span = (bh - 1) * w + bw - 1;
                let Some(cells) = win8.cells(lo, hi) else {
                    assert!(
                        span >= CELLS
                            || win8.data.len() < (br - r0 + bh) * w + 2
                            || win8.data.len() < w + CELLS + 1,
                        "{lo:?} {hi:?}"
                    );
                    continue;
                };
                let cells16 = win16.cells(lo, hi).unwrap();
                let first = (br - r0) * w + bc - c0;
                ends += (win8.data.len() - first < w + CELLS + 1) as usize;
                // Positions whose cells lie in the box.
                let (cl, ch) = (bc as f64 + 0.5, (bc + bw - 1) as f64 + 0.5);
                let (rl, rh) = (br as f64 + 0.5, (br + bh - 1) as f64 + 0.5);
                let unit = |v: u64| (v % 1_000_003) as f64 / 1_000_003.0;
                for j in 0..200 {
                    let mut pos = |j: usize| {
                        let (c, r) = (cl + unit(next()) * (ch - cl), rl + unit(next()) * (rh - rl));
                        match j % 4 {
                            0 => ((2.0 * c).round() / 2.0, (2.0 * r).round() / 2.0),
                            1 => ([cl, ch][j / 4 % 2], r),
                            2 => (c, [rl, rh][j / 4 % 2]),
                            _ => (c, r),
                        }
                    };
                    let (a, b) = (pos(j), pos(j + 1));
                    edges += (j % 4 == 1) as usize;
                    check(&win8, &cells, a, b);
                    check(&win16, &cells16, a, b);
                }
            }
        }
        assert!(edges > 10000 && ends > 20, "{edges} {ends}");
        // None: a box spanning more than CELLS pixels, a buffer too short.
        let win = window(&d8, w, (0, 0, w, h));
        assert!(win.cells((0, 0), (10, CELLS / w + 1)).is_none());
        assert!(window(&d8, w, (0, h - 100, w, 100))
            .cells((0, h - 90), (5, h - 80))
            .is_none());
        assert!(win.cells((3, 4), (w - 1, 5)).is_none() && win.cells((3, 4), (w - 2, 5)).is_some());
    }

    /// A bound of the pixels of cells is at least their largest, and no
    /// value interpolated in them exceeds the float after it (8 and 16
    /// bits, flat and steep cells, positions on the cells' edges and just
    /// inside them): below a limit above the bound, every value is too.
    #[test]
    fn cells_bound_their_values() {
        let (w, h) = (300usize, 240usize);
        let mut rng = crate::testutil::Rng::new(5);
        let mut next = move || rng.next_u64() >> 11;
        let d8: Vec<u8> = (0..w * h)
            .map(|_| match next() % 4 {
                0 => 255,
                1 => (next() % 8) as u8,
                _ => (next() % 256) as u8,
            })
            .collect();
        let d16: Vec<u16> = d8
            .iter()
            .map(|&v| v as u16 * 257 - (next() % 200) as u16 * (v > 0) as u16)
            .collect();
        fn check<P: Pixel>(win: &Plane<P>, cells: &Cells<P>, a: (f64, f64), b: (f64, f64)) {
            let (col, row) = (f64x2::new([a.0, b.0]), f64x2::new([a.1, b.1]));
            let bound = cells.corners_bound([(col, row)]);
            for (c, r) in [a, b] {
                let (ci, ri) = (
                    (c - 0.5).round_ties_even() as usize,
                    (r - 0.5).round_ties_even() as usize,
                );
                for (dc, dr) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    assert!(win.at(ci + dc, ri + dr) <= bound as f64, "{c} {r}");
                }
            }
            let v = cells.bilinear_x2(col, row).to_array();
            let limit = (bound as f64).next_up();
            assert!(v.iter().all(|&v| v <= limit), "{a:?} {b:?} {v:?} {bound}");
        }
        let (win8, win16) = (
            window(&d8, w, (1, 1, w - 2, h - 2)),
            window(&d16, w, (1, 1, w - 2, h - 2)),
        );
        // (A box of fewer than CELLS pixels.)
        let (lo, hi) = ((1, 1), (w - 3, 200));
        let (cells8, cells16) = (win8.cells(lo, hi).unwrap(), win16.cells(lo, hi).unwrap());
        let unit = |v: u64| (v % 1_000_003) as f64 / 1_000_003.0;
        for k in 0..200_000 {
            let mut pos = || {
                let (c, r) = (
                    1.5 + unit(next()) * (w as f64 - 4.0),
                    1.5 + unit(next()) * 198.0,
                );
                match k % 4 {
                    0 => (c.floor() + 0.5, r.floor() + 0.5),
                    1 => (c.floor() + 1.0 - 1e-12, r.floor() + 1.0 - 1e-12),
                    2 => (c.floor() + 1e-9, r),
                    _ => (c, r),
                }
            };
            let (a, b) = (pos(), pos());
            check(&win8, &cells8, a, b);
            check(&win16, &cells16, a, b);
        }
    }

    /// The 8-bit corners of two cells (two pixels a load, interleaved and
    /// widened in vectors) are the plain ones, for every byte value in
    /// every corner and lane.
    #[test]
    fn u8_corners_equal_the_plain_ones() {
        let s = 5;
        for v in 0..=255u8 {
            for k in 0..8 {
                let mut a = [17u8, 200, 0, 3, 9, 255, 1, 128];
                let mut b = [255u8, 0, 7, 77, 1, 2, 254, 31];
                let at = [0, 1, s, s + 1][k % 4];
                if k < 4 {
                    a[at] = v
                } else {
                    b[at] = v
                }
                let (a, b) = ([&a[..], &a[s..]], [&b[..], &b[s..]]);
                assert_eq!(
                    u8::corners_x2(a, b).map(|c| c.to_array()),
                    corners_x2(a, b).map(|c| c.to_array()),
                    "{v} {k}"
                );
            }
        }
    }

    #[test]
    fn a_window_interpolates_like_its_frame() {
        // 5 × 4 frame, value = 7·col + 13·row + (col·row) % 5.
        let data: Vec<u16> = (0..4)
            .flat_map(|r| (0..5).map(move |c| 7 * c + 13 * r + (c * r) % 5))
            .collect();
        let whole = Plane::whole(&data, 5, 4);
        // The window 3 × 2 at (1, 2), rows 5 apart.
        let win = window(&data, 5, (1, 2, 3, 2));
        assert_eq!(win.row(3), &data[16..19]);
        assert_eq!(win.at(3, 2), whole.at(3, 2));
        for (c, r) in [
            (1.0, 2.0),
            (1.5, 2.25),
            (2.9, 3.0),
            (3.0, 2.5),
            (2.0, 2.0),
            (1.0, 3.0),
        ] {
            assert_eq!(win.bilinear(c, r), whole.bilinear(c, r), "{c} {r}");
            assert_eq!(
                Some(win.bilinear_inside(c, r)),
                whole.bilinear(c, r),
                "{c} {r}"
            );
        }
        for (c, r) in [(0.9, 2.5), (1.5, 1.9), (3.1, 2.5), (2.0, 3.1)] {
            assert_eq!(win.bilinear(c, r), None, "{c} {r}");
        }
        assert!(whole.bilinear(0.9, 2.5).is_some());
    }
}

/// The short rows of a tracking window (at most 64 pixels, grown on row
/// masks by [`SeedLabeller`](crate::seed::SeedLabeller)): a row's
/// foreground mask with the largest value of its pixels, read the way
/// [`ShortRow::reading`] chose once for the window, and the grey-value
/// statistics of a blob given by its rows' masks. The plain forms go
/// through [`Pixel`]; 8-bit rows sixteen pixels at a time.
pub trait ShortRow: Pixel {
    /// How the rows of a window are read (the level, and which loads a
    /// row takes), decided once per window.
    type Reading: Copy;
    /// The largest value of rows' pixels, folded row by row
    /// ([`ShortRow::fold`]) and read once ([`ShortRow::peak`]).
    type Peak: Copy;
    /// The reading of the rows of `plane` (1 to 64 pixels wide) at
    /// `threshold`.
    fn reading(plane: &Plane<'_, Self>, threshold: Threshold) -> Self::Reading;
    /// Row `r` of `plane` (read as `reading`, formed for this plane): bit
    /// `i` set where its pixel `i` is foreground, and the largest value of
    /// its `width` pixels.
    fn read_row(plane: &Plane<'_, Self>, reading: &Self::Reading, r: usize) -> (u64, Self::Peak);
    /// The larger of two peaks.
    fn fold(a: Self::Peak, b: Self::Peak) -> Self::Peak;
    /// A peak's value.
    fn peak(p: Self::Peak) -> u32;
    /// The largest value of the pixels of a blob given by its row masks
    /// (bit `i` of `masks[k]`: column `plane.col0 + i` of row `row0 + k`;
    /// 0 if none) and how many of them are at or above `saturation`:
    /// [`Pixel::run_stats`] of all the runs of the masks.
    #[inline]
    fn masked_stats(
        plane: &Plane<'_, Self>,
        row0: usize,
        masks: &[u64],
        saturation: u32,
    ) -> (u32, u32) {
        masked_run_stats(plane, row0, masks, saturation)
    }
}

/// [`ShortRow::read_row`] one pixel at a time: window row `r`'s
/// foreground mask and the largest value of its pixels.
#[inline]
fn plain_row<P: Pixel>(plane: &Plane<'_, P>, threshold: Threshold, r: usize) -> (u64, u32) {
    let row = &plane.data[r * plane.stride..][..plane.width];
    (threshold.foreground_mask(row), P::max_of(row))
}

/// [`plain_row`] out of line: the rare path of an 8-bit window's rows
/// (its set-up would otherwise be hoisted into every pass over rows).
#[inline(never)]
#[cold]
fn plain_row_aside(plane: &Plane<'_, u8>, threshold: Threshold, r: usize) -> (u64, u32) {
    plain_row(plane, threshold, r)
}

/// [`ShortRow::masked_stats`] run by run ([`Pixel::run_stats`] of each).
#[inline]
fn masked_run_stats<P: Pixel>(
    plane: &Plane<'_, P>,
    row0: usize,
    masks: &[u64],
    saturation: u32,
) -> (u32, u32) {
    let (mut max, mut sat) = (0, 0);
    for (k, &mask) in masks.iter().enumerate() {
        let row = plane.row(row0 + k);
        let mut m = mask;
        while m != 0 {
            let start = m.trailing_zeros() as usize;
            let end = start + (!(m >> start)).trailing_zeros() as usize;
            let (a, b) = P::run_stats(row, start, end, saturation);
            (max, sat) = (max.max(a), sat + b);
            m &= !(u64::MAX >> (64 - end));
        }
    }
    (max, sat)
}

impl ShortRow for u16 {
    type Reading = Threshold;
    type Peak = u32;
    #[inline]
    fn reading(_: &Plane<'_, Self>, threshold: Threshold) -> Threshold {
        threshold
    }
    #[inline]
    fn read_row(plane: &Plane<'_, Self>, threshold: &Threshold, r: usize) -> (u64, u32) {
        plain_row(plane, *threshold, r)
    }
    #[inline(always)]
    fn fold(a: u32, b: u32) -> u32 {
        a.max(b)
    }
    #[inline(always)]
    fn peak(p: u32) -> u32 {
        p
    }
}

/// How the 8-bit rows of a window are read ([`ShortRow::reading`]): the
/// level as lanes, the loads every row of the window has room for (the
/// window's last row has the least room), and the lanes of those loads
/// that lie inside the window's width.
#[derive(Debug, Clone, Copy)]
pub struct Rows8 {
    threshold: Threshold,
    level: u8x16,
    loads: Loads8,
    /// The window's columns (bits `0..width`).
    keep: u64,
    /// The lanes inside the width of the row's last two loads of sixteen
    /// pixels (of four loads the first two lie inside; of one load the
    /// second entry is not used).
    inside: [u8x16; 2],
}

/// The loads of an 8-bit row ([`Rows8`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Loads8 {
    /// One vector (a row of at most 16 pixels).
    One,
    /// Two vectors (at most 32 pixels).
    Two,
    /// Four vectors (at most 64 pixels).
    Four,
    /// One pixel at a time (the frame holds too few pixels past the
    /// window's last row).
    Plain,
}

/// `0xff` below index 64: sixteen of them from `64 − n` are the lanes
/// below `n` (see [`Rows8`]).
const BELOW_64: [u8; 128] = lanes_set(0, 64);

/// The `N` pixels of `data` from `start`, if it holds them.
#[inline(always)]
fn block<const N: usize>(data: &[u8], start: usize) -> Option<&[u8; N]> {
    data.get(start..start.checked_add(N)?)?.try_into().ok()
}

/// Why: tracking grows about ten rows per window, each row's mask and
/// peak in a few vector operations instead of a general block mask and
/// one [`Pixel::run_stats`] per run (with the level checked once per grow:
/// tracking 162.7 M → 155.8 M instructions; the statistics over a whole
/// blob with one reduction: a further 2.9 M; a row read once, its mask
/// with its peak, the loads chosen once per window: `SeedLabeller::grow`
/// 23.8 M → 19.7 M).
impl ShortRow for u8 {
    type Reading = Rows8;
    type Peak = u8x16;

    #[inline]
    fn reading(plane: &Plane<'_, Self>, threshold: Threshold) -> Rows8 {
        // (At most 64: the lanes below.)
        let width = plane.width.clamp(1, 64);
        let room = plane
            .data
            .len()
            .saturating_sub((plane.height.max(1) - 1) * plane.stride);
        let loads = match room {
            16.. if width <= 16 => Loads8::One,
            32.. if width <= 32 => Loads8::Two,
            64.. => Loads8::Four,
            _ => Loads8::Plain,
        };
        // Lane `i` of load `k` is `BELOW_64[64 − width + 16 k + i]`, set for
        // `16 k + i < width` (four loads: of width 33 to 64).
        let last_two = if loads == Loads8::Four { 32 } else { 0 };
        let lanes = &BELOW_64[64 - width + last_two..];
        Rows8 {
            threshold,
            // (No 8-bit value lies above 255.)
            level: u8x16::splat(threshold.level().min(255) as u8),
            loads,
            keep: u64::MAX >> (64 - width),
            inside: [lanes16(&lanes[..16]), lanes16(&lanes[16..32])],
        }
    }

    #[inline(always)]
    fn read_row(plane: &Plane<'_, Self>, rd: &Rows8, r: usize) -> (u64, u8x16) {
        let start = r * plane.stride;
        let (t, inside) = (rd.level, &rd.inside);
        // (The loads were chosen for the window's last row: the blocks are
        // there. Two vectors first: tracking's windows.)
        if rd.loads == Loads8::Two {
            if let Some(b) = block::<32>(plane.data, start) {
                let (v0, v1) = (lanes16(&b[..16]), lanes16(&b[16..]));
                let m = above16(v0, t) | above16(v1, t) << 16;
                return (m as u64 & rd.keep, (v0 & inside[0]).max(v1 & inside[1]));
            }
        }
        match rd.loads {
            Loads8::One => {
                if let Some(b) = block::<16>(plane.data, start) {
                    let v = u8x16::new(*b);
                    return (above16(v, t) as u64 & rd.keep, v & inside[0]);
                }
            }
            Loads8::Four => {
                if let Some(b) = block::<64>(plane.data, start) {
                    let v = [0, 1, 2, 3].map(|k| lanes16(&b[16 * k..16 * k + 16]));
                    let p = v[0].max(v[1]).max((v[2] & inside[0]).max(v[3] & inside[1]));
                    return (mask64(v, t) & rd.keep, p);
                }
            }
            Loads8::Two | Loads8::Plain => {}
        }
        let (m, p) = plain_row_aside(plane, rd.threshold, r);
        (m, u8x16::splat(p as u8))
    }

    #[inline(always)]
    fn fold(a: u8x16, b: u8x16) -> u8x16 {
        a.max(b)
    }

    #[inline(always)]
    fn peak(p: u8x16) -> u32 {
        i16x8::from_u8x16_low(p)
            .max(i16x8::from_u8x16_high(p))
            .reduce_max() as u32
    }

    /// Sixteen pixels at a time (from the mask's next pixel, or the row's
    /// last sixteen): the mask's bits as lanes, the maximum of those lanes
    /// over all rows reduced once at the end; the saturated ones counted
    /// from a bit mask.
    #[inline]
    fn masked_stats(
        plane: &Plane<'_, Self>,
        row0: usize,
        masks: &[u64],
        saturation: u32,
    ) -> (u32, u32) {
        const BITS: u8x16 = u8x16::new([1, 2, 4, 8, 16, 32, 64, 128, 1, 2, 4, 8, 16, 32, 64, 128]);
        const SPREAD: u64 = 0x0101_0101_0101_0101;
        let len = plane.width;
        let (mut max, mut sat) = (u8x16::splat(0), 0u32);
        if len < 16 {
            return masked_run_stats(plane, row0, masks, saturation);
        }
        let sat_level = u8x16::splat(saturation.min(255) as u8);
        let mut start = (row0 - plane.row0) * plane.stride;
        for &mask in masks {
            debug_assert!(len >= 64 || mask >> len == 0);
            let row = &plane.data[start..start + len];
            start += plane.stride;
            let mut m = mask;
            while m != 0 {
                let p = (m.trailing_zeros() as usize).min(len - 16);
                let bits = m >> p & 0xffff;
                let (lo, hi) = ((bits & 0xff) * SPREAD, (bits >> 8) * SPREAD);
                let mut b = [0u8; 16];
                b[..8].copy_from_slice(&lo.to_le_bytes());
                b[8..].copy_from_slice(&hi.to_le_bytes());
                let lanes = (u8x16::new(b) & BITS).cmp_eq(BITS);
                let v = lanes16(&row[p..p + 16]);
                max = max.max(v & lanes);
                let s = v.max(sat_level).cmp_eq(v).move_mask() as u64 & bits;
                if s != 0 {
                    sat += s.count_ones();
                }
                m &= !(0xffff << p);
            }
        }
        if saturation > u8::MAX as u32 {
            sat = 0;
        }
        (Self::peak(max), sat)
    }
}

#[cfg(test)]
mod short_row_tests {
    use super::*;
    use crate::testutil::Rng;

    /// The 8-bit short rows' masks, peaks and masked statistics equal the
    /// plain ones (one pixel at a time): windows of 1 to 64 pixels and 1 to
    /// 3 rows whose last row has no pixels past it, or 16, 32, 64 or more
    /// (every kind of load), levels from 0 to 255 (none above), random
    /// masks, saturation levels at and past 255.
    #[test]
    fn u8_short_rows_equal_the_plain_ones() {
        let mut rng = Rng::new(11);
        let mut loads = Vec::new();
        for round in 0..3000 {
            let data: Vec<u8> = (0..240).map(|_| (rng.next_u64() % 256) as u8).collect();
            let width = 1 + round % 64;
            let height = 1 + round % 3;
            let room = [width, 16.max(width), 32.max(width), 64.max(width), 80][round / 3 % 5];
            let level = match round % 7 {
                0 => 255,
                1 => 254,
                2 => 0,
                _ => (rng.next_u64() % 256) as u32,
            };
            let t = Threshold::global(level);
            let plane = Plane {
                data: &data[..(height - 1) * 80 + room],
                width,
                height,
                stride: 80,
                col0: 7,
                row0: 5,
            };
            let reading = u8::reading(&plane, t);
            if !loads.contains(&reading.loads) {
                loads.push(reading.loads);
            }
            for r in 0..height {
                let px = &data[r * 80..r * 80 + width];
                let mask = (0..width).fold(0u64, |m, i| m | ((px[i] as u32 > level) as u64) << i);
                let max = px.iter().fold(0, |m, &v| m.max(v as u32));
                let (m, p) = u8::read_row(&plane, &reading, r);
                assert_eq!((m, u8::peak(p)), (mask, max), "{width} {room} {level} {r}");
                let wide: Vec<u16> = plane.data.iter().map(|&v| v as u16).collect();
                let wide = Plane {
                    data: &wide[..],
                    width,
                    height,
                    stride: 80,
                    col0: 7,
                    row0: 5,
                };
                let reading = u16::reading(&wide, t);
                assert_eq!(u16::read_row(&wide, &reading, r), (mask, max));
            }
            // A blob of three rows of the frame `data` (stride 80).
            let masks = [0, 1, 2].map(|_| rng.next_u64() & (u64::MAX >> (64 - width)));
            let sat = [200, 250, 255, 256][round % 4];
            let mut want = (0, 0);
            for (k, mask) in masks.iter().enumerate() {
                for i in (0..width).filter(|i| mask >> i & 1 != 0) {
                    let v = data[k * 80 + i] as u32;
                    want = (want.0.max(v), want.1 + (v >= sat) as u32);
                }
            }
            let plane = Plane {
                data: &data[..],
                width,
                height: 3,
                stride: 80,
                col0: 7,
                row0: 5,
            };
            assert_eq!(u8::masked_stats(&plane, 5, &masks, sat), want, "{width}");
            let wide: Vec<u16> = data.iter().map(|&v| v as u16).collect();
            let plane = Plane {
                data: &wide[..],
                width,
                height: 3,
                stride: 80,
                col0: 7,
                row0: 5,
            };
            assert_eq!(u16::masked_stats(&plane, 5, &masks, sat), want);
        }
        assert_eq!(loads.len(), 4, "{loads:?}");
    }
}
