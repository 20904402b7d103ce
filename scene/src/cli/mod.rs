//! What every degs binary does the same way: settings files ([`settings`]) and the
//! defaults their flags show in `--help` ([`help`]), progress on stderr and Ctrl-C
//! ([`progress`]), and the one-line error exit ([`exit_on_error`]).

pub mod help;
pub mod progress;
pub mod settings;

pub use help::{parse_with, show_defaults, with_default};
pub use progress::{Progress, sigint_flag};
pub use settings::Settings;

use std::process::ExitCode;

/// Run a binary's body; on error print one line `BINARY: error: …` (the whole chain of
/// causes, `{:#}`) to stderr and exit with status 1.
pub fn exit_on_error<E: std::fmt::Display>(
    binary: &str,
    body: impl FnOnce() -> Result<ExitCode, E>,
) -> ExitCode {
    match body() {
        Ok(code) => code,
        Err(e) => {
            eprintln!("{binary}: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
