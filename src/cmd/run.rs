//! `photopose run --config FILE`: the daemon. Starts the pipeline of the
//! configuration, logs one line per event (no per-frame lines; a summary
//! every 10 s), stops cleanly on SIGTERM or SIGINT: the grabber stops,
//! queued frames are finished, streams flushed, exit 0.

use crate::cmd::defaults;
use anyhow::{Context, Result};
use clap::Parser;
use photopose_pipeline::run::Wedge;
use photopose_pipeline::{Config, Pipeline, Supervision};
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
    /// Stop after this many frames, whatever the source.
    #[arg(long)]
    pub frames: Option<u64>,
    /// Print the histogram of the frame-to-pose latency at the end.
    #[arg(long)]
    pub latency_histogram: bool,
    /// Record frames and poses into this MCAP file (`[record] path`; the
    /// other `[record]` keys apply).
    #[arg(long)]
    pub record: Option<PathBuf>,
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

/// Everything `run` needs before it starts a thread, validated exactly as
/// `check-config` validates it: the configuration, the camera and field
/// files, the hand-eye file, the source (a replay's recording is opened and
/// checked), and the warnings of the combination.
pub struct Prepared {
    /// The configuration.
    pub config: Config,
    /// The camera.
    pub camera: photopose_geometry::Camera,
    /// The test field.
    pub field: photopose_field::Field,
    /// The configured frame source, constructed (not started).
    pub source: Box<dyn photopose_pipeline::FrameSource>,
    /// What is valid but probably not meant (printed by both commands;
    /// `check-config --strict` refuses them).
    pub warnings: Vec<String>,
}

/// Loads and validates `path` (or the built-in configuration) with every
/// file it names; `frames` overrides the frame count of the source.
pub fn prepare(path: Option<&std::path::Path>, frames: Option<u64>) -> Result<Prepared> {
    let mut prepared = prepare_config(load(path)?)?;
    if let Some(n) = frames {
        prepared.source = photopose_pipeline::source::limit(prepared.source, n);
    }
    Ok(prepared)
}

/// [`prepare`] for a configuration already loaded.
pub fn prepare_config(config: Config) -> Result<Prepared> {
    let camera = defaults::camera(config.camera_file.as_deref()).context("camera.camera_file")?;
    let field = defaults::field(config.field_file.as_deref()).context("camera.field_file")?;
    let mut warnings = Vec::new();
    if let Some(rsi) = &config.rsi {
        photopose_formats::hand_eye::load_hand_eye(&rsi.hand_eye).context("rsi.hand_eye")?;
        warnings.extend(rsi.settings.warnings.iter().map(|w| format!("rsi: {w}")));
    }
    let source = photopose_pipeline::source::open(&config.source, &camera, &field)?;
    Ok(Prepared {
        config,
        camera,
        field,
        source,
        warnings,
    })
}

/// The signals the daemon handles, installed before anything else is done
/// so that a signal during start-up is handled too: SIGTERM and SIGINT
/// stop cleanly (exit 0), SIGHUP reloads the configuration.
struct Signals {
    stop: Arc<AtomicBool>,
    reload: Arc<AtomicBool>,
}

impl Signals {
    fn install() -> Result<Signals> {
        let stop = Arc::new(AtomicBool::new(false));
        let reload = Arc::new(AtomicBool::new(false));
        for sig in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
            signal_hook::flag::register(sig, stop.clone())
                .context("cannot install signal handlers")?;
        }
        signal_hook::flag::register(signal_hook::consts::SIGHUP, reload.clone())
            .context("cannot install the SIGHUP handler")?;
        Ok(Signals { stop, reload })
    }

    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }
}

