//! Progress on stderr for long work: an indicatif bar on a terminal, a plain line every
//! twentieth of the work otherwise (logs and CI), and Ctrl-C as a flag the work polls.

use crate::schedule::{Schedule, TimeLeft};
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
    /// The stage's own estimate of the time left, from its schedule.
    time_left: Option<TimeLeft>,
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
            time_left: None,
        }
    }

    /// Estimate the time left from `schedule` (steps that cost unlike amounts): the
    /// estimate leads the message on a terminal and ends each plain line as
    /// `| left N s`, which the runner shows instead of its own guess from the rate.
    pub fn with_schedule(mut self, schedule: Schedule) -> Self {
        if let Some(b) = &self.bar {
            let style = ProgressStyle::with_template(
                "{prefix} {elapsed_precise} [{bar:30}] {pos}/{len} {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");
            b.set_style(style);
        }
        self.time_left = Some(TimeLeft::new(schedule, self.total));
        self
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
        let secs = self.start.elapsed().as_secs_f64();
        let left = (self.time_left.as_ref()).and_then(|t| t.update(pos, secs));
        match &self.bar {
            Some(b) => {
                b.set_position(pos);
                if pos.is_multiple_of(10) || pos == self.total {
                    match left.filter(|_| pos < self.total) {
                        Some(l) => {
                            b.set_message(format!("about {} left  {}", fmt_duration(l), msg()))
                        }
                        None => b.set_message(msg()),
                    }
                }
            }
            None => {
                if shows_line(pos, self.total) {
                    let mut line = plain_line(secs, &self.label, pos, self.total, &msg());
                    if let Some(l) = left {
                        line += &format!(" {LEFT_MARK}{:.0} s", l.max(0.0));
                    }
                    eprintln!("{line}");
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

/// Whether step `pos` of `total` gets a plain line: every twentieth of the work (every
/// step when there are fewer than 20) and the last step.
fn shows_line(pos: u64, total: u64) -> bool {
    pos.is_multiple_of((total / 20).max(1)) || pos == total
}

/// What ends a plain line that carries the stage's own estimate of the time left
/// (`… | left 412 s`).
pub const LEFT_MARK: &str = "| left ";

/// `2 min 05 s`, `45 s`, `1 h 03 min`.
pub fn fmt_duration(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min {:02} s", s / 60, s % 60),
        _ => format!("{} h {:02} min", s / 3600, (s % 3600) / 60),
    }
}

/// `[   12.3 s] LABEL POS/TOTAL: MSG` (without `: MSG` when the message is empty): the
/// line the runner reads as a stage's progress (`runner::stage_progress`).
pub fn plain_line(secs: f64, label: &str, pos: u64, total: u64, msg: &str) -> String {
    let mut line = format!("[{secs:7.1} s] {label} {pos}/{total}");
    if !msg.is_empty() {
        line += ": ";
        line += msg;
    }
    line
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_lines_every_twentieth_and_at_the_end() {
        let shown: Vec<u64> = (1..=100).filter(|&p| shows_line(p, 100)).collect();
        assert_eq!(shown, (1..=20).map(|k| 5 * k).collect::<Vec<_>>());
        let shown: Vec<u64> = (1..=7).filter(|&p| shows_line(p, 7)).collect();
        assert_eq!(
            shown,
            (1..=7).collect::<Vec<_>>(),
            "every step of short work"
        );
        assert!(shows_line(43, 43) && !shows_line(41, 43));
    }

    #[test]
    fn plain_line_format() {
        assert_eq!(
            plain_line(12.34, "iteration", 5, 10, "loss 0.1"),
            "[   12.3 s] iteration 5/10: loss 0.1"
        );
        assert_eq!(plain_line(0.0, "frame", 1, 3, ""), "[    0.0 s] frame 1/3");
    }
}
