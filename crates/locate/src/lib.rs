//! photopose-locate: one camera frame in, the camera's exterior orientation
//! out — the per-frame pipeline of the reference paper, sections 3.2–3.4.
//!
//! 1. detect the targets ([`photopose_vision::Detector`]);
//! 2. take the coded targets whose ids the field has (never a guess);
//! 3. first resection from the coded targets (hypothesise-and-verify, so a
//!    wrong reading cannot carry the pose);
//! 4. project every uncoded field target with the first pose and take the
//!    detected blob nearest to it inside a gate derived from the pose's
//!    uncertainty; two candidates inside the gate, or a blob nearer to
//!    another projected target, leave it unidentified;
//! 5. refine the pose over all identified targets (data snooping removes what
//!    still does not fit).
//!
//! Invariant: no IO, and no allocation per frame once a [`Locator`] has seen
//! a frame with as many targets.

mod gate;
pub mod track;

use gate::Grid;
use photopose_field::{Field, TargetKind};
use photopose_frame::ImageView;
use photopose_geometry::linearised::PointJacobian;
use photopose_geometry::precision::UncertainProjector;
use photopose_geometry::{
    Camera, DistortSeed, GeometryError, Matrix2, Observation, Resection, ResectionOptions,
    ResectionReport, Vector2, Vector3,
};
use photopose_vision::{
    DetectStage, Detection, Detections, Detector, DetectorOptions, FrameStatus, VisionError,
    WindowMeasurer,
};
use thiserror::Error;
use wide::{f64x2, CmpEq, CmpLt, CmpNe};

/// Why a frame could not be processed at all (as opposed to a frame that
/// simply shows too few targets, which is a [`PoseStatus`]).
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum LocateError {
    /// The image does not fit the detector (size, buffer).
    #[error(transparent)]
    Vision(#[from] VisionError),
}

/// Tuning of the pipeline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocateOptions {
    /// The resection's options.
    pub resection: ResectionOptions,
    /// Gate radius in standard deviations of the projected position.
    pub gate_sigmas: f64,
    /// Smallest gate radius, px (centroid error, eccentricity, lens model).
    pub gate_min_px: f64,
    /// Largest gate radius as a share of the distance to the nearest other
    /// projected target (keeps gates from overlapping).
    pub gate_spacing_ratio: f64,
    /// Coded targets needed for the first resection.
    pub min_coded: usize,
    /// Projected uncoded targets closer than this to the image border are
    /// not searched, px.
    pub edge_margin_px: f64,
    /// Correct each centroid for the eccentricity of the projected circle
    /// (the centre of the imaged ellipse is not the image of the circle's
    /// centre), with the first pose.
    pub eccentricity: bool,
    /// Standard deviation of a saturated (over-exposed) target's image
    /// coordinates as a multiple of an unsaturated one's: its observation
    /// gets the weight `1 / factor²` in both resections. A clipped dot's
    /// centre is unbiased but less precise (the detector's over-exposure
    /// test: RMS 0.009 px unclipped, up to 0.019 px clipped).
    pub saturated_sigma_factor: f64,
}

impl Default for LocateOptions {
    fn default() -> Self {
        LocateOptions {
            resection: ResectionOptions::default(),
            gate_sigmas: 5.0,
            gate_min_px: 1.5,
            gate_spacing_ratio: 0.4,
            min_coded: 4,
            edge_margin_px: 2.0,
            eccentricity: true,
            saturated_sigma_factor: 2.0,
        }
    }
}

/// The stages of [`Locator::locate_probed`], in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// A stage inside the detector ended (threshold, labelling, a blob's
    /// measurement or code reading, the final suppression).
    Detector(DetectStage),
    /// Threshold, labelling, centroids, code reading: all of detection.
    Detect,
    /// Coded targets taken and the first resection done.
    FirstPose,
    /// Uncoded targets identified (and centroids corrected).
    Uncoded,
    /// Final resection over all targets.
    FinalPose,
}

/// What came of a frame.
#[derive(Debug, Clone, PartialEq)]
pub enum PoseStatus {
    /// A pose was measured.
    Ok,
    /// The frame is empty, saturated or cluttered (threshold stage).
    Frame(FrameStatus),
    /// Fewer coded targets than needed were identified.
    TooFewTargets {
        /// Coded targets identified.
        coded: usize,
    },
    /// The targets do not determine a pose.
    NoPose(GeometryError),
}