/// What a recording stores besides the messages: the camera, field and
/// configuration files (the built-in ones when none is named) as
/// attachments, and the version, host, start time and source as metadata.
pub fn record_options(
    config: &Config,
    config_file: Option<&std::path::Path>,
    source: &str,
) -> Result<photopose_record::RecordOptions> {
    use photopose_record::Attachment;
    let file = |path: Option<&std::path::Path>, builtin: &str, name: &str, media: &str| {
        let (name, data) = match path {
            Some(p) => (
                p.file_name()
                    .map_or(name.to_string(), |n| n.to_string_lossy().into_owned()),
                std::fs::read(p).with_context(|| format!("cannot read {}", p.display()))?,
            ),
            None => (name.to_string(), builtin.as_bytes().to_vec()),
        };
        anyhow::Ok(Attachment {
            name,
            media_type: media.into(),
            data,
        })
    };
    let attachments = vec![
        file(
            config.camera_file.as_deref(),
            photopose_formats::camera::DEFAULT_CAMERA_TOML,
            "camera.toml",
            "application/toml",
        )?,
        file(
            config.field_file.as_deref(),
            defaults::PLATE_CSV,
            "plate.csv",
            "text/csv",
        )?,
        file(
            config_file,
            DEFAULT_CONFIG,
            "photopose.toml",
            "application/toml",
        )?,
    ];
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_else(|_| "unknown".into());
    let start_ns = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    let metadata = [
        ("version", env!("CARGO_PKG_VERSION").to_string()),
        ("host", host),
        ("start_utc_ns", start_ns.to_string()),
        ("camera_id", config.camera_id.clone()),
        ("source", source.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    Ok(photopose_record::RecordOptions {
        compression: config.record.compression,
        attachments,
        metadata,
    })
}

/// Starts the recording `config.record` names (if any): the writer thread,
/// the frame tap around `source`; the link goes into the configuration for
/// the sink. `segment` > 0 (a reload) writes `FILE-N.mcap` instead of
/// `FILE.mcap`, the first N whose file does not exist.
fn start_recording(
    config: &mut Config,
    config_file: Option<&std::path::Path>,
    camera: &photopose_geometry::Camera,
    source: Box<dyn photopose_pipeline::FrameSource>,
    reloaded: bool,
) -> Result<Box<dyn photopose_pipeline::FrameSource>> {
    use photopose_pipeline::sink::record::{segment_path, RecordLink};
    let Some(path) = config.record.path.clone() else {
        return Ok(source);
    };
    if reloaded {
        let free = (1..)
            .map(|n| segment_path(&path, n))
            .find(|p| !p.exists())
            .expect("some segment name is free");
        config.record.path = Some(free);
    }
    let options = record_options(config, config_file, &source.describe())?;
    let frame_bytes = camera.sensor.width as usize * camera.sensor.height as usize;
    let link = RecordLink::start(&config.record, options, frame_bytes)
        .context("cannot start the recording")?;
    let source = link.tap(source, &config.record);
    config.record.link = Some(link);
    Ok(source)
}

/// Starts the pipeline of a prepared configuration.
fn start(
    prepared: Prepared,
    wedge: Option<Wedge>,
    config_file: Option<&std::path::Path>,
    reloaded: bool,
) -> Result<(Pipeline, Config)> {
    for w in &prepared.warnings {
        tracing::warn!("{w}");
    }
    let Prepared {
        mut config,
        camera,
        field,
        source,
        ..
    } = prepared;
    let source = start_recording(&mut config, config_file, &camera, source, reloaded)?;
    let supervision = Supervision {
        wedge,
        ..Supervision::from_env()
    };
    let pipeline = Pipeline::start_supervised(&config, camera, field, source, supervision)
        .context("cannot start the pipeline")?;
    tracing::info!(
        workers = config.workers,
        slots = config.slots,
        udp = %config
            .udp
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", "),
        tcp = %pipeline
            .tcp_addr()
            .map_or_else(|| "off".to_string(), |a| a.to_string()),
        "photopose running"
    );
    Ok((pipeline, config))
}

/// Runs the daemon until a signal or the end of the source; SIGHUP
/// re-reads the configuration and restarts the pipeline with it, or keeps
/// the running one when the new one does not validate.
pub fn run(args: Args) -> Result<ExitCode> {
    let signals = Signals::install()?;
    let notifier = photopose_pipeline::notify::Notifier::from_env();
    // Fault injection for the watchdog's tests (never set in service).
    let wedge = std::env::var("PHOTOPOSE_TEST_WEDGE")
        .ok()
        .and_then(|w| Wedge::parse(&w));
    let mut prepared = prepare(args.config.as_deref(), args.frames)?;
    if let Some(r) = &args.record {
        prepared.config.record.path = Some(r.clone());
    }
    if signals.stopping() {
        tracing::info!("signal received during start-up: stopping");
        return Ok(ExitCode::SUCCESS);
    }
    let (mut pipeline, mut config) = start(prepared, wedge, args.config.as_deref(), false)?;
    notifier.notify("READY=1");
    let mut pipeline_started = Instant::now();
    let mut last_report = Instant::now();
    while !signals.stopping() && !pipeline.finished() {
        std::thread::sleep(Duration::from_millis(50));
        if signals.reload.swap(false, Ordering::AcqRel) {
            (pipeline, config) = reload(pipeline, config, &args, &notifier, wedge)?;
            pipeline_started = Instant::now();
        }
        if last_report.elapsed() >= Duration::from_secs(10) {
            let c = pipeline.counters();
            tracing::info!(
                frames_in = c.frames_in.get(),
                dropped = c.frames_dropped.get(),
                poses_ok = c.poses_ok.get(),
                poses_failed = c.poses_failed.get(),
                "pipeline progress"
            );
            last_report = Instant::now();
        }
    }
    if signals.stopping() {
        tracing::info!("signal received: stopping");
    }
    notifier.notify("STOPPING=1");
    pipeline.stop();
    let started = pipeline_started;
    let c = pipeline.join();
    summary(&c, started.elapsed().as_secs_f64(), args.latency_histogram);
    record_summary(&config);
    Ok(ExitCode::SUCCESS)
}

/// SIGHUP: validates the configuration file again; a valid one replaces
/// the running pipeline, an invalid one is logged and the running pipeline
/// kept. A new pipeline that cannot start (an address taken, …) is
/// replaced by the previous configuration again.
fn reload(
    running: Pipeline,
    current: Config,
    args: &Args,
    notifier: &photopose_pipeline::notify::Notifier,
    wedge: Option<Wedge>,
) -> Result<(Pipeline, Config)> {
    let Some(path) = args.config.as_deref() else {
        tracing::info!("SIGHUP: running the built-in configuration; nothing to re-read");
        return Ok((running, current));
    };
    notifier.notify("RELOADING=1");
    let prepared = match prepare(Some(path), args.frames) {
        Ok(mut p) => {
            if let Some(r) = &args.record {
                p.config.record.path = Some(r.clone());
            }
            p
        }
        Err(e) => {
            tracing::error!("reload refused, keeping the running configuration: {e:#}");
            notifier.notify("READY=1");
            return Ok((running, current));
        }
    };
    tracing::info!(config = %path.display(), "reloading: restarting the pipeline");
    running.stop();
    let old = running.join();
    tracing::info!(poses_ok = old.poses_ok.get(), "previous pipeline stopped");
    record_summary(&current);
    let started = match start(prepared, wedge, Some(path), true) {
        Ok(started) => {
            tracing::info!(config = %path.display(), "configuration reloaded");
            started
        }
        Err(e) => {
            tracing::error!(
                "the reloaded configuration did not start ({e:#}); back to the previous one"
            );
            let mut previous = current;
            previous.record.link = None;
            start(prepare_config(previous)?, wedge, Some(path), true)?
        }
    };
    notifier.notify("READY=1");
    Ok(started)
}

/// The closing figures of the recording, if one ran (closed here if the
/// pipeline did not).
fn record_summary(config: &Config) {
    let Some(link) = &config.record.link else {
        return;
    };
    link.close();
    let s = link.stats();
    let n = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed);
    let (frames, bytes, pixels) = (n(&s.frames), n(&s.bytes), n(&s.pixel_bytes));
    println!(
        "recording {}: {} frames ({} dropped), {} poses ({} dropped), {} files, {} bytes; {:.0} bytes per frame, compression ratio {:.2}",
        link.path().display(),
        frames,
        n(&s.frames_dropped),
        n(&s.poses),
        n(&s.poses_dropped),
        n(&s.files),
        bytes,
        bytes as f64 / frames.max(1) as f64,
        pixels as f64 / bytes.max(1) as f64,
    );
    tracing::info!(
        path = %link.path().display(),
        frames,
        frames_dropped = n(&s.frames_dropped),
        poses = n(&s.poses),
        poses_dropped = n(&s.poses_dropped),
        bytes,
        "recording stopped"
    );
}

