//! `photopose calibrate hand-eye`: the camera in the robot's TCP frame and
//! the plate in the robot's base frame from a station file (robot poses
//! with either camera poses or frames to measure them from), written as a
//! hand-eye file, with a report of the fit (per-station residuals, standard
//! deviations, rejected stations) as text or one JSON object, each with its
//! provenance (tool, date, the station file and every file it read with
//! their SHA-256).

use crate::cmd::batch::load_frame;
use crate::cmd::defaults;
use anyhow::{bail, Context, Result};
use clap::Parser;
use photopose_formats::hand_eye::{save_hand_eye, Fit, HandEyeFile, Transform};
use photopose_formats::provenance::{hash_file, sha256_hex, InputFile, Provenance};
use photopose_formats::FileKind;
use photopose_handeye::stations::CameraSource;
use photopose_handeye::{
    parse_stations, solve, CameraPose, HandEye, HandEyeOptions, Station, StationResidual,
};
use photopose_locate::{LocateOptions, Locator, PoseStatus};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Arguments of `photopose calibrate hand-eye`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Station file (CSV, docs/hand-eye.md): `station`, the robot's TCP
    /// pose `robot_x..robot_c`, and either `image` (a frame, relative to
    /// the station file) or the camera pose `cam_x..cam_c` (with optional
    /// `cam_std_*`).
    #[arg(long)]
    pub stations: PathBuf,
    /// Camera file (TOML) for the frames; default: the built-in camera.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Test field (CSV) for the frames; default: the built-in plate.
    #[arg(long)]
    pub field: Option<PathBuf>,
    /// The hand-eye file to write (TOML).
    #[arg(long)]
    pub out: PathBuf,
    /// Print the report as one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Robot repeatability: σ of a TCP coordinate, mm.
    #[arg(long, default_value_t = HandEyeOptions::default().robot_std_mm)]
    pub robot_std_mm: f64,
    /// Robot repeatability: σ of a small TCP rotation, degrees.
    #[arg(long, default_value_t = HandEyeOptions::default().robot_std_deg)]
    pub robot_std_deg: f64,
    /// σ of the camera centre for pose rows without `cam_std_*`, mm.
    #[arg(long, default_value_t = 0.05)]
    pub camera_std_mm: f64,
    /// σ of the camera rotations for pose rows without `cam_std_*`, degrees.
    #[arg(long, default_value_t = 0.005)]
    pub camera_std_deg: f64,
    /// Significance level of the gross-error test of a station.
    #[arg(long, default_value_t = HandEyeOptions::default().alpha)]
    pub alpha: f64,
    /// Smallest accepted spread of the robot's rotation axes, degrees.
    #[arg(long, default_value_t = HandEyeOptions::default().min_axis_spread_deg)]
    pub min_axis_spread_deg: f64,
}

/// The JSON report.
#[derive(Serialize)]
struct Report<'a> {
    provenance: &'a Provenance,
    ok: bool,
    out: String,
    /// `X = T_tcp←camera`.
    camera_in_tcp: TransformJson,
    /// `Z = T_base←plate`.
    plate_in_base: TransformJson,
    sigma0: f64,
    redundancy: usize,
    stations: usize,
    used: usize,
    rejected: &'a [String],
    rms_mm: f64,
    rms_deg: f64,
    critical: Option<f64>,
    axis_spread_deg: f64,
    iterations: usize,
    residuals: Vec<ResidualJson<'a>>,
}

#[derive(Serialize)]
struct TransformJson {
    xyzabc: [f64; 6],
    std_xyzabc: [f64; 6],
    /// σ of the small rotations about the parent frame's axes, degrees.
    std_rotation_deg: [f64; 3],
}

#[derive(Serialize)]
struct ResidualJson<'a> {
    station: &'a str,
    used: bool,
    translation_mm: [f64; 3],
    rotation_deg: [f64; 3],
    norm_mm: f64,
    norm_deg: f64,
    test: Option<f64>,
}

