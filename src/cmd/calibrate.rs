//! `photopose calibrate …`: the calibration command group (clap dispatch only).

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::process::ExitCode;

use crate::cmd::calibrate_camera;

/// Arguments of `photopose calibrate`.
#[derive(Parser, Debug)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

/// What to calibrate.
#[derive(Subcommand, Debug)]
enum What {
    /// The camera (interior orientation and distortion) from images of the
    /// test field: a self-calibrating bundle adjustment.
    Camera(calibrate_camera::Args),
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    match args.what {
        What::Camera(a) => calibrate_camera::run(a),
    }
}
