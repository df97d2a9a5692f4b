//! `photopose run --config FILE`: the daemon. Starts the pipeline of the
//! configuration, logs one line per event (no per-frame lines; a summary
//! every 10 s), stops cleanly on SIGTERM or SIGINT: the grabber stops,
//! queued frames are finished, streams flushed, exit 0.

use crate::cmd::defaults;
use anyhow::{Context, Result};
use clap::Parser;
use photopose_pipeline::config::Source;
use photopose_pipeline::source::{ReplaySource, SyntheticSource};
use photopose_pipeline::{Config, Pipeline};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Arguments of `photopose run`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Configuration file (TOML, see config/photopose.toml); default: the
    /// built-in configuration (synthetic camera over the default plate).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Stop after this many frames of the synthetic source (overrides
    /// `source.synthetic.frames`).
    #[arg(long)]
    pub frames: Option<u64>,
    /// Print the histogram of the frame-to-pose latency at the end.
    #[arg(long)]
    pub latency_histogram: bool,
}

/// The built-in configuration (`config/photopose.toml`).
pub const DEFAULT_CONFIG: &str = include_str!("../../config/photopose.toml");

/// Loads the configuration from `path` or the built-in one.
pub fn load(path: Option<&std::path::Path>) -> Result<Config> {
    Ok(match path {
        Some(p) => Config::load(p)?,
        None => Config::parse(DEFAULT_CONFIG, "<built-in config/photopose.toml>")?,
    })
}

/// The configured frame source.
pub fn open_source(
    config: &Config,
    camera: &photopose_geometry::Camera,
    field: &photopose_field::Field,
) -> Result<Box<dyn photopose_pipeline::FrameSource>> {
    Ok(match &config.source {
        Source::Synthetic(s) => {
            Box::new(SyntheticSource::new(*camera, field, s.clone()).context("synthetic source")?)
        }
        Source::Replay(r) => Box::new(ReplaySource::open(camera, r)?),
        Source::Gige(g) => Box::new(
            photopose_acquire::GigeSource::new("gige", g.clone())
                .context("GigE source: [source.gige]")?,
        ),
    })
}