impl<'a> ResidualJson<'a> {
    fn new(r: &'a StationResidual) -> Self {
        ResidualJson {
            station: &r.name,
            used: r.used,
            translation_mm: r.translation_mm,
            rotation_deg: r.rotation_deg,
            norm_mm: r.norm_mm,
            norm_deg: r.norm_deg,
            test: r.test,
        }
    }
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    let mut inputs = Vec::new();
    let stations = load_stations(&args, &mut inputs)?;
    let provenance = Provenance::now(inputs);
    let options = HandEyeOptions {
        robot_std_mm: args.robot_std_mm,
        robot_std_deg: args.robot_std_deg,
        alpha: args.alpha,
        min_axis_spread_deg: args.min_axis_spread_deg,
        ..HandEyeOptions::default()
    };
    let he = solve(&stations, &options)
        .with_context(|| format!("{}: hand-eye calibration", args.stations.display()))?;
    let file = hand_eye_file(&he);
    save_hand_eye(&args.out, &file)?;
    if args.json {
        let std_x = he.std_unknowns();
        let report = Report {
            provenance: &provenance,
            ok: true,
            out: args.out.display().to_string(),
            camera_in_tcp: TransformJson {
                xyzabc: file.camera_in_tcp.xyzabc,
                std_xyzabc: file.camera_in_tcp.std_xyzabc,
                std_rotation_deg: [std_x[3], std_x[4], std_x[5]],
            },
            plate_in_base: TransformJson {
                xyzabc: file.plate_in_base.xyzabc,
                std_xyzabc: file.plate_in_base.std_xyzabc,
                std_rotation_deg: [std_x[9], std_x[10], std_x[11]],
            },
            sigma0: he.sigma0,
            redundancy: he.redundancy,
            stations: stations.len(),
            used: he.n_used,
            rejected: &he.rejected,
            rms_mm: he.rms_mm,
            rms_deg: he.rms_deg,
            critical: he.critical,
            axis_spread_deg: he.axis_spread_deg,
            iterations: he.iterations,
            residuals: he.residuals.iter().map(ResidualJson::new).collect(),
        };
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        out!(
            "{}{}",
            provenance.to_text(),
            text_report(&he, &file, &args.out)
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The hand-eye file of a calibration.
pub(crate) fn hand_eye_file(he: &HandEye) -> HandEyeFile {
    HandEyeFile {
        camera_in_tcp: Transform {
            xyzabc: he.camera_in_tcp_xyzabc(),
            std_xyzabc: he.camera_in_tcp_std_xyzabc(),
        },
        plate_in_base: Transform {
            xyzabc: he.plate_in_base_xyzabc(),
            std_xyzabc: he.plate_in_base_std_xyzabc(),
        },
        fit: Some(Fit {
            stations: he.n_used as u32,
            sigma0: he.sigma0,
            rms_mm: he.rms_mm,
            rms_deg: he.rms_deg,
        }),
    }
}

/// Reads the station file and measures the camera pose of every station
/// that names a frame; every file read is added to `inputs` with its hash.
fn load_stations(args: &Args, inputs: &mut Vec<InputFile>) -> Result<Vec<Station>> {
    let text = photopose_formats::read_text(&args.stations, FileKind::Stations)?;
    let origin = args.stations.display().to_string();
    inputs.push(InputFile {
        path: origin.clone(),
        sha256: sha256_hex(text.as_bytes()),
    });
    let rows = parse_stations(&text, &origin)?;
    let default_std = [
        args.camera_std_mm,
        args.camera_std_mm,
        args.camera_std_mm,
        args.camera_std_deg,
        args.camera_std_deg,
        args.camera_std_deg,
    ];
    if default_std.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        bail!("--camera-std-mm and --camera-std-deg must be positive");
    }
    let dir = args.stations.parent().unwrap_or(Path::new("."));
    let mut locator: Option<Locator> = None;
    let mut camera = None;
    let mut out = Vec::with_capacity(rows.len());
    for row in &rows {
        if let Some(s) = row.to_station(default_std) {
            out.push(s);
            continue;
        }
        let CameraSource::Image(image) = &row.camera else {
            unreachable!("a row is either a pose or an image")
        };
        let path = dir.join(image);
        let cam = match camera {
            Some(c) => c,
            None => *camera.insert(defaults::camera(args.camera.as_deref())?),
        };
        let locator = match &mut locator {
            Some(l) => l,
            None => {
                for (p, kind) in [
                    (&args.camera, FileKind::Camera),
                    (&args.field, FileKind::Field),
                ] {
                    if let Some(p) = p {
                        inputs.push(hash_file(p, kind)?);
                    }
                }
                locator.insert(Locator::new(
                    cam,
                    defaults::field(args.field.as_deref())?,
                    LocateOptions::default(),
                )?)
            }
        };
        if let Ok(h) = hash_file(&path, FileKind::Image) {
            inputs.push(h);
        }
        let pose = locate(locator, &cam, &path)
            .map_err(|e| anyhow::anyhow!("{origin}:{}: station {}: {e}", row.line, row.name))?;
        out.push(Station {
            name: row.name.clone(),
            robot: photopose_geometry::pose::isometry_from_xyzabc(row.robot_xyzabc),
            camera: pose,
        });
    }
    Ok(out)
}

/// The camera pose of one frame, with its covariance.
fn locate(
    locator: &mut Locator,
    camera: &photopose_geometry::Camera,
    path: &Path,
) -> Result<CameraPose, String> {
    let name = path.display().to_string();
    let image = load_frame(path, camera)?;
    let loc = locator
        .locate(image.view())
        .map_err(|e| format!("{name}: {e}"))?;
    match (loc.status, loc.pose) {
        (PoseStatus::Ok, Some(p)) => Ok(CameraPose::from_resection(p)),
        (PoseStatus::TooFewTargets { coded }, _) => Err(format!(
            "{name}: too few targets: {coded} coded targets identified, a pose needs 4"
        )),
        (PoseStatus::Frame(status), _) => Err(format!(
            "{name}: no targets: the frame is {}",
            status.name()
        )),
        (PoseStatus::NoPose(e), _) => Err(format!("{name}: {e}")),
        (PoseStatus::Ok, None) => Err(format!("{name}: no pose")),
    }
}

fn six(v: &[f64; 6], decimals: [usize; 2]) -> String {
    let [d1, d2] = decimals;
    format!(
        "{:.d1$} {:.d1$} {:.d1$} {:.d2$} {:.d2$} {:.d2$}",
        v[0], v[1], v[2], v[3], v[4], v[5]
    )
}

/// The text report.
fn text_report(he: &HandEye, file: &HandEyeFile, out: &Path) -> String {
    let mut s = String::new();
    s += &format!(
        "hand-eye calibration: {} stations used of {}, σ0 {:.3}, redundancy {}, \
         axis spread {:.1}°\n",
        he.n_used,
        he.residuals.len(),
        he.sigma0,
        he.redundancy,
        he.axis_spread_deg
    );
    s += "station      used      |dt| mm   |dr| deg   dt (x y z) mm               test F\n";
    for r in &he.residuals {
        let t = r.translation_mm;
        s += &format!(
            "{:<12} {:<9} {:>8.4} {:>10.5}   {:>8.4} {:>8.4} {:>8.4}   {}\n",
            r.name,
            if r.used { "yes" } else { "REJECTED" },
            r.norm_mm,
            r.norm_deg,
            t[0],
            t[1],
            t[2],
            r.test
                .map(|f| format!("{f:.2}"))
                .unwrap_or_else(|| "-".into())
        );
    }
    if let Some(c) = he.critical {
        s += &format!(
            "critical value of the station test (F(6, {})): {c:.2}\n",
            he.redundancy.saturating_sub(6)
        );
    }
    if he.rejected.is_empty() {
        s += "rejected stations: none\n";
    } else {
        s += &format!("rejected stations: {}\n", he.rejected.join(", "));
    }
    s += &format!("rms per station: {:.4} mm, {:.5}°\n", he.rms_mm, he.rms_deg);
    for (label, t) in [
        ("camera in TCP   (X = T_tcp←camera)", &file.camera_in_tcp),
        ("plate in base   (Z = T_base←plate)", &file.plate_in_base),
    ] {
        s += &format!(
            "{label}\n  X Y Z A B C     {}\n  σ               {}\n",
            six(&t.xyzabc, [4, 5]),
            six(&t.std_xyzabc, [4, 5])
        );
    }
    s += &format!("written: {}\n", out.display());
    s
}
