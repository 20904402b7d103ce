//! Progress on stderr for long work: an indicatif bar on a terminal, a plain line every
//! twentieth of the work otherwise (logs and CI), and Ctrl-C as a flag the work polls.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// A progress display of `total` steps of one piece of work named `label`.
pub struct Progress {
    bar: Option<ProgressBar>,
    label: String,
    total: u64,
    start: Instant,
}

impl Progress {
    /// A bar when stderr is a terminal, plain lines otherwise.
    pub fn new(label: &str, total: u64) -> Self {
        Self::with_terminal(label, total, std::io::stderr().is_terminal())
    }

    /// Plain lines whatever stderr is (tests, `--quiet` runners).
    pub fn plain(label: &str, total: u64) -> Self {
        Self::with_terminal(label, total, false)
    }

    fn with_terminal(label: &str, total: u64, terminal: bool) -> Self {
        let bar = terminal.then(|| {
            let b = ProgressBar::new(total);
            let style = ProgressStyle::with_template(
                "{prefix} {elapsed_precise} [{bar:30}] {pos}/{len} ({eta}) {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");
            b.set_style(style);
            b.set_prefix(label.to_string());
            b
        });
        Progress {
            bar,
            label: label.to_string(),
            total,
            start: Instant::now(),
        }
    }

    /// Change the number of steps (work whose size is known only once it started).
    pub fn set_length(&mut self, total: u64) {
        self.total = total;
        if let Some(b) = &self.bar {
            b.set_length(total);
        }
    }

    /// Step `pos` of the total is done; `msg` (built only when shown) says how it went.
    pub fn set(&self, pos: u64, msg: impl FnOnce() -> String) {
        match &self.bar {
            Some(b) => {
                b.set_position(pos);
                if pos.is_multiple_of(10) || pos == self.total {
                    b.set_message(msg());
                }
            }
            None => {
                let every = (self.total / 20).max(1);
                if pos.is_multiple_of(every) || pos == self.total {
                    eprintln!(
                        "[{:7.1} s] {} {pos}/{}: {}",
                        self.start.elapsed().as_secs_f64(),
                        self.label,
                        self.total,
                        msg()
                    );
                }
            }
        }
    }

    /// A line above the bar (or a plain line).
    pub fn println(&self, line: &str) {
        match &self.bar {
            Some(b) => b.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }

    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish();
        }
    }
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_sigint(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Install a SIGINT handler that sets the returned flag: long work stops at its next
/// step boundary and still writes its outputs.
pub fn sigint_flag() -> &'static AtomicBool {
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        libc::signal(
            libc::SIGINT,
            on_sigint as extern "C" fn(libc::c_int) as libc::sighandler_t,
        );
    }
    &INTERRUPTED
}
