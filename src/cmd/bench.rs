//! `photopose bench`: per-stage timing of the whole frame pipeline
//! (threshold, labelling, centroids, decoding, the rest of detection, first
//! pose from the coded targets, identification of the uncoded targets, final
//! pose) on rendered 1300×1030 frames of the default plate, single thread.
//! Prints medians and 99th percentiles per stage; a stage's time per frame
//! is the sum over its blobs where it runs per blob. The probe adds a clock
//! read per stage mark (a few µs per frame), so `total` is slightly above a
//! plain run.

use crate::cmd::defaults;
use anyhow::{bail, Context, Result};
use clap::Parser;
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::{Exterior, Vector3};
use photopose_locate::{LocateOptions, Locator, PoseStatus, Stage};
use photopose_render::{RenderOptions, Renderer};
use photopose_vision::DetectStage;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

/// Arguments of `photopose bench`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Camera file (TOML); default: the built-in camera.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Test field (CSV); default: the built-in plate.
    #[arg(long)]
    pub field: Option<PathBuf>,
    /// Rendered frames (varied poses, 0.8–1.2 m, up to 30° tilt).
    #[arg(long, default_value_t = 10)]
    pub frames: usize,
    /// Passes over the frames.
    #[arg(long, default_value_t = 50)]
    pub rounds: usize,
    /// Print one JSON object instead of a table: per stage `median_us` and
    /// `p99_us`, and `full_frame_median_us` (`tracking_median_us` is null
    /// until tracking mode exists).
    #[arg(long)]
    pub json: bool,
}

/// The reported stages, in pipeline order.
const NAMES: [&str; 9] = [
    "threshold",
    "labelling",
    "centroids",
    "decoding",
    "detect_rest",
    "first_pose",
    "identification",
    "final_pose",
    "total",
];

/// Index into [`NAMES`] of the stage that ends at `s`.
fn slot(s: Stage) -> usize {
    match s {
        Stage::Detector(DetectStage::Threshold) => 0,
        Stage::Detector(DetectStage::Label) => 1,
        Stage::Detector(DetectStage::Measure) => 2,
        Stage::Detector(DetectStage::Decode) => 3,
        Stage::Detector(DetectStage::Finish) | Stage::Detect => 4,
        Stage::FirstPose => 5,
        Stage::Uncoded => 6,
        Stage::FinalPose => 7,
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    if args.frames == 0 || args.rounds == 0 {
        bail!("--frames and --rounds must be at least 1");
    }
    let camera = defaults::camera(args.camera.as_deref())?;
    let field = defaults::field(args.field.as_deref())?;
    let mut renderer =
        Renderer::new(camera, &field, RenderOptions::default()).context("renderer")?;
    let mut rng = SplitMix64::new(7);
    let mut frames = Vec::with_capacity(args.frames);
    let mut targets = 0;
    for k in 0..args.frames {
        let distance = 800.0 + 400.0 * rng.unit();
        let tilt = (30.0 * rng.unit()).to_radians();
        let az = std::f64::consts::TAU * rng.unit();
        let eye = Vector3::new(tilt.sin() * az.cos(), tilt.sin() * az.sin(), tilt.cos()) * distance;
        let roll = std::f64::consts::TAU * rng.unit();
        let e = Exterior::look_at(
            eye,
            Vector3::zeros(),
            Vector3::new(roll.cos(), roll.sin(), 0.0),
        )
        .context("bench pose")?;
        renderer.set_options(RenderOptions {
            seed: k as u64 + 1,
            ..RenderOptions::default()
        })?;
        let mut img = renderer.new_image();
        renderer.render(&e, &mut img)?;
        targets += renderer.truth().iter().filter(|t| t.visible).count();
        frames.push(img);
    }
    let mut locator = Locator::new(camera, field, LocateOptions::default())?;
    let mut times: Vec<Vec<f64>> = (0..NAMES.len())
        .map(|_| Vec::with_capacity(args.frames * args.rounds))
        .collect();
    let mut failed = 0;
    for _ in 0..args.rounds {
        for img in &frames {
            // Time since the previous mark goes to the stage that just ended
            // (per-blob stages add up over the frame).
            let mut acc = [0.0f64; NAMES.len()];
            let t0 = Instant::now();
            let mut prev = t0;
            let status = {
                let mut probe = |s: Stage| {
                    let now = Instant::now();
                    acc[slot(s)] += (now - prev).as_secs_f64() * 1e6;
                    prev = now;
                };
                let loc = locator.locate_probed(img.view(), &mut probe)?;
                loc.status.clone()
            };
            acc[8] = t0.elapsed().as_secs_f64() * 1e6;
            if status != PoseStatus::Ok {
                failed += 1;
                continue;
            }
            for (t, a) in times.iter_mut().zip(acc) {
                t.push(a);
            }
        }
    }
    if times[8].is_empty() {
        bail!("no frame gave a pose ({failed} failed)");
    }
    for t in &mut times {
        t.sort_by(f64::total_cmp);
    }
    let names = NAMES;
    if args.json {
        let mut obj: serde_json::Map<String, serde_json::Value> = names
            .iter()
            .zip(&times)
            .map(|(n, t)| {
                (
                    n.to_string(),
                    serde_json::json!({"median_us": percentile(t, 0.5), "p99_us": percentile(t, 0.99)}),
                )
            })
            .collect();
        // The headline figures: the whole frame's median, and tracking
        // mode's (null until tracking mode exists).
        obj.insert(
            "full_frame_median_us".into(),
            serde_json::json!(percentile(&times[8], 0.5)),
        );
        obj.insert("tracking_median_us".into(), serde_json::Value::Null);
        println!("{}", serde_json::Value::Object(obj));
    } else {
        println!(
            "frame pipeline, single thread: {} frames × {} rounds, {:.0} visible targets per frame on average, {} failed",
            args.frames,
            args.rounds,
            targets as f64 / args.frames as f64,
            failed
        );
        println!(
            "{:>12} | {:>11} | {:>11}",
            "stage", "median [µs]", "p99 [µs]"
        );
        for (n, t) in names.iter().zip(&times) {
            println!(
                "{:>12} | {:>11.1} | {:>11.1}",
                n,
                percentile(t, 0.5),
                percentile(t, 0.99)
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
