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
    /// Targets of images, identified: one JSON line per image.
    Detect(cmd::detect::Args),
    /// Records the frames of the configured source into an MCAP file.
    Record(cmd::record::Args),
    /// Writes the frames of a recording as PGM files.
    Export(cmd::export::Args),
    /// The whole chain on a simulated robot cell, ending with the circular test.
    Demo(cmd::demo::Args),
    /// The daemon: frames → poses → streams (default: synthetic camera).
    Run(cmd::run::Args),
    /// Checks a daemon configuration file (for systemd's ExecStartPre).
    CheckConfig(cmd::run::CheckArgs),
    /// Per-stage timing of the frame pipeline on rendered frames.
    Bench(cmd::bench::Args),
    /// Predicted precision of a configuration without images (and a Monte Carlo check).
    Simulate(cmd::simulate::Args),
    /// A synthetic frame of the test field from a camera pose, with its truth.
    Render(cmd::render::Args),
    /// Test-field tools: a printable SVG of a plate, a new plate design.
    Field(cmd::field::Args),
    /// Calibrations: the camera (bundle adjustment on images of the test
    /// field) and hand-eye (camera on the flange, plate in the robot base).
    Calibrate(cmd::calibrate::Args),
    /// ISO 230-4 circular test of a recorded pose stream: report and plots.
    CircleTest(cmd::circle_test::Args),
    /// A simulated KUKA controller against the daemon's RSI server.
    RsiSim(cmd::rsi_sim::Args),
    /// KUKA RSI tools: `rsi kit` writes the controller-side files.
    Rsi(cmd::rsi_kit::Args),
}

fn main() -> ExitCode {
    init_logging();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Resect(args) => cmd::resect::run(args),
        Command::Detect(args) => cmd::detect::run(args),
        Command::Record(args) => cmd::record::run(args),
        Command::Export(args) => cmd::export::run(args),
        Command::Demo(args) => cmd::demo::run(args),
        Command::Run(args) => cmd::run::run(args),
        Command::CheckConfig(args) => cmd::run::check(args),
        Command::Bench(args) => cmd::bench::run(args),
        Command::Simulate(args) => cmd::simulate::run(args),
        Command::Render(args) => cmd::render::run(args),
        Command::Field(args) => cmd::field::run(args),
        Command::Calibrate(args) => cmd::calibrate::run(args),
        Command::CircleTest(args) => cmd::circle_test::run(args),
        Command::RsiSim(args) => cmd::rsi_sim::run(args),
        Command::Rsi(args) => cmd::rsi_kit::run(args),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            let priority = if stderr_is_journal() { "<3>" } else { "" };
            eprintln!("{priority}photopose: error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// Logs to stderr, one line per event, no colours unless on a terminal;
/// `RUST_LOG` filters (default `info`). When stderr is the journal (systemd
/// sets `JOURNAL_STREAM` to its device and inode), each line starts with
/// its syslog priority (`<3>` error, `<4>` warning, `<6>` info, `<7>` debug
/// and trace), which journald reads as the entry's priority, and carries no
/// timestamp of its own (journald stamps every entry).
fn init_logging() {
    use std::io::IsTerminal;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    if stderr_is_journal() {
        let _ = tracing_subscriber::fmt()
            .with_env_filter(filter)
            .with_writer(std::io::stderr)
            .with_ansi(false)
            .event_format(journal::Prefixed(
                tracing_subscriber::fmt::format()
                    .without_time()
                    .with_target(false)
                    .with_level(false),
            ))
            .try_init();
    } else {
        let _ = tracing_subscriber::fmt()
            .with_env_filter(filter)
            .with_writer(std::io::stderr)
            .with_ansi(std::io::stderr().is_terminal())
            .with_target(false)
            .try_init();
    }
}

/// Whether stderr is the stream systemd connected to the journal: the
/// `dev:inode` in `JOURNAL_STREAM` is stderr's own.
fn stderr_is_journal() -> bool {
    use std::os::unix::fs::MetadataExt;
    let Ok(stream) = std::env::var("JOURNAL_STREAM") else {
        return false;
    };
    let Some((dev, ino)) = stream.split_once(':') else {
        return false;
    };
    let (Ok(dev), Ok(ino)) = (dev.parse::<u64>(), ino.parse::<u64>()) else {
        return false;
    };
    std::fs::metadata("/proc/self/fd/2").is_ok_and(|m| m.dev() == dev && m.ino() == ino)
}

mod journal {
    //! The syslog priority prefix journald reads from a service's stderr.

    use tracing::{Level, Subscriber};
    use tracing_subscriber::fmt::format::Writer;
    use tracing_subscriber::fmt::{FmtContext, FormatEvent, FormatFields};
    use tracing_subscriber::registry::LookupSpan;

    /// An event format with `<N>` (the event's syslog priority) in front.
    pub struct Prefixed<F>(pub F);

    impl<S, N, F> FormatEvent<S, N> for Prefixed<F>
    where
        S: Subscriber + for<'a> LookupSpan<'a>,
        N: for<'a> FormatFields<'a> + 'static,
        F: FormatEvent<S, N>,
    {
        fn format_event(
            &self,
            ctx: &FmtContext<'_, S, N>,
            mut writer: Writer<'_>,
            event: &tracing::Event<'_>,
        ) -> std::fmt::Result {
            let priority = match *event.metadata().level() {
                Level::ERROR => 3,
                Level::WARN => 4,
                Level::INFO => 6,
                Level::DEBUG | Level::TRACE => 7,
            };
            write!(writer, "<{priority}>")?;
            self.0.format_event(ctx, writer, event)
        }
    }
}
