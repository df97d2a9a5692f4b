//! `photopose field`: test-field tools. `field svg` draws a plate at 1:1
//! for printing, with a scale-check bar, the field's origin and axes, its
//! name and checksum, on one sheet of `--paper` or tiled over several;
//! `field new` designs a rectangular plate (grid of uncoded
//! targets, coded targets on a coarser sub-grid, even codes) and writes
//! its CSV.

use crate::cmd::defaults;
use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use photopose_field::design::PlateDesign;
use photopose_field::{Field, TargetKind};
use photopose_formats::provenance::{self, hash_file, Provenance};
use photopose_render::sheet::{annotate, layout, sheets, Paper, SheetText};
use photopose_render::svg::{plate_drawing, SvgOptions};
use serde::Serialize;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `photopose field`.
#[derive(Parser, Debug)]
pub struct Args {
    /// What to do.
    #[command(subcommand)]
    pub command: FieldCommand,
}

/// The `field` subcommands.
#[derive(Subcommand, Debug)]
pub enum FieldCommand {
    /// Draws the plate as SVG at 1:1 (mm), seen from the targets' side.
    Svg(SvgArgs),
    /// Designs a new plate and writes its test-field CSV.
    New(NewArgs),
}

/// Arguments of `photopose field svg`.
#[derive(Parser, Debug)]
pub struct SvgArgs {
    /// Test field (CSV); default: the built-in plate.
    #[arg(long)]
    pub field: Option<PathBuf>,
    /// Output SVG file.
    #[arg(long)]
    pub out: PathBuf,
    /// Height of the id labels, mm (0: no labels).
    #[arg(long, default_value_t = SvgOptions::default().label_mm)]
    pub label_mm: f64,
    /// Dark border around the outermost quiet zones, mm.
    #[arg(long, default_value_t = SvgOptions::default().border_mm)]
    pub border_mm: f64,
    /// Paper to print on at 1:1 (A4, A3, A2, A1, A0): one page with the
    /// drawing centred when it fits, else tiles `OUT-r1c1.svg`, … beside
    /// `--out`. Without it the SVG has the drawing's own size.
    #[arg(long, value_parser = parse_paper)]
    pub paper: Option<Paper>,
    /// Least overlap of neighbouring tiles, mm (raised to the largest
    /// target's diameter plus 2 mm so every target is whole on a tile).
    #[arg(long, default_value_t = 20.0)]
    pub overlap_mm: f64,
}

fn parse_paper(text: &str) -> Result<Paper, String> {
    Paper::parse(text).ok_or_else(|| format!("\"{text}\": one of A4, A3, A2, A1, A0"))
}

/// Arguments of `photopose field new` (defaults: the default plate).
#[derive(Parser, Debug)]
pub struct NewArgs {
    /// Grid columns.
    #[arg(long, default_value_t = PlateDesign::default().cols)]
    pub cols: u32,
    /// Grid rows.
    #[arg(long, default_value_t = PlateDesign::default().rows)]
    pub rows: u32,
    /// Grid spacing, mm.
    #[arg(long, default_value_t = PlateDesign::default().spacing)]
    pub spacing: f64,
    /// Centre-dot radius of the coded targets, mm.
    #[arg(long, default_value_t = PlateDesign::default().coded_radius)]
    pub coded_radius: f64,
    /// Centre-dot radius of the uncoded targets, mm.
    #[arg(long, default_value_t = PlateDesign::default().uncoded_radius)]
    pub uncoded_radius: f64,
    /// A coded target every K grid cells in both directions (0: none).
    #[arg(long, default_value_t = PlateDesign::default().coded_step)]
    pub coded_step: u32,
    /// Output CSV; default: standard output.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    match args.command {
        FieldCommand::Svg(a) => svg(a),
        FieldCommand::New(a) => new(a),
    }
}

#[derive(Serialize)]
struct Written {
    out: String,
    ok: bool,
    targets: usize,
    coded: usize,
}

