//! Pixel access shared by the stages: one generic code path for 8-bit and
//! 16-bit frames, and bilinear interpolation at sub-pixel positions
//! (integer coordinates are pixel centres).

/// A grey value type the detector reads.
pub trait Pixel: Copy + Send + Sync + 'static {
    /// Largest value of the type.
    const MAX: u32;
    /// The grey value.
    fn value(self) -> u32;
    /// Largest value of a slice (vectorises).
    fn max_of(chunk: &[Self]) -> u32;
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
        if !(col >= 0.0 && row >= 0.0) {
            return None;
        }
        let c0 = col.floor();
        let r0 = row.floor();
        let (ci, ri) = (c0 as usize, r0 as usize);
        if ci + 1 >= self.width || ri + 1 >= self.height {
            // Exactly on the last column or row is still inside.
            if (ci + 1 == self.width && col == c0 && ri < self.height)
                || (ri + 1 == self.height && row == r0 && ci < self.width)
            {
                return Some(self.at(ci.min(self.width - 1), ri.min(self.height - 1)));
            }
            return None;
        }
        let fx = col - c0;
        let fy = row - r0;
        let i = ri * self.width + ci;
        let p00 = self.data[i].value() as f64;
        let p01 = self.data[i + 1].value() as f64;
        let p10 = self.data[i + self.width].value() as f64;
        let p11 = self.data[i + self.width + 1].value() as f64;
        let top = p00 + fx * (p01 - p00);
        let bottom = p10 + fx * (p11 - p10);
        Some(top + fy * (bottom - top))
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
        assert_eq!(p.bilinear(2.1, 0.0), None);
        assert_eq!(p.bilinear(-0.1, 0.0), None);
        assert_eq!(u16::max_of(&[3, 900, 7]), 900);
    }
}
