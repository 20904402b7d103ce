//! The stage kit: what every degs binary does the same way: the flags they share
//! ([`args`]), settings files ([`settings`]) and the
//! defaults their flags show in `--help` ([`help`]), progress on stderr and Ctrl-C
//! ([`progress`]; with the time left of steps that cost unlike amounts, [`schedule`]),
//! the `settings` verb through which the runner learns a stage's
//! settings ([`verb`]), the one-line error exit ([`exit_on_error`]), the phase timings and
//! peak memory of each stage's `report.json` ([`report`]), and Adam with its learning-rate
//! schedule, shared by every trainer ([`optim`]).

pub mod args;
pub mod help;
pub mod optim;
pub mod progress;
pub mod report;
pub mod schedule;
pub mod settings;
pub mod verb;

pub use args::{OutputArgs, StageArgs, TrainingArgs};
pub use help::{parse_with, show_defaults, with_default};
pub use progress::{Progress, sigint_flag};
pub use schedule::Schedule;
pub use settings::Settings;
pub use verb::SettingsArgs;

use std::process::ExitCode;

/// Run a binary's body; on error print one line `BINARY: error: …` (the whole chain of
/// causes, `{:#}`) to stderr and exit with status 1. A closed stdout (`degs plan | head`)
/// ends the process quietly, as it ends any Unix tool, not with a panic.
pub fn exit_on_error<E: std::fmt::Display>(
    binary: &str,
    body: impl FnOnce() -> Result<ExitCode, E>,
) -> ExitCode {
    // Rust ignores SIGPIPE, so a print to a closed pipe panics; the default disposition
    // ends the process silently instead.
    // SAFETY: setting a signal's disposition to SIG_DFL has no preconditions.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    match body() {
        Ok(code) => code,
        Err(e) => {
            eprintln!("{binary}: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
