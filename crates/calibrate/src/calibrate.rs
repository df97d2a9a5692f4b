//! The whole calibration from detected blobs: start values, identification
//! of the uncoded targets as the solution improves, and the adjustment.
//!
//! 1. Coded targets are taken by their ids (the detector reads rings
//!    without knowing the camera; a distorted lens only moves the blobs).
//! 2. Each image's exterior orientation starts from
//!    [`photopose_geometry::Resection`] over its coded targets with the
//!    initial (nominal) camera; a wide hypothesise-and-verify gate lets
//!    the uncorrected distortion pass. Images without enough coded targets,
//!    or whose resection fails, are skipped and named.
//! 3. A first adjustment over the coded targets estimates the camera.
//! 4. Every uncoded field target is projected with the current camera and
//!    orientation; the one uncoded blob inside a gate (a share of the image
//!    distance to the nearest other target) is taken, a blob claimed twice
//!    by none. Adjust again; repeat until the identified set stops changing.

use crate::bundle::{Bundle, BundleOptions, BundleResult, ImageBlock, PointObservation};
use crate::error::CalibrateError;
use nalgebra::{Vector2, Vector3};
use photopose_field::{Field, TargetKind};
use photopose_geometry::{Camera, Exterior, Observation, Resection, ResectionOptions};

/// A blob of the detector, as far as calibration needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Blob {
    /// Centre column, pixels.
    pub col: f64,
    /// Centre row, pixels.
    pub row: f64,
    /// Coded (a ring seen) or uncoded.
    pub kind: TargetKind,
    /// The id read from the ring (coded targets).
    pub id: Option<u64>,
}

/// The detections of one image.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageDetections {
    /// The image's name (its path) for reports.
    pub name: String,
    /// The blobs.
    pub blobs: Vec<Blob>,
}

/// Tuning of the calibration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationOptions {
    /// The adjustment's options.
    pub bundle: BundleOptions,
    /// Coded targets an image needs for its start.
    pub min_coded: usize,
    /// Hypothesise-and-verify gate of the start resection, pixels (wide:
    /// the nominal camera leaves the distortion uncorrected).
    pub start_gate_px: f64,
    /// Gate of the uncoded identification as a share of the image distance
    /// to the nearest other target.
    pub gate_spacing_ratio: f64,
    /// Largest gate of the uncoded identification once the camera is
    /// adjusted, pixels.
    pub gate_px: f64,
    /// Identification rounds at most.
    pub max_rounds: usize,
    /// Least tilt of the steepest image against a planar field, degrees.
    pub min_tilt_deg: f64,
    /// Least number of usable images.
    pub min_images: usize,
    /// Take the eccentricity of each target's image off its measured
    /// position (the centre of the imaged ellipse is not the image of the
    /// circle's centre), with the current camera and orientation.
    pub eccentricity: bool,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        CalibrationOptions {
            bundle: BundleOptions::default(),
            min_coded: 6,
            start_gate_px: 25.0,
            gate_spacing_ratio: 0.35,
            gate_px: 5.0,
            max_rounds: 5,
            min_tilt_deg: 3.0,
            min_images: 3,
            eccentricity: true,
        }
    }
}

/// An image left out of the adjustment.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Skipped {
    /// Its name.
    pub image: String,
    /// Why.
    pub reason: String,
}

/// One observation's outcome, for reports and plots.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Residual {
    /// Target id.
    pub id: u64,
    /// Measured position, pixels.
    pub col: f64,
    /// Measured position, pixels.
    pub row: f64,
    /// Residual along `col`, pixels (measured minus adjusted model).
    pub dcol: f64,
    /// Residual along `row`, pixels.
    pub drow: f64,
    /// Used (false: rejected by data snooping).
    pub used: bool,
}

/// An adjusted image.
#[derive(Debug, Clone, PartialEq)]
pub struct AdjustedImage {
    /// Its name.
    pub name: String,
    /// The adjusted exterior orientation.
    pub exterior: Exterior,
    /// Every observation with its residual.
    pub residuals: Vec<Residual>,
}

/// The result of [`calibrate`].
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The adjustment's result (camera, covariance, σ0, …).
    pub result: BundleResult,
    /// The images used.
    pub images: Vec<AdjustedImage>,
    /// Images skipped, in input order.
    pub skipped: Vec<Skipped>,
    /// Identification rounds run.
    pub rounds: usize,
    /// Target ids and adjusted coordinates (differ from the field's only
    /// with free targets).
    pub targets: Vec<(u64, Vector3<f64>)>,
}

