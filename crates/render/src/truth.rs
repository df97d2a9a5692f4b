//! The truth of a rendered frame: per field target its projected centre,
//! the dot's image radius, and how far its outline stays inside the sensor.

use photopose_field::TargetKind;

/// The truth of one field target in a rendered frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetTruth {
    /// Field id.
    pub id: u64,
    /// Coded or uncoded.
    pub kind: TargetKind,
    /// Image of the circle's centre, pixels (`NaN` if behind the camera).
    pub col: f64,
    /// Image of the circle's centre, pixels.
    pub row: f64,
    /// In front of the camera, and the dot with its ring and quiet zone
    /// (coded) or dark surround (uncoded) wholly inside the frame.
    pub visible: bool,
    /// Radius of the dot's image, pixels (largest axis).
    pub radius_px: f64,
    /// Smallest distance of the image of the target's outline (coded: the
    /// quiet zone's outer circle at 4 r; uncoded: the dark surround at 2 r)
    /// from the sensor's edge, pixels; negative if it reaches outside,
    /// `-inf` if part of the target is behind the camera. A detector that
    /// needs dark background around a target asks for more than 0.
    pub margin_px: f64,
}

/// Points on a target's outline projected per frame (visibility, extent).
pub(crate) const OUTLINE: usize = 32;

/// The smallest value of a smooth periodic function sampled at equal
/// steps: the least sample refined by the parabola through it and its two
/// neighbours (never above the least sample).
pub(crate) fn outline_minimum(m: &[f64; OUTLINE]) -> f64 {
    let k = (0..OUTLINE)
        .min_by(|&a, &b| m[a].total_cmp(&m[b]))
        .unwrap_or(0);
    let (a, b, c) = (m[(k + OUTLINE - 1) % OUTLINE], m[k], m[(k + 1) % OUTLINE]);
    let curvature = a - 2.0 * b + c;
    if curvature > 1e-12 {
        b - (c - a) * (c - a) / (8.0 * curvature)
    } else {
        b
    }
}
