//! Tracking mode: a frame located from a recent pose instead of from its
//! coded targets. Every field target is projected with the predicted pose
//! and its uncertainty; each is looked for only in a small window around
//! its prediction (`photopose_vision::WindowMeasurer`, the whole-frame
//! detector's labelling, blob tests and centroid with the threshold of the
//! last whole-frame pass) and identified by the prediction alone: exactly
//! one blob inside a gate that never reaches half-way to the next target.
//! The pose is then refined over all of them as in the whole-frame path, so
//! the result means the same: same ids, same centres, same adjustment.
//!
//! A wrong prediction could make every gate catch its neighbour on a
//! regular grid. Two guards keep that from ever becoming a pose: the rings
//! of a few coded targets are read and must give their own ids (none may
//! give another), and the refined pose must project every target within its
//! gate of the prediction. A frame that fails them is not a result: the
//! caller locates it on the whole frame. The coded targets read are spread
//! over the plate ([`spread_order`]): a prediction off by a grid step in
//! one part of the view only (a tilt or a turn) moves some of them.
//!
//! [`Motion`] predicts the pose of a later frame from the two latest poses
//! (constant velocity per frame).

use crate::{Identified, Locator, PoseStatus, Window};
use photopose_field::{Target, TargetKind};
use photopose_frame::ImageView;
use photopose_geometry::linearised::PointJacobian;
use photopose_geometry::precision::UncertainProjector;
use photopose_geometry::{
    Camera, DistortSeed, Exterior, Matrix2, Matrix3, Matrix6, Observation, ResectionReport,
    Rotation3, Vector3,
};
use photopose_vision::{Expected, ThresholdResult, WindowMeasurer, WindowOutcome};

/// Targets ahead of the one measured whose windows are asked for from
/// memory (the bench's tracked frame: 405 µs with all windows touched
/// first, 341 µs asking 4 to 16 ahead; 6 sits in that plateau).
const PREFETCH_AHEAD: usize = 6;

/// Tuning of tracking mode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackOptions {
    /// Targets that must be found for a tracked pose (fewer: locate the
    /// whole frame).
    pub min_targets: usize,
    /// Coded targets whose rings are read to confirm the prediction (the
    /// first of the plate's spread order that land on the sensor).
    pub verify_codes: usize,
    /// Share of the predicted motion since the prior added to each gate,
    /// px per px (the prediction's error grows with the speed).
    pub motion_gate: f64,
    /// Largest shift of the refined pose against the prediction, as a
    /// share of the gate (beyond it the tracked pose is refused).
    pub max_shift_ratio: f64,
}

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            min_targets: 12,
            verify_codes: 4,
            motion_gate: 0.5,
            max_shift_ratio: 1.0,
        }
    }
}

/// What tracking starts from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    /// The predicted exterior orientation of this frame.
    pub exterior: Exterior,
    /// The covariance of the pose the prediction came from.
    pub covariance: Matrix6<f64>,
    /// Image motion of the prediction against that pose, px (widens the
    /// gates).
    pub motion_px: f64,
    /// The threshold of the last whole-frame pass.
    pub threshold: ThresholdResult,
}

/// Why a frame could not be tracked (the caller locates it whole).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackLost {
    /// Fewer targets found than needed.
    TooFewTargets {
        /// Targets found.
        found: usize,
    },
    /// A coded target's ring gave another id, or none confirmed the
    /// prediction.
    CodeMismatch,
    /// The refined pose lies too far from the prediction.
    Jump,
    /// The adjustment failed.
    NoPose,
}

/// Two poses of a camera and the frames they belong to: the prediction of a
/// later frame's pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// The latest pose and its frame.
    pub last: (u64, Exterior),
    /// The one before (`None`: standing still is assumed).
    pub before: Option<(u64, Exterior)>,
}

