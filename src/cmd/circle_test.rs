//! `photopose circle-test`: the ISO 230-4 circular test of a recorded pose
//! stream (the daemon's JSON lines, docs/streams.md, or `photopose resect`
//! output), of the projection centres and — with a hand-eye transform — of
//! the TCP. Writes report.txt, report.json and the figure-2 style plots
//! circle.svg, radial.svg and angular.svg into the output folder, each with
//! its provenance (tool, date, input files with their SHA-256). The figures
//! are ISO 230-4's: the circular deviation `G` always, the radial deviation
//! `F` when the nominal circle is given (`--nominal-center`,
//! `--nominal-radius`).

use anyhow::{bail, Context, Result};
use clap::Parser;
use photopose_circle::pose::tcp_from_camera;
use photopose_circle::{
    analyse, plot, report, AnalysisOptions, CircleTest, Isometry3, NominalCircle,
};
use photopose_formats::provenance::{hash_file, sha256_hex, InputFile, Provenance};
use photopose_geometry::pose::{camera_pose, isometry_from_xyzabc};
use photopose_geometry::{rotation, Exterior, Matrix3, Vector3};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Arguments of `photopose circle-test`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Pose files: JSON lines of the daemon's pose stream (docs/streams.md)
    /// or of `photopose resect`, or recordings (MCAP: the pose messages of
    /// `/pose/message`); several files are joined in order.
    #[arg(required = true)]
    pub poses: Vec<PathBuf>,
    /// Hand-eye file (TOML, `[camera_in_tcp] xyzabc = [x, y, z, a, b, c]`,
    /// mm and KUKA degrees): also test the TCP, and plot it.
    #[arg(long)]
    pub hand_eye: Option<PathBuf>,
    /// Magnification of the radial deviations in circle.svg.
    #[arg(long, default_value_t = 25.0)]
    pub magnify: f64,
    /// Highest harmonic order (undulations per revolution) of the filtered
    /// profiles; 0: no filter.
    #[arg(long, default_value_t = AnalysisOptions::default().harmonics)]
    pub harmonics: u32,
    /// Folder for report.txt, report.json, circle.svg, radial.svg, angular.svg.
    #[arg(long, default_value = "circle-test")]
    pub out_dir: PathBuf,
    /// Print the JSON report on stdout instead of the text report.
    #[arg(long)]
    pub json: bool,
    /// Centre of the nominal (programmed) circle, X,Y,Z mm in the plate
    /// frame: of the TCP with `--hand-eye`, else of the projection centre.
    /// With `--nominal-radius` the report gives ISO 230-4's radial
    /// deviation F.
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        requires = "nominal_radius"
    )]
    pub nominal_center: Option<Vec<f64>>,
    /// Radius of the nominal circle, mm (with `--nominal-center`).
    #[arg(long, allow_hyphen_values = true, requires = "nominal_center")]
    pub nominal_radius: Option<f64>,
}

/// What was read from one pose file.
#[derive(Serialize, Debug, Clone)]
pub struct InputSummary {
    /// The file (or a name for an in-memory stream).
    pub path: String,
    /// Non-empty lines.
    pub lines: usize,
    /// Poses used.
    pub used: usize,
    /// Lines without a pose, by status (`stale`, `too_few_targets`,
    /// `error`, `failed` for a resect line with `ok: false`).
    pub skipped: BTreeMap<String, usize>,
    /// SHA-256 of the bytes read (None for an in-memory stream).
    #[serde(skip)]
    pub sha256: Option<String>,
}

/// A hand-eye transform as read.
#[derive(Debug, Clone)]
pub struct HandEye {
    /// `X` as KUKA `X, Y, Z, A, B, C` (mm, degrees).
    pub xyzabc: [f64; 6],
    /// `X = T_tcp←camera`.
    pub camera_in_tcp: Isometry3<f64>,
    /// The file it was read from, with its SHA-256.
    pub input: Option<InputFile>,
}

/// The JSON report (report.json).
#[derive(Serialize)]
struct Report<'a> {
    provenance: &'a Provenance,
    inputs: &'a [InputSummary],
    n_poses: usize,
    hand_eye_xyzabc: Option<[f64; 6]>,
    magnify: f64,
    plots_of: &'static str,
    camera: &'a CircleTest,
    tcp: Option<&'a CircleTest>,
}

