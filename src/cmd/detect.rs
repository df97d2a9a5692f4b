//! `photopose detect IMAGE...`: every target of each image, identified where
//! it can be (coded targets by their rings, uncoded ones by projection with
//! the first pose), one JSON object per image per line, in input order. An
//! input may be a recording (`.mcap`): each of its frames, or those
//! `--frames` selects, is one image (`FILE#SEQ`).

use crate::cmd::batch::{exit_status, image_lines, workers_for, ErrorLine};
use crate::cmd::defaults;
use crate::cmd::input::{for_each_frame, is_recording, FrameSelection};
use anyhow::Result;
use clap::Parser;
use photopose_field::TargetKind;
use photopose_locate::{LocateOptions, Locator, PoseStatus};
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `photopose detect`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Camera file (TOML); default: the built-in camera.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Test field (CSV); default: the built-in plate.
    #[arg(long)]
    pub field: Option<PathBuf>,
    /// Images (PGM or PNG, 8 or 16 bit, the camera's size) or recordings
    /// (MCAP: every frame, or those of --frames).
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    /// Frames of the recordings by sequence number: N, A-B, or a comma
    /// list (default: every frame).
    #[arg(long)]
    pub frames: Option<FrameSelection>,
}

/// One target of the output (keys `id`, `kind`, `col`, `row` are fixed).
#[derive(Serialize)]
struct TargetLine {
    /// Field id, or null when not identified.
    id: Option<u64>,
    /// "coded" (a ring was seen) or "uncoded".
    kind: &'static str,
    /// Image of the target's centre, pixels (eccentricity-corrected when
    /// identified; the blob centre otherwise).
    col: f64,
    /// Image of the target's centre, pixels.
    row: f64,
    /// Centre of the bright blob as measured, pixels.
    blob_col: f64,
    /// Centre of the bright blob as measured, pixels.
    blob_row: f64,
    /// Semi-axes of the dot's ellipse, pixels, and angle (radians, from +col towards +row).
    semi_major: f64,
    semi_minor: f64,
    angle_rad: f64,
    /// Used in the final pose.
    used: bool,
    /// Outcome of reading the code ring.
    code: &'static str,
    /// The canonical 12-bit value read from the ring (certain readings
    /// only).
    code_value: Option<u16>,
    /// The dot is over-exposed (saturated pixels): measured, weighted down.
    saturated: bool,
}

#[derive(Serialize)]
struct ImageLine<'a> {
    image: &'a str,
    ok: bool,
    /// What came of the frame: ok, too_few_targets, empty, saturated, cluttered, no_pose.
    status: String,
    targets: Vec<TargetLine>,
    n_targets: usize,
    n_identified: usize,
    /// Targets with saturated pixels: over-exposure costs precision.
    n_saturated: usize,
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    let camera = defaults::camera(args.camera.as_deref())?;
    let field = defaults::field(args.field.as_deref())?;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    if !args.images.iter().any(|p| is_recording(p)) {
        // Image files only: on every core, lines in input order.
        let workers = workers_for(args.images.len());
        let failed = image_lines(
            &args.images,
            &camera,
            workers,
            || {
                Ok(Locator::new(
                    camera,
                    field.clone(),
                    LocateOptions::default(),
                )?)
            },
            |locator, name, image| {
                Ok(match image.and_then(|i| detect_one(locator, i, name)) {
                    Ok(l) => (serde_json::to_string(&l)?, false),
                    Err(error) => (serde_json::to_string(&ErrorLine::new(name, error))?, true),
                })
            },
            &mut out,
        )?;
        return Ok(exit_status(failed));
    }
    let mut locator = Locator::new(camera, field, LocateOptions::default())?;
    let mut failed = 0;
    for_each_frame(
        &args.images,
        &camera,
        args.frames.as_ref(),
        |name, image| -> Result<()> {
            let line = match image.and_then(|i| detect_one(&mut locator, &i, name)) {
                Ok(l) => serde_json::to_string(&l)?,
                Err(error) => {
                    failed += 1;
                    serde_json::to_string(&ErrorLine::new(name, error))?
                }
            };
            writeln!(out, "{line}")?;
            Ok(())
        },
    )?;
    Ok(exit_status(failed))
}

fn detect_one<'a>(
    locator: &mut Locator,
    image: &photopose_frame::Image,
    name: &'a str,
) -> Result<ImageLine<'a>, String> {
    let loc = locator
        .locate(image.view())
        .map_err(|e| format!("{name}: {e}"))?;
    let status = match loc.status {
        PoseStatus::Ok => "ok".to_string(),
        PoseStatus::TooFewTargets { .. } => "too_few_targets".to_string(),
        PoseStatus::Frame(s) => s.name().to_string(),
        PoseStatus::NoPose(_) => "no_pose".to_string(),
    };
    let mut targets = Vec::with_capacity(loc.detections.targets.len());
    for (k, d) in loc.detections.targets.iter().enumerate() {
        let ident = loc.targets.iter().find(|t| t.detection == k);
        targets.push(TargetLine {
            id: ident.map(|t| t.id),
            kind: match ident.map_or(d.kind, |t| t.kind) {
                TargetKind::Coded => "coded",
                TargetKind::Uncoded => "uncoded",
            },
            col: ident.map_or(d.col, |t| t.col),
            row: ident.map_or(d.row, |t| t.row),
            blob_col: d.col,
            blob_row: d.row,
            semi_major: d.semi_major,
            semi_minor: d.semi_minor,
            angle_rad: d.angle,
            used: ident.is_some_and(|t| t.used),
            code: d.code.name(),
            code_value: d.code.value(),
            saturated: d.saturated,
        });
    }
    Ok(ImageLine {
        image: name,
        ok: true,
        status,
        n_targets: targets.len(),
        n_identified: targets.iter().filter(|t| t.id.is_some()).count(),
        n_saturated: loc.detections.n_saturated,
        targets,
    })
}