/// An identified target of the frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Identified {
    /// Field id.
    pub id: u64,
    /// Coded or uncoded.
    pub kind: TargetKind,
    /// Image of the target's centre, pixels: the blob centre corrected for
    /// the eccentricity of the projected circle (equal to the blob centre
    /// when the correction is off).
    pub col: f64,
    /// Image of the target's centre, pixels.
    pub row: f64,
    /// Centre of the bright blob as measured, pixels.
    pub blob_col: f64,
    /// Centre of the bright blob as measured, pixels.
    pub blob_row: f64,
    /// Index into [`Detections::targets`].
    pub detection: usize,
    /// Used in the final pose (not rejected by the adjustment).
    pub used: bool,
    /// The dot is over-exposed (saturated pixels): its observation is
    /// weighted down ([`LocateOptions::saturated_sigma_factor`]).
    pub saturated: bool,
    /// The dot's largest grey value (its blob's brightest pixel; the
    /// exposure control loop's measurement).
    pub peak: u32,
}

/// The result of [`Locator::locate`].
#[derive(Debug, Clone, Copy)]
pub struct Location<'a> {
    /// What came of the frame.
    pub status: &'a PoseStatus,
    /// The final pose (status `Ok`).
    pub pose: Option<&'a ResectionReport>,
    /// The first pose, from the coded targets only.
    pub coarse: Option<&'a ResectionReport>,
    /// Identified targets, coded first, then uncoded.
    pub targets: &'a [Identified],
    /// Everything the detector saw.
    pub detections: &'a Detections,
    /// Ids rejected by the final adjustment.
    pub rejected_ids: &'a [u64],
    /// Identified targets that are over-exposed (weighted down in the
    /// adjustment): when it is not zero, over-exposure costs precision.
    pub n_saturated: usize,
}

/// The per-frame pipeline with all its buffers.
#[derive(Debug)]
pub struct Locator {
    camera: Camera,
    field: Field,
    options: LocateOptions,
    detector: Detector,
    resection: Resection,
    obs: Vec<Observation>,
    identified: Vec<Identified>,
    taken: Vec<bool>,
    grid: Grid,
    projected: Vec<Projected>,
    status: PoseStatus,
    coarse: Option<ResectionReport>,
    pose: Option<ResectionReport>,
    rejected: Vec<u64>,
    /// Field indices of the uncoded targets, each with the field index of
    /// its nearest other target (for the gate's upper bound).
    uncoded: Vec<(usize, usize)>,
    /// Each field target's distance to its nearest other target, mm.
    spacing: Vec<f64>,
    /// Tracking mode's measurer of one target in its window.
    window: WindowMeasurer,
    /// Tracking mode's windows of one frame.
    windows: Vec<Window>,
    /// The rows of each window's target in the refinement's first pass
    /// (formed while projecting it).
    jacobians: Vec<PointJacobian>,
    /// Each field target's inverse distortion in the last tracked frame
    /// that projected it (the start of the next: `Camera::distort_seeded`).
    seeds: Vec<Option<DistortSeed>>,
    /// Tracking mode's order of the coded targets whose rings are read
    /// (`track::spread_order`).
    verify_order: Vec<usize>,
    /// A ball holding every field target (centre, radius, mm): the
    /// tracked frame's jump check bounds the shift of all at once.
    plate_centre: Vector3<f64>,
    plate_radius: f64,
}

/// A tracked target's window: before it is measured, where to look; once
/// it is found (the first windows then are the observations'), what the
/// eccentricity and the jump check need of its projection.
#[derive(Debug, Clone, Copy)]
struct Window {
    field_index: usize,
    /// Where to look.
    expected: photopose_vision::Expected,
    /// The ideal projection, mm.
    ideal: Vector2<f64>,
    /// The target in camera coordinates with the pose projected from, mm
    /// (`R (P − C)`, kept for the eccentricity).
    camera: Vector3<f64>,
}

#[derive(Debug, Clone, Copy)]
struct Projected {
    field_index: usize,
    col: f64,
    row: f64,
    sigma_px: f64,
    spacing: f64,
}

impl Locator {
    /// A pipeline for `camera` and `field`; allocates its buffers.
    pub fn new(camera: Camera, field: Field, options: LocateOptions) -> Result<Self, LocateError> {
        let detector = Detector::new(
            camera.sensor.width,
            camera.sensor.height,
            DetectorOptions::for_field(&field),
        )?;
        Self::with_detector(camera, field, options, detector)
    }

