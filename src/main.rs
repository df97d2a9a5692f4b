//! `photopose`: the command-line front end and daemon entry point. Glue only:
//! every subcommand lives in `cmd/` and calls into the library crates.

/// Writes one line to stdout, returning the IO error instead of panicking
/// as `println!` does when the reader has gone (a closed pipe): every
/// command prints through it and passes the error up with `?`, and `main`
/// ends quietly on a broken pipe.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*)
    }};
}

/// [`outln!`] without the line end (text that brings its own).
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        write!(std::io::stdout().lock(), $($arg)*)
    }};
}

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
    /// GigE Vision camera tools: list the cameras, grab stills.
    Camera(cmd::camera::Args),
    /// The man page and shell completions, generated from this CLI
    /// (packaging).
    #[command(hide = true)]
    Generate(cmd::generate::Args),
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
        Command::Camera(args) => cmd::camera::run(args),
        Command::Generate(args) => cmd::generate::run(args),
    };
    match result {
        Ok(code) => code,
        // The reader of our output went away (`photopose detect … | head
        // -1`): nothing more to say, and no one to say it to. The status a
        // process killed by SIGPIPE shows in a shell.
        Err(e) if broken_pipe(&e) => ExitCode::from(141),
        Err(e) => {
            let priority = if stderr_is_journal() { "<3>" } else { "" };
            eprintln!("{priority}photopose: error: {}", error_text(&e));
            ExitCode::from(2)
        }
    }
}

/// Whether an error is, at its root, a write to a closed pipe.
fn broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// An error and its causes on one line, each said once: library errors
/// often show their source in their own message (`{path}: cannot read:
/// {source}`) and also return it as `source()`, so anyhow's `{:#}` would
/// print the innermost cause twice. A cause whose text the line already
/// holds is left out.
/// A cause that starts with the text of the context above it (a context
/// naming the file, a cause naming it again with what went wrong) takes
/// that context's place.
pub fn error_text(e: &anyhow::Error) -> String {
    let mut line = String::new();
    let mut last = 0;
    for cause in e.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() && text.starts_with(&line[last..]) {
            line.truncate(last);
        } else if !line.is_empty() {
            line.push_str(": ");
        }
        last = line.len();
        line.push_str(&text);
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An error that shows its source in its own message and returns it.
    #[derive(Debug)]
    struct Write(std::io::Error);

    impl std::fmt::Display for Write {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            write!(f, "out.pgm: cannot write: {}", self.0)
        }
    }

    impl std::error::Error for Write {
        fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
            Some(&self.0)
        }
    }

    #[test]
    fn each_cause_is_said_once() {
        let io = || std::io::Error::from(std::io::ErrorKind::NotFound);
        let e = anyhow::Error::new(Write(io())).context("render");
        let text = error_text(&e);
        assert_eq!(text, format!("render: out.pgm: cannot write: {}", io()));
        assert_eq!(format!("{e:#}").matches(&io().to_string()).count(), 2);
        let e = anyhow::Error::new(Write(io())).context("out.pgm");
        assert_eq!(error_text(&e), format!("out.pgm: cannot write: {}", io()));
        let e = anyhow::anyhow!("inner").context("outer");
        assert_eq!(error_text(&e), "outer: inner");
        let pipe = anyhow::Error::new(std::io::Error::from(std::io::ErrorKind::BrokenPipe))
            .context("printing");
        assert!(broken_pipe(&pipe) && !broken_pipe(&e));
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
