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
//! then a Gaussian blur (`blur_px`) and Gaussian noise (`noise_dn`) from a
//! seeded generator, rounded and clamped to the image's saturation level.
//! Same options and seed, same bytes.
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

mod noise;
pub mod plate;
pub mod svg;

use nalgebra::{Matrix2, Vector2, Vector3};
use noise::Normal;
use photopose_field::{codes, Field, TargetKind};
use photopose_frame::{Image, Pixels};
use photopose_geometry::{Camera, Exterior};
pub use plate::Plate;
use thiserror::Error;

/// Why a frame cannot be rendered.
#[derive(Debug, Clone, PartialEq, Error)]
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
}

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
        }
    }
}

impl RenderOptions {
    fn check(&self) -> Result<(), RenderError> {
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
        Ok(())
    }
}

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
const OUTLINE: usize = 32;

/// A target in the plate's own 2-D frame.
#[derive(Debug, Clone, Copy)]
struct Flat {
    id: u64,
    kind: TargetKind,
    /// Centre in plate coordinates, mm.
    at: Vector2<f64>,
    radius: f64,
    code: u16,
    /// Bit `k` set: the sector boundary at `k·30°` separates a bright from
    /// a dark sector.
    edges: u16,
}

/// The renderer with its scratch buffers.
#[derive(Debug, Clone)]
pub struct Renderer {
    camera: Camera,
    options: RenderOptions,
    /// Plate frame: origin, in-plane axes (u × v = n, n towards +Z).
    origin: Vector3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
    n: Vector3<f64>,
    targets: Vec<Flat>,
    /// Excess brightness of the targets over the background, per pixel.
    excess: Vec<f32>,
    scratch: Vec<f32>,
    /// Bounding boxes touched this frame `[c0, r0, c1, r1]`.
    boxes: Vec<[usize; 4]>,
    truth: Vec<TargetTruth>,
    kernel: Vec<f32>,
    normal: Normal,
}

impl Renderer {
    /// A renderer of `field` seen by `camera`.
    pub fn new(camera: Camera, field: &Field, options: RenderOptions) -> Result<Self, RenderError> {
        options.check()?;
        let Plate { origin, u, v, n } = Plate::fit(field)?;
        let targets = field
            .targets()
            .iter()
            .map(|t| {
                let d = t.position - origin;
                let code = if t.kind == TargetKind::Coded {
                    codes::value_of(t.id).unwrap_or(0)
                } else {
                    0
                };
                let edges = (0..12u32)
                    .filter(|&k| codes::sector_bit(code, k) != codes::sector_bit(code, k + 11))
                    .fold(0u16, |m, k| m | 1 << k);
                Flat {
                    id: t.id,
                    kind: t.kind,
                    at: Vector2::new(d.dot(&u), d.dot(&v)),
                    radius: t.radius,
                    code,
                    edges,
                }
            })
            .collect::<Vec<_>>();
        let size = camera.sensor.width as usize * camera.sensor.height as usize;
        let mut r = Renderer {
            camera,
            options,
            origin,
            u,
            v,
            n,
            truth: Vec::with_capacity(targets.len()),
            boxes: Vec::with_capacity(targets.len()),
            targets,
            excess: vec![0.0; size],
            scratch: vec![0.0; size],
            kernel: Vec::new(),
            normal: Normal::new(),
        };
        r.set_options(options)?;
        Ok(r)
    }

    /// Changes the options (noise, blur, seed, ...).
    pub fn set_options(&mut self, options: RenderOptions) -> Result<(), RenderError> {
        options.check()?;
        self.options = options;
        let s = options.blur_px;
        self.kernel.clear();
        if s > 0.0 {
            let k = (3.5 * s).ceil() as i32;
            for i in -k..=k {
                self.kernel
                    .push((-(i * i) as f64 / (2.0 * s * s)).exp() as f32);
            }
            let sum: f32 = self.kernel.iter().sum();
            self.kernel.iter_mut().for_each(|x| *x /= sum);
        }
        Ok(())
    }

