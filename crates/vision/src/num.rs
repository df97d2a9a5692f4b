//! Rounding of pixel positions without libm: on baseline x86-64 (no
//! SSE4.1) `f64::floor`, `ceil` and `round` are library calls, which the
//! per-target paths (centroid windows, tracking windows) would make
//! thousands of times per frame.

use wide::{f64x2, i64x2, CmpGt, CmpLe};

/// `1.5 · 2⁵²`: adding it to an `x` with `|x| < 2³¹` leaves the nearest
/// integer (ties to even) in the low bits of the mantissa.
pub(crate) const ROUND: f64 = 6_755_399_441_055_744.0;

/// The nearest integers of both lanes (`|x| < 2³¹`) plus [`ROUND`], with
/// an add: as floats in the order of the integers (so that they can be
/// clipped as floats), the integers read with [`low_i32x2`].
#[inline(always)]
pub(crate) fn near_f64x2(x: f64x2) -> f64x2 {
    x + f64x2::splat(ROUND)
}

/// The larger of `a` and `b` in each lane, `b` where `a` is NaN: one
/// `maxpd` with SSE2 (which takes its second operand when either is
/// NaN), a comparison and a blend elsewhere.
#[inline(always)]
pub(crate) fn max_or_f64x2(a: f64x2, b: f64x2) -> f64x2 {
    #[cfg(target_feature = "sse2")]
    {
        a.fast_max(b)
    }
    #[cfg(not(target_feature = "sse2"))]
    {
        wide::CmpGe::cmp_ge(a, b).blend(a, b)
    }
}

/// The integers `n` of `n + ROUND` (see [`near_f64x2`]).
#[inline(always)]
pub(crate) fn low_i32x2(r: f64x2) -> [i32; 2] {
    r.to_array().map(|r| r.to_bits() as u32 as i32)
}

/// `2ˣ` of both lanes from `x + ROUND` (see [`near_f64x2`]), for integers
/// `−1022 ≤ x ≤ 1023`: `x` moved from the low bits of the mantissa into
/// the exponent field with its bias (exact, no conversion).
#[inline(always)]
pub(crate) fn pow2_f64x2(r: f64x2) -> f64x2 {
    let x = i64x2::from(r.to_array().map(|r| r.to_bits() as i64));
    let p: i64x2 = (x + i64x2::splat(1023)) << 52;
    f64x2::from(p.to_array().map(|p| f64::from_bits(p as u64)))
}

/// `floor` (no libm call on baseline x86-64), saturating at the ends of
/// the `i64` range like `as` (infinities included; NaN gives 0).
#[inline(always)]
pub(crate) fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    t.saturating_sub(((t as f64) > x) as i64)
}

/// [`round_i64`] of both lanes, in floats while both lie within ±2³⁰
/// (the nearest integer of `x + 0.5`, less one where it lies above: exact
/// there), else one at a time.
#[inline(always)]
pub(crate) fn round_i64x2(x: f64x2) -> [i64; 2] {
    const LIMIT: f64 = (1u64 << 30) as f64;
    let y = x + f64x2::splat(0.5);
    // (NaN fails the comparison: one at a time.)
    if !y.abs().cmp_le(f64x2::splat(LIMIT)).all() {
        return x.to_array().map(round_i64);
    }
    let n = near_f64x2(y) - f64x2::splat(ROUND);
    let floor = n - (n.cmp_gt(y) & f64x2::splat(1.0));
    low_i32x2(near_f64x2(floor)).map(i64::from)
}

/// `ceil`, see [`floor_i64`].
#[inline(always)]
pub(crate) fn ceil_i64(x: f64) -> i64 {
    let t = x as i64;
    t.saturating_add(((t as f64) < x) as i64)
}

/// Nearest integer, see [`floor_i64`].
#[inline(always)]
pub(crate) fn round_i64(x: f64) -> i64 {
    floor_i64(x + 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Powers of two from integers as `x + ROUND`, at the ends of the
    /// exponent's range too.
    #[test]
    fn powers_of_two() {
        for e in (-1022..=1023).step_by(7).chain([-1022, 0, 32, 1023]) {
            let got = pow2_f64x2(f64x2::new([e as f64, -1.0]) + f64x2::splat(ROUND));
            assert_eq!(got.to_array(), [2f64.powi(e), 0.5], "{e}");
        }
    }

    /// The larger of two lanes, the second where the first is NaN.
    #[test]
    fn max_or_takes_the_second_for_nan() {
        let cases = [
            (1.0, -1.0, 1.0),
            (-0.0, -1.0, -0.0),
            (-2.0, -1.0, -1.0),
            (f64::NAN, -1.0, -1.0),
            (-f64::NAN, -1.0, -1.0),
            (f64::INFINITY, -1.0, f64::INFINITY),
        ];
        for (a, b, want) in cases {
            let got = max_or_f64x2(f64x2::new([a, 0.5]), f64x2::new([b, 0.25])).to_array();
            assert_eq!(got[0].to_bits(), want.to_bits(), "{a} {b}");
            assert_eq!(got[1], 0.5);
        }
    }

    #[test]
    fn rounding_helpers() {
        for x in [-3.7, -3.5, -0.2, 0.0, 0.5, 1.5, 2.49, 1299.51] {
            assert_eq!(
                low_i32x2(near_f64x2(f64x2::new([x, -x]))),
                [x, -x].map(|x| x.round_ties_even() as i32),
                "{x}"
            );
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
            assert_eq!(ceil_i64(x), x.ceil() as i64, "{x}");
        }
        // Past the ends of `i64`: saturated as `as` saturates, never
        // wrapped (a debug build would panic).
        for x in [f64::INFINITY, f64::NEG_INFINITY, 1e300, -1e300, f64::NAN] {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
            assert_eq!(ceil_i64(x), x.ceil() as i64, "{x}");
            assert_eq!(round_i64(x), (x + 0.5).floor() as i64, "{x}");
        }
        // Two at a time: within ±2³⁰ in floats, else (NaN, past it) one
        // at a time, the same either way.
        let xs = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            0.49999999999999994,
            -0.49999999999999994,
            1073741823.5,
            -1073741824.5,
            1073741824.0,
            1e9 + 0.5,
            4e9,
            -4e9,
            1e300,
            f64::INFINITY,
            f64::NAN,
            3.7,
            -3.7,
            1299.51,
        ];
        for &a in &xs {
            for &b in &xs {
                let got = round_i64x2(f64x2::new([a, b]));
                assert_eq!(got, [round_i64(a), round_i64(b)], "{a} {b}");
            }
        }
    }
}
