//! `photopose export RECORDING --out DIR [--format pgm|png]`: the frames
//! of a recording as PGM or PNG files (`frame-SEQ.pgm`, 8 or 16 bits as
//! recorded), for tools that do not read MCAP.

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
    /// The image format: pgm or png (8 or 16 bits as recorded).
    #[arg(long, default_value = "pgm", value_parser = ["pgm", "png"])]
    pub format: String,
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    let recording = Recording::open(&args.recording)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut bytes = Vec::new();
    for index in 0..recording.len() {
        let (meta, image) = recording.frame(index)?;
        let path = args
            .out
            .join(format!("frame-{:06}.{}", meta.seq, args.format));
        bytes.clear();
        let name = path.display().to_string();
        if args.format == "png" {
            photopose_formats::image::encode_png(&image, &name, &mut bytes)?;
        } else {
            photopose_formats::image::encode_pgm(&image, &name, &mut bytes)?;
        }
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
