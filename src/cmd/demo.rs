//! `photopose demo`: the whole chain and the closed loop on the simulated
//! robot cell, no hardware. Each phase runs the daemon's pipeline on the
//! closed-loop cell source (`photopose_pipeline::source::cell`): a
//! simulated KUKA controller moves the robot along its program with the
//! cell's injected path error plus the corrections the daemon's RSI server
//! sends over loopback UDP, and frames are rendered at the robot's true
//! camera pose (motion blur over the exposure), handed over after the
//! transfer delay, located and streamed.
//!
//! (a) hand-eye: the robot visits still stations; stations are gathered from
//! the daemon's own pose stream (`photopose_handeye::gather`, as
//! `calibrate stations`) and solved (as `calibrate hand-eye`); the rest of
//! the demo uses this estimate. (b) the circle, measure-only; (c) the same
//! circle with corrections; (d) (c) without latency compensation. The
//! report gives the circular deviation at the TCP as measured by the camera
//! and as the simulation's truth, and overlays (b) and (c) in the plots.

use crate::cmd::calibrate_hand_eye::hand_eye_file;
use crate::cmd::calibrate_stations::sample;
use anyhow::{bail, Context, Result};
use clap::Parser;
use nalgebra::Isometry3;
use photopose_circle::cell::{CameraMount, CirclePath, RobotError};
use photopose_circle::{analyse, AnalysisOptions, CircleTest, NominalCircle};
use photopose_geometry::pose::isometry_from_xyzabc;
use photopose_handeye::gather::{GatherSettings, Gatherer};
use photopose_handeye::{solve, HandEyeOptions};
use photopose_pipeline::source::{CellFrameTruth, CellPath, CellSettings, CellSource};
use photopose_pipeline::{Config, Pipeline};
use std::io::{IsTerminal, Write};
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Arguments of `photopose demo`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Folder for the pose streams, the hand-eye file, the reports and the
    /// plots.
    #[arg(long, default_value = "photopose-demo")]
    pub out: PathBuf,
    /// Feed along the circle, mm/s (the reference experiment ran 10 mm/s).
    #[arg(long, default_value_t = 40.0)]
    pub feed: f64,
    /// Camera frame rate, frames/s. 10 by default: every simulated frame is
    /// rendered with motion blur on this machine's cores beside the
    /// daemon's own work, and at 25 frames/s a 2-core machine falls behind
    /// the cell's clock (the measurements then arrive too old to correct
    /// with). A real camera costs the host nothing to expose.
    #[arg(long, default_value_t = 10.0)]
    pub rate: f64,
    /// Transfer from the end of the exposure to the hand-over, ms (default:
    /// the frame's bytes at 1 Gbit/s, ≈ 10.7 ms).
    #[arg(long)]
    pub transfer_ms: Option<f64>,
    /// Exposure time, ms (motion blur over it).
    #[arg(long, default_value_t = 2.0)]
    pub exposure_ms: f64,
    /// End the output with one JSON object of the figures.
    #[arg(long)]
    pub json: bool,
    /// Radius of the circle, mm (100 keeps the demo about a minute).
    #[arg(long, default_value_t = 100.0, hide = true)]
    pub radius_mm: f64,
    /// Hand-eye stations (at least 12 for the demo's report).
    #[arg(long, default_value_t = 12, hide = true)]
    pub stations: usize,
    /// The correction law's gain in (c) and (d) (`[rsi] gain`). 0.9 here,
    /// against the daemon's cautious 0.5: at 10 frames/s a gain of 0.5
    /// leaves the correction about two frames behind a path error that
    /// changes along the circle (true F 41 µm against 32 µm at 40 mm/s);
    /// the slew limit and the clamp bound every step all the same.
    #[arg(long, default_value_t = 0.9)]
    pub gain: f64,
    /// Feed-forward of the error's rate in (c) and (d) (`[rsi] feed_forward`).
    #[arg(long)]
    pub feed_forward: bool,
}

