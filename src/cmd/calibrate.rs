//! `photopose calibrate …`: the calibration command group, one subcommand
//! each (this module is only the dispatch).

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::process::ExitCode;

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
    Camera(crate::cmd::calibrate_camera::Args),
    /// Camera on the flange (hand-eye) and plate in the robot base from
    /// stations of robot and camera poses.
    HandEye(crate::cmd::calibrate_hand_eye::Args),
    /// Hand-eye stations gathered live from a running daemon's pose stream
    /// (the robot's RIst from the RSI server), one per still phase.
    Stations(crate::cmd::calibrate_stations::Args),
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    match args.what {
        What::Camera(a) => crate::cmd::calibrate_camera::run(a),
        What::HandEye(a) => crate::cmd::calibrate_hand_eye::run(a),
        What::Stations(a) => crate::cmd::calibrate_stations::run(a),
    }
}
