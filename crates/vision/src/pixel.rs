//! Pixel access shared by the stages: one generic code path for 8-bit and
//! 16-bit frames, and bilinear interpolation at sub-pixel positions
//! (integer coordinates are pixel centres).

use wide::u8x16;

/// A grey value type the detector reads.
pub trait Pixel: Copy + Send + Sync + 'static {
    /// Largest value of the type.
    const MAX: u32;
    /// The grey value.
    fn value(self) -> u32;
    /// Largest value of a slice (vectorises).
    fn max_of(chunk: &[Self]) -> u32;
    /// Bit `i` set if `block[i] > threshold`, for a block of at most 64 pixels.
    #[inline]
    fn above_mask(block: &[Self], threshold: u32) -> u64 {
        debug_assert!(block.len() <= 64);
        let mut m = 0u64;
        for (i, p) in block.iter().enumerate() {
            m |= ((p.value() > threshold) as u64) << i;
        }
        m
    }
}

impl Pixel for u8 {
    const MAX: u32 = u8::MAX as u32;
    #[inline(always)]
    fn value(self) -> u32 {
        self as u32
    }
    #[inline(always)]
    fn max_of(chunk: &[Self]) -> u32 {
        chunk.iter().fold(0u8, |m, &p| m.max(p)) as u32
    }
    /// Sixteen pixels at a time (SSE2 on x86-64).
    #[inline]
    fn above_mask(block: &[Self], threshold: u32) -> u64 {
        debug_assert!(block.len() <= 64);
        if threshold >= u8::MAX as u32 {
            return 0;
        }
        let t = u8x16::splat(threshold as u8);
        let zero = u8x16::splat(0);
        // 0xffff where all sixteen are `≤ t`, else the lanes `≤ t`.
        let dark = |v: u8x16| v.saturating_sub(t).cmp_eq(zero).move_mask() as u32 & 0xffff;
        let load = |c: &[u8]| u8x16::new(c.try_into().unwrap_or([0; 16]));
        if let Ok(b) = <&[u8; 64]>::try_from(block) {
            let v = [
                load(&b[..16]),
                load(&b[16..32]),
                load(&b[32..48]),
                load(&b[48..]),
            ];
            // A dark block (most of a frame) costs one test.
            if dark(v[0].max(v[1]).max(v[2].max(v[3]))) == 0xffff {
                return 0;
            }
            let mut m = 0u64;
            for (k, &x) in v.iter().enumerate() {
                m |= ((!dark(x) & 0xffff) as u64) << (16 * k);
            }
            return m;
        }
        let mut chunks = block.chunks_exact(16);
        let mut m = 0u64;
        let mut shift = 0;
        for c in &mut chunks {
            m |= ((!dark(load(c)) & 0xffff) as u64) << shift;
            shift += 16;
        }
        for (i, &p) in chunks.remainder().iter().enumerate() {
            m |= ((p as u32 > threshold) as u64) << (shift + i);
        }
        m
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

/// A borrowed grey-value plane.
#[derive(Debug, Clone, Copy)]
pub struct Plane<'a, P> {
    /// Row-major pixels.
    pub data: &'a [P],
    /// Width.
    pub width: usize,
    /// Height.
    pub height: usize,
}

impl<P: Pixel> Plane<'_, P> {
    /// Grey value at an integer position (must be inside).
    #[inline(always)]
    pub fn at(&self, col: usize, row: usize) -> f64 {
        self.data[row * self.width + col].value() as f64
    }

    /// Bilinear interpolation at `(col, row)`; `None` outside the pixel
    /// centres' hull.
    #[inline]
    pub fn bilinear(&self, col: f64, row: f64) -> Option<f64> {
        let (w, h) = (self.width, self.height);
        // Inside the hull of the pixel centres (false for NaN).
        // (Signed conversions: a single instruction each on x86-64.)
        let (wl, hl) = (w as i64 - 1, h as i64 - 1);
        if !(col >= 0.0 && row >= 0.0 && col <= wl as f64 && row <= hl as f64) {
            return None;
        }
        if w < 2 || h < 2 {
            return Some(self.at(col as usize, row as usize));
        }
        // Truncation is the floor for non-negative values (and needs no
        // libm call on baseline x86-64). On the last column or row, the
        // cell to the left or above is used with a fraction of exactly 1.
        let (ci, ri) = ((col as i64).min(wl - 1), (row as i64).min(hl - 1));
        let fx = col - ci as f64;
        let fy = row - ri as f64;
        let i = ri as usize * w + ci as usize;
        let top = &self.data[i..i + 2];
        let bottom = &self.data[i + w..i + w + 2];
        let (p00, p01) = (top[0].value() as f64, top[1].value() as f64);
        let (p10, p11) = (bottom[0].value() as f64, bottom[1].value() as f64);
        let top = p00 + fx * (p01 - p00);
        let bottom = p10 + fx * (p11 - p10);
        Some(top + fy * (bottom - top))
    }
}

impl<P: Pixel> Plane<'_, P> {
    /// [`Plane::bilinear`] at a position the caller knows to lie inside the
    /// pixel centres' hull (`0 ≤ col ≤ width − 1`, `0 ≤ row ≤ height − 1`,
    /// at least 2 × 2 pixels); outside it, the value is that of a nearby
    /// position (never a panic for finite positions).
    #[inline(always)]
    pub fn bilinear_inside(&self, col: f64, row: f64) -> f64 {
        let (w, h) = (self.width, self.height);
        // The cell's corner: `col − 0.5` rounded to an integer by adding
        // 1.5 · 2⁵² (its low mantissa bits are the integer). That is the
        // floor of `col`, or one less for an integer `col`, where the
        // fraction is then 1 and the interpolation gives the same value.
        const ROUND: f64 = 6_755_399_441_055_744.0;
        let ci = (((col - 0.5) + ROUND).to_bits() as u32 as usize).min(w - 2);
        let ri = (((row - 0.5) + ROUND).to_bits() as u32 as usize).min(h - 2);
        let fx = col - ci as f64;
        let fy = row - ri as f64;
        let i = ri * w + ci;
        // One range check for the 2 × 2 cell.
        let cell = &self.data[i..i + w + 2];
        let (p00, p01) = (cell[0].value() as f64, cell[1].value() as f64);
        let (p10, p11) = (cell[w].value() as f64, cell[w + 1].value() as f64);
        let top = p00 + fx * (p01 - p00);
        let bottom = p10 + fx * (p11 - p10);
        top + fy * (bottom - top)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_interpolates_between_centres() {
        let data = [0u8, 10, 20, 30, 40, 50];
        let p = Plane {
            data: &data,
            width: 3,
            height: 2,
        };
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
}