    /// A pipeline with a detector configured by the caller.
    pub fn with_detector(
        camera: Camera,
        field: Field,
        options: LocateOptions,
        detector: Detector,
    ) -> Result<Self, LocateError> {
        let n = field.len();
        let targets = field.targets();
        let nearest: Vec<usize> = (0..n)
            .map(|k| {
                (0..n)
                    .filter(|&j| j != k)
                    .min_by(|&a, &b| {
                        let da = (targets[a].position - targets[k].position).norm_squared();
                        let db = (targets[b].position - targets[k].position).norm_squared();
                        da.total_cmp(&db)
                    })
                    .unwrap_or(k)
            })
            .collect();
        let uncoded = (0..n)
            .filter(|&k| targets[k].kind == TargetKind::Uncoded)
            .map(|k| (k, nearest[k]))
            .collect();
        let spacing = (0..n)
            .map(|k| match nearest[k] {
                j if j == k => f64::INFINITY,
                j => (targets[j].position - targets[k].position).norm(),
            })
            .collect();
        let window = WindowMeasurer::new(*detector.options());
        let plate_centre =
            targets.iter().fold(Vector3::zeros(), |s, t| s + t.position) / n.max(1) as f64;
        let plate_radius = targets
            .iter()
            .map(|t| (t.position - plate_centre).norm())
            .fold(0.0, f64::max);
        Ok(Locator {
            resection: Resection::new(&camera, options.resection),
            grid: Grid::new(camera.sensor.width, camera.sensor.height, 16, 4 * n.max(64)),
            camera,
            options,
            detector,
            obs: Vec::with_capacity(n),
            identified: Vec::with_capacity(n),
            taken: Vec::with_capacity(4 * n.max(64)),
            projected: Vec::with_capacity(n),
            status: PoseStatus::TooFewTargets { coded: 0 },
            coarse: None,
            pose: None,
            rejected: Vec::with_capacity(n),
            uncoded,
            spacing,
            window,
            windows: Vec::with_capacity(n),
            jacobians: Vec::with_capacity(n),
            seeds: vec![None; n],
            verify_order: track::spread_order(targets, TargetKind::Coded),
            plate_centre,
            plate_radius,
            field,
        })
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The test field.
    pub fn field(&self) -> &Field {
        &self.field
    }

    /// What came of the last frame (located or tracked).
    pub fn status(&self) -> &PoseStatus {
        &self.status
    }

    /// The pose of the last frame, when it has one.
    pub fn pose(&self) -> Option<&ResectionReport> {
        self.pose.as_ref()
    }

    /// The targets identified in the last frame (located or tracked),
    /// coded first in a located frame, in field order in a tracked one.
    pub fn identified(&self) -> &[Identified] {
        &self.identified
    }

    /// Detects, identifies and resects one frame.
    pub fn locate(&mut self, image: ImageView<'_>) -> Result<Location<'_>, LocateError> {
        self.locate_probed(image, &mut |_| {})
    }

    /// [`Locator::locate`], calling `probe` as each [`Stage`] ends (the
    /// caller may read a clock there: this crate reads none).
    pub fn locate_probed(
        &mut self,
        image: ImageView<'_>,
        probe: &mut dyn FnMut(Stage),
    ) -> Result<Location<'_>, LocateError> {
        self.identified.clear();
        self.rejected.clear();
        self.coarse = None;
        self.pose = None;
        self.detector
            .detect_probed(image, &mut |s| probe(Stage::Detector(s)))?;
        probe(Stage::Detect);
        self.status = self.run(probe);
        Ok(Location {
            status: &self.status,
            pose: self.pose.as_ref(),
            coarse: self.coarse.as_ref(),
            targets: &self.identified,
            detections: self.detector.detections(),
            rejected_ids: &self.rejected,
            n_saturated: self.identified.iter().filter(|t| t.saturated).count(),
        })
    }

    fn run(&mut self, probe: &mut dyn FnMut(Stage)) -> PoseStatus {
        let det = self.detector.detections();
        if det.status != FrameStatus::Normal {
            return PoseStatus::Frame(det.status);
        }
        // 2. Coded targets: ids the field has as coded; an id read twice is
        // ambiguous and dropped.
        self.obs.clear();
        for (k, d) in det.targets.iter().enumerate() {
            let Some(id) = d.id else { continue };
            let Some(t) = self.field.get(id) else {
                continue;
            };
            if t.kind != TargetKind::Coded {
                continue;
            }
            let twice = det
                .targets
                .iter()
                .enumerate()
                .any(|(j, o)| j != k && o.id == Some(id));
            if twice {
                continue;
            }
            self.identified.push(Identified {
                id,
                kind: TargetKind::Coded,
                col: d.col,
                row: d.row,
                blob_col: d.col,
                blob_row: d.row,
                detection: k,
                used: true,
                saturated: d.saturated,
                peak: d.peak,
            });
            self.obs.push(observation(
                &self.camera,
                id,
                t.position,
                d,
                self.options.saturated_sigma_factor,
            ));
        }
        let coded = self.obs.len();
        if coded < self.options.min_coded.max(4) {
            return PoseStatus::TooFewTargets { coded };
        }
        // 3. First resection.
        let coarse = match self.resection.solve(&self.obs) {
            Ok(r) => r,
            Err(e) => return PoseStatus::NoPose(e),
        };
        self.coarse = Some(coarse);
        probe(Stage::FirstPose);
        // Coded targets the adjustment rejected are not identified.
        let rejected = self.resection.rejected_ids();
        self.identified.retain(|t| !rejected.contains(&t.id));
        self.obs.retain(|o| !rejected.contains(&o.id));
        // 4. Uncoded targets by projection.
        self.identify_uncoded(&coarse);
        if self.options.eccentricity {
            self.correct_eccentricity(&coarse.exterior);
        }
        probe(Stage::Uncoded);
        // 5. Final pose over all identified targets.
        match self.resection.refine(&self.obs, coarse.exterior) {
            Ok(r) => {
                let rejected = self.resection.rejected_ids();
                for t in &mut self.identified {
                    t.used = !rejected.contains(&t.id);
                }
                self.rejected.extend_from_slice(rejected);
                self.pose = Some(r);
                probe(Stage::FinalPose);
                PoseStatus::Ok
            }
            Err(e) => PoseStatus::NoPose(e),
        }
    }

    /// Moves every observation from the centre of the imaged ellipse to the
    /// image of the circle's centre. Under the collinearity equations the
    /// image of the dot's rim is exactly an ellipse — the conic
    /// `Q' = M⁻ᵀ diag(1, 1, −r²) M⁻¹` with `M` the plane-to-image
    /// transformation of the target's plane — and the centroid of the imaged
    /// dot is that ellipse's centre; its offset from the projected centre is
    /// taken off (lens distortion changes it only in the second order).
    fn correct_eccentricity(&mut self, e: &photopose_geometry::Exterior) {
        let pose = EccentricityPose::new(self.camera.interior.c, e);
        let field = &self.field;
        let target = |t: &Identified, _| {
            let t = field.get(t.id)?;
            Some((&t.position, e.to_camera(&t.position), t.radius))
        };
        let ps = self.camera.sensor.pixel_size;
        correct_in_pairs(&pose, ps, &mut self.obs, &mut self.identified, target);
    }

    /// [`Locator::correct_eccentricity`] of a tracked frame with the pose
    /// its targets were projected with: each observation's target comes
    /// from its window (no look-up by id) and so does its camera point.
    fn correct_eccentricity_tracked(&mut self, e: &photopose_geometry::Exterior) {
        let pose = EccentricityPose::new(self.camera.interior.c, e);
        let (targets, windows) = (self.field.targets(), &self.windows);
        let target = |_: &Identified, k: usize| {
            let w: &Window = &windows[k];
            let t = &targets[w.field_index];
            Some((&t.position, w.camera, t.radius))
        };
        let ps = self.camera.sensor.pixel_size;
        correct_in_pairs(&pose, ps, &mut self.obs, &mut self.identified, target);
    }

    fn identify_uncoded(&mut self, coarse: &ResectionReport) {
        let det = self.detector.detections();
        let c = self.camera.interior.c;
        let px = self.camera.sensor.pixel_size;
        // Index the uncoded detections.
        self.taken.clear();
        self.taken.resize(det.targets.len(), false);
        self.grid.clear();
        for (k, d) in det.targets.iter().enumerate() {
            if d.kind == TargetKind::Uncoded {
                self.grid.insert(k as u32, d.col, d.row);
            }
        }
        // Project every uncoded field target with its uncertainty.
        self.projected.clear();
        let projector = UncertainProjector::new(c, &coarse.exterior, &coarse.covariance);
        for &(fi, neighbour) in &self.uncoded {
            let t = &self.field.targets()[fi];
            let Some(u) = projector.project(&t.position) else {
                continue;
            };
            let ideal = u.ideal;
            let Some(measured) = self.camera.distort(ideal) else {
                continue;
            };
            let p = self.camera.image_to_pixel(measured);
            if !self.camera.contains_pixel(p, self.options.edge_margin_px) {
                continue;
            }
            // Image distance to the nearest other target (pinhole is close
            // enough for a bound).
            let spacing = coarse
                .exterior
                .project_ideal(c, &self.field.targets()[neighbour].position)
                .map_or(f64::INFINITY, |q| (q - ideal).norm() / px);
            self.projected.push(Projected {
                field_index: fi,
                col: p.x,
                row: p.y,
                sigma_px: largest_sigma(&u.covariance) / px,
                spacing,
            });
        }
        // Match each projection to the nearest blob inside its gate.
        for i in 0..self.projected.len() {
            let p = self.projected[i];
            let spacing = p.spacing;
            let gate = (self.options.gate_min_px + self.options.gate_sigmas * p.sigma_px)
                .min(self.options.gate_spacing_ratio * spacing);
            let mut best: Option<(u32, f64)> = None;
            let mut inside = 0;
            self.grid.for_each_near(p.col, p.row, gate, |k| {
                let d = &det.targets[k as usize];
                let dist = ((d.col - p.col).powi(2) + (d.row - p.row).powi(2)).sqrt();
                if dist <= gate {
                    inside += 1;
                    if best.is_none_or(|(_, b)| dist < b) {
                        best = Some((k, dist));
                    }
                }
            });
            let Some((k, _)) = best else { continue };
            if inside != 1 || self.taken[k as usize] {
                continue;
            }
            self.taken[k as usize] = true;
            let d = &det.targets[k as usize];
            let t = &self.field.targets()[p.field_index];
            self.identified.push(Identified {
                id: t.id,
                kind: TargetKind::Uncoded,
                col: d.col,
                row: d.row,
                blob_col: d.col,
                blob_row: d.row,
                detection: k as usize,
                used: true,
                saturated: d.saturated,
                peak: d.peak,
            });
            self.obs.push(observation(
                &self.camera,
                t.id,
                t.position,
                d,
                self.options.saturated_sigma_factor,
            ));
        }
    }
}

/// The observation of a detection: its centre corrected with `camera`,
/// weighted down by `1 / saturated_factor²` when the dot is over-exposed.
fn observation(
    camera: &Camera,
    id: u64,
    object: Vector3<f64>,
    d: &Detection,
    saturated_factor: f64,
) -> Observation {
    let mut o = Observation::from_pixel(camera, id, object, d.col, d.row);
    if d.saturated && saturated_factor.is_finite() && saturated_factor > 0.0 {
        o.weight = Matrix2::identity() / (saturated_factor * saturated_factor);
    }
    o
}

/// The largest standard deviation of a projected position with covariance
/// `cov` (the square root of its larger eigenvalue), in its units.
fn largest_sigma(cov: &Matrix2<f64>) -> f64 {
    let (a, b, d) = (cov[(0, 0)], cov[(0, 1)], cov[(1, 1)]);
    let lmax = 0.5 * (a + d) + (0.25 * (a - d) * (a - d) + b * b).sqrt();
    lmax.max(0.0).sqrt()
}

/// The eccentricity of a circular target facing `+Z` (centre `position`,
/// radius `radius`, mm) seen from `e` with principal distance `c`: the
/// centre of its image (an ellipse) minus the image of its centre, in ideal
/// image coordinates, mm. Under the collinearity equations the image of the
/// rim is exactly the conic `Q' = M⁻ᵀ diag(1, 1, −r²) M⁻¹`, `M` the
/// plane-to-image transformation of the target's plane. `None` if the
/// target is not in front of the camera or the conic degenerates.
pub fn eccentricity(
    c: f64,
    e: &photopose_geometry::Exterior,
    position: &Vector3<f64>,
    radius: f64,
) -> Option<Vector2<f64>> {
    let camera = e.to_camera(position);
    EccentricityPose::new(c, e).pair([position; 2], [&camera; 2], [radius; 2])[0]
}

/// Moves an observation and its identified target (pixel size `ps`) from
/// the centre of the imaged ellipse to the image of the circle's centre,
/// `offset` being the first's offset from the second (ideal image
/// coordinates, `y'` up).
fn move_by_eccentricity(o: &mut Observation, t: &mut Identified, offset: Vector2<f64>, ps: f64) {
    o.image -= offset;
    t.col -= offset.x / ps;
    t.row += offset.y / ps;
}

/// Moves each observation `k` of `obs` and its identified target by the
/// eccentricity seen from `pose` (pixel size `ps`), `target` giving the
/// target's position, camera point and radius (`None`: left as it is),
/// two targets at a time ([`EccentricityPose::pair`]; a last one alone
/// fills both lanes).
#[inline(always)]
fn correct_in_pairs<'a>(
    pose: &EccentricityPose,
    ps: f64,
    obs: &mut [Observation],
    identified: &mut [Identified],
    target: impl Fn(&Identified, usize) -> Option<(&'a Vector3<f64>, Vector3<f64>, f64)>,
) {
    debug_assert_eq!(obs.len(), identified.len());
    let apply = |obs: &mut [Observation], ids: &mut [Identified], k: usize, offset| {
        if let Some(offset) = offset {
            debug_assert_eq!(obs[k].id, ids[k].id);
            move_by_eccentricity(&mut obs[k], &mut ids[k], offset, ps);
        }
    };
    let mut pending = None;
    for k in 0..obs.len() {
        let Some((p, camera, r)) = target(&identified[k], k) else {
            continue;
        };
        let Some((j, pj, cj, rj)) = pending.take() else {
            pending = Some((k, p, camera, r));
            continue;
        };
        let [first, second] = pose.pair([pj, p], [&cj, &camera], [rj, r]);
        apply(obs, identified, j, first);
        apply(obs, identified, k, second);
    }
    if let Some((j, pj, cj, rj)) = pending {
        apply(obs, identified, j, pose.pair([pj; 2], [&cj; 2], [rj; 2])[0]);
    }
}

/// The part of [`eccentricity`] that depends on the pose alone, formed once
/// per pose, and the eccentricities of two targets at a time
/// ([`EccentricityPose::pair`]).
///
/// The products `M = diag(−c, −c, 1) · R · [x̂ ŷ (P − C)]` and
/// `Q' = M⁻ᵀ diag(1, 1, −r²) M⁻¹` written out without their terms in the
/// zeros and ones of the three known factors: the same operations in the
/// same order as nalgebra's products and inverses on what remains (a term
/// `0 · x` only ever added `±0`), so the same bits in half the
/// instructions (tracking: 2.91 M → 1.91 M per 50 frames). `M`'s first two
/// columns and last row but its corner are the pose's alone (another
/// 0.6 M, hoisted). Each SIMD lane computes one target's scalar
/// expression, operation for operation: two targets for the instructions
/// of one (tracking and full frame: 0.24 M less per 50 and 0.14 M less per 8 frames).
#[derive(Debug, Clone, Copy)]
struct EccentricityPose {
    /// `−c`.
    neg_c: f64x2,
    /// The projection centre `C`.
    center: [f64x2; 3],
    /// Rows 0 and 1 of `diag(−c, −c, 1) · R`.
    k0: [f64x2; 3],
    k1: [f64x2; 3],
    /// `M`'s entries `m31`, `m32` (`R`'s) and the minors and cofactor
    /// numerators that hold no `P − C`.
    m31: f64x2,
    m32: f64x2,
    minor_m11_m22: f64x2,
    num21: f64x2,
    num22: f64x2,
}

impl EccentricityPose {
    fn new(c: f64, e: &photopose_geometry::Exterior) -> Self {
        let r = &e.rotation;
        let (k00, k01, k02) = (-c * r[(0, 0)], -c * r[(0, 1)], -c * r[(0, 2)]);
        let (k10, k11, k12) = (-c * r[(1, 0)], -c * r[(1, 1)], -c * r[(1, 2)]);
        // M: columns (kR) x̂, (kR) ŷ, (kR) (P − C).
        let (m11, m12) = (k00, k01);
        let (m21, m22) = (k10, k11);
        let (m31, m32) = (r[(2, 0)], r[(2, 1)]);
        let s = f64x2::splat;
        EccentricityPose {
            neg_c: s(-c),
            center: [s(e.center.x), s(e.center.y), s(e.center.z)],
            k0: [s(k00), s(k01), s(k02)],
            k1: [s(k10), s(k11), s(k12)],
            m31: s(m31),
            m32: s(m32),
            minor_m11_m22: s(m21 * m32 - m31 * m22),
            num21: s(m12 * m31 - m32 * m11),
            num22: s(m11 * m22 - m21 * m12),
        }
    }

