//! `photopose calibrate camera`: detects the targets of 10–30 images of the
//! test field, runs the self-calibrating bundle adjustment of
//! `photopose-calibrate` and writes the camera file (with its
//! `[calibration]` section), the report (text on stdout, JSON on request)
//! and the residual plots, all carrying the provenance (tool, date, input
//! files with their SHA-256). Images may come from recordings (`.mcap`,
//! every frame or `--frames`).

use crate::cmd::defaults;
use crate::cmd::input::{for_each_frame_hashed, FrameSelection};
use anyhow::{bail, Context, Result};
use clap::Parser;
use photopose_calibrate::{
    calibrate, natural_cmp, svg, Blob, CalibrationOptions, Fixed, ImageDetections, Report, Skipped,
};
use photopose_formats::provenance::{hash_file, InputFile, Provenance};
use photopose_formats::{CalibrationRecord, CameraFile, FileKind, ParameterStd};
use photopose_vision::{Detector, DetectorOptions, FrameStatus};
use serde::Serialize;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `photopose calibrate camera`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Test field (CSV); default: the built-in plate.
    #[arg(long)]
    pub field: Option<PathBuf>,
    /// Initial camera (TOML): sensor size, pixel size and a nominal
    /// principal distance; default: the built-in camera.
    #[arg(long)]
    pub initial: Option<PathBuf>,
    /// Images of the test field (PGM or PNG, the camera's size) or
    /// recordings (MCAP: every frame, or those of --frames).
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    /// Frames of the recordings by sequence number: N, A-B, or a comma
    /// list (default: every frame).
    #[arg(long)]
    pub frames: Option<FrameSelection>,
    /// The calibrated camera file to write (TOML).
    #[arg(long)]
    pub out: PathBuf,
    /// Parameters held at their initial value, comma-separated (c, x0, y0,
    /// k1, k2, k3, p1, p2, b1, b2); repeatable.
    #[arg(long, value_delimiter = ',')]
    pub fix: Vec<String>,
    /// Adjust the target coordinates too (free network with inner constraints).
    #[arg(long)]
    pub free_targets: bool,
    /// Writes the report as JSON to this file.
    #[arg(long)]
    pub report_json: Option<PathBuf>,
    /// Writes the residual plots (residuals.svg, radial.svg) into this folder.
    #[arg(long)]
    pub plot_dir: Option<PathBuf>,
}

/// The JSON report: the provenance, then the calibration's report.
#[derive(Serialize)]
struct JsonReport<'a> {
    provenance: &'a Provenance,
    #[serde(flatten)]
    report: &'a Report,
}

/// The `[calibration]` section of the camera file written.
fn record(report: &Report, provenance: &Provenance) -> CalibrationRecord {
    let std = ParameterStd::from_values(std::array::from_fn(|k| {
        let name = photopose_formats::camera::PARAMETERS[k].0;
        report
            .parameters
            .iter()
            .find(|p| p.name == name)
            .and_then(|p| p.std)
    }));
    CalibrationRecord {
        date: provenance.date.clone(),
        tool: provenance.tool.clone(),
        images: report.images.len() as u32,
        observations: report.n_observations as u32,
        sigma0_px: report.sigma0_px,
        sigma0_mm: report.sigma0_mm,
        fixed: report
            .parameters
            .iter()
            .filter(|p| p.fixed)
            .map(|p| p.name.to_string())
            .collect(),
        std,
        inputs: provenance.inputs.clone(),
    }
}

