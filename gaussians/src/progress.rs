//! Progress display and Ctrl-C handling of the `gaussians` binary.

use crate::train::StepInfo;
use std::sync::atomic::{AtomicBool, Ordering};

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_sigint(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Install a SIGINT handler that sets the returned flag (training stops at the next
/// step boundary and still saves its outputs).
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

/// Progress display on stderr: an indicatif bar on a terminal, a plain line every
/// `every` iterations otherwise.
pub struct Progress {
    bar: Option<indicatif::ProgressBar>,
    total: u32,
    every: u32,
    start: std::time::Instant,
}

impl Progress {
    pub fn new(total: u32) -> Self {
        use std::io::IsTerminal;
        let bar = std::io::stderr().is_terminal().then(|| {
            let b = indicatif::ProgressBar::new(total as u64);
            b.set_style(
                indicatif::ProgressStyle::with_template(
                    "{elapsed_precise} [{bar:30}] {pos}/{len} ({eta}) {msg}",
                )
                .expect("template")
                .progress_chars("=> "),
            );
            b
        });
        Progress {
            bar,
            total,
            every: (total / 20).clamp(1, 250),
            start: std::time::Instant::now(),
        }
    }

    pub fn step(&mut self, s: &StepInfo) {
        let msg = format!(
            "loss {:.4}  PSNR {:.2} dB  {} Gaussians{}",
            s.loss,
            s.psnr,
            s.gaussians,
            if s.field_on { "  field on" } else { "" }
        );
        match &self.bar {
            Some(b) => {
                b.set_position(s.iteration as u64);
                if s.iteration.is_multiple_of(10) || s.iteration == self.total {
                    b.set_message(msg);
                }
            }
            None => {
                if s.iteration.is_multiple_of(self.every) || s.iteration == self.total {
                    eprintln!(
                        "[{:7.1} s] iteration {}/{}: {msg}",
                        self.start.elapsed().as_secs_f64(),
                        s.iteration,
                        self.total
                    );
                }
            }
        }
    }

    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish();
        }
    }
}
