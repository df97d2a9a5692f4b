//! `photopose resect`: exterior orientation with precision from observation
//! files (`id,col,row`), one JSON object per input per line, in input order.

use crate::cmd::batch::{exit_status, image_lines, workers_for, ErrorLine};
use crate::cmd::defaults;
use crate::cmd::input::{for_each_frame, is_recording, FrameSelection};
use anyhow::Result;
use clap::Parser;
use photopose_field::Field;
use photopose_geometry::{Camera, Observation, Resection, ResectionOptions, ResectionReport};
use photopose_locate::{LocateOptions, Locator, PoseStatus};
use photopose_stream::PoseEstimate;
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `photopose resect`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Camera file (TOML); default: the built-in camera.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Test field (CSV); default: the built-in plate.
    #[arg(long)]
    pub field: Option<PathBuf>,
    /// Observation files, CSV `id,col,row` in pixels.
    #[arg(long, num_args = 1..)]
    pub observations: Vec<PathBuf>,
    /// Images (PGM or PNG, 8 or 16 bit) or recordings (MCAP, every frame
    /// or those of --frames): targets are detected and identified, then
    /// the camera resected.
    pub images: Vec<PathBuf>,
    /// Frames of the recordings among the images, by sequence number: N,
    /// A-B, or a comma list (default: every frame).
    #[arg(long)]
    pub frames: Option<FrameSelection>,
    /// Inlier gate of the hypothesise-and-verify stage, pixels.
    #[arg(long, default_value_t = ResectionOptions::default().ransac_threshold_px)]
    pub gate_px: f64,
    /// Critical value of the data-snooping test.
    #[arg(long, default_value_t = ResectionOptions::default().snooping_critical)]
    pub critical: f64,
}

/// One line of output for a successful resection: the pose object of the
/// pose message (`photopose.pose.v2`, docs/streams.md) under the same key
/// and names, plus what only a resection reports.
#[derive(Serialize)]
pub struct PoseLine<'a> {
    /// The input path.
    pub image: &'a str,
    /// Always true here.
    pub ok: bool,
    /// The frame the pose is given in (the field's), as in the message.
    pub frame_id: &'static str,
    /// The camera's pose in the field frame with the adjustment's full
    /// covariance, exactly as the pose message carries it.
    pub pose: PoseEstimate,
    /// RMS image-coordinate residual, px.
    pub rms_px: f64,
    /// Points rejected by data snooping.
    pub n_rejected: usize,
    /// Ids rejected.
    pub rejected_ids: &'a [u64],
    /// The camera's pose in the field as KUKA `X, Y, Z` (mm), `A, B, C`
    /// (degrees), `M = Rᵀ`.
    pub camera_xyzabc_mm_deg: [f64; 6],
    /// Iterations of the final adjustment.
    pub iterations: usize,
    /// Closed-form hypotheses tried.
    pub hypotheses: usize,
}

impl<'a> PoseLine<'a> {
    /// The output line of a report.
    pub fn new(image: &'a str, r: &ResectionReport, rejected_ids: &'a [u64]) -> Self {
        PoseLine {
            image,
            ok: true,
            frame_id: photopose_stream::message::FIELD_FRAME,
            pose: photopose_pipeline::sink::pose_estimate(r),
            rms_px: r.rms_px,
            n_rejected: r.n_rejected,
            rejected_ids,
            camera_xyzabc_mm_deg: r.exterior.to_kuka_pose(),
            iterations: r.iterations,
            hypotheses: r.hypotheses,
        }
    }
}