/// Calibrates `initial` (sensor and nominal parameters) from the detections
/// of images of `field`.
pub fn calibrate(
    initial: &Camera,
    field: &Field,
    images: &[ImageDetections],
    options: &CalibrationOptions,
) -> Result<Calibration, CalibrateError> {
    if field.is_empty() {
        return Err(CalibrateError::BadField("no targets".into()));
    }
    let targets: Vec<Vector3<f64>> = field.targets().iter().map(|t| t.position).collect();
    let mut skipped = Vec::new();
    let mut blocks = Vec::new();
    let mut used_inputs = Vec::new();
    let ropt = ResectionOptions {
        ransac_threshold_px: options.start_gate_px,
        ..ResectionOptions::default()
    };
    let mut resection = Resection::new(initial, ropt);
    for (k, im) in images.iter().enumerate() {
        match start_block(initial, field, im, &mut resection, options) {
            Ok(b) => {
                blocks.push(b);
                used_inputs.push(k);
            }
            Err(reason) => skipped.push(Skipped {
                image: im.name.clone(),
                reason,
            }),
        }
    }
    let describe = |skipped: &[Skipped]| {
        if skipped.is_empty() {
            "none".to_string()
        } else {
            skipped
                .iter()
                .map(|s| format!("{}: {}", s.image, s.reason))
                .collect::<Vec<_>>()
                .join("; ")
        }
    };
    if blocks.len() < options.min_images {
        return Err(CalibrateError::TooFewImages {
            usable: blocks.len(),
            need: options.min_images,
            skipped: describe(&skipped),
        });
    }
    check_tilt(field, &blocks, options)?;
    let mut bundle = Bundle {
        camera: *initial,
        targets,
        images: blocks,
    };
    // Round 1 over the coded targets; then identify (and take the
    // eccentricities off with the current solution) and adjust again until
    // the identified set stops changing.
    let mut result = bundle.adjust(&options.bundle)?;
    let mut iterations = result.iterations;
    let mut rounds = 1;
    while rounds < options.max_rounds {
        let first = rounds == 1;
        let mut changed = false;
        for (block, &k) in bundle.images.iter_mut().zip(&used_inputs) {
            let mut next = identify(
                &bundle.camera,
                field,
                &bundle.targets,
                &block.exterior,
                &images[k].blobs,
                options,
                first,
            );
            let same = next.len() == block.points.len()
                && next
                    .iter()
                    .zip(&block.points)
                    .all(|(a, b)| a.target == b.target && a.measured == b.measured);
            if same {
                // Keep what data snooping decided.
                for (n, old) in next.iter_mut().zip(&block.points) {
                    n.used = old.used;
                }
            } else {
                changed = true;
            }
            block.points = next;
        }
        rounds += 1;
        result = bundle.adjust(&options.bundle)?;
        iterations += result.iterations;
        if !changed {
            break;
        }
    }
    result.iterations = iterations;
    let ps = initial.sensor.pixel_size;
    let adjusted = bundle
        .images
        .iter()
        .zip(&used_inputs)
        .map(|(b, &k)| AdjustedImage {
            name: images[k].name.clone(),
            exterior: b.exterior,
            residuals: b
                .points
                .iter()
                .filter_map(|p| {
                    let v = crate::model::residual(
                        &bundle.camera,
                        &b.exterior,
                        &bundle.targets[p.target],
                        &p.centre(),
                    )?;
                    let px = bundle.camera.image_to_pixel(p.measured);
                    Some(Residual {
                        id: field.targets()[p.target].id,
                        col: px.x,
                        row: px.y,
                        dcol: v.x / ps,
                        drow: -v.y / ps,
                        used: p.used,
                    })
                })
                .collect(),
        })
        .collect();
    Ok(Calibration {
        result,
        images: adjusted,
        skipped,
        rounds,
        targets: field
            .targets()
            .iter()
            .zip(&bundle.targets)
            .map(|(t, x)| (t.id, *x))
            .collect(),
    })
}

/// Coded observations and the start orientation of one image.
fn start_block(
    camera: &Camera,
    field: &Field,
    im: &ImageDetections,
    resection: &mut Resection,
    options: &CalibrationOptions,
) -> Result<ImageBlock, String> {
    let mut obs = Vec::new();
    let mut points = Vec::new();
    for (k, b) in im.blobs.iter().enumerate() {
        let Some(id) = b.id else { continue };
        let Some(ti) = field.index_of(id) else {
            continue;
        };
        if field.targets()[ti].kind != TargetKind::Coded {
            continue;
        }
        // An id read twice is ambiguous: neither is taken.
        if im
            .blobs
            .iter()
            .enumerate()
            .any(|(j, o)| j != k && o.id == Some(id))
        {
            continue;
        }
        obs.push(Observation::from_pixel(
            camera,
            id,
            field.targets()[ti].position,
            b.col,
            b.row,
        ));
        points.push(PointObservation {
            target: ti,
            measured: camera.pixel_to_image(b.col, b.row),
            used: true,
            eccentricity: Vector2::zeros(),
        });
    }
    if obs.len() < options.min_coded {
        return Err(format!(
            "test field not found: {} coded target(s) identified, need {}",
            obs.len(),
            options.min_coded
        ));
    }
    let report = resection
        .solve(&obs)
        .map_err(|e| format!("no start orientation from the coded targets: {e}"))?;
    let rejected = resection.rejected_ids();
    points.retain(|p| !rejected.contains(&field.targets()[p.target].id));
    Ok(ImageBlock {
        exterior: report.exterior,
        points,
    })
}

