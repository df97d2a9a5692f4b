//! `photopose render`: one synthetic frame of the test field seen from a
//! given camera pose, written as PGM or PNG (by extension), with a truth
//! JSON file beside it (the pose, the camera, every target's true image
//! position and visibility).

use crate::cmd::{defaults, pose_arg};
use anyhow::{bail, Context, Result};
use clap::Parser;
use photopose_field::Field;
use photopose_formats::image::{save_image, ImageFormat};
use photopose_frame::Image;
use photopose_geometry::{Camera, Exterior};
use photopose_render::{RenderOptions, Renderer};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Arguments of `photopose render`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Camera file (TOML); default: the built-in camera.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Test field (CSV); default: the built-in plate.
    #[arg(long)]
    pub field: Option<PathBuf>,
    /// Camera pose in the field frame: X,Y,Z,A,B,C (mm, degrees, KUKA
    /// Z-Y'-X''); `0,0,1000,0,0,0` is 1 m above the plate looking down.
    #[arg(long, allow_hyphen_values = true)]
    pub pose: String,
    /// Output image, `.pgm` or `.png`.
    #[arg(long)]
    pub out: PathBuf,
    /// Gaussian noise σ, grey values of the output image.
    #[arg(long, default_value_t = RenderOptions::default().noise_dn)]
    pub noise_dn: f64,
    /// Gaussian blur σ, pixels (0: none).
    #[arg(long, default_value_t = RenderOptions::default().blur_px)]
    pub blur_px: f64,
    /// Seed of the noise (same seed, same bytes).
    #[arg(long, default_value_t = RenderOptions::default().seed)]
    pub seed: u64,
    /// Samples per pixel side at corners of the pattern (1..=16; 1: point
    /// sampling, no anti-aliasing).
    #[arg(long, default_value_t = RenderOptions::default().supersample)]
    pub supersample: u32,
    /// Bits per pixel of the output: 8 or 16 (saturation 255 or 65535).
    #[arg(long, default_value_t = 8)]
    pub bit_depth: u32,
    /// Truth JSON file; default: the image path with `.truth.json`.
    #[arg(long)]
    pub truth: Option<PathBuf>,
}

/// The truth file.
#[derive(Serialize)]
struct Truth<'a> {
    /// The rendered image.
    image: String,
    width: u32,
    height: u32,
    bit_depth: u32,
    max_value: u16,
    /// The pose as given: camera in the field, KUKA X,Y,Z,A,B,C (mm, deg).
    pose_xyzabc: [f64; 6],
    /// Projection centre, mm.
    center: [f64; 3],
    /// `R` of the collinearity equations (object → camera).
    rotation: [[f64; 3]; 3],
    camera: CameraJson,
    options: OptionsJson,
    /// What `col`/`row` give.
    col_row: &'static str,
    targets: Vec<TargetJson<'a>>,
}

#[derive(Serialize)]
struct CameraJson {
    width: u32,
    height: u32,
    pixel_size: f64,
    c: f64,
    x0: f64,
    y0: f64,
    k1: f64,
    k2: f64,
    k3: f64,
    p1: f64,
    p2: f64,
    b1: f64,
    b2: f64,
}

#[derive(Serialize)]
struct OptionsJson {
    noise_dn: f64,
    blur_px: f64,
    seed: u64,
    supersample: u32,
    background: f64,
    target: f64,
    reference_distance_mm: f64,
    auto_exposure: bool,
}

#[derive(Serialize)]
struct TargetJson<'a> {
    id: u64,
    kind: &'a str,
    /// `null` if the centre is behind the camera.
    col: Option<f64>,
    row: Option<f64>,
    visible: bool,
    /// Distance of the target's outline from the sensor edge, px (`null`:
    /// partly behind the camera).
    margin_px: Option<f64>,
    radius_px: f64,
}