impl Motion {
    /// The pose predicted for frame `seq` (constant motion per frame; `seq`
    /// may also lie before the latest pose), and
    /// the change from the latest pose as an image motion estimate, px,
    /// for a camera of principal distance `c` and pixel size `pixel_size`
    /// looking at targets `distance` mm away.
    pub fn predict(&self, seq: u64, c: f64, pixel_size: f64, distance: f64) -> (Exterior, f64) {
        let (s1, e1) = self.last;
        let Some((s0, e0)) = self.before.filter(|(s0, _)| *s0 < s1) else {
            return (e1, 0.0);
        };
        // Negative for a frame older than the latest pose (workers finish
        // frames out of order): the same motion, backwards.
        let k = (seq as f64 - s1 as f64) / (s1 - s0) as f64;
        if !k.is_finite() || k == 0.0 {
            return (e1, 0.0);
        }
        let step = Rotation3::from_matrix_unchecked(e1.rotation * e0.rotation.transpose());
        let turn = step.powf(k);
        let rotation: Matrix3<f64> = turn.matrix() * e1.rotation;
        let center = e1.center + (e1.center - e0.center) * k;
        let shift = (center - e1.center).norm() / distance.max(1.0) + turn.angle();
        (Exterior::new(rotation, center), c * shift / pixel_size)
    }
}

/// The field indices of `targets` of `kind` in an order that spreads them
/// over the plate: first the one farthest from their centroid, then each
/// time the one farthest from all chosen so far (farthest-point order; ties
/// to the lower index). Any first few of the order lie far apart, so that a
/// check of those few covers the whole plate.
pub fn spread_order(targets: &[Target], kind: TargetKind) -> Vec<usize> {
    let mut left: Vec<usize> = (0..targets.len())
        .filter(|&k| targets[k].kind == kind)
        .collect();
    if left.is_empty() {
        return left;
    }
    let centroid = left
        .iter()
        .fold(Vector3::zeros(), |s, &k| s + targets[k].position)
        / left.len() as f64;
    // Squared distance of each remaining target to the chosen set (to the
    // centroid before the first choice).
    let mut reach: Vec<f64> = left
        .iter()
        .map(|&k| (targets[k].position - centroid).norm_squared())
        .collect();
    let mut order = Vec::with_capacity(left.len());
    while !left.is_empty() {
        let mut best = 0;
        for i in 1..left.len() {
            if reach[i] > reach[best] {
                best = i;
            }
        }
        let chosen = left.swap_remove(best);
        reach.swap_remove(best);
        for (r, &k) in reach.iter_mut().zip(&left) {
            *r = r.min((targets[k].position - targets[chosen].position).norm_squared());
        }
        order.push(chosen);
    }
    order
}

/// What places a tracked frame's windows: the projector of the predicted
/// pose and the gates' terms.
struct Projection {
    projector: UncertainProjector,
    gate_min_px: f64,
    gate_sigmas: f64,
    gate_spacing_ratio: f64,
    /// The share of the predicted motion added to every gate, px.
    gate_extra: f64,
    edge_margin_px: f64,
}

impl Projection {
    /// The window of every field target that lands on the sensor, in field
    /// order, and its rows of the refinement's first pass.
    ///
    /// A function of its own, the camera and these terms given by
    /// reference: what derives from them alone (the sensor's centre, the
    /// lens's zero test) is formed once, not after every store into the
    /// buffers (out of line: inlined, its arguments' promise not to alias
    /// would be lost).
    #[inline(never)]
    fn windows(
        &self,
        camera: &Camera,
        targets: &[Target],
        spacing: &[f64],
        seeds: &mut [Option<DistortSeed>],
        windows: &mut Vec<Window>,
        jacobians: &mut Vec<PointJacobian>,
    ) {
        windows.clear();
        jacobians.clear();
        let (c, px) = (camera.interior.c, camera.sensor.pixel_size);
        let projector = &self.projector;
        for (fi, t) in targets.iter().enumerate() {
            // The covariance only of a target that lands on the sensor.
            let Some((z, ideal)) = projector.project_point(&t.position) else {
                continue;
            };
            let Some(measured) = camera.distort_seeded(ideal, &mut seeds[fi]) else {
                continue;
            };
            let p = camera.image_to_pixel(measured);
            if !camera.contains_pixel(p, self.edge_margin_px) {
                continue;
            }
            // With the covariance, the rows of the refinement's first pass
            // (it starts from this pose): formed from the same partials.
            let (covariance, jacobian) = projector.covariance_and_jacobian_at(&z);
            let sigma_px = crate::largest_sigma(&covariance) / px;
            // `R (P − C)` of the projection, not computed again.
            let depth = z.z.abs();
            let scale = c / (depth * px);
            let spacing = spacing[fi] * scale;
            let gate = (self.gate_min_px + self.gate_sigmas * sigma_px + self.gate_extra)
                .min(self.gate_spacing_ratio * spacing);
            let expected = Expected {
                col: p.x,
                row: p.y,
                gate_px: gate,
                radius_px: t.radius * scale,
                coded: t.kind == TargetKind::Coded,
                read_code: false,
                id: (t.kind == TargetKind::Coded).then_some(t.id),
            };
            windows.push(Window {
                field_index: fi,
                expected,
                ideal,
                camera: z,
            });
            jacobians.push(jacobian);
        }
    }
}

