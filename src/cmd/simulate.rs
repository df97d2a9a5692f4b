//! `photopose simulate`: predicted precision of the exterior orientation for
//! a configuration (camera, plate, pose, image noise) without images, checked
//! by Monte Carlo on request. Reproduces the form of the reference paper's
//! table 1.

use crate::cmd::{defaults, pose_arg};
use anyhow::{bail, Context, Result};
use clap::Parser;
use photopose_geometry::precision::{predict, visible_points, Prediction};
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::{Camera, Exterior};
use serde::Serialize;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `photopose simulate`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Camera file (TOML); default: the built-in camera.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Test field (CSV); default: the built-in plate.
    #[arg(long)]
    pub field: Option<PathBuf>,
    /// Camera pose in the field frame: X,Y,Z,A,B,C (mm, degrees, KUKA Z-Y'-X'').
    #[arg(long, default_value = "0,0,1000,0,0,0", allow_hyphen_values = true)]
    pub pose: String,
    /// Image noise per coordinate, pixels (repeat for several rows; fractions
    /// like 1/5 are accepted).
    #[arg(long = "sigma-px", default_values_t = vec!["1/5".to_string(), "1/10".to_string()])]
    pub sigma_px: Vec<String>,
    /// Monte Carlo trials to check each prediction (0: prediction only).
    #[arg(long, default_value_t = 0)]
    pub trials: usize,
    /// Seed of the Monte Carlo noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Margin inside the sensor edge for a target to count as visible, pixels.
    #[arg(long, default_value_t = 5.0)]
    pub margin_px: f64,
    /// Print JSON lines instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Also write one set of simulated observations (`id,col,row`, noise of
    /// the first --sigma-px, --seed) to this CSV file, for `resect`.
    #[arg(long)]
    pub observations_out: Option<PathBuf>,
}

/// One row of the result.
#[derive(Serialize)]
struct Row {
    sigma_px: f64,
    n_points: usize,
    predicted_std_center: [f64; 3],
    predicted_std_rotation_deg: [f64; 3],
    #[serde(skip_serializing_if = "Option::is_none")]
    monte_carlo: Option<MonteCarlo>,
}

#[derive(Serialize)]
struct MonteCarlo {
    trials: usize,
    failed: usize,
    std_center: [f64; 3],
    std_rotation_deg: [f64; 3],
    mean_error_center: [f64; 3],
    mean_error_rotation_deg: [f64; 3],
}

fn parse_sigma(s: &str) -> Result<f64> {
    let v = match s.split_once('/') {
        Some((a, b)) => a.trim().parse::<f64>()? / b.trim().parse::<f64>()?,
        None => s.trim().parse::<f64>()?,
    };
    if !(v.is_finite() && v > 0.0) {
        bail!("--sigma-px `{s}` must be a positive number of pixels");
    }
    Ok(v)
}

