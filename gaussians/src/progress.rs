//! The `gaussians train` progress display: [`stagekit::Progress`] over the iterations,
//! each shown with its loss, PSNR and Gaussian count (and, with depth priors, how far
//! the render's depth is from the prior).

use crate::train::StepInfo;
use stagekit::Progress;

/// Training progress on stderr (a bar on a terminal, a plain line every twentieth of
/// the iterations otherwise).
pub struct TrainProgress(Progress);

impl TrainProgress {
    /// `schedule`: the steps' expected relative costs (`train::work_schedule`).
    pub fn new(iterations: u32, schedule: stagekit::Schedule) -> Self {
        TrainProgress(Progress::new("iteration", iterations as u64).with_schedule(schedule))
    }

    pub fn step(&self, s: &StepInfo) {
        self.0.set(s.iteration as u64, || {
            let prior = (s.prior_error).map_or(String::new(), |e| {
                format!("  depth {:.1} % off the prior", 100.0 * e)
            });
            format!(
                "loss {:.4}  PSNR {:.2} dB  {} Gaussians{}{prior}",
                s.loss,
                s.psnr,
                s.gaussians,
                if s.field_on { "  field on" } else { "" }
            )
        });
    }

    pub fn finish(&self) {
        self.0.finish();
    }
}