    /// The options in force.
    pub fn options(&self) -> &RenderOptions {
        &self.options
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The truth of the last frame, one entry per field target in field order.
    pub fn truth(&self) -> &[TargetTruth] {
        &self.truth
    }

    /// A new black image of the camera's size (8-bit).
    pub fn new_image(&self) -> Image {
        Image::new_mono8(self.camera.sensor.width, self.camera.sensor.height)
    }

    /// The point of the plate's plane hit by the ray through pixel
    /// `(col, row)`, in plate coordinates; `None` if the ray misses.
    #[inline]
    fn hit(
        &self,
        e: &Exterior,
        rt: &nalgebra::Matrix3<f64>,
        col: f64,
        row: f64,
    ) -> Option<Vector2<f64>> {
        let ideal = self.camera.correct_pixel(col, row);
        let d = rt * Vector3::new(ideal.x, ideal.y, -self.camera.interior.c);
        let denom = d.dot(&self.n);
        if denom.abs() < 1e-15 {
            return None;
        }
        let s = (self.origin - e.center).dot(&self.n) / denom;
        if s <= 0.0 {
            return None;
        }
        let q = e.center + d * s - self.origin;
        Some(Vector2::new(q.dot(&self.u), q.dot(&self.v)))
    }

    /// Renders the field seen from `exterior` into `out` (8- or 16-bit,
    /// the camera's size) and returns the truth of the frame (also
    /// available afterwards from [`Renderer::truth`]), kept in the
    /// renderer's own preallocated storage.
    pub fn render(
        &mut self,
        exterior: &Exterior,
        out: &mut Image,
    ) -> Result<&[TargetTruth], RenderError> {
        let (w, h) = (self.camera.sensor.width, self.camera.sensor.height);
        if (out.width(), out.height()) != (w, h) {
            return Err(RenderError::Size {
                width: w,
                height: h,
                got_width: out.width(),
                got_height: out.height(),
            });
        }
        let (w, h) = (w as usize, h as usize);
        self.truth.clear();
        self.boxes.clear();
        let rt = exterior.rotation.transpose();
        // Optical axis in the object frame (the camera looks along -z).
        let axis = -exterior.rotation.row(2).transpose();
        let ss = self.options.supersample as usize;
        // Exposure: fixed (reference distance), or set so that the nearest
        // target in view has the brightness `target` (an auto-exposure).
        let mut reference = self.options.reference_distance_mm;
        if self.options.auto_exposure {
            let nearest = self
                .targets
                .iter()
                .map(|t| self.origin + self.u * t.at.x + self.v * t.at.y)
                .filter(|c| {
                    exterior
                        .project_pixel(&self.camera, c)
                        .is_some_and(|p| self.camera.contains_pixel(p, 0.0))
                })
                .map(|c| (c - exterior.center).norm())
                .fold(f64::INFINITY, f64::min);
            if nearest.is_finite() {
                reference = nearest;
            }
        }
        for ti in 0..self.targets.len() {
            let t = self.targets[ti];
            let centre = self.origin + self.u * t.at.x + self.v * t.at.y;
            let reach = match t.kind {
                TargetKind::Coded => 4.0 * t.radius,
                TargetKind::Uncoded => 2.0 * t.radius,
            };
            // Image of the centre and of the target's circles.
            let centre_px = exterior.project_pixel(&self.camera, &centre);
            let mut ext: f64 = 0.0;
            let mut ext_min = f64::INFINITY;
            let mut dot_px: f64 = 0.0;
            let mut all_in_front = centre_px.is_some();
            // Smallest distance of the outline (quiet zone or dark
            // surround) from the frame's edge, pixels.
            let mut margins = [f64::INFINITY; OUTLINE];
            for (k, margin) in margins.iter_mut().enumerate() {
                let a = k as f64 * std::f64::consts::TAU / OUTLINE as f64;
                let dir = self.u * a.cos() + self.v * a.sin();
                let (Some(c), Some(q), Some(qd)) = (
                    centre_px,
                    exterior.project_pixel(&self.camera, &(centre + dir * reach)),
                    exterior.project_pixel(&self.camera, &(centre + dir * t.radius)),
                ) else {
                    all_in_front = false;
                    continue;
                };
                ext = ext.max((q - c).norm());
                ext_min = ext_min.min((q - c).norm());
                dot_px = dot_px.max((qd - c).norm());
                *margin = (q.x + 0.5)
                    .min(q.y + 0.5)
                    .min(w as f64 - 0.5 - q.x)
                    .min(h as f64 - 0.5 - q.y);
            }
            let margin_px = if all_in_front {
                outline_minimum(&margins)
            } else {
                f64::NEG_INFINITY
            };
            let (col, row) = centre_px
                .map(|p| (p.x, p.y))
                .unwrap_or((f64::NAN, f64::NAN));
            // "Visible": in front of the camera, and the whole outline of
            // the quiet zone (or dark surround) on the sensor. The image of
            // the outline is a convex curve, so the target lies inside too.
            let visible = all_in_front && margin_px >= 0.0;
            self.truth.push(TargetTruth {
                id: t.id,
                kind: t.kind,
                col,
                row,
                visible,
                margin_px,
                radius_px: dot_px,
            });
            let Some(p) = centre_px else { continue };
            if !all_in_front || !ext.is_finite() {
                continue;
            }
            let margin = ext * 1.05 + 2.0;
            let c0 = (p.x - margin).floor().max(0.0);
            let r0 = (p.y - margin).floor().max(0.0);
            let c1 = (p.x + margin).ceil().min(w as f64 - 1.0);
            let r1 = (p.y + margin).ceil().min(h as f64 - 1.0);
            if c0 > c1 || r0 > r1 {
                continue;
            }
            let (c0, r0, c1, r1) = (c0 as usize, r0 as usize, c1 as usize, r1 as usize);
            self.boxes.push([c0, r0, c1, r1]);
            // Ring light, evaluated at the target's centre (the gradient
            // across one dot is below 0.5 % and is left out): inverse square
            // of the distance, cos⁴ of the off-axis angle, retro-reflection
            // falling gently with the incidence angle.
            let to_target = centre - exterior.center;
            let dist = to_target.norm();
            let ray = to_target / dist;
            let off_axis = ray.dot(&axis).clamp(0.0, 1.0);
            let cos_inc = (-ray.dot(&self.n)).clamp(0.0, 1.0);
            let gain = (reference / dist).powi(2) * off_axis.powi(4) * (0.6 + 0.4 * cos_inc);
            // Largest footprint of a pixel on the plate, mm (for adaptive
            // sampling): the longest plate distance one pixel step covers
            // (foreshortened direction), from the narrowest axis of the
            // outline's image.
            let mm_per_px = reach / ext_min.max(1e-9);
            for row in r0..=r1 {
                for col in c0..=c1 {
                    let Some(q) = self.hit(exterior, &rt, col as f64, row as f64) else {
                        continue;
                    };
                    let local = (q - t.at) / t.radius;
                    let rho = local.norm();
                    if rho > reach / t.radius + 0.5 * mm_per_px / t.radius + 1.0 {
                        continue;
                    }
                    // A pixel reaches 0.707 px (half its diagonal) from its
                    // centre; 0.8 leaves room for the scale's variation
                    // across the target and between the sampled directions.
                    let foot = 0.8 * mm_per_px / t.radius;
                    let coverage = if ss > 1 && near_edge(&t, local, rho, foot) {
                        // One edge through the pixel: exact area coverage of
                        // the pixel's image on the plate (linearised over the
                        // pixel); corners of the pattern: supersampling.
                        let jac = self.local_jacobian(exterior, &rt, &t, col as f64, row as f64);
                        jac.and_then(|j| analytic_coverage(&t, local, &j))
                            .unwrap_or_else(|| self.supersampled(exterior, &rt, &t, col, row))
                    } else {
                        reflectance(&t, local)
                    };
                    if coverage <= 0.0 {
                        continue;
                    }
                    self.excess[row * w + col] += (coverage * gain * self.options.target) as f32;
                }
            }
        }
        self.blur(w, h);
        self.quantise(w, h, out);
        Ok(&self.truth)
    }

    /// Jacobian of the target-local plate coordinates (dot radii) with
    /// respect to `(col, row)` at a pixel centre, by central differences
    /// over the pixel (±½ px).
    #[inline]
    fn local_jacobian(
        &self,
        e: &Exterior,
        rt: &nalgebra::Matrix3<f64>,
        t: &Flat,
        col: f64,
        row: f64,
    ) -> Option<Matrix2<f64>> {
        let l = self.hit(e, rt, col - 0.5, row)?;
        let r = self.hit(e, rt, col + 0.5, row)?;
        let u = self.hit(e, rt, col, row - 0.5)?;
        let d = self.hit(e, rt, col, row + 0.5)?;
        let (dc, dr) = ((r - l) / t.radius, (d - u) / t.radius);
        Some(Matrix2::new(dc.x, dr.x, dc.y, dr.y))
    }

    /// Mean reflectance of `supersample²` samples on a regular grid.
    fn supersampled(
        &self,
        exterior: &Exterior,
        rt: &nalgebra::Matrix3<f64>,
        t: &Flat,
        col: usize,
        row: usize,
    ) -> f64 {
        let ss = self.options.supersample as usize;
        let mut acc = 0.0;
        for sy in 0..ss {
            for sx in 0..ss {
                let pc = col as f64 - 0.5 + (sx as f64 + 0.5) / ss as f64;
                let pr = row as f64 - 0.5 + (sy as f64 + 0.5) / ss as f64;
                if let Some(qs) = self.hit(exterior, rt, pc, pr) {
                    acc += reflectance(t, (qs - t.at) / t.radius);
                }
            }
        }
        acc / (ss * ss) as f64
    }

    /// Blurs the excess brightness inside the touched boxes (the background
    /// is uniform, so blurring it changes nothing).
    fn blur(&mut self, w: usize, h: usize) {
        if self.kernel.is_empty() {
            return;
        }
        let k = self.kernel.len() / 2;
        let kernel = &self.kernel;
        let excess = &mut self.excess;
        let scratch = &mut self.scratch;
        for b in self.boxes.iter_mut() {
            let [c0, r0, c1, r1] = *b;
            let (c0, c1) = (c0.saturating_sub(k), (c1 + k).min(w - 1));
            let (r0, r1) = (r0.saturating_sub(k), (r1 + k).min(h - 1));
            *b = [c0, r0, c1, r1];
            for row in r0..=r1 {
                let line = &excess[row * w..(row + 1) * w];
                for col in c0..=c1 {
                    let s = if col >= k && col + k < w {
                        // The whole window on the sensor: a plain dot product.
                        kernel
                            .iter()
                            .zip(&line[col - k..=col + k])
                            .map(|(kv, v)| kv * v)
                            .sum()
                    } else {
                        let mut s = 0.0f32;
                        for (j, kv) in kernel.iter().enumerate() {
                            s += kv * line[(col + j).saturating_sub(k).min(w - 1)];
                        }
                        s
                    };
                    scratch[row * w + col] = s;
                }
            }
        }
        // Vertical pass, a row at a time (vectorises along the row). Rows
        // outside every box hold no excess: the horizontal pass left them
        // zero in `scratch`.
        for &[c0, r0, c1, r1] in self.boxes.iter() {
            for row in r0..=r1 {
                let dst = &mut excess[row * w + c0..=row * w + c1];
                dst.fill(0.0);
                for (j, kv) in kernel.iter().enumerate() {
                    let rr = (row + j).saturating_sub(k).min(h - 1);
                    let src = &scratch[rr * w + c0..=rr * w + c1];
                    for (d, s) in dst.iter_mut().zip(src) {
                        *d += kv * s;
                    }
                }
            }
        }
        // Clear the horizontal pass for the next frame.
        for b in 0..self.boxes.len() {
            let [c0, r0, c1, r1] = self.boxes[b];
            for row in r0..=r1 {
                self.scratch[row * w + c0..=row * w + c1].fill(0.0);
            }
        }
    }

    /// Background, excess, noise → grey values; clears the excess.
    fn quantise(&mut self, w: usize, h: usize, out: &mut Image) {
        let n = w * h;
        let level = Level {
            max: out.max_value() as f32,
            bg: self.options.background as f32 * out.max_value() as f32,
            noise: self.options.noise_dn as f32,
        };
        self.normal.reseed(self.options.seed);
        let excess = &self.excess[..n];
        match out.pixels_mut() {
            Pixels::Mono8(data) => {
                level.fill(&mut data[..n], excess, &mut self.normal, |v| v as u8)
            }
            Pixels::Mono16(data) => {
                level.fill(&mut data[..n], excess, &mut self.normal, |v| v as u16)
            }
        }
        self.excess[..n].fill(0.0);
    }
}

/// Grey levels of a frame: saturation, background, noise σ (all DN).
struct Level {
    max: f32,
    bg: f32,
    noise: f32,
}

impl Level {
    /// Writes `bg + excess·max + noise·N(0,1)`, clamped to `[0, max]` and
    /// rounded (half up: offset by ½, then `cast` truncates).
    #[inline(always)]
    fn fill<T>(&self, out: &mut [T], excess: &[f32], normal: &mut Normal, cast: impl Fn(f32) -> T) {
        let value = |e: f32, z: f32| {
            cast((self.bg + e * self.max + self.noise * z).clamp(0.0, self.max) + 0.5)
        };
        let mut oc = out.chunks_exact_mut(4);
        let mut ec = excess.chunks_exact(4);
        for (o, e) in (&mut oc).zip(&mut ec) {
            let z = normal.next4();
            for j in 0..4 {
                o[j] = value(e[j], z[j]);
            }
        }
        for (o, e) in oc.into_remainder().iter_mut().zip(ec.remainder()) {
            *o = value(*e, normal.next());
        }
    }
}

/// The smallest value of a smooth periodic function sampled at equal
/// steps: the least sample refined by the parabola through it and its two
/// neighbours (never above the least sample).
fn outline_minimum(m: &[f64; OUTLINE]) -> f64 {
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

/// Reflectance of the pattern at `local` (plate coordinates relative to the
/// target centre, in dot radii): 1 bright, 0 dark.
#[inline]
fn reflectance(t: &Flat, local: Vector2<f64>) -> f64 {
    let rho2 = local.norm_squared();
    if rho2 <= 1.0 {
        return 1.0;
    }
    if t.kind == TargetKind::Uncoded || !(4.0..9.0).contains(&rho2) {
        return 0.0;
    }
    let a = local.y.atan2(local.x).rem_euclid(std::f64::consts::TAU);
    let k = ((a / (std::f64::consts::PI / 6.0)) as u32).min(11);
    codes::sector_bit(t.code, k) as u8 as f64
}

/// Share of `[-½, ½]²` where `g·δ < t` (the CDF of the sum of two
/// uniform variables of widths `|g.x|`, `|g.y|`).
#[inline]
fn square_share_below(g: Vector2<f64>, t: f64) -> f64 {
    let (a, b) = (g.x.abs().max(g.y.abs()), g.x.abs().min(g.y.abs()));
    let s = t + 0.5 * (a + b);
    if s <= 0.0 {
        0.0
    } else if s >= a + b {
        1.0
    } else if s < b {
        s * s / (2.0 * a * b)
    } else if s <= a {
        (s - 0.5 * b) / a
    } else {
        1.0 - (a + b - s) * (a + b - s) / (2.0 * a * b)
    }
}

/// Share of the pixel inside the circle `ρ < a` (local units): the pixel
/// is cut into strips across the edge, each with the circle linearised at
/// its own centre, which follows the edge's curvature (the error of one
/// straight line, about 1/(24 R) of a pixel for an image radius of R px,
/// drops by the square of the strip count).
fn circle_share(local: Vector2<f64>, jac: &Matrix2<f64>, a: f64, g: Vector2<f64>) -> f64 {
    const STRIPS: usize = 8;
    let m = STRIPS as f64;
    // Strips narrow along the axis the edge runs along.
    let split_col = g.x.abs() <= g.y.abs();
    // Pixel offsets: `along` across the strips, `across` along each strip.
    let (along, across) = if split_col {
        (Vector2::x(), Vector2::y())
    } else {
        (Vector2::y(), Vector2::x())
    };
    let (ja, jc) = (jac * along, jac * across);
    let mut sum = 0.0;
    for i in 0..STRIPS {
        let off = (i as f64 + 0.5) / m - 0.5;
        // Where the edge crosses the strip's centre line (Newton from the
        // middle), kept inside the pixel.
        let mut y = 0.0;
        for _ in 0..2 {
            let l = local + ja * off + jc * y;
            let rho = l.norm();
            let slope = jc.dot(&l) / rho.max(1e-12);
            if slope.abs() < 1e-12 {
                break;
            }
            y = (y - (rho - a) / slope).clamp(-0.5, 0.5);
        }
        let l = local + ja * off + jc * y;
        let rho = l.norm();
        if rho < 1e-12 {
            return square_share_below(g, a - local.norm());
        }
        let n = l / rho;
        // ρ − a ≈ (rho − a) + ga·(x − off) + gc·(y' − y) in the strip, with
        // x − off ∈ [−1/2m, 1/2m] and y' ∈ [−½, ½].
        let (ga, gc) = (ja.dot(&n), jc.dot(&n));
        let gs = if split_col {
            Vector2::new(ga / m, gc)
        } else {
            Vector2::new(gc, ga / m)
        };
        sum += square_share_below(gs, a - rho + gc * y);
    }
    sum / m
}

/// Exact share of the pattern's brightness in a pixel crossed by a single
/// edge, with the pixel → plate mapping linearised over the pixel:
/// `local(δ) = local + jac·δ`, `δ ∈ [-½, ½]²`. `None` if more than one
/// edge crosses the pixel (or the linearisation is unusable).
fn analytic_coverage(t: &Flat, local: Vector2<f64>, jac: &Matrix2<f64>) -> Option<f64> {
    let rho = local.norm();
    if rho < 0.25 {
        return None;
    }
    let sector = std::f64::consts::PI / 6.0;
    let a = local.y.atan2(local.x).rem_euclid(std::f64::consts::TAU);
    let j = ((a / sector) as u32).min(11);
    let bit = |k: u32| f64::from(u8::from(codes::sector_bit(t.code, k % 12)));
    let coded = t.kind == TargetKind::Coded;
    // Edges as (circle radius or 0 for a straight boundary, d0, g, value
    // where d0 + g·δ < 0, value where > 0).
    let radial = jac.transpose() * (local / rho);
    let mut edge: Option<(f64, f64, Vector2<f64>, f64, f64)> = None;
    let mut crossing = 0;
    // How far a circle bends away from its linearisation within the pixel
    // (tangential reach² / 2ρ): a curved edge may cut a corner the straight
    // one misses.
    let tangential = jac.transpose() * Vector2::new(-local.y, local.x) / rho;
    let bend = (0.5 * (tangential.x.abs() + tangential.y.abs())).powi(2) / (2.0 * rho);
    let mut consider = |circle: f64, d0: f64, g: Vector2<f64>, below: f64, above: f64| {
        let slack = if circle > 0.0 { bend } else { 0.0 };
        if below != above && d0.abs() < 0.5 * (g.x.abs() + g.y.abs()) + slack {
            crossing += 1;
            edge = Some((circle, d0, g, below, above));
        }
    };
    consider(1.0, rho - 1.0, radial, 1.0, 0.0);
    if coded {
        consider(2.0, rho - 2.0, radial, 0.0, bit(j));
        consider(3.0, rho - 3.0, radial, bit(j), 0.0);
        // Sector boundaries either side, where the ring is.
        for k in [j, j + 1] {
            let phi = k as f64 * sector;
            let (dir, normal) = (
                Vector2::new(phi.cos(), phi.sin()),
                Vector2::new(-phi.sin(), phi.cos()),
            );
            let d0 = normal.dot(&local);
            let g = jac.transpose() * normal;
            let along = dir.dot(&local);
            let reach = 0.5 * (jac.column(0).norm() + jac.column(1).norm());
            if along > 0.0 && along > 2.0 - reach && along < 3.0 + reach {
                if along < 2.0 + reach || along > 3.0 - reach {
                    // The boundary ends inside the pixel: a corner.
                    if d0.abs() < 0.5 * (g.x.abs() + g.y.abs()) && bit(k + 11) != bit(k) {
                        return None;
                    }
                }
                consider(0.0, d0, g, bit(k + 11), bit(k));
            }
        }
    }
    match (crossing, edge) {
        (0, _) => Some(reflectance(t, local)),
        (1, Some((circle, d0, g, below, above))) => {
            if g.norm() < 1e-12 {
                return None;
            }
            let share = if circle > 0.0 {
                circle_share(local, jac, circle, g)
            } else {
                square_share_below(g, -d0)
            };
            Some(below * share + above * (1.0 - share))
        }
        _ => None,
    }
}

/// Whether a pixel whose centre maps to `local` (radius `rho`, in dot radii)
/// with a footprint of `foot` dot radii may straddle an edge of the pattern.
#[inline]
fn near_edge(t: &Flat, local: Vector2<f64>, rho: f64, foot: f64) -> bool {
    let radii: &[f64] = match t.kind {
        TargetKind::Coded => &[1.0, 2.0, 3.0],
        TargetKind::Uncoded => &[1.0],
    };
    if radii.iter().any(|r| (rho - r).abs() <= foot) {
        return true;
    }
    if t.kind == TargetKind::Coded && t.edges != 0 && rho > 2.0 - foot && rho < 3.0 + foot {
        // Distance to the two sector boundaries either side, where they
        // separate sectors of different bits.
        let sector = std::f64::consts::PI / 6.0;
        let a = local.y.atan2(local.x).rem_euclid(std::f64::consts::TAU);
        let j = ((a / sector) as u32).min(11);
        let da = a - j as f64 * sector;
        let near = |boundary: u32, angle: f64| {
            t.edges & (1 << (boundary % 12)) != 0 && rho * angle.min(sector).sin() <= foot
        };
        return near(j, da) || near(j + 1, sector - da);
    }
    false
}

#[cfg(test)]
mod tests;
