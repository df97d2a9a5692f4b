//! Fast deterministic Gaussian noise for rendering: a SplitMix64 stream
//! indexing a table of standard-normal quantiles (65 536 equiprobable
//! values, so the tails end at about ±4.3 σ — harmless for image noise).

use photopose_geometry::rng::SplitMix64;

const BITS: u32 = 16;

/// Standard-normal deviates.
#[derive(Debug, Clone)]
pub(crate) struct Normal {
    table: Vec<f32>,
    rng: SplitMix64,
    buffer: u64,
    left: u32,
}

impl Normal {
    pub fn new() -> Self {
        let n = 1usize << BITS;
        let raw: Vec<f64> = (0..n)
            .map(|i| inverse_normal_cdf((i as f64 + 0.5) / n as f64))
            .collect();
        // Mid-bin quantiles understate the spread of the wide tail bins:
        // scale the table to unit variance exactly.
        let var = raw.iter().map(|x| x * x).sum::<f64>() / n as f64;
        let table = raw.iter().map(|x| (x / var.sqrt()) as f32).collect();
        Normal {
            table,
            rng: SplitMix64::new(0),
            buffer: 0,
            left: 0,
        }
    }

    pub fn reseed(&mut self, seed: u64) {
        self.rng = SplitMix64::new(seed);
        self.left = 0;
    }

    /// Four deviates from one generator step; the same values, in the same
    /// order, as four calls of [`Normal::next`] at a step boundary (which
    /// is where [`Normal::reseed`] leaves the stream).
    #[inline]
    pub fn next4(&mut self) -> [f32; 4] {
        debug_assert_eq!(self.left, 0);
        let x = self.rng.next_u64();
        let m = (1u64 << BITS) - 1;
        [
            self.table[(x & m) as usize],
            self.table[((x >> BITS) & m) as usize],
            self.table[((x >> (2 * BITS)) & m) as usize],
            self.table[(x >> (3 * BITS)) as usize],
        ]
    }

    #[inline]
    pub fn next(&mut self) -> f32 {
        if self.left == 0 {
            self.buffer = self.rng.next_u64();
            self.left = 64 / BITS;
        }
        let i = (self.buffer & ((1 << BITS) - 1)) as usize;
        self.buffer >>= BITS;
        self.left -= 1;
        self.table[i]
    }
}

/// Acklam's rational approximation of the standard-normal quantile
/// (relative error below 1.2e-9), refined by one Halley step.
fn inverse_normal_cdf(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383_577_518_672_69e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let lo = 0.02425;
    if p < lo {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - lo {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -inverse_normal_cdf(1.0 - p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deviates_are_standard_normal() {
        let mut n = Normal::new();
        n.reseed(42);
        let k = 200_000;
        let (mut s, mut s2) = (0.0f64, 0.0f64);
        for _ in 0..k {
            let x = n.next() as f64;
            s += x;
            s2 += x * x;
        }
        let mean = s / k as f64;
        let var = s2 / k as f64 - mean * mean;
        assert!(mean.abs() < 0.01, "mean {mean}");
        // Standard error of the variance over 200 000 draws: 0.003.
        assert!((var - 1.0).abs() < 0.02, "variance {var}");
        assert!((inverse_normal_cdf(0.975) - 1.959964).abs() < 1e-5);
        // Blocks of four are the single-value stream.
        let (mut a, mut b) = (Normal::new(), Normal::new());
        a.reseed(7);
        b.reseed(7);
        let four: Vec<f32> = (0..3).flat_map(|_| a.next4()).collect();
        let one: Vec<f32> = (0..12).map(|_| b.next()).collect();
        assert_eq!(four, one);
    }
}
