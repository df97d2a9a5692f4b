//! `photopose calibrate`: the calibration commands, one subcommand each
//! (this module is only the dispatch).

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
    /// Camera on the flange (hand-eye) and plate in the robot base from
    /// stations of robot and camera poses.
    HandEye(crate::cmd::calibrate_hand_eye::Args),
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    match args.what {
        What::HandEye(a) => crate::cmd::calibrate_hand_eye::run(a),
    }
}