    /// [`eccentricity`] of the targets at `position` (facing `+Z`, radius
    /// `radius`), given their centres in camera coordinates,
    /// `camera = R (P − C)` ([`photopose_geometry::Exterior::to_camera`]).
    #[inline(always)]
    fn pair(
        &self,
        position: [&Vector3<f64>; 2],
        camera: [&Vector3<f64>; 2],
        radius: [f64; 2],
    ) -> [Option<Vector2<f64>>; 2] {
        let lanes = |f: &dyn Fn(usize) -> f64| f64x2::new([f(0), f(1)]);
        let (qx, qy, qz) = (
            lanes(&|k| camera[k].x),
            lanes(&|k| camera[k].y),
            lanes(&|k| camera[k].z),
        );
        // The image of the centre (`ideal_of_camera_point`; `qz < 0` is
        // checked with the rest below).
        let centre = [self.neg_c * qx / qz, self.neg_c * qy / qz];
        let ux = lanes(&|k| position[k].x) - self.center[0];
        let uy = lanes(&|k| position[k].y) - self.center[1];
        let uz = lanes(&|k| position[k].z) - self.center[2];
        let ([k00, k01, k02], [k10, k11, k12]) = (self.k0, self.k1);
        let (m11, m12, m13) = (k00, k01, k00 * ux + k01 * uy + k02 * uz);
        let (m21, m22, m23) = (k10, k11, k10 * ux + k11 * uy + k12 * uz);
        let (m31, m32, m33) = (self.m31, self.m32, qz);
        // nalgebra's 3 × 3 inverse (`try_inverse`), operation for operation.
        let minor_m12_m23 = m22 * m33 - m32 * m23;
        let minor_m11_m23 = m21 * m33 - m31 * m23;
        let minor_m11_m22 = self.minor_m11_m22;
        let det = m11 * minor_m12_m23 - m12 * minor_m11_m23 + m13 * minor_m11_m22;
        // a[i][j] = (M⁻¹)_ij.
        let a = [
            [
                minor_m12_m23 / det,
                (m13 * m32 - m33 * m12) / det,
                (m12 * m23 - m22 * m13) / det,
            ],
            [
                neg(minor_m11_m23) / det,
                (m11 * m33 - m31 * m13) / det,
                (m13 * m21 - m23 * m11) / det,
            ],
            [minor_m11_m22 / det, self.num21 / det, self.num22 / det],
        ];
        // Q'_ij = Σ_k (M⁻ᵀ D)_ik (M⁻¹)_kj with (M⁻ᵀ D)_ik = a[k][i] D_kk.
        let r = f64x2::new(radius);
        let neg_r2 = neg(r * r);
        let d2 = [a[2][0] * neg_r2, a[2][1] * neg_r2];
        let q = |i: usize, j: usize| a[0][i] * a[0][j] + a[1][i] * a[1][j] + d2[i] * a[2][j];
        let (q00, q01, q10, q11) = (q(0, 0), q(0, 1), q(1, 0), q(1, 1));
        let (q02, q12) = (q(0, 2), q(1, 2));
        // nalgebra's 2 × 2 inverse, then −A⁻¹ (q02, q12).
        let det2 = q00 * q11 - q10 * q01;
        let (i00, i01, i10, i11) = (q11 / det2, neg(q01) / det2, neg(q10) / det2, q00 / det2);
        let ellipse_centre = [neg(i00 * q02 + i01 * q12), neg(i10 * q02 + i11 * q12)];
        let offset = [ellipse_centre[0] - centre[0], ellipse_centre[1] - centre[1]];
        // Where the scalar form returned early (behind the camera, a
        // degenerate conic) or gave up (a non-finite offset: `0 · x` is
        // zero exactly for a finite `x`).
        let zero = f64x2::ZERO;
        let finite = |v: f64x2| (v * zero).cmp_eq(zero);
        let seen = qz.cmp_lt(zero) & det.cmp_ne(zero) & det2.cmp_ne(zero);
        let ok = (seen & finite(offset[0]) & finite(offset[1])).move_mask();
        let (ox, oy) = (offset[0].to_array(), offset[1].to_array());
        std::array::from_fn(|k| (ok >> k & 1 == 1).then(|| Vector2::new(ox[k], oy[k])))
    }
}

/// `−v` lane by lane as scalar negation does it (the sign flipped, also of
/// a zero; `wide`'s `−v` is `0 − v`, which gives `+0` for `+0`).
#[inline(always)]
fn neg(v: f64x2) -> f64x2 {
    v ^ f64x2::splat(-0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use photopose_geometry::Matrix3;
    use photopose_vision::{CodeStatus, TargetKind};

    /// The former, plain form of `EccentricityPose::pair` (nalgebra's
    /// products, one target).
    fn eccentricity_plain(
        c: f64,
        e: &photopose_geometry::Exterior,
        position: &Vector3<f64>,
        camera: &Vector3<f64>,
        radius: f64,
    ) -> Option<Vector2<f64>> {
        let k = Matrix3::from_diagonal(&Vector3::new(-c, -c, 1.0));
        let centre = photopose_geometry::exterior::ideal_of_camera_point(c, camera)?;
        // Plane (s, t) of a target facing +Z, origin at its centre.
        let plane = Matrix3::from_columns(&[Vector3::x(), Vector3::y(), position - e.center]);
        let m_inv = (k * e.rotation * plane).try_inverse()?;
        let r2 = radius * radius;
        let q = m_inv.transpose() * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -r2)) * m_inv;
        let a2 = Matrix2::new(q[(0, 0)], q[(0, 1)], q[(1, 0)], q[(1, 1)]);
        let ellipse_centre = -(a2.try_inverse()? * Vector2::new(q[(0, 2)], q[(1, 2)]));
        let offset = ellipse_centre - centre;
        (offset.x.is_finite() && offset.y.is_finite()).then_some(offset)
    }

