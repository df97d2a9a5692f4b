//! The rendering options (sampling, noise, blur, radiometry) and their checks.

use crate::RenderError;

/// Rendering options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Samples per pixel side at corners of the pattern (1 = point sampling
    /// everywhere, no anti-aliasing; ≥ 2: exact coverage at single edges).
    pub supersample: u32,
    /// Gaussian noise, grey values (DN of the output image).
    pub noise_dn: f64,
    /// Gaussian blur σ, pixels (0 = none).
    pub blur_px: f64,
    /// Seed of the noise.
    pub seed: u64,
    /// Background level as a share of the saturation level.
    pub background: f64,
    /// Brightness of a target on the optical axis at the reference distance,
    /// as a share of the saturation level.
    pub target: f64,
    /// Distance at which a target has the brightness `target`, mm (without
    /// auto-exposure).
    pub reference_distance_mm: f64,
    /// Set the exposure per frame so that the nearest target in view has the
    /// brightness `target`, as a camera's auto-exposure would.
    pub auto_exposure: bool,
    /// Half angle of the ring light's beam, degrees: the light on a target
    /// falls as `cosᵐ` of its angle off the optical axis, to half at this
    /// angle (on top of the inverse square of the distance and the lens's
    /// cos⁴). 0: a uniform beam (the default).
    pub beam_half_angle_deg: f64,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            supersample: 4,
            noise_dn: 2.0,
            blur_px: 0.6,
            seed: 1,
            background: 0.05,
            target: 0.8,
            reference_distance_mm: 1000.0,
            auto_exposure: true,
            beam_half_angle_deg: 0.0,
        }
    }
}

impl RenderOptions {
    pub(crate) fn check(&self) -> Result<(), RenderError> {
        let bad = |name, value: f64, why| Err(RenderError::Option { name, value, why });
        if !(1..=16).contains(&self.supersample) {
            return bad("supersample", self.supersample as f64, "must be 1..=16");
        }
        if !(self.noise_dn.is_finite() && self.noise_dn >= 0.0) {
            return bad("noise_dn", self.noise_dn, "must be ≥ 0");
        }
        if !(self.blur_px.is_finite() && (0.0..=10.0).contains(&self.blur_px)) {
            return bad("blur_px", self.blur_px, "must be 0..=10 pixels");
        }
        if !(self.background.is_finite() && (0.0..1.0).contains(&self.background)) {
            return bad("background", self.background, "must be in [0, 1)");
        }
        if !(self.target.is_finite() && self.target > 0.0 && self.target <= 4.0) {
            return bad("target", self.target, "must be in (0, 4]");
        }
        if !(self.reference_distance_mm.is_finite() && self.reference_distance_mm > 0.0) {
            return bad(
                "reference_distance_mm",
                self.reference_distance_mm,
                "must be positive",
            );
        }
        if !(self.beam_half_angle_deg.is_finite()
            && (0.0..90.0).contains(&self.beam_half_angle_deg))
        {
            return bad(
                "beam_half_angle_deg",
                self.beam_half_angle_deg,
                "must be in [0, 90) degrees",
            );
        }
        Ok(())
    }
}