/// Runs the daemon until a signal or the end of the source.
pub fn run(args: Args) -> Result<ExitCode> {
    let mut config = load(args.config.as_deref())?;
    if let (Some(n), Source::Synthetic(s)) = (args.frames, &mut config.source) {
        s.frames = n;
    }
    let camera = defaults::camera(config.camera_file.as_deref())?;
    let field = defaults::field(config.field_file.as_deref())?;
    let source = open_source(&config, &camera, &field)?;
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
        signal_hook::flag::register(sig, stop.clone()).context("cannot install signal handlers")?;
    }
    let pipeline =
        Pipeline::start(&config, camera, field, source).context("cannot start the pipeline")?;
    let pipeline_started = Instant::now();
    tracing::info!(
        workers = config.workers,
        slots = config.slots,
        udp = ?config.udp,
        tcp = ?pipeline.tcp_addr(),
        "photopose running"
    );
    let mut last_report = Instant::now();
    while !stop.load(Ordering::Acquire) && !pipeline.finished() {
        std::thread::sleep(Duration::from_millis(50));
        if last_report.elapsed() >= Duration::from_secs(10) {
            let c = pipeline.counters();
            tracing::info!(
                frames_in = c.frames_in.load(Ordering::Relaxed),
                dropped = c.frames_dropped.load(Ordering::Relaxed),
                poses_ok = c.poses_ok.load(Ordering::Relaxed),
                poses_failed = c.poses_failed.load(Ordering::Relaxed),
                "pipeline progress"
            );
            last_report = Instant::now();
        }
    }
    if stop.load(Ordering::Acquire) {
        tracing::info!("signal received: stopping");
    }
    pipeline.stop();
    let started = pipeline_started;
    let c = pipeline.join();
    let secs = started.elapsed().as_secs_f64();
    let ok = c.poses_ok.load(Ordering::Relaxed);
    let done = ok + c.poses_failed.load(Ordering::Relaxed);
    let q = |p: f64| c.latency_quantile_us(p).map_or(f64::NAN, |us| us / 1000.0);
    println!(
        "latency (frame handed over → pose sent): p50 {:.2} ms, p99 {:.2} ms, p99.9 {:.2} ms",
        q(0.5),
        q(0.99),
        q(0.999)
    );
    println!(
        "{} frames in, {} dropped, {} poses ({} ok) in {:.1} s ({:.1} poses/s), mean latency {:.2} ms",
        c.frames_in.load(Ordering::Relaxed),
        c.frames_dropped.load(Ordering::Relaxed),
        done,
        ok,
        secs,
        done as f64 / secs.max(1e-9),
        c.latency_us_sum.load(Ordering::Relaxed) as f64 / done.max(1) as f64 / 1000.0
    );
    if args.latency_histogram {
        print_histogram(&c);
    }
    if let Some(rsi) = &c.rsi {
        let s = rsi.snapshot();
        let us = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.0} µs"));
        println!(
            "RSI: {} cycles, {} replies; reply latency (datagram received → reply sent) p50 {}, p99 {}, p99.9 {}, max {:.0} µs; controller Delay max {}",
            s.cycles,
            s.replies,
            us(s.latency_p50_us),
            us(s.latency_p99_us),
            us(s.latency_p999_us),
            s.latency_max_us,
            s.delay_max
        );
    }
    tracing::info!(
        frames_in = c.frames_in.load(Ordering::Relaxed),
        dropped = c.frames_dropped.load(Ordering::Relaxed),
        poses_ok = c.poses_ok.load(Ordering::Relaxed),
        "photopose stopped"
    );
    Ok(ExitCode::SUCCESS)
}

/// Prints the non-empty buckets of the latency histogram (upper edges,
/// eight buckets per octave) with a bar each.
fn print_histogram(c: &photopose_pipeline::Counters) {
    use photopose_pipeline::run::LATENCY_BASE_US;
    let counts: Vec<u64> = c
        .latency_histogram
        .iter()
        .map(|b| b.load(Ordering::Relaxed))
        .collect();
    let total: u64 = counts.iter().sum();
    let (Some(first), Some(last)) = (
        counts.iter().position(|&n| n > 0),
        counts.iter().rposition(|&n| n > 0),
    ) else {
        return;
    };
    let most = counts.iter().copied().max().unwrap_or(1).max(1);
    println!("latency histogram (frame handed over → pose sent):");
    let mut below = 0u64;
    for (k, &n) in counts.iter().enumerate().take(last + 1).skip(first) {
        below += n;
        println!(
            "  ≤ {:>9.3} ms {:>8} {:>6.2} % {}",
            LATENCY_BASE_US * 2f64.powf(k as f64 / 8.0) / 1000.0,
            n,
            100.0 * below as f64 / total as f64,
            "#".repeat((n * 50).div_ceil(most) as usize)
        );
    }
}

/// Arguments of `photopose check-config`.
#[derive(Parser, Debug)]
pub struct CheckArgs {
    /// Configuration file to check.
    pub file: PathBuf,
}

/// Checks a configuration (and the camera and field files it names).
pub fn check(args: CheckArgs) -> Result<ExitCode> {
    let config = Config::load(&args.file)?;
    defaults::camera(config.camera_file.as_deref())?;
    defaults::field(config.field_file.as_deref())?;
    if let Some(rsi) = &config.rsi {
        photopose_formats::hand_eye::load_hand_eye(&rsi.hand_eye)
            .with_context(|| format!("{}: rsi.hand_eye", args.file.display()))?;
    }
    println!("{}: ok", args.file.display());
    Ok(ExitCode::SUCCESS)
}