/// A free UDP port on the loopback (for the RSI server).
fn free_udp_port() -> Result<u16> {
    Ok(UdpSocket::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// The RSI law's settings of a phase.
#[derive(Debug, Clone, Copy)]
struct Law {
    measure_only: bool,
    compensate: bool,
}

/// What a phase left behind.
struct PhaseRun {
    /// Camera poses of the stream (plate frame) with their frame numbers.
    poses: Vec<(u64, Isometry3<f64>)>,
    /// The truth of every frame.
    truth: Vec<CellFrameTruth>,
    /// Poses located / frames in.
    ok: u64,
    frames_in: u64,
    /// The controller's cycles, late replies, max step and total.
    report: photopose_rsi::controller::SimReport,
}

/// Runs the pipeline on the cell source along `path` for `frames` frames;
/// every pose line goes to `stream_path` and to `on_line`.
#[allow(clippy::too_many_arguments)] // one phase's whole set-up
fn run_phase(
    args: &Args,
    label: &str,
    path: CellPath,
    frames: u64,
    law: Law,
    hand_eye: &Path,
    stream_path: &Path,
    mut on_line: impl FnMut(&photopose_stream::PoseLine, &serde_json::Value),
) -> Result<PhaseRun> {
    let poses_rx = UdpSocket::bind("127.0.0.1:0").context("cannot bind the demo's UDP socket")?;
    poses_rx.set_read_timeout(Some(Duration::from_millis(100)))?;
    let rsi_port = free_udp_port()?;
    let config = Config::parse(
        &format!(
            "[pipeline]\nworkers = 2\nslots = 8\noverflow = \"block\"\nmax_age_ms = 2000.0\n\
             [output]\nudp = [\"{udp}\"]\n\
             [rsi]\nenabled = true\nbind = \"127.0.0.1\"\nport = {rsi_port}\ncontrollers = [\"127.0.0.1\"]\n\
             measure_only = {mo}\ncompensate_latency = {comp}\nmax_age_ms = 1000.0\nhand_eye = \"{he}\"\n\
             gain = {gain}\nfeed_forward = {ff}\n",
            udp = poses_rx.local_addr()?,
            mo = law.measure_only,
            comp = law.compensate,
            he = hand_eye.display(),
            gain = args.gain,
            ff = args.feed_forward,
        ),
        "<demo configuration>",
    )?;
    let Some(rsi) = config.rsi.as_ref() else {
        bail!("the demo configuration has no [rsi]")
    };
    let camera = photopose_formats::default_camera();
    let field = photopose_field::design::default_plate();
    let mut settings = CellSettings::new(([127, 0, 0, 1], rsi_port).into(), args.rate, frames);
    settings.exposure_ms = args.exposure_ms;
    settings.transfer_ms = args.transfer_ms;
    settings.controller.sen = rsi.settings.sen.clone();
    settings.controller.mode = rsi.settings.law.mode;
    settings.controller.frame = rsi.settings.law.frame;
    let source = CellSource::new(camera, &field, settings, path).context("the cell source")?;
    let cell = source.handle();
    let pipeline = Pipeline::start(&config, camera, field, Box::new(source))
        .context("cannot start the pipeline")?;
    let mut stream = std::io::BufWriter::new(
        std::fs::File::create(stream_path)
            .with_context(|| format!("cannot create {}", stream_path.display()))?,
    );
    let terminal = std::io::stdout().is_terminal();
    let started = Instant::now();
    let mut last_print = Instant::now();
    let mut buf = [0u8; 8192];
    let mut poses = Vec::new();
    loop {
        let finished = pipeline.finished();
        match poses_rx.recv(&mut buf) {
            Ok(n) => {
                stream.write_all(&buf[..n])?;
                if buf[n - 1] != b'\n' {
                    stream.write_all(b"\n")?;
                }
                let text =
                    std::str::from_utf8(&buf[..n]).context("a pose line that is not UTF-8")?;
                let l = photopose_stream::PoseLine::parse(text.trim())
                    .context("a pose message that is not JSON")?;
                let v: serde_json::Value = serde_json::from_str(text.trim())?;
                if let (Some(seq), Some(cam)) = (l.seq, camera_of(&l)) {
                    poses.push((seq, cam));
                }
                on_line(&l, &v);
            }
            Err(_) if finished => break,
            Err(_) => {}
        }
        if terminal && last_print.elapsed() >= Duration::from_millis(250) {
            last_print = Instant::now();
            out!(
                "\r{label}: {}/{frames} frames, {:.1} s\x1b[K",
                poses.len(),
                started.elapsed().as_secs_f64()
            )?;
            std::io::stdout().flush()?;
        }
    }
    if terminal {
        out!("\r\x1b[K")?;
    }
    stream.flush()?;
    pipeline.stop();
    let counters = pipeline.join();
    if let Some(e) = cell.controller_error() {
        bail!("{label}: the simulated controller: {e}");
    }
    let report = cell.report().unwrap_or_default();
    Ok(PhaseRun {
        poses,
        truth: cell.frames(),
        ok: counters.poses_ok.get(),
        frames_in: counters.frames_in.get(),
        report,
    })
}

/// The camera pose (plate frame) of a pose line with a pose.
fn camera_of(l: &photopose_stream::PoseLine) -> Option<Isometry3<f64>> {
    if l.has_pose() != Some(true) {
        return None;
    }
    let p = l.pose.as_ref()?;
    let r = photopose_geometry::Matrix3::from_fn(|i, j| p.rotation_field_to_camera[i][j]);
    Some(photopose_geometry::pose::camera_pose(
        &photopose_geometry::Exterior::new(r, photopose_geometry::Vector3::from(p.position_mm)),
    ))
}

/// The hand-eye stations: TCP poses around the circle's centre at three
/// heights, turned about the vertical by up to ±20° and tilted by up to
/// ±8° about both horizontal axes (rotations about all three axes).
fn station_poses(centre: [f64; 3], n: usize) -> Vec<Isometry3<f64>> {
    (0..n)
        .map(|i| {
            let phi = std::f64::consts::TAU * i as f64 / n as f64;
            let dz = [-30.0, 0.0, 30.0][i % 3];
            isometry_from_xyzabc([
                centre[0] + 60.0 * phi.cos(),
                centre[1] + 60.0 * phi.sin(),
                centre[2] + dz,
                20.0 * phi.cos(),
                8.0 * phi.sin(),
                180.0 + 8.0 * (2.0 * phi).cos(),
            ])
        })
        .collect()
}

fn wrap_deg(d: f64) -> f64 {
    (d + 180.0).rem_euclid(360.0) - 180.0
}

/// The circular tests (measured through the estimated hand-eye, and the
/// truth) of one circle phase, from frame `first` on.
struct CircleFigures {
    measured: CircleTest,
    /// The fit of the true TCP (exact data can stall the fit's
    /// convergence test: then only `truth_f_um`).
    truth: Option<CircleTest>,
    /// F of the true TCP: max − min of its horizontal distance from the
    /// nominal centre minus the nominal radius (the circle is horizontal),
    /// µm.
    truth_f_um: f64,
    truth_g_um: f64,
}

fn span_um(t: &CircleTest) -> f64 {
    t.f_um.as_ref().map_or(f64::NAN, |f| f.max - f.min)
}

fn circle_figures(
    run: &PhaseRun,
    first: u64,
    nominal: NominalCircle,
    he: &photopose_handeye::HandEye,
) -> Result<CircleFigures> {
    let options = AnalysisOptions {
        harmonics: 15,
        nominal: Some(nominal),
    };
    let x_inv = he.camera_in_tcp.inverse();
    let measured: Vec<Isometry3<f64>> = run
        .poses
        .iter()
        .filter(|(seq, _)| *seq >= first)
        .map(|(_, cam)| he.plate_in_base * cam * x_inv)
        .collect();
    let truth: Vec<Isometry3<f64>> = run
        .truth
        .iter()
        .filter(|f| f.seq >= first)
        .map(|f| f.tcp.actual)
        .collect();
    if measured.len() < 10 || truth.len() < 10 {
        bail!(
            "only {} measured poses and {} frames of truth: too few for a circular test",
            measured.len(),
            truth.len()
        );
    }
    let radial: Vec<f64> = truth
        .iter()
        .map(|p| {
            let d = p.translation.vector;
            ((d.x - nominal.center_mm[0]).hypot(d.y - nominal.center_mm[1]) - nominal.radius_mm)
                * 1e3
        })
        .collect();
    let span = radial.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - radial.iter().copied().fold(f64::INFINITY, f64::min);
    let truth_test = analyse(&truth, &options).ok();
    Ok(CircleFigures {
        measured: analyse(&measured, &options).context("circular test of the measured TCP")?,
        truth_g_um: truth_test.as_ref().map_or(f64::NAN, |t| t.g_um),
        truth: truth_test,
        truth_f_um: span,
    })
}

/// Runs the demo.
pub fn run(args: Args) -> Result<ExitCode> {
    if !(args.feed.is_finite() && (1.0..=500.0).contains(&args.feed)) {
        bail!("--feed {}: must be in [1, 500] mm/s", args.feed);
    }
    if !(args.rate.is_finite() && (1.0..=200.0).contains(&args.rate)) {
        bail!("--rate {}: must be in [1, 200] frames/s", args.rate);
    }
    if !(args.exposure_ms.is_finite() && (0.0..=100.0).contains(&args.exposure_ms)) {
        bail!("--exposure-ms {}: must be in [0, 100] ms", args.exposure_ms);
    }
    if let Some(t) = args.transfer_ms {
        if !(t.is_finite() && (0.0..=1000.0).contains(&t)) {
            bail!("--transfer-ms {t}: must be in [0, 1000] ms");
        }
    }
    if !(args.radius_mm.is_finite() && (10.0..=150.0).contains(&args.radius_mm)) {
        bail!("--radius-mm {}: must be in [10, 150] mm", args.radius_mm);
    }
    if !(3..=60).contains(&args.stations) {
        bail!("--stations {}: must be in [3, 60]", args.stations);
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let error = RobotError::default();
    let circle = CirclePath {
        radius_mm: args.radius_mm,
        feed_mm_s: args.feed,
        rate_hz: args.rate,
        ..CirclePath::default()
    };
    let started = Instant::now();
    outln!(
        "photopose demo: simulated cell (closed loop over UDP), circle of {:.1} mm at {} mm/s, {} frames/s, \
         exposure {} ms, transfer {}; injected radial deviation F = {:.1} µm",
        circle.radius_mm,
        args.feed,
        args.rate,
        args.exposure_ms,
        args.transfer_ms
            .map_or("1 Gbit/s".to_string(), |t| format!("{t} ms")),
        error.radial_f_mm() * 1000.0
    )?;

    // (a) Hand-eye from the daemon's own stream. The law of this phase only
    // measures; its hand-eye file is the mount's drawing, never used for a
    // correction.
    let nominal_he = args.out.join("hand-eye-drawing.toml");
    let f6 = |v: [f64; 6]| v.map(|x| format!("{x:.6}")).join(", ");
    std::fs::write(
        &nominal_he,
        format!(
            "# photopose demo: the camera mount as drawn (phase a only measures)\n\
             [camera_in_tcp]\nxyzabc = [{}]\nstd_xyzabc = [1.0, 1.0, 1.0, 0.1, 0.1, 0.1]\n\n\
             [plate_in_base]\nxyzabc = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\nstd_xyzabc = [1.0, 1.0, 1.0, 0.1, 0.1, 0.1]\n",
            f6(CameraMount::DEFAULT_XYZABC)
        ),
    )
    .with_context(|| format!("cannot write {}", nominal_he.display()))?;
    let (dwell_s, move_s) = (0.9, 0.5);
    let stations_path = CellPath::stations(
        station_poses(circle.center_mm, args.stations),
        dwell_s,
        move_s,
        error.clone(),
        circle.center_mm,
    );
    let frames = (stations_path.duration_s() * args.rate).ceil() as u64;
    let mut gatherer = Gatherer::new(GatherSettings {
        still_s: 0.5,
        min_poses: 4,
        ..GatherSettings::default()
    });
    let mut stations = Vec::new();
    let mut rows = Vec::new();
    let mut readings = std::collections::VecDeque::new();
    let a = run_phase(
        &args,
        "(a) hand-eye stations",
        stations_path,
        frames,
        Law {
            measure_only: true,
            compensate: true,
        },
        &nominal_he,
        &args.out.join("poses-stations.jsonl"),
        |l, v| {
            // A message carries the newest RIst when it is sent, later than
            // its frame's exposure: pair each frame with the robot's RIst
            // read at or just before its exposure instead (the reading's
            // instant is the sending time minus its age), so a frame taken
            // while the robot still moved never joins a still station.
            if let (Some(r), Some(sent)) = (&l.robot, v["time"]["sent_utc_ns"].as_f64()) {
                let t = sent / 1e9 - r.age_ms / 1e3;
                if readings.back().is_none_or(|b: &(f64, [f64; 6])| t > b.0) {
                    readings.push_back((t, r.xyzabc_mm_deg));
                }
                while readings.len() > 4096 {
                    readings.pop_front();
                }
            }
            let Some(mut s) = sample(l) else { return };
            let Some((_, robot)) = readings.iter().rev().find(|(t, _)| *t <= s.time_s) else {
                return;
            };
            s.robot_xyzabc = *robot;
            if let Some(row) = gatherer.push(s) {
                if let Some(st) = row.to_station([0.01, 0.01, 0.01, 0.001, 0.001, 0.001]) {
                    stations.push(st);
                }
                rows.push(row);
            }
        },
    )?;
    let mut csv = String::from(photopose_handeye::STATIONS_HEADER);
    csv.push('\n');
    for r in &rows {
        csv.push_str(&r.csv_line()?);
        csv.push('\n');
    }
    std::fs::write(args.out.join("stations.csv"), csv)?;
    let he = solve(&stations, &HandEyeOptions::default()).with_context(|| {
        format!(
            "hand-eye from {} stations gathered from the stream ({} frames, {} poses)",
            stations.len(),
            a.frames_in,
            a.ok
        )
    })?;
    let he_path = args.out.join("hand-eye.toml");
    let file = hand_eye_file(&he);
    photopose_formats::hand_eye::save_hand_eye(&he_path, &file)?;
    // Within 3σ of the truth in all 12 unknowns (X then Z, X Y Z A B C).
    let truth12: Vec<f64> = CameraMount::DEFAULT_XYZABC
        .iter()
        .chain([0.0; 6].iter())
        .copied()
        .collect();
    let est12: Vec<f64> = file
        .camera_in_tcp
        .xyzabc
        .iter()
        .chain(file.plate_in_base.xyzabc.iter())
        .copied()
        .collect();
    let std12: Vec<f64> = file
        .camera_in_tcp
        .std_xyzabc
        .iter()
        .chain(file.plate_in_base.std_xyzabc.iter())
        .copied()
        .collect();
    let z_scores: Vec<f64> = (0..12)
        .map(|k| {
            let d = est12[k] - truth12[k];
            let d = if k % 6 >= 3 { wrap_deg(d) } else { d };
            d.abs() / std12[k].max(1e-12)
        })
        .collect();
    let within = z_scores.iter().all(|z| *z <= 3.0);
    outln!(
        "(a) hand-eye: {} stations gathered from the stream ({} frames), σ0 {:.2}; camera in TCP {} (truth {}); \
         plate in base {}; largest |estimate − truth| / σ = {:.2}: {} 3σ",
        stations.len(),
        a.frames_in,
        he.sigma0,
        f6(file.camera_in_tcp.xyzabc),
        f6(CameraMount::DEFAULT_XYZABC),
        f6(file.plate_in_base.xyzabc),
        z_scores.iter().copied().fold(0.0, f64::max),
        if within { "within" } else { "NOT within" }
    )?;

    // (b), (c), (d): the circle, with a lead-in of an eighth of a turn that
    // the report leaves out (the corrections settle there).
    let lead_in = 0.125;
    let lap = CirclePath {
        revolutions: 1.0 + lead_in,
        ..circle
    };
    let frames = (lap.duration_s() * args.rate).ceil() as u64;
    let first = (circle.duration_s() * lead_in * args.rate).ceil() as u64;
    let nominal = NominalCircle {
        center_mm: circle.center_mm,
        radius_mm: circle.radius_mm,
    };
    let phases = [
        ("(b) measure-only", "measure-only", true, true),
        ("(c) corrected", "corrected", false, true),
        (
            "(d) corrected, no latency compensation",
            "uncompensated",
            false,
            false,
        ),
    ];
    let mut figures = Vec::new();
    for (label, name, measure_only, compensate) in phases {
        let run = run_phase(
            &args,
            label,
            CellPath::circle(lap, error.clone()),
            frames,
            Law {
                measure_only,
                compensate,
            },
            &he_path,
            &args.out.join(format!("poses-{name}.jsonl")),
            |_, _| {},
        )?;
        let f = circle_figures(&run, first, nominal, &he)
            .with_context(|| format!("{label}: {} poses of {} frames", run.ok, run.frames_in))?;
        outln!(
            "{label}: {} frames, {} poses; TCP F measured {:.1} µm, true {:.1} µm (G measured {:.1} µm, true {:.1} µm); \
             controller {} cycles, {} late, max step {:.4} mm, max total {:.4} mm",
            run.frames_in,
            run.ok,
            span_um(&f.measured),
            f.truth_f_um,
            f.measured.g_um,
            f.truth_g_um,
            run.report.cycles,
            run.report.late,
            run.report.max_step[..3].iter().copied().fold(0.0, f64::max),
            run.report.max_total[..3].iter().copied().fold(0.0, f64::max),
        )?;
        let dir = args.out.join(name);
        std::fs::create_dir_all(&dir)?;
        let mut text =
            photopose_circle::report::text(&format!("{label}: the TCP as measured"), &f.measured);
        if let Some(t) = &f.truth {
            text.push('\n');
            text.push_str(&photopose_circle::report::text(
                &format!("{label}: the TCP's truth (simulation)"),
                t,
            ));
        }
        std::fs::write(dir.join("report.txt"), text)?;
        figures.push(f);
    }
    // Plots: measure-only and corrected overlaid.
    let (b, c) = (&figures[0], &figures[1]);
    std::fs::write(
        args.out.join("radial.svg"),
        photopose_circle::plot::radial_overlay_svg(
            &[(&b.measured, "measure-only"), (&c.measured, "corrected")],
            "Radial deviation of the TCP as measured: measure-only and corrected",
        ),
    )?;
    if let (Some(bt), Some(ct)) = (&b.truth, &c.truth) {
        std::fs::write(
            args.out.join("radial-truth.svg"),
            photopose_circle::plot::radial_overlay_svg(
                &[(bt, "measure-only"), (ct, "corrected")],
                "Radial deviation of the true TCP (simulation): measure-only and corrected",
            ),
        )?;
    }
    let f = |k: usize, m: bool| {
        if m {
            span_um(&figures[k].measured)
        } else {
            figures[k].truth_f_um
        }
    };
    outln!(
        "\nTCP circular deviation F (µm)   measured   true\n  (b) measure-only            {:8.1} {:8.1}\n  (c) corrected               {:8.1} {:8.1}\n  (d) no latency compensation {:8.1} {:8.1}\n\
         corrected / measure-only (true): {:.0} %; injected F {:.1} µm; {:.0} s in all\nwritten to {}",
        f(0, true),
        f(0, false),
        f(1, true),
        f(1, false),
        f(2, true),
        f(2, false),
        100.0 * f(1, false) / f(0, false),
        error.radial_f_mm() * 1000.0,
        started.elapsed().as_secs_f64(),
        args.out.display()
    )?;
    if args.json {
        let v = serde_json::json!({
            "f_true_measure_only_um": f(0, false),
            "f_true_corrected_um": f(1, false),
            "f_true_uncompensated_um": f(2, false),
            "f_measured_measure_only_um": f(0, true),
            "f_measured_corrected_um": f(1, true),
            "f_measured_uncompensated_um": f(2, true),
            "g_measured_measure_only_um": figures[0].measured.g_um,
            "g_measured_corrected_um": figures[1].measured.g_um,
            "g_measured_uncompensated_um": figures[2].measured.g_um,
            "injected_f_um": error.radial_f_mm() * 1000.0,
            "hand_eye_within_3sigma": within,
            "hand_eye_max_z": z_scores.iter().copied().fold(0.0, f64::max),
            "hand_eye_sigma0": he.sigma0,
            "hand_eye_camera_in_tcp_xyzabc": file.camera_in_tcp.xyzabc,
            "hand_eye_plate_in_base_xyzabc": file.plate_in_base.xyzabc,
            "stations": stations.len(),
            "feed_mm_s": args.feed,
            "radius_mm": args.radius_mm,
            "rate_hz": args.rate,
            "exposure_ms": args.exposure_ms,
            "transfer_ms": args.transfer_ms,
        });
        outln!("{v}")?;
    }
    Ok(ExitCode::SUCCESS)
}
