//! Progress of long work on stderr (`indicatif`): a bar when the length is
//! known, a counter otherwise; drawn only when stderr is a terminal, so a
//! log, a pipe or a test sees no escape codes and no partial lines.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::time::Duration;

/// Whether progress is drawn at all (stderr is a terminal).
pub fn shown() -> bool {
    std::io::stderr().is_terminal()
}

fn target() -> ProgressDrawTarget {
    if shown() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    }
}

/// A bar for `len` steps of `what` (`frames`, `cycles`, …); `None`: an
/// open-ended counter with its rate.
pub fn bar(len: Option<u64>, what: &str) -> ProgressBar {
    let (bar, template) = match len {
        Some(n) => (
            ProgressBar::with_draw_target(Some(n), target()),
            format!("{{prefix}} [{{bar:30}}] {{pos}}/{{len}} {what} ({{per_sec}}, {{eta}} left) {{msg}}"),
        ),
        None => (
            ProgressBar::with_draw_target(None, target()),
            format!("{{prefix}} {{spinner}} {{pos}} {what} ({{per_sec}}) {{msg}}"),
        ),
    };
    if let Ok(style) = ProgressStyle::with_template(&template) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.enable_steady_tick(Duration::from_millis(200));
    bar
}

/// A status line rewritten in place (no bar): a spinner and a message.
pub fn status() -> ProgressBar {
    let bar = ProgressBar::with_draw_target(None, target());
    if let Ok(style) = ProgressStyle::with_template("{spinner} {msg}") {
        bar.set_style(style);
    }
    bar.enable_steady_tick(Duration::from_millis(200));
    bar
}
