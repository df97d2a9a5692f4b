//! `photopose export RECORDING --out DIR`: the frames of a recording as
//! PGM files (`frame-SEQ.pgm`, 8 or 16 bits as recorded), for tools that
//! do not read MCAP.

use anyhow::{Context, Result};
use clap::Parser;
use photopose_record::Recording;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `photopose export`.
#[derive(Parser, Debug)]
pub struct Args {
    /// The recording (MCAP, as `photopose record` or `run --record` write).
    pub recording: PathBuf,
    /// The directory to write the frames into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    let recording = Recording::open(&args.recording)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut bytes = Vec::new();
    for index in 0..recording.len() {
        let (meta, image) = recording.frame(index)?;
        let path = args.out.join(format!("frame-{:06}.pgm", meta.seq));
        bytes.clear();
        photopose_formats::image::encode_pgm(&image, &path.display().to_string(), &mut bytes)?;
        std::fs::write(&path, &bytes)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    outln!(
        "{}: {} frames written to {}",
        recording.path(),
        recording.len(),
        args.out.display()
    )?;
    Ok(ExitCode::SUCCESS)
}