/// The coded observations plus the uncoded targets identified by projection
/// with `camera` and `exterior`, sorted by target.
#[allow(clippy::too_many_arguments)]
fn identify(
    camera: &Camera,
    field: &Field,
    positions: &[Vector3<f64>],
    exterior: &Exterior,
    blobs: &[Blob],
    options: &CalibrationOptions,
    first: bool,
) -> Vec<PointObservation> {
    let t = field.targets();
    let c = camera.interior.c;
    let ps = camera.sensor.pixel_size;
    let project = |x: &Vector3<f64>| -> Option<Vector2<f64>> {
        let ideal = exterior.project_ideal(c, x)?;
        let m = camera.distort(ideal)?;
        Some(camera.image_to_pixel(m))
    };
    let mut out = Vec::new();
    // Coded: by id, checked against the projection (a misread ring falls out).
    let mut claimed = vec![0u32; blobs.len()];
    let mut cand: Vec<(usize, usize)> = Vec::new();
    let ideal: Vec<Option<Vector2<f64>>> = t
        .iter()
        .map(|x| exterior.project_ideal(c, &x.position))
        .collect();
    for (fi, target) in t.iter().enumerate() {
        let Some(p) = project(&positions[fi]) else {
            continue;
        };
        if !camera.contains_pixel(p, 2.0) {
            continue;
        }
        // Image distance to the nearest other target (pinhole, px).
        let spacing = ideal[fi].map_or(f64::INFINITY, |q| {
            ideal
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != fi)
                .filter_map(|(_, o)| o.map(|o| (o - q).norm() / ps))
                .fold(f64::INFINITY, f64::min)
        });
        let mut gate = options.gate_spacing_ratio * spacing;
        if !first {
            gate = gate.min(options.gate_px);
        }
        let mut inside = 0;
        let mut best = None;
        for (k, b) in blobs.iter().enumerate() {
            let matches = match target.kind {
                TargetKind::Coded => b.id == Some(target.id),
                TargetKind::Uncoded => b.kind == TargetKind::Uncoded,
            };
            if !matches {
                continue;
            }
            let d = ((b.col - p.x).powi(2) + (b.row - p.y).powi(2)).sqrt();
            if d <= gate {
                inside += 1;
                best = Some(k);
            }
        }
        if inside == 1 {
            let k = best.expect("one inside");
            claimed[k] += 1;
            cand.push((fi, k));
        }
    }
    for (fi, k) in cand {
        if claimed[k] != 1 {
            continue;
        }
        out.push(PointObservation {
            target: fi,
            measured: camera.pixel_to_image(blobs[k].col, blobs[k].row),
            used: true,
            eccentricity: if options.eccentricity {
                photopose_locate::eccentricity(c, exterior, &positions[fi], t[fi].radius)
                    .unwrap_or_else(Vector2::zeros)
            } else {
                Vector2::zeros()
            },
        });
    }
    out
}

/// All images looking straight onto a planar field leave the principal
/// distance undetermined: diagnose it before adjusting.
fn check_tilt(
    field: &Field,
    blocks: &[ImageBlock],
    options: &CalibrationOptions,
) -> Result<(), CalibrateError> {
    let pts: Vec<Vector3<f64>> = field.targets().iter().map(|t| t.position).collect();
    let mean = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
    let mut m = nalgebra::Matrix3::zeros();
    for p in &pts {
        let d = p - mean;
        m += d * d.transpose();
    }
    let eig = m.symmetric_eigen();
    let (k, &lmin) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .expect("three eigenvalues");
    let lmax = eig.eigenvalues.max();
    // Not planar (depth spread above 1 % of the extent): depth separates c.
    if lmin > 1e-4 * lmax {
        return Ok(());
    }
    let normal: Vector3<f64> = eig.eigenvectors.column(k).into();
    let max_tilt = blocks
        .iter()
        .map(|b| {
            let axis: Vector3<f64> = b.exterior.rotation.row(2).transpose();
            axis.dot(&normal).abs().min(1.0).acos().to_degrees()
        })
        .fold(0.0, f64::max);
    if max_tilt < options.min_tilt_deg {
        return Err(CalibrateError::ParallelImages {
            images: blocks.len(),
            max_tilt_deg: max_tilt,
            min_tilt_deg: options.min_tilt_deg,
        });
    }
    Ok(())
}
