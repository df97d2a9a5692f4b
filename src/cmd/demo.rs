//! `photopose demo`: the whole chain on the simulated robot cell, no
//! hardware. The cell (`photopose_circle::cell`: a circle of 149.9 mm
//! radius at constant orientation, a robot with an injected radial
//! deviation pattern and orientation wobble, the camera 100 mm from the
//! TCP looking down at the default plate) gives the camera's actual pose
//! frame by frame; the daemon's pipeline renders each frame (synthetic
//! source), detects, identifies and resects it, and streams the poses over
//! UDP and TCP; the RSI server answers the project's simulated KUKA
//! controller every 4 ms (measure-only: the circle is measured, not
//! corrected). Live progress goes to the terminal; at the end the ISO
//! 230-4 circular test of the streamed poses (transformed to the TCP with
//! the mount) is written to a folder with its plots.

use crate::cmd::circle_test::{evaluate, read_hand_eye, read_poses, write_outputs};
use anyhow::{bail, Context, Result};
use clap::Parser;
use photopose_circle::cell::Cell;
use photopose_pipeline::config::Source;
use photopose_pipeline::source::SyntheticSource;
use photopose_pipeline::{Config, Pipeline};
use photopose_rsi::controller::{SimConfig, SimController};
use photopose_rsi::server::RsiClock;
use std::io::{IsTerminal, Write};
use std::net::UdpSocket;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Arguments of `photopose demo`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Folder for the pose stream, the report and the plots.
    #[arg(long, default_value = "photopose-demo")]
    pub out: PathBuf,
    /// Feed along the circle, mm/s (the reference experiment ran 10 mm/s;
    /// 40 mm/s keeps the demo under half a minute).
    #[arg(long, default_value_t = 40.0)]
    pub feed: f64,
    /// Camera frame rate, frames/s.
    #[arg(long, default_value_t = 25.0)]
    pub rate: f64,
}