/// Runs the command.
pub fn run(mut args: Args) -> Result<ExitCode> {
    args.images
        .sort_by(|a, b| natural_cmp(&a.display().to_string(), &b.display().to_string()));
    let initial = defaults::camera(args.initial.as_deref())?;
    let field = defaults::field(args.field.as_deref())?;
    let mut fixed = Fixed::none();
    for name in &args.fix {
        let f = Fixed::parse_list(name).context("--fix")?;
        for p in photopose_calibrate::Param::ALL {
            if f.is_fixed(p) {
                fixed.fix(p);
            }
        }
    }
    let mut detector = Detector::new(
        initial.sensor.width,
        initial.sensor.height,
        DetectorOptions::for_field(&field),
    )?;
    let started = std::time::Instant::now();
    let mut inputs = Vec::with_capacity(args.images.len());
    let mut unreadable = Vec::new();
    let mut hashes: Vec<InputFile> = Vec::new();
    for (path, kind) in [
        (&args.initial, FileKind::Camera),
        (&args.field, FileKind::Field),
    ] {
        if let Some(p) = path {
            hashes.push(hash_file(p, kind)?);
        }
    }
    let bar = crate::cmd::progress::bar(None, "images detected");
    let mut n_images = 0;
    // Each image file is read once: hashed and decoded from the same bytes.
    for_each_frame_hashed(
        &args.images,
        &initial,
        args.frames.as_ref(),
        &mut hashes,
        |name, image| -> Result<()> {
            n_images += 1;
            bar.inc(1);
            let name = name.to_string();
            let image = match image {
                Ok(i) => i,
                Err(e) => {
                    unreadable.push(Skipped {
                        image: name,
                        reason: e,
                    });
                    return Ok(());
                }
            };
            let det = detector
                .detect(image.view())
                .with_context(|| format!("detecting in {name}"))?;
            if det.status != FrameStatus::Normal {
                unreadable.push(Skipped {
                    image: name,
                    reason: format!("test field not found: the frame is {}", det.status.name()),
                });
                return Ok(());
            }
            let blobs = det
                .targets
                .iter()
                .map(|d| Blob {
                    col: d.col,
                    row: d.row,
                    kind: d.kind,
                    id: d.id,
                })
                .collect();
            inputs.push(ImageDetections { name, blobs });
            Ok(())
        },
    )?;
    bar.finish_and_clear();
    let detected = std::time::Instant::now();
    let adjusting = crate::cmd::progress::status();
    adjusting.set_message(format!("bundle adjustment of {} images", inputs.len()));
    let mut options = CalibrationOptions::default();
    options.bundle.fixed = fixed;
    options.bundle.free_targets = args.free_targets;
    let adjusted = calibrate(&initial, &field, &inputs, &options);
    adjusting.finish_and_clear();
    let cal = match adjusted {
        Ok(c) => c,
        Err(e) => {
            let mut msg = e.to_string();
            for s in &unreadable {
                msg.push_str(&format!("\n  skipped {}: {}", s.image, s.reason));
            }
            bail!("calibration failed: {msg}");
        }
    };
    tracing::info!(
        "detection of {} images {:.3} s, adjustment {:.3} s",
        n_images,
        (detected - started).as_secs_f64(),
        detected.elapsed().as_secs_f64()
    );
    let camera = cal.result.camera;
    // The result must be a valid camera file.
    photopose_geometry::Camera::new(camera.sensor, camera.interior, camera.distortion)
        .context("the adjusted camera is not a valid camera")?;
    let report = Report::new(&cal, &fixed, &unreadable);
    let provenance = Provenance::now(hashes);
    let file = CameraFile {
        camera,
        calibration: Some(record(&report, &provenance)),
    };
    std::fs::write(&args.out, photopose_formats::camera_file_to_toml(&file))
        .with_context(|| format!("writing {}", args.out.display()))?;
    out!("{}{}", provenance.to_text(), report.to_text())?;
    outln!("camera written to {}", args.out.display())?;
    if let Some(p) = &args.report_json {
        let json = JsonReport {
            provenance: &provenance,
            report: &report,
        };
        std::fs::write(p, serde_json::to_string_pretty(&json)? + "\n")
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(dir) = &args.plot_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let name = args
            .out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let camera_label = format!(
            "{name} ({} × {} px, c = {:.3} mm)",
            camera.sensor.width, camera.sensor.height, camera.interior.c
        );
        let metadata = provenance.svg_metadata();
        let labels = svg::PlotLabels {
            camera: &camera_label,
            date: &provenance.date,
            metadata: &metadata,
        };
        for (name, text) in [
            (
                "residuals.svg",
                svg::vector_plot(&camera, &cal.images, &labels),
            ),
            (
                "radial.svg",
                svg::radial_plot(&camera, &cal.images, &labels),
            ),
        ] {
            let p = dir.join(name);
            std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?;
        }
    }
    Ok(ExitCode::SUCCESS)
}
