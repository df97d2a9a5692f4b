//! photopose-render: synthetic frames of the test field, for tests,
//! fixtures, benchmarks and the simulated robot cell.
//!
//! Every sub-pixel sample is traced back through the camera model of
//! `docs/conventions.md` (pixel → measured image coordinates → Brown/Fraser
//! correction → ray) onto the plane of the plate and looks up the target
//! pattern of `docs/coded-targets.md`; so a rendered frame obeys the camera model
//! exactly, distortion included. Pixels far from every edge of the pattern
//! take one sample; a pixel crossed by one edge gets its exact area
//! coverage (pixel → plate mapping linearised over the pixel from four
//! traced rays, circles followed in strips); a pixel at a corner of the
//! pattern (circle meets sector boundary) takes `supersample²` samples.
//! With `supersample = 1` every pixel is point-sampled (aliased, fastest).
//!
//! Radiometry of a near-infrared ring light on retro-reflective targets: a
//! dark background, targets whose brightness falls with the square of their
//! distance from the camera (relative to `reference_distance_mm`), with the
//! off-axis angle (cos⁴ vignetting) and gently with the incidence angle;
//! optionally the ring light's own beam (`cosᵐ` off the axis,
//! `beam_half_angle_deg`); then a Gaussian blur (`blur_px`) and Gaussian
//! noise (`noise_dn`) from a seeded generator, rounded and clamped to the
//! image's saturation level (`target` above 1 over-exposes: the dots clip).
//! Same options and seed, same bytes.
//!
//! Motion blur ([`Renderer::render_moving`]): the camera moves from one
//! pose to another during the exposure; the frame is the mean of
//! sub-exposures along the path, close enough that no target's image
//! moves more than [`MOTION_STEP_PX`] between two; exposure and truth are
//! those of mid-exposure.
//!
//! Code-ring phase: sector `k` spans the angles `[k·30°, (k+1)·30°)` measured
//! counter-clockwise from the plate's `+X` axis seen from `+Z`, and carries
//! bit `k` of the canonical value (bit 0 the most significant). Readers are
//! rotation-invariant, so this choice is only a convention of the drawing.
//!
//! Look-up: no global index is needed; per frame each target's outline is
//! projected (32 points on its quiet-zone circle), which gives its bounding
//! box on the sensor, its visibility and the pixel footprint on the plate.
//! Only pixels inside those boxes are traced; the rest of the frame is
//! background. A pixel is treated as an edge pixel only where its footprint
//! (0.8 × the largest plate distance of one pixel step, which covers the
//! pixel's half-diagonal) reaches a circle of the pattern or a sector
//! boundary between sectors of different bits.
//!
//! Radiometry defaults ([`RenderOptions::default`]): background 5 % of the
//! saturation level, a target on the optical axis at the reference distance
//! 80 %; with `auto_exposure` (default) the reference distance is that of
//! the nearest target in view, so the brightest targets sit near 80 %. Gain
//! of a target = `(reference / distance)²` × `cos⁴(off-axis angle)` ×
//! `(0.6 + 0.4 cos(incidence))`, evaluated at its centre. Blur σ 0.6 px,
//! noise σ 2 DN, seed 1.
//!
//! Truth: per field target, in field order, the projected circle centre, the
//! dot's image radius, and `visible` = in front of the camera with its
//! whole outline (quiet zone at 4 r, or dark surround at 2 r) on the sensor;
//! `margin_px` tells by how much.
//!
//! Invariant: no IO, no clock, no threads; a [`Renderer`] allocates nothing
//! per frame once it has rendered one frame of a given size.
//!
//! Modules: `renderer` (the frame: exposure, outlines, per-pixel coverage),
//! `pattern` (a target's reflectance and a pixel's exact coverage),
//! `blur`, `quantise` (grey values and noise), `truth`, `options`;
//! [`plate`] (the plate's frame), [`svg`] (the drawing for printing) and
//! [`sheet`] (its annotations and its layout on paper, tiled when it does
//! not fit one sheet).

mod blur;
mod noise;
mod options;
mod pattern;
pub mod plate;
mod quantise;
mod renderer;
pub mod sheet;
pub mod svg;
mod truth;

pub use options::RenderOptions;
pub use plate::Plate;
pub use renderer::{interpolate, Renderer, MAX_SUB_EXPOSURES, MOTION_STEP_PX};
use thiserror::Error;
pub use truth::TargetTruth;

/// Why a frame cannot be rendered.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum RenderError {
    /// The output image's size differs from the camera's sensor.
    #[error("output image is {got_width}×{got_height}, the camera's sensor is {width}×{height}")]
    Size {
        /// Sensor width.
        width: u32,
        /// Sensor height.
        height: u32,
        /// Image width.
        got_width: u32,
        /// Image height.
        got_height: u32,
    },
    /// The field's targets do not lie in one plane.
    #[error(
        "the renderer draws planar plates; target {id} lies {distance:.3} mm off the plate's plane"
    )]
    NotPlanar {
        /// Target furthest off.
        id: u64,
        /// Its distance from the fitted plane, mm.
        distance: f64,
    },
    /// An option is out of range.
    #[error("render option `{name}` = {value} is invalid: {why}")]
    Option {
        /// Option name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The valid range.
        why: &'static str,
    },
    /// The field is empty.
    #[error("the test field has no targets")]
    EmptyField,
    /// A drawing cannot be laid out on paper as asked.
    #[error("cannot lay the drawing out on paper: {what}")]
    BadSheet {
        /// What is wrong (the value and the limit).
        what: String,
    },
}

#[cfg(test)]
mod tests;