/// What `field svg` wrote.
#[derive(Serialize)]
struct Drawn {
    out: String,
    ok: bool,
    targets: usize,
    coded: usize,
    /// Drawing size, mm.
    width_mm: f64,
    height_mm: f64,
    /// The paper, its orientation and the files written (one per sheet).
    #[serde(skip_serializing_if = "Option::is_none")]
    paper: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    landscape: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    overlap_mm: Option<f64>,
    sheets: Vec<String>,
    field_sha256: String,
}

fn svg(args: SvgArgs) -> Result<ExitCode> {
    for (name, v) in [
        ("--label-mm", args.label_mm),
        ("--border-mm", args.border_mm),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            bail!("{name} {v}: must be a length ≥ 0 in mm");
        }
    }
    if !(args.overlap_mm.is_finite() && args.overlap_mm >= 0.0) {
        bail!(
            "--overlap-mm {}: must be a length ≥ 0 in mm",
            args.overlap_mm
        );
    }
    let field = defaults::field(args.field.as_deref())?;
    let (name, sha256) = match &args.field {
        Some(p) => (
            p.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| p.display().to_string()),
            hash_file(p, photopose_formats::FileKind::Field)?.sha256,
        ),
        None => (
            "built-in plate (config/plate.csv)".to_string(),
            provenance::sha256_hex(defaults::PLATE_CSV.as_bytes()),
        ),
    };
    let plain = plate_drawing(
        &field,
        &SvgOptions {
            border_mm: args.border_mm,
            label_mm: args.label_mm,
        },
    )?;
    let footer = format!(
        "{} targets ({} coded), drawn 1:1 by {}",
        field.len(),
        field.coded().count(),
        Provenance::now(vec![]).headline()
    );
    let drawing = annotate(
        &plain,
        &SheetText {
            name: &name,
            checksum: &sha256[..12],
            footer: &footer,
        },
    );
    let mut written = Drawn {
        out: args.out.display().to_string(),
        ok: true,
        targets: field.len(),
        coded: field.coded().count(),
        width_mm: drawing.width_mm,
        height_mm: drawing.height_mm,
        paper: None,
        landscape: None,
        overlap_mm: None,
        sheets: Vec::new(),
        field_sha256: sha256.clone(),
    };
    let write = |path: &std::path::Path, text: &str| {
        std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))
    };
    match args.paper {
        None => {
            write(&args.out, &drawing.to_svg())?;
            written.sheets.push(args.out.display().to_string());
        }
        Some(paper) => {
            let largest = field
                .targets()
                .iter()
                .map(|t| t.bright_radius())
                .fold(0.0, f64::max);
            let overlap = args.overlap_mm.max(2.0 * largest + 2.0);
            let l = layout(drawing.width_mm, drawing.height_mm, paper, overlap)?;
            let pages = sheets(&drawing, &l);
            for page in &pages {
                let path = if pages.len() == 1 {
                    args.out.clone()
                } else {
                    let stem = args
                        .out
                        .file_stem()
                        .map(|s| s.to_string_lossy().into_owned())
                        .unwrap_or_else(|| "plate".into());
                    args.out
                        .with_file_name(format!("{stem}-{}.svg", page.label))
                };
                write(&path, &page.svg)?;
                written.sheets.push(path.display().to_string());
            }
            written.paper = Some(paper.name());
            written.landscape = Some(l.landscape);
            written.overlap_mm = Some(overlap);
        }
    }
    outln!("{}", serde_json::to_string(&written)?)?;
    Ok(ExitCode::SUCCESS)
}

/// Radius out to which a target is bright, mm (coded: the code ring).
fn bright_radius(kind: TargetKind, r: f64) -> f64 {
    match kind {
        TargetKind::Coded => 3.0 * r,
        TargetKind::Uncoded => r,
    }
}

