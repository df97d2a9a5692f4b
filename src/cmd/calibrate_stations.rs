//! `photopose calibrate stations --stream HOST:PORT --out STATIONS.csv
//! --count N`: gathers hand-eye stations live from a running daemon. It
//! reads the daemon's TCP pose stream (which carries the robot's `RIst`
//! when the RSI server runs), and each time the robot has stood still long
//! enough (and has moved on since the previous station) it appends a
//! station — the robot pose and the mean camera pose — to the station file
//! that `photopose calibrate hand-eye` reads.
//!
//! While it waits it says why on stderr (a terminal only), rewritten in
//! place: "still 0.4/1.0 s, moved 3.1/5.0 mm, 4/12 stations"; a last line
//! with the stations taken is always printed.

use anyhow::{bail, Context, Result};
use clap::Parser;
use photopose_handeye::gather::{GatherSettings, Gatherer, Sample};
use photopose_handeye::STATIONS_HEADER;
use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Arguments of `photopose calibrate stations`.
#[derive(Parser, Debug)]
pub struct Args {
    /// The daemon's TCP pose stream (`[output] tcp_listen`).
    #[arg(long)]
    pub stream: String,
    /// Station file to write (CSV, `photopose calibrate hand-eye --stations`).
    #[arg(long)]
    pub out: PathBuf,
    /// Stations to gather before stopping.
    #[arg(long, default_value_t = 12)]
    pub count: usize,
    /// Seconds the robot must stand still for a station.
    #[arg(long, default_value_t = 1.0)]
    pub still_s: f64,
    /// Largest robot motion while still, mm.
    #[arg(long, default_value_t = 0.01)]
    pub still_mm: f64,
    /// Largest robot rotation while still, degrees.
    #[arg(long, default_value_t = 0.002)]
    pub still_deg: f64,
    /// Motion away from the previous station before the next one counts, mm.
    #[arg(long, default_value_t = 5.0)]
    pub move_mm: f64,
    /// Rotation away from the previous station before the next one counts, degrees.
    #[arg(long, default_value_t = 2.0)]
    pub move_deg: f64,
    /// Give up after this many seconds.
    #[arg(long, default_value_t = 3600.0)]
    pub timeout_s: f64,
}

/// The camera pose of an `ok` pose-stream line that carries `RIst`.
pub(crate) fn sample(l: &photopose_stream::PoseLine) -> Option<Sample> {
    if l.has_pose() != Some(true) {
        return None;
    }
    let p = l.pose.as_ref()?;
    let (c, r) = (p.position_mm, p.rotation_field_to_camera);
    let (sc, sr) = (p.std_position_mm?, p.std_rotation_deg?);
    let r = photopose_geometry::Matrix3::from_fn(|i, j| r[i][j]);
    Some(Sample {
        time_s: l.time_utc_ns()? as f64 / 1e9,
        robot_xyzabc: l.robot.as_ref()?.xyzabc_mm_deg,
        camera: photopose_geometry::pose::camera_pose(&photopose_geometry::Exterior::new(
            r,
            photopose_geometry::Vector3::from(c),
        )),
        camera_std: [sc[0], sc[1], sc[2], sr[0], sr[1], sr[2]],
    })
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    if args.count == 0 {
        bail!("--count 0: gather at least one station");
    }
    let settings = GatherSettings {
        still_s: args.still_s,
        still_mm: args.still_mm,
        still_deg: args.still_deg,
        move_mm: args.move_mm,
        move_deg: args.move_deg,
        ..GatherSettings::default()
    };
    for (name, v) in [
        ("--still-s", settings.still_s),
        ("--still-mm", settings.still_mm),
        ("--still-deg", settings.still_deg),
        ("--move-mm", settings.move_mm),
        ("--move-deg", settings.move_deg),
        ("--timeout-s", args.timeout_s),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{name} {v}: must be a positive number");
        }
    }
    let stream = TcpStream::connect(&args.stream)
        .with_context(|| format!("cannot connect to the pose stream {}", args.stream))?;
    stream.set_read_timeout(Some(Duration::from_secs(1)))?;
    let mut out = std::fs::File::create(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    writeln!(out, "{STATIONS_HEADER}")?;
    let mut gatherer = Gatherer::new(settings);
    let status = crate::cmd::progress::status();
    let result = gather(&args, &mut gatherer, stream, &mut out, &status);
    status.finish_and_clear();
    let progress = gatherer.progress();
    eprintln!(
        "photopose: {} of {} stations written to {}",
        progress.taken,
        args.count,
        args.out.display()
    );
    result?;
    outln!("{}: {} stations", args.out.display(), gatherer.taken())?;
    Ok(ExitCode::SUCCESS)
}

/// What the gatherer is waiting for, in words: "still 0.4/1.0 s, moved
/// 3.1/5.0 mm, 4/12 stations".
fn waiting(g: &Gatherer, s: &GatherSettings, count: usize, lines: u64) -> String {
    let p = g.progress();
    let moved = match p.moved {
        Some((mm, deg)) => format!(
            "moved {mm:.1}/{:.1} mm {deg:.1}/{:.1}° (waiting for the robot to move on)",
            s.move_mm, s.move_deg
        ),
        None => "next station armed".to_string(),
    };
    format!(
        "still {:.1}/{:.1} s, {moved}, {}/{count} stations, {lines} pose lines",
        p.still_s, s.still_s, p.taken
    )
}

/// Reads the stream until `args.count` stations are written, the stream
/// closes or the time is up.
fn gather(
    args: &Args,
    gatherer: &mut Gatherer,
    stream: TcpStream,
    out: &mut std::fs::File,
    status: &indicatif::ProgressBar,
) -> Result<()> {
    let settings = *gatherer.settings();
    let (mut lines, mut without_robot) = (0u64, 0u64);
    let started = Instant::now();
    let mut reader = BufReader::new(stream);
    let mut line = String::new();
    while gatherer.taken() < args.count {
        status.set_message(waiting(gatherer, &settings, args.count, lines));
        if started.elapsed().as_secs_f64() > args.timeout_s {
            bail!(
                "{} of {} stations after {} s ({lines} pose lines, {without_robot} ok without RIst: is [rsi] enabled and the controller sending RIst?)",
                gatherer.taken(),
                args.count,
                args.timeout_s
            );
        }
        line.clear();
        match reader.read_line(&mut line) {
            Ok(0) => bail!(
                "the pose stream {} closed after {} of {} stations",
                args.stream,
                gatherer.taken(),
                args.count
            ),
            Ok(_) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                continue
            }
            Err(e) => return Err(e).context("reading the pose stream"),
        }
        lines += 1;
        let v = photopose_stream::PoseLine::parse(line.trim())
            .with_context(|| format!("pose stream line {lines} is not a pose message"))?;
        let Some(s) = sample(&v) else {
            if v.has_pose() == Some(true) {
                without_robot += 1;
            }
            continue;
        };
        if let Some(row) = gatherer.push(s) {
            writeln!(out, "{}", row.csv_line()?)?;
            out.flush()?;
            let [x, y, z, a, b, c] = row.robot_xyzabc;
            status.suspend(|| {
                outln!(
                    "station {} of {}: robot X {x:.3} Y {y:.3} Z {z:.3} mm, A {a:.4} B {b:.4} C {c:.4} deg",
                    row.name,
                    args.count
                )
            })?;
        }
    }
    Ok(())
}