    #[test]
    fn written_out_eccentricity_is_bit_identical() {
        use photopose_geometry::Exterior;
        // Tilted, turned cameras over a plate, and the axis-aligned
        // rotations of `look_at` with their exact zeros.
        let (mut seen, mut missed) = (0, 0);
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for k in 0..3000 {
            let eye = Vector3::new(600.0 * next(), 600.0 * next(), 900.0 + 400.0 * next());
            let (at, up) = if k % 10 == 0 {
                (Vector3::new(eye.x, eye.y, 0.0), Vector3::x())
            } else {
                (
                    Vector3::new(200.0 * next(), 200.0 * next(), 0.0),
                    Vector3::new(next(), next(), 0.0),
                )
            };
            let Some(e) = Exterior::look_at(eye, at, up) else {
                continue;
            };
            // Two targets a pair: mostly on the plate, some behind the
            // camera or in its plane (the conic degenerates), some of no
            // radius.
            let mut target = || {
                let z = match (next() * 1000.0) as i64 {
                    -500..=-481 => eye.z + 100.0,
                    -480..=-461 => eye.z,
                    _ => 2.0 * next(),
                };
                // A dot of no size now and then: a point, its conic a
                // pair of lines through it.
                let r = if next() < -0.45 {
                    0.0
                } else {
                    2.0 + 4.0 * next()
                };
                (Vector3::new(500.0 * next(), 500.0 * next(), z), r)
            };
            let (pa, ra) = target();
            let (pb, rb) = target();
            let (ca, cb) = (e.to_camera(&pa), e.to_camera(&pb));
            let pose = EccentricityPose::new(12.0, &e);
            let got = pose.pair([&pa, &pb], [&ca, &cb], [ra, rb]);
            let one = eccentricity(12.0, &e, &pa, ra);
            for (g, want) in [
                (got[0], eccentricity_plain(12.0, &e, &pa, &ca, ra)),
                (got[1], eccentricity_plain(12.0, &e, &pb, &cb, rb)),
                (one, eccentricity_plain(12.0, &e, &pa, &ca, ra)),
            ] {
                assert_eq!(want.is_some(), g.is_some(), "case {k}");
                if let (Some(w), Some(g)) = (want, g) {
                    seen += 1;
                    assert_eq!(
                        (w.x.to_bits(), w.y.to_bits()),
                        (g.x.to_bits(), g.y.to_bits())
                    );
                } else {
                    missed += 1;
                }
            }
        }
        assert!(missed > 100, "{missed} targets behind or edge-on");
        assert!(seen > 6000, "{seen} targets in front");
    }

    fn detection(saturated: bool) -> Detection {
        Detection {
            col: 650.0,
            row: 515.0,
            semi_major: 5.0,
            semi_minor: 5.0,
            angle: 0.0,
            area: 80,
            peak: 255,
            signal: 1.0e4,
            background: 13.0,
            kind: TargetKind::Uncoded,
            id: None,
            code: CodeStatus::NoRing,
            saturated,
        }
    }

    #[test]
    fn saturated_observations_are_weighted_down() {
        let camera = photopose_geometry::Camera::reference_ideal();
        let p = Vector3::new(1.0, 2.0, 0.0);
        let plain = observation(&camera, 7, p, &detection(false), 2.0);
        let clipped = observation(&camera, 7, p, &detection(true), 2.0);
        assert_eq!(plain.weight, Matrix2::identity());
        assert_eq!(clipped.weight, Matrix2::identity() * 0.25);
        assert_eq!(plain.image, clipped.image);
        // A factor that is no factor leaves the weight alone.
        for f in [0.0, -1.0, f64::NAN] {
            let o = observation(&camera, 7, p, &detection(true), f);
            assert_eq!(o.weight, Matrix2::identity());
        }
    }
}
