//! `photopose record --out FILE.mcap`: records the frames of the configured
//! source alone (with their sequence numbers and timestamps, no poses) into
//! an MCAP file in the standard Foxglove schemas that `source.kind =
//! "replay"` plays back (format: `photopose-record`; the running daemon
//! records with `photopose run --record`).

use crate::cmd::{defaults, run};
use anyhow::{Context, Result};
use clap::Parser;
use photopose_pipeline::config::Source;
use photopose_pipeline::{Slot, SourceError};
use photopose_record::Recorder;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Arguments of `photopose record`.
#[derive(Parser, Debug)]
pub struct Args {
    /// The recording to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Configuration whose source is recorded; default: the built-in one.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Frames to record (the synthetic source otherwise runs until SIGINT).
    #[arg(long)]
    pub frames: Option<u64>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    let mut config = run::load(args.config.as_deref())?;
    if let (Some(n), Source::Synthetic(s)) = (args.frames, &mut config.source) {
        s.frames = n;
    }
    let camera = defaults::camera(config.camera_file.as_deref()).context(run::CAMERA_KEY)?;
    let field = defaults::field(config.field_file.as_deref()).context(run::FIELD_KEY)?;
    let mut source = photopose_pipeline::source::open(&config.source, &camera, &field)?;
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
        signal_hook::flag::register(sig, stop.clone()).context("cannot install signal handlers")?;
    }
    let options = run::record_options(&config, args.config.as_deref(), &source.describe())?;
    let mut recorder = Recorder::create_with(&args.out, &options)?;
    let mut slot = Slot::new(photopose_frame::Image::new_mono8(
        camera.sensor.width,
        camera.sensor.height,
    ));
    source.start().context("cannot start the source")?;
    let bar = crate::cmd::progress::bar(args.frames, "frames recorded");
    let mut n = 0u64;
    while !stop.load(Ordering::Acquire) && args.frames.is_none_or(|max| n < max) {
        match source.next_frame(&mut slot, Duration::from_millis(200)) {
            Ok(()) => {
                recorder.write(slot.meta, slot.image())?;
                n += 1;
                bar.inc(1);
            }
            Err(SourceError::Ended) => break,
            Err(e) if e.is_fatal() => {
                bar.finish_and_clear();
                source.stop();
                recorder.finish()?;
                return Err(e).context("the source failed");
            }
            Err(e @ (SourceError::Lost { .. } | SourceError::Frame { .. })) => {
                bar.suspend(|| tracing::warn!(error = %e, "recording goes on"))
            }
            Err(_) => {}
        }
    }
    bar.finish_and_clear();
    source.stop();
    // Finished even after a signal: the file stays readable.
    recorder.finish()?;
    outln!("{}: {n} frames recorded", args.out.display())?;
    Ok(ExitCode::SUCCESS)
}
