//! What the `rgm` command (`src/main.rs`) shares with the project's runner (`cargo xtask`): its
//! progress bars, one look for every long task.

use std::io::Write;
use std::sync::OnceLock;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};

/// `println!` that returns the error instead of panicking: standard output on a full disk or
/// `/dev/full` fails the command with a message (rc 1), not a backtrace.
#[macro_export]
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::write_line(format_args!($($arg)*))
    };
}

/// One line on standard output, written through at once (see [`outln!`]).
pub fn write_line(line: std::fmt::Arguments) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_fmt(line)
        .and_then(|()| out.write_all(b"\n"))
        .and_then(|()| out.flush())
        .context("writing standard output")
}

/// A progress bar on stderr for `len` steps of `what` (hidden when stderr is not a terminal).
pub fn progress(len: usize, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{prefix} [{bar:30}] {pos}/{len} {msg} ({elapsed}, eta {eta})",
        )
        .expect("static template")
        .progress_chars("=> "),
    );
    bar.set_prefix(what.to_string());
    bar
}

/// The progress of a resumable evaluation or of many pairs ([`rgm_model::progress::Progress`]) as a
/// [`progress`] bar labelled `what`, drawn only once pairs are computed (none when an
/// evaluation reads every pair back); notes go to stderr, above the bar.
pub struct TaskBar {
    what: String,
    bar: OnceLock<ProgressBar>,
}

impl TaskBar {
    pub fn new(what: impl Into<String>) -> Self {
        Self {
            what: what.into(),
            bar: OnceLock::new(),
        }
    }
}

impl rgm_model::progress::Progress for TaskBar {
    fn start(&self, total: usize, done: usize) {
        let bar = self.bar.get_or_init(|| progress(total, &self.what));
        bar.set_position(done as u64);
    }

    fn advance(&self) {
        if let Some(bar) = self.bar.get() {
            bar.inc(1);
        }
    }

    fn finish(&self, complete: bool) {
        if let Some(bar) = self.bar.get() {
            if complete {
                bar.finish();
            } else {
                bar.abandon_with_message("stopped at the time limit");
            }
        }
    }

    fn note(&self, message: &str) {
        match self.bar.get() {
            Some(bar) => bar.suspend(|| eprintln!("rgm: {message}")),
            None => eprintln!("rgm: {message}"),
        }
    }
}