/// The closing figures of a run.
fn summary(c: &photopose_pipeline::Counters, secs: f64, histogram: bool) {
    let ok = c.poses_ok.get();
    let done = ok + c.poses_failed.get();
    let q = |p: f64| c.latency_quantile_us(p).map_or(f64::NAN, |us| us / 1000.0);
    println!(
        "latency (frame handed over → pose sent): p50 {:.2} ms, p99 {:.2} ms, p99.9 {:.2} ms",
        q(0.5),
        q(0.99),
        q(0.999)
    );
    println!(
        "{} frames in, {} dropped, {} poses ({} ok) in {:.1} s ({:.1} poses/s), mean latency {:.2} ms",
        c.frames_in.get(),
        c.frames_dropped.get(),
        done,
        ok,
        secs,
        done as f64 / secs.max(1e-9),
        c.latency.sum_seconds() / done.max(1) as f64 * 1000.0
    );
    if histogram {
        print_histogram(c);
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
        frames_in = c.frames_in.get(),
        dropped = c.frames_dropped.get(),
        poses_ok = c.poses_ok.get(),
        "photopose stopped"
    );
}

/// Prints the non-empty buckets of the latency histogram (upper edges,
/// eight buckets per octave) with a bar each.
fn print_histogram(c: &photopose_pipeline::Counters) {
    let buckets: Vec<(f64, u64)> = c.latency.nonempty_buckets().collect();
    let total: u64 = buckets.iter().map(|b| b.1).sum();
    let most = buckets.iter().map(|b| b.1).max().unwrap_or(1).max(1);
    if total == 0 {
        return;
    }
    println!("latency histogram (frame handed over → pose sent):");
    let mut below = 0u64;
    for (edge_s, n) in buckets {
        below += n;
        println!(
            "  ≤ {:>9.3} ms {:>8} {:>6.2} % {}",
            edge_s * 1000.0,
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
    /// Warnings are errors (exit 2).
    #[arg(long)]
    pub strict: bool,
}

/// Checks a configuration exactly as `run` does before it starts (every
/// file it names opened and parsed, every warning printed).
pub fn check(args: CheckArgs) -> Result<ExitCode> {
    let prepared =
        prepare(Some(&args.file), None).with_context(|| format!("{}", args.file.display()))?;
    for w in &prepared.warnings {
        eprintln!("photopose: warning: {}: {w}", args.file.display());
    }
    if args.strict && !prepared.warnings.is_empty() {
        eprintln!(
            "photopose: error: {}: {} warning(s) and --strict",
            args.file.display(),
            prepared.warnings.len()
        );
        return Ok(ExitCode::from(2));
    }
    println!("{}: ok", args.file.display());
    Ok(ExitCode::SUCCESS)
}