/// A free UDP port on the loopback (for the RSI server).
fn free_udp_port() -> Result<u16> {
    Ok(UdpSocket::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// Runs the demo.
pub fn run(args: Args) -> Result<ExitCode> {
    if !(args.feed.is_finite() && (1.0..=500.0).contains(&args.feed)) {
        bail!("--feed {}: must be in [1, 500] mm/s", args.feed);
    }
    if !(args.rate.is_finite() && (1.0..=200.0).contains(&args.rate)) {
        bail!("--rate {}: must be in [1, 200] frames/s", args.rate);
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut cell = Cell::default();
    cell.path.feed_mm_s = args.feed;
    cell.path.rate_hz = args.rate;
    let samples = cell.samples().context("the simulated cell")?;
    let frames = samples.len();

    // The mount is the hand-eye transform; the plate's pose in the robot
    // base is the cell's (the plate frame is the base frame here).
    let hand_eye = args.out.join("hand-eye.toml");
    let x = photopose_geometry::pose::xyzabc_from_isometry(&cell.mount.camera_in_tcp);
    let f = |v: [f64; 6]| {
        v.iter()
            .map(|x| format!("{x:.6}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    std::fs::write(
        &hand_eye,
        format!(
            "# photopose demo: the simulated cell's camera mount\n\
             [camera_in_tcp]\nxyzabc = [{}]\nstd_xyzabc = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n\n\
             [plate_in_base]\nxyzabc = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\nstd_xyzabc = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n",
            f(x)
        ),
    )
    .with_context(|| format!("cannot write {}", hand_eye.display()))?;

    let poses_rx = UdpSocket::bind("127.0.0.1:0").context("cannot bind the demo's UDP socket")?;
    poses_rx.set_read_timeout(Some(Duration::from_millis(100)))?;
    let rsi_port = free_udp_port()?;
    let config = Config::parse(
        &format!(
            "[source]\nkind = \"synthetic\"\n[source.synthetic]\nrate_hz = {rate}\nnoise_dn = 2.0\nblur_px = 0.6\nseed = 1\n\
             [pipeline]\nworkers = 2\nslots = 8\noverflow = \"block\"\nmax_age_ms = 500.0\n\
             [output]\nudp = [\"{udp}\"]\ntcp_listen = \"127.0.0.1:0\"\n\
             [rsi]\nenabled = true\nbind = \"127.0.0.1\"\nport = {rsi_port}\ncontrollers = [\"127.0.0.1\"]\n\
             measure_only = true\nhand_eye = \"{he}\"\n",
            rate = args.rate,
            udp = poses_rx.local_addr()?,
            he = hand_eye.display()
        ),
        "<demo configuration>",
    )?;
    let Source::Synthetic(synthetic) = config.source.clone() else {
        bail!("the demo configuration has no synthetic source")
    };
    let camera = photopose_formats::default_camera();
    let field = photopose_field::design::default_plate();
    let source = SyntheticSource::along(
        camera,
        &field,
        synthetic,
        samples.iter().map(|s| s.exterior()).collect(),
    )
    .context("synthetic source")?;
    outln!(
        "photopose demo: circle of {:.1} mm at {} mm/s, {} frames at {} frames/s over the default plate; \
         injected radial deviation F = {:.1} µm",
        cell.path.radius_mm,
        args.feed,
        frames,
        args.rate,
        cell.error.radial_f_mm() * 1000.0
    )?;
    let pipeline = Pipeline::start(&config, camera, field, Box::new(source))
        .context("cannot start the pipeline")?;
    let rsi_addr = pipeline
        .rsi_addr()
        .context("the RSI server did not start")?;
    if let Some(tcp) = pipeline.tcp_addr() {
        outln!(
            "poses: TCP JSON lines on {tcp} (nc {} {}), RSI server on {rsi_addr}",
            tcp.ip(),
            tcp.port()
        )?;
    }
    let cycle = Duration::from_millis(4);
    let cycles = (frames as f64 / args.rate / cycle.as_secs_f64()).ceil() as u64;
    let controller = SimController::spawn(
        SimConfig {
            cycles,
            timeout: 100,
            ..SimConfig::new(rsi_addr)
        },
        RsiClock::new(),
    )
    .context("cannot start the simulated controller")?;

    // The pose stream, written as it arrives, with live progress.
    let stream_path = args.out.join("poses.jsonl");
    let mut stream = std::io::BufWriter::new(
        std::fs::File::create(&stream_path)
            .with_context(|| format!("cannot create {}", stream_path.display()))?,
    );
    let terminal = std::io::stdout().is_terminal();
    let started = Instant::now();
    let mut last_print = Instant::now();
    let (mut received, mut ok) = (0usize, 0usize);
    let mut buf = [0u8; 4096];
    let mut last: Option<serde_json::Value> = None;
    while ok < frames {
        let finished = pipeline.finished();
        match poses_rx.recv(&mut buf) {
            Ok(n) => {
                stream.write_all(&buf[..n])?;
                let v: serde_json::Value =
                    serde_json::from_slice(&buf[..n]).context("a pose message that is not JSON")?;
                if v["status"] != "stale" {
                    received += 1;
                }
                if v["status"] == "ok" {
                    ok += 1;
                    last = Some(v);
                }
            }
            Err(_) if finished => break,
            Err(_) => {}
        }
        if last_print.elapsed() >= Duration::from_millis(if terminal { 250 } else { 5000 }) {
            last_print = Instant::now();
            let c = pipeline.counters();
            let p50 = c.latency_quantile_us(0.5).unwrap_or(f64::NAN) / 1000.0;
            let rsi = c.rsi.as_ref().map(|r| r.snapshot());
            let pose = last.as_ref().map_or(String::from("-"), |v| {
                let n = |k: &str, i: usize| v["pose"][k][i].as_f64().unwrap_or(f64::NAN);
                format!(
                    "centre ({:8.3} {:8.3} {:7.3}) ± ({:.3} {:.3} {:.3}) mm, {} targets",
                    n("position_mm", 0),
                    n("position_mm", 1),
                    n("position_mm", 2),
                    n("std_position_mm", 0),
                    n("std_position_mm", 1),
                    n("std_position_mm", 2),
                    v["pose"]["n_targets"]
                )
            });
            let line = format!(
                "frames {received:>4}/{frames}  {:5.1} frames/s  latency p50 {p50:4.1} ms  {pose}  RSI {} cycles, Delay {}",
                received as f64 / started.elapsed().as_secs_f64(),
                rsi.as_ref().map_or(0, |s| s.cycles),
                rsi.as_ref().map_or(0, |s| s.delay_last),
            );
            if terminal {
                out!("\r{line}\x1b[K")?;
                std::io::stdout().flush()?;
            } else {
                outln!("{line}")?;
            }
        }
    }
    if terminal {
        outln!()?;
    }
    stream.flush()?;
    drop(stream);
    pipeline.stop();
    let counters = pipeline.join();
    let sim = controller.stop().context("the simulated controller")?;
    let secs = started.elapsed().as_secs_f64();
    outln!(
        "{} frames in {:.1} s: {} poses ok, {} dropped; latency p50 {:.2} ms, p99 {:.2} ms",
        counters.frames_in.get(),
        secs,
        counters.poses_ok.get(),
        counters.frames_dropped.get(),
        counters.latency_quantile_us(0.5).unwrap_or(f64::NAN) / 1000.0,
        counters.latency_quantile_us(0.99).unwrap_or(f64::NAN) / 1000.0
    )?;
    if let Some(r) = counters.rsi.as_ref().map(|r| r.snapshot()) {
        outln!(
            "RSI: {} cycles answered of {} sent by the simulated controller, {} late, {} mismatched; \
             reply latency p99 {} µs (measure-only: zero correction)",
            r.replies,
            sim.cycles,
            sim.late,
            sim.mismatched,
            r.latency_p99_us.map_or("-".into(), |v| format!("{v:.0}"))
        )?;
    }

    // The circular test of the recorded stream, as `photopose circle-test`.
    let mut poses = Vec::new();
    let inputs = vec![read_poses(&stream_path, &mut poses)?];
    if poses.len() < 10 {
        bail!(
            "only {} poses in {}: too few for a circular test",
            poses.len(),
            stream_path.display()
        );
    }
    let he = read_hand_eye(&hand_eye)?;
    let out = evaluate(&poses, &inputs, Some(&he), 15, 25.0)?;
    let written = write_outputs(&args.out, &out)?;
    outln!("\n{}", out.text)?;
    let report: serde_json::Value = serde_json::from_str(&out.json)?;
    outln!(
        "injected F = {:.1} µm, measured at the TCP G = {:.1} µm (filtered {:.1} µm)",
        cell.error.radial_f_mm() * 1000.0,
        report["tcp"]["g_um"].as_f64().unwrap_or(f64::NAN),
        report["tcp"]["g_filtered_um"].as_f64().unwrap_or(f64::NAN)
    )?;
    outln!(
        "written to {}: {}, poses.jsonl, hand-eye.toml",
        args.out.display(),
        written
            .iter()
            .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .collect::<Vec<_>>()
            .join(", ")
    )?;
    Ok(ExitCode::SUCCESS)
}
