//! Progress on stderr: a spinner per running stage on a terminal, plain lines otherwise.

use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use std::collections::HashMap;
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::Duration;

pub struct Progress {
    multi: Option<MultiProgress>,
    bars: Mutex<HashMap<String, ProgressBar>>,
    quiet: bool,
}

impl Progress {
    /// Spinners when stderr is a terminal; `quiet` prints nothing.
    pub fn new(quiet: bool) -> Progress {
        let tty = std::io::stderr().is_terminal() && !quiet;
        Progress {
            multi: tty.then(MultiProgress::new),
            bars: Mutex::new(HashMap::new()),
            quiet,
        }
    }

    /// A stage starts.
    pub fn start(&self, stage: &str, msg: &str) {
        if self.quiet {
            return;
        }
        match &self.multi {
            Some(m) => {
                let bar = m.add(ProgressBar::new_spinner());
                bar.set_style(
                    ProgressStyle::with_template("{spinner} {prefix:>9} {elapsed:>4} {wide_msg}")
                        .unwrap_or_else(|_| ProgressStyle::default_spinner()),
                );
                bar.set_prefix(stage.to_string());
                bar.set_message(msg.to_string());
                bar.enable_steady_tick(Duration::from_millis(120));
                self.bars
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .insert(stage.into(), bar);
            }
            None => eprintln!("[degs] {stage:>9}: {msg}"),
        }
    }

    /// A line about the run as a whole (e.g. which experiment of a sweep starts).
    pub fn note(&self, msg: &str) {
        if self.quiet {
            return;
        }
        match &self.multi {
            Some(m) => {
                let _ = m.println(format!("[degs] {msg}"));
            }
            None => eprintln!("[degs] {msg}"),
        }
    }

    /// A line of the stage's own output (shown on the spinner only).
    pub fn output(&self, stage: &str, line: &str) {
        if let Some(bar) = self
            .bars
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(stage)
        {
            bar.set_message(line.to_string());
        }
    }

    /// A stage is done (or was not run): its one summary line.
    pub fn finish(&self, stage: &str, msg: &str) {
        if self.quiet {
            return;
        }
        let bar = self
            .bars
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .remove(stage);
        match (bar, &self.multi) {
            (Some(bar), _) => {
                bar.set_style(
                    ProgressStyle::with_template("  {prefix:>9} {wide_msg}")
                        .unwrap_or_else(|_| ProgressStyle::default_spinner()),
                );
                bar.finish_with_message(msg.to_string());
            }
            (None, Some(m)) => {
                let _ = m.println(format!("  {stage:>9} {msg}"));
            }
            (None, None) => eprintln!("[degs] {stage:>9}: {msg}"),
        }
    }
}