/// Where a tracked frame's measurements go: the windows and rows of the
/// targets found move to the front, in order (the first windows and rows
/// then belong to the observations; nothing moves while every target is
/// found), and each found target is identified and observed.
struct Found<'a> {
    windows: &'a mut Vec<Window>,
    jacobians: &'a mut Vec<PointJacobian>,
    identified: &'a mut Vec<Identified>,
    obs: &'a mut Vec<Observation>,
}

/// Measures every window of `found` in `image` with `threshold`, asking
/// for the pixels of the window `PREFETCH_AHEAD` targets on while one is
/// measured, so that the frame's lines come from memory while the targets
/// before them are measured. The coded targets whose rings are read must
/// give their own ids: how many did (another id: a mismatch). Observations
/// of saturated targets are weighted by `1 / saturated_factor²`.
///
/// A function of its own (out of line), the camera given by reference:
/// what derives from it alone is formed once, not after every call into
/// the measurer.
#[inline(never)]
fn measure(
    camera: &Camera,
    targets: &[Target],
    saturated_factor: f64,
    measurer: &mut WindowMeasurer,
    (image, threshold): (&ImageView<'_>, &ThresholdResult),
    found: Found<'_>,
) -> Result<usize, TrackLost> {
    let Found {
        windows,
        jacobians,
        identified,
        obs,
    } = found;
    for w in windows.iter().take(PREFETCH_AHEAD) {
        measurer.prefetch(image, &w.expected);
    }
    let (mut confirmed, mut kept) = (0, 0);
    for wi in 0..windows.len() {
        if let Some(ahead) = windows.get(wi + PREFETCH_AHEAD) {
            measurer.prefetch(image, &ahead.expected);
        }
        let w = &windows[wi];
        let t = &targets[w.field_index];
        let WindowOutcome::Found(m) = measurer.measure(image, threshold, &w.expected) else {
            continue;
        };
        if let Some(code) = m.code {
            match code.id() {
                Some(id) if id == t.id => confirmed += 1,
                Some(_) => return Err(TrackLost::CodeMismatch),
                None => {}
            }
        }
        if kept != wi {
            windows[kept] = windows[wi];
            jacobians[kept] = jacobians[wi];
        }
        kept += 1;
        identified.push(Identified {
            id: t.id,
            kind: t.kind,
            col: m.col,
            row: m.row,
            blob_col: m.col,
            blob_row: m.row,
            detection: usize::MAX,
            used: true,
            saturated: m.saturated,
            peak: m.peak,
        });
        let mut o = Observation::from_pixel(camera, t.id, t.position, m.col, m.row);
        let f = saturated_factor;
        if m.saturated && f.is_finite() && f > 0.0 {
            o.weight = Matrix2::identity() / (f * f);
        }
        obs.push(o);
    }
    windows.truncate(kept);
    jacobians.truncate(kept);
    Ok(confirmed)
}

impl Locator {
    /// Locates `image` from `prior` (tracking mode). `Ok` with a pose, or
    /// why the frame must be located whole. Allocates nothing once warm.
    pub fn track(
        &mut self,
        image: ImageView<'_>,
        prior: &Prior,
        options: &TrackOptions,
    ) -> Result<&ResectionReport, TrackLost> {
        self.identified.clear();
        self.rejected.clear();
        self.obs.clear();
        self.projected.clear();
        self.coarse = None;
        self.pose = None;
        let c = self.camera.interior.c;
        let e = &prior.exterior;
        // First every target's window; then the measurements, each asking
        // for the pixels of the window `PREFETCH_AHEAD` targets on, so that
        // the frame's lines come from memory while the targets before them
        // are measured.
        let projection = Projection {
            projector: UncertainProjector::new(c, e, &prior.covariance),
            gate_min_px: self.options.gate_min_px,
            gate_sigmas: self.options.gate_sigmas,
            gate_spacing_ratio: self.options.gate_spacing_ratio,
            gate_extra: options.motion_gate * prior.motion_px,
            edge_margin_px: self.options.edge_margin_px,
        };
        projection.windows(
            &self.camera,
            self.field.targets(),
            &self.spacing,
            &mut self.seeds,
            &mut self.windows,
            &mut self.jacobians,
        );
        // The coded targets to read: the first `verify_codes` of the spread
        // order that land on the sensor (the windows are in field order).
        let mut marked = 0;
        for &fi in &self.verify_order {
            if marked == options.verify_codes {
                break;
            }
            if let Ok(k) = self.windows.binary_search_by_key(&fi, |w| w.field_index) {
                self.windows[k].expected.read_code = true;
                marked += 1;
            }
        }
        let found = Found {
            windows: &mut self.windows,
            jacobians: &mut self.jacobians,
            identified: &mut self.identified,
            obs: &mut self.obs,
        };
        let sought = (&image, &prior.threshold);
        let targets = self.field.targets();
        let factor = self.options.saturated_sigma_factor;
        let confirmed = measure(
            &self.camera,
            targets,
            factor,
            &mut self.window,
            sought,
            found,
        )?;
        let found = self.obs.len();
        if found < options.min_targets.max(self.options.min_coded.max(4)) {
            self.status = PoseStatus::TooFewTargets { coded: confirmed };
            return Err(TrackLost::TooFewTargets { found });
        }
        if options.verify_codes > 0 && confirmed == 0 {
            return Err(TrackLost::CodeMismatch);
        }
        if self.options.eccentricity {
            self.correct_eccentricity_tracked(e);
        }
        let report = match self.resection.refine_from(&self.obs, *e, &self.jacobians) {
            Ok(r) => r,
            Err(_) => return Err(TrackLost::NoPose),
        };
        if self.jumped(e, &report.exterior, options.max_shift_ratio) {
            return Err(TrackLost::Jump);
        }
        // Every target was identified as used.
        let rejected = self.resection.rejected_ids();
        if !rejected.is_empty() {
            for t in &mut self.identified {
                t.used = !rejected.contains(&t.id);
            }
        }
        self.rejected.extend_from_slice(rejected);
        self.pose = Some(report);
        self.status = PoseStatus::Ok;
        Ok(self.pose.as_ref().expect("just set"))
    }
}

impl Locator {
    /// Whether the refined pose `refined` projects a tracked target outside
    /// its gate of the prediction made with `prior`: a pose that moved a
    /// grid step is a wrong match. The shift is measured in ideal image
    /// coordinates: the lens distortion changes a shift of a few pixels by
    /// a small fraction of it, and the gates are far from a grid step.
    ///
    /// Every gate is at least `max_shift_ratio · gate_min_px` wide, so a
    /// bound on the shift of every point of the plate
    /// ([`photopose_geometry::Exterior::shift_bound`]) below that proves
    /// the answer without projecting a target; only otherwise is each one
    /// projected ([`Locator::jumped_plain`], the same answer).
    fn jumped(&self, prior: &Exterior, refined: &Exterior, max_shift_ratio: f64) -> bool {
        let c = self.camera.interior.c;
        let px = self.camera.sensor.pixel_size;
        let narrowest = max_shift_ratio * self.options.gate_min_px;
        let bound = prior.shift_bound(refined, c, &self.plate_centre, self.plate_radius);
        if bound.is_some_and(|b| b / px < narrowest) {
            return false;
        }
        self.jumped_plain(refined, max_shift_ratio)
    }

    /// [`Locator::jumped`] target by target.
    fn jumped_plain(&self, refined: &Exterior, max_shift_ratio: f64) -> bool {
        let c = self.camera.interior.c;
        let px = self.camera.sensor.pixel_size;
        self.windows.iter().any(|w| {
            let t = &self.field.targets()[w.field_index];
            let Some(q) = refined.project_ideal(c, &t.position) else {
                return true;
            };
            let shift = (q - w.ideal).norm() / px;
            let gate = w.expected.gate_px;
            shift.is_nan() || shift > max_shift_ratio * gate.max(self.options.gate_min_px)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use photopose_field::design::default_plate;

    /// The smallest distance between any two of `picked`, mm.
    fn closest_pair(targets: &[Target], picked: &[usize]) -> f64 {
        let mut d = f64::INFINITY;
        for (i, &a) in picked.iter().enumerate() {
            for &b in &picked[i + 1..] {
                d = d.min((targets[a].position - targets[b].position).norm());
            }
        }
        d
    }

    /// The jump check through the plate's shift bound answers as the check
    /// target by target does, for refined poses from a rounding to several
    /// pixels away from the prediction (both answers occur, and the bound
    /// decides some of them).
    #[test]
    fn the_bounded_jump_check_answers_as_the_plain_one() {
        use photopose_geometry::{rotation::cayley, Camera};
        use photopose_render::{RenderOptions, Renderer};
        let camera = Camera::reference();
        let field = default_plate();
        let mut renderer = Renderer::new(camera, &field, RenderOptions::default()).unwrap();
        let mut locator = Locator::new(camera, field, crate::LocateOptions::default()).unwrap();
        let truth = Exterior::from_kuka_pose([30.0, -20.0, 1000.0, 20.0, 5.0, -3.0]);
        let mut img = renderer.new_image();
        renderer.render(&truth, &mut img).unwrap();
        let whole = locator.locate(img.view()).unwrap();
        let pose = *whole.pose.unwrap();
        let prior = Prior {
            exterior: pose.exterior,
            covariance: pose.covariance,
            motion_px: 0.0,
            threshold: whole.detections.threshold,
        };
        locator
            .track(img.view(), &prior, &TrackOptions::default())
            .unwrap();
        assert!(locator.windows.len() > 100);
        let e = &prior.exterior;
        let (c, px) = (camera.interior.c, camera.sensor.pixel_size);
        let mut rng = photopose_geometry::rng::SplitMix64::new(0x5eed);
        let mut next = move || rng.unit() - 0.5;
        let (mut jumps, mut stays, mut proved) = (0, 0, 0);
        for k in 0..4000 {
            // From no change at all to a few pixels, in rotation and
            // position; ratios around one.
            let scale = 10f64.powf(-9.0 + 7.0 * (k as f64 / 4000.0));
            let refined = Exterior::new(
                e.rotation * cayley(scale * next(), scale * next(), scale * next()),
                e.center + Vector3::new(next(), next(), next()) * 1000.0 * scale,
            );
            let ratio = [1.0, 0.5, 2.0, 0.0, -1.0, f64::NAN][k % 6];
            let plain = locator.jumped_plain(&refined, ratio);
            assert_eq!(locator.jumped(e, &refined, ratio), plain, "case {k}");
            let bound = e.shift_bound(&refined, c, &locator.plate_centre, locator.plate_radius);
            proved += bound.is_some_and(|b| b / px < ratio * 1.5) as usize;
            if plain {
                jumps += 1;
            } else {
                stays += 1;
            }
        }
        assert!(
            jumps > 300 && stays > 1000 && proved > 1000,
            "{jumps} {stays} {proved}"
        );
    }

    #[test]
    fn the_spread_order_holds_every_target_of_the_kind_once() {
        let field = default_plate();
        let t = field.targets();
        let mut order = spread_order(t, TargetKind::Coded);
        assert_eq!(order.len(), 30);
        assert!(order.iter().all(|&k| t[k].kind == TargetKind::Coded));
        order.sort_unstable();
        order.dedup();
        assert_eq!(order.len(), 30);
        assert!(spread_order(&[], TargetKind::Coded).is_empty());
    }

    #[test]
    fn the_first_targets_of_the_spread_order_lie_far_apart() {
        // The default plate lists its coded targets row by row: its first
        // four share the top row. The first four of the spread order must
        // lie much farther apart, in both directions of the plate.
        let field = default_plate();
        let t = field.targets();
        let order = spread_order(t, TargetKind::Coded);
        let in_field_order: Vec<usize> = (0..t.len())
            .filter(|&k| t[k].kind == TargetKind::Coded)
            .take(4)
            .collect();
        let spread = &order[..4];
        assert!(
            closest_pair(t, spread) > 2.0 * closest_pair(t, &in_field_order),
            "{} vs {}",
            closest_pair(t, spread),
            closest_pair(t, &in_field_order)
        );
        let span = |axis: usize, set: &[usize]| {
            let v: Vec<f64> = set.iter().map(|&k| t[k].position[axis]).collect();
            v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min)
        };
        for axis in 0..2 {
            assert!(span(axis, spread) > 0.6 * span(axis, &order), "axis {axis}");
        }
    }
}
