//! `photopose calibrate camera`: detects the targets of 10–30 images of the
//! test field, runs the self-calibrating bundle adjustment of
//! `photopose-calibrate` and writes the camera file, the report (text on
//! stdout, JSON on request) and the residual plots.

use crate::cmd::{batch::load_frame, defaults};
use anyhow::{bail, Context, Result};
use clap::Parser;
use photopose_calibrate::{
    calibrate, svg, Blob, CalibrationOptions, Fixed, ImageDetections, Report, Skipped,
};
use photopose_vision::{Detector, DetectorOptions, FrameStatus};
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
    /// Images of the test field (PGM or PNG, the camera's size).
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
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

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
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
    for path in &args.images {
        let name = path.display().to_string();
        let image = match load_frame(path, &initial) {
            Ok(i) => i,
            Err(e) => {
                unreadable.push(Skipped {
                    image: name,
                    reason: e,
                });
                continue;
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
            continue;
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
    }
    let detected = std::time::Instant::now();
    let mut options = CalibrationOptions::default();
    options.bundle.fixed = fixed;
    options.bundle.free_targets = args.free_targets;
    let cal = match calibrate(&initial, &field, &inputs, &options) {
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
        args.images.len(),
        (detected - started).as_secs_f64(),
        detected.elapsed().as_secs_f64()
    );
    let camera = cal.result.camera;
    // The result must be a valid camera file.
    photopose_geometry::Camera::new(camera.sensor, camera.interior, camera.distortion)
        .context("the adjusted camera is not a valid camera")?;
    std::fs::write(&args.out, photopose_formats::camera_to_toml(&camera))
        .with_context(|| format!("writing {}", args.out.display()))?;
    let report = Report::new(&cal, &fixed, &unreadable);
    print!("{}", report.to_text());
    println!("camera written to {}", args.out.display());
    if let Some(p) = &args.report_json {
        std::fs::write(p, serde_json::to_string_pretty(&report)? + "\n")
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(dir) = &args.plot_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for (name, text) in [
            ("residuals.svg", svg::vector_plot(&camera, &cal.images)),
            ("radial.svg", svg::radial_plot(&camera, &cal.images)),
        ] {
            let p = dir.join(name);
            std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?;
        }
    }
    Ok(ExitCode::SUCCESS)
}
