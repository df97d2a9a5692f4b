//! The [`Renderer`]: the plate's frame and its targets, the scratch buffers,
//! and the rendering of one frame — exposure, per target its projected
//! outline (truth, bounding box), ring-light gain and the coverage of every
//! pixel in its box — before blur and quantisation.

use crate::noise::Normal;
use crate::pattern::{analytic_coverage, near_edge, reflectance, Flat};
use crate::truth::{outline_minimum, OUTLINE};
use crate::{blur, quantise, Plate, RenderError, RenderOptions, TargetTruth};
use nalgebra::{Matrix2, Rotation3, Vector2, Vector3};
use photopose_field::{codes, Field, TargetKind};
use photopose_frame::Image;
use photopose_geometry::{Camera, Exterior};

/// Largest image displacement of a target between two sub-exposures of a
/// moving exposure, px ([`Renderer::render_moving`]).
pub const MOTION_STEP_PX: f64 = 0.2;

/// Most sub-exposures of one moving exposure.
pub const MAX_SUB_EXPOSURES: usize = 256;

/// The pose at the share `t` of the way from `a` to `b`: centre moved
/// linearly, rotation turned about the one axis that takes `a`'s to `b`'s,
/// by `t` of the angle.
pub fn interpolate(a: &Exterior, b: &Exterior, t: f64) -> Exterior {
    let rel = Rotation3::from_matrix(&(b.rotation * a.rotation.transpose()));
    let step = Rotation3::new(rel.scaled_axis() * t);
    Exterior::new(
        step.matrix() * a.rotation,
        a.center + (b.center - a.center) * t,
    )
}