/// Everything a circular test writes, in memory.
pub struct Outputs {
    /// The text report.
    pub text: String,
    /// The JSON report.
    pub json: String,
    /// File name and content of each output file.
    pub files: Vec<(&'static str, String)>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    if !(args.magnify.is_finite() && args.magnify > 0.0) {
        bail!("--magnify {}: must be a positive number", args.magnify);
    }
    let mut poses = Vec::new();
    let mut inputs = Vec::new();
    for path in &args.poses {
        inputs.push(read_poses(path, &mut poses)?);
    }
    if poses.is_empty() {
        bail!("no usable pose in {} file(s)", args.poses.len());
    }
    let hand_eye = args.hand_eye.as_deref().map(read_hand_eye).transpose()?;
    let nominal = match (&args.nominal_center, args.nominal_radius) {
        (Some(c), Some(r)) => {
            let [x, y, z] = c[..] else {
                bail!(
                    "--nominal-center {}: must be three numbers X,Y,Z (mm)",
                    c.iter().map(f64::to_string).collect::<Vec<_>>().join(",")
                );
            };
            Some(NominalCircle {
                center_mm: [x, y, z],
                radius_mm: r,
            })
        }
        _ => None,
    };
    let out = evaluate_against(
        &poses,
        &inputs,
        hand_eye.as_ref(),
        nominal,
        args.harmonics,
        args.magnify,
    )?;
    let written = write_outputs(&args.out_dir, &out)?;
    if args.json {
        outln!("{}", out.json)?;
    } else {
        out!("{}", out.text)?;
        outln!(
            "\nwritten: {}",
            written
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The circular test of camera poses (time order, plate frame) and, with a
/// hand-eye transform, of the TCP (reports and plots of the TCP if given),
/// with the nominal circle of the subject (the TCP with a
/// hand-eye transform, else the projection centre), for ISO 230-4's `F`.
pub fn evaluate_against(
    poses: &[Isometry3<f64>],
    inputs: &[InputSummary],
    hand_eye: Option<&HandEye>,
    nominal: Option<NominalCircle>,
    harmonics: u32,
    magnify: f64,
) -> Result<Outputs> {
    let options = AnalysisOptions {
        harmonics,
        nominal: None,
    };
    let subject_options = AnalysisOptions { nominal, ..options };
    let camera_options = if hand_eye.is_some() {
        &options
    } else {
        &subject_options
    };
    let camera =
        analyse(poses, camera_options).context("circular test of the projection centres")?;
    let tcp = match hand_eye {
        Some(h) => {
            let tcp: Vec<Isometry3<f64>> = poses
                .iter()
                .map(|c| tcp_from_camera(c, &h.camera_in_tcp))
                .collect();
            Some(analyse(&tcp, &subject_options).context("circular test of the TCP")?)
        }
        None => None,
    };
    let mut files: Vec<InputFile> = inputs
        .iter()
        .filter_map(|i| {
            i.sha256.as_ref().map(|h| InputFile {
                path: i.path.clone(),
                sha256: h.clone(),
            })
        })
        .collect();
    files.extend(hand_eye.and_then(|h| h.input.clone()));
    let provenance = Provenance::now(files);
    let (subject, plotted) = match &tcp {
        Some(t) => ("TCP", t),
        None => ("projection centre", &camera),
    };
    let report = Report {
        provenance: &provenance,
        inputs,
        n_poses: poses.len(),
        hand_eye_xyzabc: hand_eye.map(|h| h.xyzabc),
        magnify,
        plots_of: if tcp.is_some() { "tcp" } else { "camera" },
        camera: &camera,
        tcp: tcp.as_ref(),
    };
    let json = serde_json::to_string_pretty(&report)?;
    let mut text = provenance.to_text();
    for i in inputs {
        let skipped: Vec<String> = i.skipped.iter().map(|(k, n)| format!("{n} {k}")).collect();
        text.push_str(&format!(
            "{}: {} lines, {} poses used{}\n",
            i.path,
            i.lines,
            i.used,
            if skipped.is_empty() {
                String::new()
            } else {
                format!(", skipped: {}", skipped.join(", "))
            }
        ));
    }
    text.push('\n');
    text.push_str(&report::text(
        "Circular test (ISO 230-4) of the projection centre",
        &camera,
    ));
    if let (Some(t), Some(h)) = (&tcp, hand_eye) {
        text.push('\n');
        let title = format!(
            "Circular test (ISO 230-4) of the TCP (camera in TCP X,Y,Z,A,B,C = {})",
            h.xyzabc.map(|v| format!("{v}")).join(", ")
        );
        text.push_str(&report::text(&title, t));
    }
    let files = vec![
        ("report.txt", text.clone()),
        ("report.json", json.clone() + "\n"),
        (
            "circle.svg",
            provenance.insert_into_svg(&plot::path_svg(
                plotted,
                &format!("Circular path of the {subject}"),
                magnify,
            )),
        ),
        (
            "radial.svg",
            provenance.insert_into_svg(&plot::radial_svg(
                plotted,
                &format!("Radial deviation of the {subject}"),
            )),
        ),
        (
            "angular.svg",
            provenance.insert_into_svg(&plot::angular_svg(
                plotted,
                &format!("Orientation deviation of the {subject}"),
            )),
        ),
    ];
    Ok(Outputs { text, json, files })
}

/// Writes the output files into `dir` (created if needed); their paths.
pub fn write_outputs(dir: &Path, out: &Outputs) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut written = Vec::new();
    for (name, body) in &out.files {
        let p = dir.join(name);
        std::fs::write(&p, body).with_context(|| format!("cannot write {}", p.display()))?;
        written.push(p);
    }
    Ok(written)
}

/// Appends the camera poses of one file; lines without a pose are counted.
pub fn read_poses(path: &Path, out: &mut Vec<Isometry3<f64>>) -> Result<InputSummary> {
    let name = path.display().to_string();
    // A recording's pose messages are its lines, `FILE#N` the N-th.
    let file_sha256;
    let (lines, mark) = if crate::cmd::input::is_recording(path) {
        file_sha256 =
            photopose_formats::provenance::hash_file(path, photopose_formats::FileKind::Recording)?
                .sha256;
        let messages = photopose_record::pose_messages(path)?;
        let lines = messages
            .iter()
            .enumerate()
            .map(|(k, m)| {
                String::from_utf8(m.clone())
                    .with_context(|| format!("{name}#{}: a pose message that is not UTF-8", k + 1))
            })
            .collect::<Result<Vec<String>>>()?;
        (lines, '#')
    } else {
        let text = photopose_formats::read_text(path, photopose_formats::FileKind::Poses)?;
        file_sha256 = sha256_hex(text.as_bytes());
        (text.lines().map(str::to_string).collect(), ':')
    };
    let mut summary = InputSummary {
        path: name.clone(),
        lines: 0,
        used: 0,
        skipped: BTreeMap::new(),
        sha256: Some(file_sha256),
    };
    for (k, line) in lines.iter().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let at = format!("{name}{mark}{}", k + 1);
        summary.lines += 1;
        let l = photopose_stream::PoseLine::parse(line)
            .with_context(|| format!("{at}: not a JSON pose line"))?;
        let Some(has_pose) = l.has_pose() else {
            bail!("{at}: neither a pose message (no \"status\") nor a resect line (no \"ok\")")
        };
        if !has_pose {
            let why = l.status.clone().unwrap_or_else(|| "failed".into());
            *summary.skipped.entry(why).or_default() += 1;
        }
        if !has_pose {
            continue;
        }
        let Some(p) = &l.pose else {
            bail!("{at}: a pose line without \"pose\"");
        };
        let (c, r) = (p.position_mm, p.rotation_field_to_camera);
        let r = Matrix3::from_fn(|i, j| r[i][j]);
        if let Some(v) = c.iter().find(|v| !v.is_finite()) {
            bail!("{at}: \"pose.position_mm\" has {v}, not a finite number");
        }
        if !rotation::is_rotation(&r, 1e-6) {
            bail!("{at}: \"pose.rotation_field_to_camera\" is not a rotation matrix");
        }
        out.push(camera_pose(&Exterior::new(r, Vector3::from(c))));
        summary.used += 1;
    }
    Ok(summary)
}

/// The hand-eye transform `X = T_tcp←camera` of a hand-eye file
/// (`photopose calibrate hand-eye`, format in `photopose-formats`).
pub fn read_hand_eye(path: &Path) -> Result<HandEye> {
    let name = path.display().to_string();
    let file = photopose_formats::hand_eye::load_hand_eye(path)?;
    let xyzabc = file.camera_in_tcp.xyzabc;
    if let Some(k) = xyzabc.iter().position(|v| !v.is_finite()) {
        bail!(
            "{name}: camera_in_tcp.xyzabc[{k}] = {} is not finite",
            xyzabc[k]
        );
    }
    Ok(HandEye {
        xyzabc,
        camera_in_tcp: isometry_from_xyzabc(xyzabc),
        input: Some(hash_file(path, photopose_formats::FileKind::HandEye)?),
    })
}
