//! `photopose rsi-sim --server ADDR`: a simulated KUKA controller
//! (`photopose_rsi::controller`) against a running daemon's RSI server —
//! `<Rob>` every cycle on its own clock, late and mismatched replies counted
//! into `Delay`, stop after `Timeout` faults — for commissioning without a
//! robot and for measuring the daemon's reply timing. Prints the run's
//! summary; exit status 1 if the simulated controller stopped on `Timeout`.

use anyhow::{Context, Result};
use clap::Parser;
use photopose_rsi::controller::{SimConfig, SimController};
use photopose_rsi::server::RsiClock;
use photopose_rsi::CorrectionMode;
use std::net::SocketAddr;
use std::process::ExitCode;
use std::time::Duration;

/// Arguments of `photopose rsi-sim`.
#[derive(Parser, Debug)]
pub struct Args {
    /// The daemon's RSI address (`[rsi] bind` and `port`).
    #[arg(long)]
    pub server: SocketAddr,
    /// Cycles to send.
    #[arg(long, default_value_t = 10_000)]
    pub cycles: u64,
    /// Cycle time, ms (4 for `#IPO_FAST`, 12 for `#IPO`).
    #[arg(long, default_value_t = 4.0)]
    pub cycle_ms: f64,
    /// Late or mismatched replies after which the controller stops (its
    /// Ethernet object's `Timeout`).
    #[arg(long, default_value_t = 100)]
    pub timeout: u64,
    /// Correction mode the controller applies: `relative` or `absolute`.
    #[arg(long, default_value = "relative")]
    pub mode: String,
    /// SCHED_FIFO priority of the controller's thread (failure: a warning).
    #[arg(long)]
    pub realtime_priority: Option<u8>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    if !(args.cycle_ms.is_finite() && (1.0..=100.0).contains(&args.cycle_ms)) {
        anyhow::bail!("--cycle-ms {}: must be in [1, 100]", args.cycle_ms);
    }
    let mode = match args.mode.as_str() {
        "relative" => CorrectionMode::Relative,
        "absolute" => CorrectionMode::Absolute,
        other => anyhow::bail!("--mode {other:?}: must be relative or absolute"),
    };
    let config = SimConfig {
        cycles: args.cycles,
        cycle: Duration::from_secs_f64(args.cycle_ms / 1000.0),
        timeout: args.timeout,
        mode,
        realtime_priority: args.realtime_priority,
        ..SimConfig::new(args.server)
    };
    let controller = SimController::spawn(config, RsiClock::new())
        .with_context(|| format!("cannot start the simulated controller for {}", args.server))?;
    let r = controller
        .join()
        .context("the simulated controller failed")?;
    let last = r.errors.last().copied().unwrap_or((f64::NAN, f64::NAN));
    println!(
        "{} cycles ({} skipped by the simulator), {} late, {} mismatched, Delay {}, {}; \
         final TCP error {:.4} mm / {:.5}°",
        r.cycles,
        r.skipped,
        r.late,
        r.mismatched,
        r.delay,
        if r.stopped_by_timeout {
            "stopped on Timeout"
        } else {
            "completed"
        },
        last.0,
        last.1
    );
    Ok(if r.stopped_by_timeout {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