/// The Monte Carlo figures of the report (degrees for rotations).
fn monte_carlo(
    camera: &Camera,
    truth: &Exterior,
    points: &[(u64, nalgebra::Vector3<f64>)],
    sigma: f64,
    trials: usize,
    rng: &mut SplitMix64,
) -> MonteCarlo {
    let r = photopose_geometry::simulation::monte_carlo(camera, truth, points, sigma, trials, rng);
    let deg = |v: [f64; 3]| v.map(f64::to_degrees);
    MonteCarlo {
        trials: r.solved,
        failed: r.failed,
        std_center: r.std_center,
        std_rotation_deg: deg(r.std_rotation),
        mean_error_center: r.mean_error_center,
        mean_error_rotation_deg: deg(r.mean_error_rotation),
    }
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    let camera = defaults::camera(args.camera.as_deref())?;
    let field = defaults::field(args.field.as_deref())?;
    let pose = pose_arg::parse_pose(&args.pose)?;
    let truth = Exterior::from_kuka_pose(pose);
    let sigmas = args
        .sigma_px
        .iter()
        .map(|s| parse_sigma(s))
        .collect::<Result<Vec<_>>>()?;
    let mut visible = Vec::new();
    visible_points(
        &camera,
        &truth,
        field.targets().iter().map(|t| t.position),
        args.margin_px,
        &mut visible,
    );
    let in_front = field
        .targets()
        .iter()
        .filter(|t| truth.to_camera(&t.position).z < 0.0)
        .count();
    if in_front == 0 {
        bail!(
            "pose {}: every target of the field lies behind the camera",
            args.pose
        );
    }
    if visible.len() < 4 {
        bail!(
            "pose {}: only {} targets fall on the sensor ({} in front of the camera); a resection needs 4",
            args.pose,
            visible.len(),
            in_front
        );
    }
    let points: Vec<(u64, nalgebra::Vector3<f64>)> = field
        .targets()
        .iter()
        .filter(|t| visible.contains(&t.position))
        .map(|t| (t.id, t.position))
        .collect();
    let mut rng = SplitMix64::new(args.seed);
    if let Some(path) = &args.observations_out {
        let sigma = sigmas[0];
        let mut noise = SplitMix64::new(args.seed);
        let csv =
            photopose_formats::observations::observations_to_csv(points.iter().map(|(id, p)| {
                let px = truth
                    .project_pixel(&camera, p)
                    .expect("visible points project");
                (
                    *id,
                    px.x + sigma * noise.normal(),
                    px.y + sigma * noise.normal(),
                )
            }));
        std::fs::write(path, csv).with_context(|| format!("cannot write {}", path.display()))?;
    }
    let mut rows = Vec::new();
    for &s in &sigmas {
        let p: Prediction = predict(&camera, &truth, &visible, s).with_context(|| {
            format!(
                "pose {} does not determine the exterior orientation",
                args.pose
            )
        })?;
        let mc = (args.trials > 0)
            .then(|| monte_carlo(&camera, &truth, &points, s, args.trials, &mut rng));
        rows.push(Row {
            sigma_px: s,
            n_points: p.n_points,
            predicted_std_center: p.std_center().into(),
            predicted_std_rotation_deg: p.std_rotation_deg().into(),
            monte_carlo: mc,
        });
    }
    if args.json {
        for r in &rows {
            outln!("{}", serde_json::to_string(r)?)?;
        }
        return Ok(ExitCode::SUCCESS);
    }
    let s = &camera.sensor;
    outln!(
        "Predicted precision of the exterior orientation (a-priori, from image noise)\n\
         camera {}x{} px, pixel {:.4} mm, c = {:.3} mm; pose X,Y,Z,A,B,C = {}; {} of {} targets visible\n",
        s.width,
        s.height,
        s.pixel_size,
        camera.interior.c,
        args.pose,
        visible.len(),
        field.len()
    )?;
    outln!(
        "{:>14} | {:>9} {:>9} {:>9} | {:>9} {:>9} {:>9}",
        "sigma image",
        "sX [mm]",
        "sY [mm]",
        "sZ [mm]",
        "sωX [°]",
        "sωY [°]",
        "sωZ [°]"
    )?;
    outln!("{}", "-".repeat(82))?;
    for (r, label) in rows.iter().zip(&args.sigma_px) {
        let c = r.predicted_std_center;
        let w = r.predicted_std_rotation_deg;
        outln!(
            "{:>14} | {:>9.4} {:>9.4} {:>9.4} | {:>9.5} {:>9.5} {:>9.5}",
            format!("{label} px"),
            c[0],
            c[1],
            c[2],
            w[0],
            w[1],
            w[2]
        )?;
        if let Some(mc) = &r.monte_carlo {
            let c = mc.std_center;
            let w = mc.std_rotation_deg;
            outln!(
                "{:>14} | {:>9.4} {:>9.4} {:>9.4} | {:>9.5} {:>9.5} {:>9.5}",
                format!("MC n={}", mc.trials),
                c[0],
                c[1],
                c[2],
                w[0],
                w[1],
                w[2]
            )?;
            let m = mc.mean_error_center;
            let mw = mc.mean_error_rotation_deg;
            outln!(
                "{:>14} | {:>9.4} {:>9.4} {:>9.4} | {:>9.5} {:>9.5} {:>9.5}",
                "MC mean err",
                m[0],
                m[1],
                m[2],
                mw[0],
                mw[1],
                mw[2]
            )?;
        }
    }
    Ok(ExitCode::SUCCESS)
}
