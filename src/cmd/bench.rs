//! `photopose bench`: per-stage timing of the whole frame pipeline
//! (threshold, labelling, centroids, decoding, the rest of detection, first
//! pose from the coded targets, identification of the uncoded targets, final
//! pose) on rendered 1300×1030 frames of the default plate, single thread.
//! Prints medians and 99th percentiles per stage; a stage's time per frame
//! is the sum over its blobs where it runs per blob. The probe adds a clock
//! read per stage mark (a few µs per frame), so `total` is slightly above a
//! plain run; the whole-frame figure (`full_frame`) is timed without it.
//!
//! Tracking mode is timed along a moving circle of the simulated cell (its
//! default robot, mount and feed, frames at `--track-rate`) on a circle of
//! its own, [`track_path`]: 40 mm radius, the camera 1000 mm above the plate
//! looking straight down, so that the whole default plate (230 targets) is
//! in view all along it (the demo's circle at 600 mm sees about half of
//! it). Each frame is tracked from the pose predicted by the two before it,
//! as the daemon does; a frame that cannot be tracked is located whole and
//! counted.

use crate::cmd::defaults;
use anyhow::{bail, Context, Result};
use clap::Parser;
use photopose_circle::cell::{Cell, CirclePath};
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::{Exterior, Vector3};
use photopose_locate::track::{Motion, Prior, TrackOptions};
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
    /// Frames along the moving circle for tracking mode.
    #[arg(long, default_value_t = 200)]
    pub track_frames: usize,
    /// Frame rate along the moving circle, frames/s.
    #[arg(long, default_value_t = 1000.0)]
    pub track_rate: f64,
    /// End the output with one JSON object (`full_frame_median_us`,
    /// `tracking_median_us`, the stages …).
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
    let bar = crate::cmd::progress::bar(Some(args.frames as u64), "frames rendered");
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
        bar.inc(1);
    }
    bar.finish_and_clear();
    let bar = crate::cmd::progress::bar(Some((args.frames * args.rounds) as u64), "frames timed");
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
            bar.inc(1);
            if status != PoseStatus::Ok {
                failed += 1;
                continue;
            }
            for (t, a) in times.iter_mut().zip(acc) {
                t.push(a);
            }
        }
    }
    bar.finish_and_clear();
    if times[8].is_empty() {
        bail!("no frame gave a pose ({failed} failed)");
    }
    // The whole frame without the probe's clock reads.
    let mut full = Vec::with_capacity(args.frames * args.rounds);
    for _ in 0..args.rounds {
        for img in &frames {
            let t0 = Instant::now();
            let ok = *locator.locate(img.view())?.status == PoseStatus::Ok;
            let dt = t0.elapsed().as_secs_f64() * 1e6;
            if ok {
                full.push(dt);
            }
        }
    }
    full.sort_by(f64::total_cmp);
    let tracking = track_circle(&mut renderer, &mut locator, &args)?;
    for t in &mut times {
        t.sort_by(f64::total_cmp);
    }
    let names = NAMES;
    if args.json {
        let stages: serde_json::Map<String, serde_json::Value> = names
            .iter()
            .zip(&times)
            .map(|(n, t)| {
                (
                    n.to_string(),
                    serde_json::json!({"median_us": percentile(t, 0.5), "p99_us": percentile(t, 0.99)}),
                )
            })
            .collect();
        let obj = serde_json::json!({
            "full_frame_median_us": percentile(&full, 0.5),
            "full_frame_p99_us": percentile(&full, 0.99),
            "tracking_median_us": percentile(&tracking.times, 0.5),
            "tracking_p99_us": percentile(&tracking.times, 0.99),
            "tracking_frames": tracking.times.len(),
            "tracking_fallbacks": tracking.fallbacks,
            "tracking_targets_mean": tracking.targets_mean,
            "frames": args.frames,
            "rounds": args.rounds,
            "failed": failed,
            "stages_us": serde_json::Value::Object(stages),
        });
        outln!("{obj}")?;
    } else {
        outln!(
            "frame pipeline, single thread: {} frames × {} rounds, {:.0} visible targets per frame on average, {} failed",
            args.frames,
            args.rounds,
            targets as f64 / args.frames as f64,
            failed
        )?;
        outln!(
            "{:>12} | {:>11} | {:>11}",
            "stage",
            "median [µs]",
            "p99 [µs]"
        )?;
        for (n, t) in names.iter().zip(&times) {
            outln!(
                "{:>12} | {:>11.1} | {:>11.1}",
                n,
                percentile(t, 0.5),
                percentile(t, 0.99)
            )?;
        }
        outln!(
            "{:>12} | {:>11.1} | {:>11.1}",
            "full_frame",
            percentile(&full, 0.5),
            percentile(&full, 0.99)
        )?;
        outln!(
            "{:>12} | {:>11.1} | {:>11.1}   ({} frames along the moving circle at {} frames/s, {:.0} targets per frame, {} located whole)",
            "tracking",
            percentile(&tracking.times, 0.5),
            percentile(&tracking.times, 0.99),
            tracking.times.len(),
            args.track_rate,
            tracking.targets_mean,
            tracking.fallbacks
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

/// What tracking along the circle measured.
struct Tracking {
    /// Time per tracked frame, µs, sorted.
    times: Vec<f64>,
    /// Frames that could not be tracked and were located whole.
    fallbacks: usize,
    /// Targets per tracked frame, mean.
    targets_mean: f64,
}

/// The bench's tracking circle: the cell's default path moved up to a
/// 1000 mm standoff (the TCP 920 mm above the plate, the default mount 80 mm
/// above it) with a 40 mm radius, frames at `rate_hz`. The default camera
/// then sees 726 × 575 mm at the plate, the default plate (544 × 384 mm
/// between its outer targets) whole from every point of the circle.
pub fn track_path(rate_hz: f64) -> CirclePath {
    CirclePath {
        center_mm: [-60.0, 0.0, 920.0],
        radius_mm: 40.0,
        rate_hz,
        ..CirclePath::default()
    }
}

/// Tracks frames rendered along the bench's circle, each from the
/// pose predicted by the two before it.
fn track_circle(renderer: &mut Renderer, locator: &mut Locator, args: &Args) -> Result<Tracking> {
    if args.track_frames < 3 || !(args.track_rate.is_finite() && args.track_rate > 0.0) {
        bail!("--track-frames must be at least 3 and --track-rate positive");
    }
    let cell = Cell {
        path: track_path(args.track_rate),
        ..Cell::default()
    };
    let samples = cell.samples().context("the simulated cell")?;
    let mut frames = Vec::with_capacity(args.track_frames);
    for (k, s) in samples.iter().take(args.track_frames).enumerate() {
        renderer.set_options(RenderOptions {
            seed: 1000 + k as u64,
            ..RenderOptions::default()
        })?;
        let mut img = renderer.new_image();
        renderer.render(&s.exterior(), &mut img)?;
        frames.push(img);
    }
    let camera = *locator.camera();
    let (c, px) = (camera.interior.c, camera.sensor.pixel_size);
    let options = TrackOptions::default();
    let mut times = Vec::with_capacity(frames.len() * args.rounds.min(10));
    let (mut fallbacks, mut targets) = (0usize, 0usize);
    for _ in 0..args.rounds.min(10) {
        let mut motion: Option<Motion> = None;
        let mut last = None;
        for (k, img) in frames.iter().enumerate() {
            let seq = k as u64;
            let t0 = Instant::now();
            let tracked = match (&motion, &last) {
                (Some(m), Some((cov, threshold))) => {
                    let distance = m.last.1.center.norm();
                    let (exterior, motion_px) = m.predict(seq, c, px, distance);
                    let prior = Prior {
                        exterior,
                        covariance: *cov,
                        motion_px,
                        threshold: *threshold,
                    };
                    locator.track(img.view(), &prior, &options).ok().copied()
                }
                _ => None,
            };
            let dt = t0.elapsed().as_secs_f64() * 1e6;
            let pose = match tracked {
                Some(p) => {
                    times.push(dt);
                    targets += p.n_points;
                    p
                }
                None => {
                    if motion.is_some() {
                        fallbacks += 1;
                    }
                    let loc = locator.locate(img.view())?;
                    let Some(p) = loc.pose.copied() else {
                        bail!("frame {k} of the moving circle gave no pose");
                    };
                    last = Some((p.covariance, loc.detections.threshold));
                    p
                }
            };
            if let Some((cov, _)) = &mut last {
                *cov = pose.covariance;
            }
            motion = Some(Motion {
                last: (seq, pose.exterior),
                before: motion.map(|m| m.last),
            });
        }
    }
    if times.is_empty() {
        bail!("no frame of the moving circle could be tracked ({fallbacks} located whole)");
    }
    times.sort_by(f64::total_cmp);
    Ok(Tracking {
        targets_mean: targets as f64 / times.len() as f64,
        times,
        fallbacks,
    })
}
