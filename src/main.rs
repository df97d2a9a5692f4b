//! `photopose`: the command-line front end and daemon entry point. Glue only:
//! every subcommand lives in `cmd/` and calls into the library crates.

mod cmd;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// On-line 6-DOF pose measurement by photogrammetry.
#[derive(Parser)]
#[command(name = "photopose", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Exterior orientation from observations (or images): one JSON line per input.
    Resect(cmd::resect::Args),
    /// Per-stage timing of the frame pipeline on rendered frames.
    Bench(cmd::bench::Args),
    /// Predicted precision of a configuration without images (and a Monte Carlo check).
    Simulate(cmd::simulate::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Resect(args) => cmd::resect::run(args),
        Command::Bench(args) => cmd::bench::run(args),
        Command::Simulate(args) => cmd::simulate::run(args),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("photopose: error: {e:#}");
            ExitCode::from(2)
        }
    }
}
