//! `photopose record --out FILE.mcap`: records the frames of the configured
//! source (with their sequence numbers and timestamps) into an MCAP file
//! that `source.kind = "replay"` plays back (format: `photopose-record`).

use crate::cmd::{defaults, run};
use anyhow::{Context, Result};
use clap::Parser;
use photopose_pipeline::config::Source;
use photopose_pipeline::source::{Frame, SourceEvent};
use photopose_record::{FrameMeta, Recorder};
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
    let camera = defaults::camera(config.camera_file.as_deref())?;
    let field = defaults::field(config.field_file.as_deref())?;
    let mut source = run::open_source(&config, &camera, &field)?;
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
        signal_hook::flag::register(sig, stop.clone()).context("cannot install signal handlers")?;
    }
    let mut recorder = Recorder::create(&args.out)?;
    let mut frame = Frame::new(camera.sensor.width, camera.sensor.height);
    let mut n = 0u64;
    while !stop.load(Ordering::Acquire) && args.frames.is_none_or(|max| n < max) {
        match source.next_frame(&mut frame, Duration::from_millis(200))? {
            SourceEvent::Frame => {
                let meta = FrameMeta {
                    seq: frame.seq,
                    camera_time_ns: frame.camera_time_ns,
                    host_time_ns: frame.host_time_ns,
                };
                recorder.write(meta, &frame.image)?;
                n += 1;
            }
            SourceEvent::Timeout => {}
            SourceEvent::End => break,
        }
    }
    // Finished even after a signal: the file stays readable.
    recorder.finish()?;
    println!("{}: {n} frames recorded", args.out.display());
    Ok(ExitCode::SUCCESS)
}