/// Builds the resection observations of an observation file, checking ids
/// against the field.
pub fn observations_for(
    camera: &Camera,
    field: &Field,
    path: &std::path::Path,
    out: &mut Vec<Observation>,
) -> Result<(), String> {
    let obs = photopose_formats::load_observations(path).map_err(|e| e.to_string())?;
    out.clear();
    for o in obs {
        let Some(t) = field.get(o.id) else {
            return Err(format!(
                "{}:{}: id {} is not in the test field",
                path.display(),
                o.line,
                o.id
            ));
        };
        out.push(Observation::from_pixel(
            camera, o.id, t.position, o.col, o.row,
        ));
    }
    Ok(())
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    if args.observations.is_empty() && args.images.is_empty() {
        anyhow::bail!(
            "no input: give images (PGM, PNG), recordings (MCAP) or --observations FILE..."
        );
    }
    // A camera or field that cannot be used fails every input, each on its
    // own line, so that a batch reader sees why.
    let setup = defaults::camera(args.camera.as_deref())
        .and_then(|c| Ok((c, defaults::field(args.field.as_deref())?)));
    let (camera, field) = match setup {
        Ok(cf) => cf,
        Err(e) => {
            let error = crate::error_text(&e);
            for path in args.observations.iter().chain(&args.images) {
                let name = path.display().to_string();
                let line = ErrorLine::new(&name, error.clone());
                outln!("{}", serde_json::to_string(&line)?)?;
            }
            return Ok(exit_status(args.observations.len() + args.images.len()));
        }
    };
    let options = ResectionOptions {
        ransac_threshold_px: args.gate_px,
        snooping_critical: args.critical,
        ..ResectionOptions::default()
    };
    let mut resection = Resection::new(&camera, options);
    let mut locator: Option<Locator> = None;
    let mut obs = Vec::new();
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut failed = 0;
    for path in &args.observations {
        let name = path.display().to_string();
        let result = observations_for(&camera, &field, path, &mut obs)
            .and_then(|()| resection.solve(&obs).map_err(|e| format!("{name}: {e}")));
        let line = match result {
            Ok(report) => {
                serde_json::to_string(&PoseLine::new(&name, &report, resection.rejected_ids()))?
            }
            Err(error) => {
                failed += 1;
                serde_json::to_string(&ErrorLine::new(&name, error))?
            }
        };
        writeln!(out, "{line}")?;
    }
    let locate_options = LocateOptions {
        resection: options,
        ..LocateOptions::default()
    };
    if !args.images.iter().any(|p| is_recording(p)) {
        // Image files only: on every core, lines in input order.
        let workers = workers_for(args.images.len());
        failed += image_lines(
            &args.images,
            &camera,
            workers,
            || Ok(Locator::new(camera, field.clone(), locate_options)?),
            |locator, name, image| {
                Ok(match image.and_then(|i| locate_image(locator, i, name)) {
                    Ok((report, rejected)) => (
                        serde_json::to_string(&PoseLine::new(name, &report, &rejected))?,
                        false,
                    ),
                    Err(error) => (serde_json::to_string(&ErrorLine::new(name, error))?, true),
                })
            },
            &mut out,
        )?;
        return Ok(exit_status(failed));
    }
    for_each_frame(
        &args.images,
        &camera,
        args.frames.as_ref(),
        |name, image| -> Result<()> {
            let locator = match &mut locator {
                Some(l) => l,
                None => locator.insert(Locator::new(camera, field.clone(), locate_options)?),
            };
            let result = image.and_then(|i| locate_image(locator, &i, name));
            let line = match result {
                Ok((report, rejected)) => {
                    serde_json::to_string(&PoseLine::new(name, &report, &rejected))?
                }
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

/// Detects, identifies and resects one image (`name` for errors).
fn locate_image(
    locator: &mut Locator,
    image: &photopose_frame::Image,
    name: &str,
) -> Result<(ResectionReport, Vec<u64>), String> {
    let loc = locator
        .locate(image.view())
        .map_err(|e| format!("{name}: {e}"))?;
    match (loc.status, loc.pose) {
        (PoseStatus::Ok, Some(p)) => Ok((*p, loc.rejected_ids.to_vec())),
        (PoseStatus::TooFewTargets { coded }, _) => Err(format!(
            "{name}: too few targets: {coded} coded targets identified, a first pose needs 4"
        )),
        (PoseStatus::Frame(status), _) => Err(format!(
            "{name}: no targets: the frame is {}",
            status.name()
        )),
        (PoseStatus::NoPose(e), _) => Err(format!("{name}: {e}")),
        (PoseStatus::Ok, None) => Err(format!("{name}: no pose")),
    }
}
