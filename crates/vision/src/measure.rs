//! Sub-pixel centre of a blob: background-subtracted, intensity-weighted
//! centroid over the blob's bounding box grown by 2 px, with the
//! intensity-weighted second moments (the ellipse) and a shape statistic.
//!
//! Every pixel of the window counts with weight `g − background`, not only
//! the pixels above the threshold: cutting the blurred edge at the threshold
//! biases the centre by several hundredths of a pixel. The window is the
//! grown box intersected with the blob's moment ellipse scaled up by the same
//! margin, so that the corners of the box never reach a coded target's ring.
//! The background is the mean of the dark pixels just outside the window.

use crate::label::Blob;
use crate::pixel::{Pixel, Plane};

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
    /// higher for a dot with a tail).
    pub kurtosis: f64,
}

/// Semi-axes and angle of the ellipse with central moments `(cxx, cyy, cxy)`
/// (a uniform ellipse with semi-axes `a, b` has moments `a²/4, b²/4`): returns
/// `(a, b, angle)` with the angle of the major axis from `+col` towards `+row`.
pub fn ellipse(cxx: f64, cyy: f64, cxy: f64) -> (f64, f64, f64) {
    let tr = cxx + cyy;
    let d = ((cxx - cyy) * (cxx - cyy) / 4.0 + cxy * cxy).sqrt();
    let l1 = (tr / 2.0 + d).max(0.0);
    let l2 = (tr / 2.0 - d).max(0.0);
    let angle = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
    (2.0 * l1.sqrt(), 2.0 * l2.sqrt(), angle)
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

/// Measures a blob; `None` if the window holds no signal.
pub fn measure<P: Pixel>(
    plane: &Plane<P>,
    blob: &Blob,
    threshold: u32,
    fallback_background: f64,
    grow: f64,
    max_scale: f64,
) -> Option<Measurement> {
    let (bx, by) = blob.centre();
    let (cxx, cyy, cxy) = blob.covariance();
    let (a, b, angle) = ellipse(cxx, cyy, cxy);
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
    let rho2 = |dx: f64, dy: f64| qxx * dx * dx + 2.0 * qxy * dx * dy + qyy * dy * dy;
    let (s_in, s_out) = (scale * scale, bg_outer * bg_outer);
    let (ux, uy) = (angle.cos(), angle.sin());
    let _ = a;

    // Window: the box grown by GROW (and one more pixel for the background).
    let g = grow.ceil() as i64 + 2;
    let c0 = (blob.col0 as i64 - g).max(0) as usize;
    let r0 = (blob.row0 as i64 - g).max(0) as usize;
    let c1 = ((blob.col1 as i64 + g) as usize).min(plane.width - 1);
    let r1 = ((blob.row1 as i64 + g) as usize).min(plane.height - 1);
    let (wc0, wr0) = (blob.col0 as f64 - grow, blob.row0 as f64 - grow);
    let (wc1, wr1) = (blob.col1 as f64 + grow, blob.row1 as f64 + grow);

    // Background: 30th percentile of the dark pixels in the ring just
    // outside the window (robust against a coded target's ring reaching
    // into it; the small downward bias for pure noise moves the centre by
    // nothing, as the window is centred on the blob).
    let mut bg_buf = [0u32; BG_SAMPLES];
    let est = std::f64::consts::PI * (s_out - s_in) * 4.0 * det.sqrt();
    let stride = (est / BG_SAMPLES as f64).ceil().max(1.0) as usize;
    let (mut bg_n, mut seen) = (0usize, 0usize);
    for row in r0..=r1 {
        let dy = row as f64 - by;
        for col in c0..=c1 {
            let dx = col as f64 - bx;
            let r2 = rho2(dx, dy);
            let in_box = (col as f64) >= wc0
                && (col as f64) <= wc1
                && (row as f64) >= wr0
                && (row as f64) <= wr1;
            if (r2 > s_in || !in_box) && r2 <= s_out {
                let v = plane.at(col, row);
                if v <= threshold as f64 {
                    if seen % stride == 0 && bg_n < BG_SAMPLES {
                        bg_buf[bg_n] = v as u32;
                        bg_n += 1;
                    }
                    seen += 1;
                }
            }
        }
    }
    let background = if bg_n >= 4 {
        let buf = &mut bg_buf[..bg_n];
        let (_, &mut q, _) = buf.select_nth_unstable(bg_n * 3 / 10);
        q as f64
    } else {
        fallback_background
    };

    // Weighted sums over the window.
    let (mut sw, mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut n_fg, mut su2, mut su4) = (0.0, 0.0, 0.0);
    let wr0i = wr0.max(0.0) as usize;
    let wr1i = (wr1 as usize).min(plane.height - 1);
    let wc0i = wc0.max(0.0) as usize;
    let wc1i = (wc1 as usize).min(plane.width - 1);
    for row in wr0i..=wr1i {
        let dy = row as f64 - by;
        for col in wc0i..=wc1i {
            let dx = col as f64 - bx;
            if rho2(dx, dy) > s_in {
                continue;
            }
            let v = plane.at(col, row);
            let w = v - background;
            sw += w;
            sx += w * dx;
            sy += w * dy;
            sxx += w * dx * dx;
            syy += w * dy * dy;
            sxy += w * dx * dy;
            if v > threshold as f64 {
                let u = dx * ux + dy * uy;
                let u2 = u * u;
                n_fg += 1.0;
                su2 += u2;
                su4 += u2 * u2;
            }
        }
    }
    if sw.is_nan() || sw <= 0.0 {
        return None;
    }
    let (mx, my) = (sx / sw, sy / sw);
    let kurtosis = if su2 > 0.0 {
        n_fg * su4 / (su2 * su2)
    } else {
        0.0
    };
    Some(Measurement {
        col: bx + mx,
        row: by + my,
        cxx: sxx / sw - mx * mx - 1.0 / 12.0,
        cyy: syy / sw - my * my - 1.0 / 12.0,
        cxy: sxy / sw - mx * my,
        signal: sw,
        background,
        kurtosis,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

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