/// The summary line on stdout.
#[derive(Serialize)]
struct Summary {
    image: String,
    ok: bool,
    truth: String,
    targets: usize,
    visible: usize,
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn camera_json(c: &Camera) -> CameraJson {
    let d = &c.distortion;
    CameraJson {
        width: c.sensor.width,
        height: c.sensor.height,
        pixel_size: c.sensor.pixel_size,
        c: c.interior.c,
        x0: c.interior.x0,
        y0: c.interior.y0,
        k1: d.k1,
        k2: d.k2,
        k3: d.k3,
        p1: d.p1,
        p2: d.p2,
        b1: d.b1,
        b2: d.b2,
    }
}

/// The default truth path: `frame.pgm` → `frame.truth.json`.
pub fn default_truth_path(image: &Path) -> PathBuf {
    image.with_extension("truth.json")
}

/// Renders one frame and its truth (the command without its IO of
/// arguments): returns the image and the truth's targets.
fn render(
    camera: Camera,
    field: &Field,
    pose: [f64; 6],
    options: RenderOptions,
    bit_depth: u32,
) -> Result<(Image, Renderer, Exterior)> {
    let exterior = Exterior::from_kuka_pose(pose);
    let mut renderer = Renderer::new(camera, field, options).context("renderer")?;
    let (w, h) = (camera.sensor.width, camera.sensor.height);
    let mut image = match bit_depth {
        8 => Image::new_mono8(w, h),
        16 => Image::new_mono16(w, h, u16::MAX),
        other => bail!("--bit-depth {other}: must be 8 or 16"),
    };
    renderer.render(&exterior, &mut image)?;
    Ok((image, renderer, exterior))
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    let pose = pose_arg::parse_pose(&args.pose)?;
    // Refuse a bad output name before any work.
    ImageFormat::from_path(&args.out)?;
    let camera = defaults::camera(args.camera.as_deref())?;
    let field = defaults::field(args.field.as_deref())?;
    let options = RenderOptions {
        noise_dn: args.noise_dn,
        blur_px: args.blur_px,
        seed: args.seed,
        supersample: args.supersample,
        ..RenderOptions::default()
    };
    let (image, renderer, exterior) = render(camera, &field, pose, options, args.bit_depth)?;
    save_image(&args.out, &image)?;

    let truth_path = args
        .truth
        .clone()
        .unwrap_or_else(|| default_truth_path(&args.out));
    let r = exterior.rotation;
    let o = renderer.options();
    let truth = Truth {
        image: args.out.display().to_string(),
        width: image.width(),
        height: image.height(),
        bit_depth: args.bit_depth,
        max_value: image.max_value(),
        pose_xyzabc: pose,
        center: exterior.center.into(),
        rotation: [
            [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
            [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
            [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
        ],
        camera: camera_json(&camera),
        options: OptionsJson {
            noise_dn: o.noise_dn,
            blur_px: o.blur_px,
            seed: o.seed,
            supersample: o.supersample,
            background: o.background,
            target: o.target,
            reference_distance_mm: o.reference_distance_mm,
            auto_exposure: o.auto_exposure,
        },
        col_row: "projected centre of the target circle (not the blob centroid)",
        targets: renderer
            .truth()
            .iter()
            .map(|t| TargetJson {
                id: t.id,
                kind: t.kind.as_str(),
                col: finite(t.col),
                row: finite(t.row),
                visible: t.visible,
                margin_px: finite(t.margin_px),
                radius_px: t.radius_px,
            })
            .collect(),
    };
    let text = serde_json::to_string_pretty(&truth)?;
    std::fs::write(&truth_path, text + "\n")
        .with_context(|| format!("{}: cannot write the truth file", truth_path.display()))?;
    let visible = renderer.truth().iter().filter(|t| t.visible).count();
    if visible == 0 {
        tracing::warn!("no target of the field is wholly in view from this pose");
    }
    outln!(
        "{}",
        serde_json::to_string(&Summary {
            image: args.out.display().to_string(),
            ok: true,
            truth: truth_path.display().to_string(),
            targets: field.len(),
            visible,
        })?
    )?;
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn truth_path_sits_beside_the_image() {
        assert_eq!(
            default_truth_path(Path::new("/tmp/a/frame.pgm")),
            PathBuf::from("/tmp/a/frame.truth.json")
        );
    }

    #[test]
    fn bit_depth_picks_the_container() {
        let camera = defaults::camera(None).unwrap();
        let field = defaults::field(None).unwrap();
        let pose = [0.0, 0.0, 1000.0, 0.0, 0.0, 0.0];
        let (img, _, _) = render(camera, &field, pose, RenderOptions::default(), 16).unwrap();
        assert_eq!(img.max_value(), 65535);
        let e = render(camera, &field, pose, RenderOptions::default(), 12).unwrap_err();
        assert!(e.to_string().contains("--bit-depth 12"), "{e}");
    }
}
