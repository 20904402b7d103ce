//! Progress on stderr: a spinner per running stage on a terminal, plain lines otherwise.
//! A stage's own progress lines ([`crate::stage_progress`]) show as its phase, position
//! and time left: on the spinner, or as a plain line at each tenth of the work.

use crate::stage_progress::StageProgress;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use std::collections::HashMap;
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::Duration;

pub struct Progress {
    multi: Option<MultiProgress>,
    bars: Mutex<HashMap<String, ProgressBar>>,
    /// The last tenth of its work each stage's plain progress line showed.
    tenths: Mutex<HashMap<String, (String, u64)>>,
    quiet: bool,
}

impl Progress {
    /// Spinners when stderr is a terminal; `quiet` prints nothing.
    pub fn new(quiet: bool) -> Progress {
        let tty = std::io::stderr().is_terminal() && !quiet;
        Progress {
            multi: tty.then(MultiProgress::new),
            bars: Mutex::new(HashMap::new()),
            tenths: Mutex::new(HashMap::new()),
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

    /// A line of the stage's own output: on a terminal the spinner shows it (a progress
    /// line as phase, position and time left); otherwise a progress line is printed at
    /// each new tenth of a phase's work, other lines only go to the stage's log. `read`
    /// is the line read as progress, its time left at the recent rate ([`RecentRate`]).
    ///
    /// [`RecentRate`]: crate::stage_progress::RecentRate
    pub fn output(&self, stage: &str, line: &str, read: Option<&StageProgress>) {
        if let Some(bar) = self
            .bars
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(stage)
        {
            bar.set_message(read.map_or_else(|| line.to_string(), |p| p.line()));
            return;
        }
        let Some(p) = read.filter(|_| !self.quiet && self.multi.is_none()) else {
            return;
        };
        let mut tenths = self.tenths.lock().unwrap_or_else(|e| e.into_inner());
        let now = (p.label.clone(), p.tenth());
        if tenths.get(stage) != Some(&now) {
            tenths.insert(stage.to_string(), now);
            eprintln!("[degs] {stage:>9}: {}", p.line());
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