/// The exponent `m` of a beam `cosᵐ(angle)` that falls to half its
/// intensity at `half_angle_deg` (0: a uniform beam).
fn beam_exponent(half_angle_deg: f64) -> f64 {
    if half_angle_deg <= 0.0 {
        0.0
    } else {
        0.5f64.ln() / half_angle_deg.to_radians().cos().ln()
    }
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
    /// Per target, its entry in `boxes` this frame (`u32::MAX`: none yet).
    box_of: Vec<u32>,
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
            box_of: vec![u32::MAX; targets.len()],
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
        blur::gaussian_kernel(options.blur_px, &mut self.kernel);
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
        self.begin(out)?;
        let reference = self.exposure_reference(exterior);
        self.expose(exterior, reference, 1.0, true);
        self.finish(out);
        Ok(&self.truth)
    }

    /// Renders a frame whose exposure lasts while the camera moves from
    /// `start` to `end` (motion blur): the frame is the mean of
    /// sub-exposures at poses evenly spaced in time along the path (centre
    /// moved linearly, rotation about one fixed axis at a constant rate),
    /// as many as keep consecutive images of every target less than
    /// [`MOTION_STEP_PX`] apart (at most [`MAX_SUB_EXPOSURES`]). The
    /// exposure (auto-exposure included) and the truth are those of the
    /// pose at mid-exposure, the instant a frame's time stamp names.
    /// Allocates nothing once warm, like [`Renderer::render`].
    pub fn render_moving(
        &mut self,
        start: &Exterior,
        end: &Exterior,
        out: &mut Image,
    ) -> Result<&[TargetTruth], RenderError> {
        self.begin(out)?;
        let mid = interpolate(start, end, 0.5);
        let reference = self.exposure_reference(&mid);
        // The truth at mid-exposure (no light).
        self.expose(&mid, reference, 0.0, true);
        let n = self.sub_exposures(start, end);
        for k in 0..n {
            let e = interpolate(start, end, (k as f64 + 0.5) / n as f64);
            self.expose(&e, reference, 1.0 / n as f64, false);
        }
        self.finish(out);
        Ok(&self.truth)
    }

    /// Number of sub-exposures for the path `start` → `end`: the largest
    /// image displacement of a target centre in front of the camera at
    /// both ends, divided by [`MOTION_STEP_PX`], at least 1.
    fn sub_exposures(&self, start: &Exterior, end: &Exterior) -> usize {
        let mut largest: f64 = 0.0;
        for t in &self.targets {
            let c = self.origin + self.u * t.at.x + self.v * t.at.y;
            if let (Some(a), Some(b)) = (
                start.project_pixel(&self.camera, &c),
                end.project_pixel(&self.camera, &c),
            ) {
                largest = largest.max((a - b).norm());
            }
        }
        ((largest / MOTION_STEP_PX).ceil() as usize).clamp(1, MAX_SUB_EXPOSURES)
    }

    /// Checks the output's size and clears the frame's truth and boxes.
    fn begin(&mut self, out: &Image) -> Result<(), RenderError> {
        let (w, h) = (self.camera.sensor.width, self.camera.sensor.height);
        if (out.width(), out.height()) != (w, h) {
            return Err(RenderError::Size {
                width: w,
                height: h,
                got_width: out.width(),
                got_height: out.height(),
            });
        }
        self.truth.clear();
        self.boxes.clear();
        self.box_of.fill(u32::MAX);
        Ok(())
    }

    /// Blur and quantisation of the accumulated excess into `out`.
    fn finish(&mut self, out: &mut Image) {
        let (w, h) = (
            self.camera.sensor.width as usize,
            self.camera.sensor.height as usize,
        );
        blur::blur(
            &self.kernel,
            &mut self.excess,
            &mut self.scratch,
            &mut self.boxes,
            w,
            h,
        );
        quantise::quantise(
            &self.options,
            &mut self.excess,
            &mut self.normal,
            w * h,
            out,
        );
    }

    /// The exposure: the distance at which a target on the axis has the
    /// brightness `target`: fixed (reference distance), or that of the
    /// nearest target in view (an auto-exposure).
    fn exposure_reference(&self, exterior: &Exterior) -> f64 {
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
        reference
    }

    /// Adds `weight` × the targets' excess brightness seen from `exterior`
    /// to the frame (nothing for weight 0), growing each target's box;
    /// with `record_truth` the truth of every target is recorded.
    fn expose(&mut self, exterior: &Exterior, reference: f64, weight: f64, record_truth: bool) {
        let (w, h) = (
            self.camera.sensor.width as usize,
            self.camera.sensor.height as usize,
        );
        let rt = exterior.rotation.transpose();
        // Optical axis in the object frame (the camera looks along -z).
        let axis = -exterior.rotation.row(2).transpose();
        let ss = self.options.supersample as usize;
        let beam = beam_exponent(self.options.beam_half_angle_deg);
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
            if record_truth {
                self.truth.push(TargetTruth {
                    id: t.id,
                    kind: t.kind,
                    col,
                    row,
                    visible,
                    margin_px,
                    radius_px: dot_px,
                });
            }
            if weight == 0.0 {
                continue;
            }
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
            // One box per target, grown over the sub-exposures.
            match self.box_of[ti] {
                u32::MAX => {
                    self.box_of[ti] = self.boxes.len() as u32;
                    self.boxes.push([c0, r0, c1, r1]);
                }
                b => {
                    let bx = &mut self.boxes[b as usize];
                    *bx = [bx[0].min(c0), bx[1].min(r0), bx[2].max(c1), bx[3].max(r1)];
                }
            }
            // Ring light, evaluated at the target's centre (the gradient
            // across one dot is below 0.5 % and is left out): inverse square
            // of the distance, cos⁴ of the off-axis angle, retro-reflection
            // falling gently with the incidence angle, and the ring light's
            // beam (cosᵐ of the off-axis angle, half the intensity at the
            // beam's half angle; none by default).
            let to_target = centre - exterior.center;
            let dist = to_target.norm();
            let ray = to_target / dist;
            let off_axis = ray.dot(&axis).clamp(0.0, 1.0);
            let cos_inc = (-ray.dot(&self.n)).clamp(0.0, 1.0);
            let gain = (reference / dist).powi(2)
                * off_axis.powi(4)
                * (0.6 + 0.4 * cos_inc)
                * off_axis.powf(beam)
                * weight;
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
}