/// Checks that no bright part of a target (dot or code ring) reaches into
/// another target's quiet zone (docs/coded-targets.md: "no other target or
/// bright mark reaches into it").
fn check_bright_marks(field: &Field) -> Result<()> {
    let t = field.targets();
    for (i, a) in t.iter().enumerate() {
        for b in &t[i + 1..] {
            let d = (a.position - b.position).norm();
            let need = (a.quiet_radius() + bright_radius(b.kind, b.radius))
                .max(b.quiet_radius() + bright_radius(a.kind, a.radius));
            if d < need {
                bail!(
                    "targets {} and {} are {d:.2} mm apart; their quiet zones need {need:.2} mm \
                     (a quiet zone reaches 4 r around a coded target, 2 r around an uncoded one, \
                     and no dot or code ring may reach into it): increase --spacing or reduce the radii",
                    a.id,
                    b.id
                );
            }
        }
    }
    Ok(())
}

fn design(args: &NewArgs) -> Result<Field> {
    for (name, v) in [
        ("--spacing", args.spacing),
        ("--coded-radius", args.coded_radius),
        ("--uncoded-radius", args.uncoded_radius),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{name} {v}: must be a positive length in mm");
        }
    }
    if args.cols == 0 || args.rows == 0 {
        bail!(
            "--cols {} --rows {}: a plate needs at least one column and one row",
            args.cols,
            args.rows
        );
    }
    let design = PlateDesign {
        cols: args.cols,
        rows: args.rows,
        spacing: args.spacing,
        coded_radius: args.coded_radius,
        uncoded_radius: args.uncoded_radius,
        coded_step: args.coded_step,
        ..PlateDesign::default()
    };
    let field = design.build().context("plate design refused")?;
    check_bright_marks(&field).context("plate design refused")?;
    Ok(field)
}

fn new(args: NewArgs) -> Result<ExitCode> {
    let field = design(&args)?;
    let csv = field.to_csv();
    match &args.out {
        None => out!("{csv}")?,
        Some(path) => {
            std::fs::write(path, csv)
                .with_context(|| format!("{}: cannot write", path.display()))?;
            outln!(
                "{}",
                serde_json::to_string(&Written {
                    out: path.display().to_string(),
                    ok: true,
                    targets: field.len(),
                    coded: field.coded().count(),
                })?
            )?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args() -> NewArgs {
        let d = PlateDesign::default();
        NewArgs {
            cols: d.cols,
            rows: d.rows,
            spacing: d.spacing,
            coded_radius: d.coded_radius,
            uncoded_radius: d.uncoded_radius,
            coded_step: d.coded_step,
            out: None,
        }
    }

    #[test]
    fn default_design_is_the_default_plate() {
        let f = design(&args()).unwrap();
        assert_eq!(
            f.to_csv(),
            photopose_field::design::default_plate().to_csv()
        );
    }

    #[test]
    fn a_code_ring_in_a_quiet_zone_is_refused() {
        // Coded r = 3 mm: quiet zone to 12 mm; an uncoded neighbour (r = 1)
        // 10.5 mm away has its dot inside it.
        let a = NewArgs {
            spacing: 10.5,
            coded_radius: 3.0,
            uncoded_radius: 1.0,
            ..args()
        };
        let e = format!("{:#}", design(&a).unwrap_err());
        assert!(e.contains("plate design refused"), "{e}");
        // Two coded targets side by side: the field's own check counts the
        // neighbour's dot (3 mm) only, ours its ring (9 mm).
        let b = NewArgs {
            cols: 4,
            rows: 1,
            spacing: 17.0,
            coded_radius: 3.0,
            uncoded_radius: 1.0,
            coded_step: 1,
            out: None,
        };
        let e = format!("{:#}", design(&b).unwrap_err());
        assert!(e.contains("quiet zones need 21.00 mm"), "{e}");
        let e = format!(
            "{:#}",
            design(&NewArgs {
                spacing: -1.0,
                ..args()
            })
            .unwrap_err()
        );
        assert!(e.contains("--spacing -1"), "{e}");
    }
}
