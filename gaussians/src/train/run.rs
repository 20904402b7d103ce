//! The training run: the trainer's steps until the iteration budget or a stop request,
//! with the time per phase.

use super::{StepInfo, Trainer, View};
use crate::raster::Rasterizer;

/// Steps and wall time per phase and how the run ended (for `report.json`).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct RunSummary {
    /// The trainer's iteration count at the end of the run.
    pub iterations: u32,
    /// Steps this run took before / after the field was switched on.
    pub static_steps: u32,
    pub deform_steps: u32,
    pub static_seconds: f64,
    pub deform_seconds: f64,
    pub interrupted: bool,
    pub final_loss: f64,
    pub gaussians: usize,
}

/// Train `tr` until `settings.iterations` or until `stop` is set (e.g. by a SIGINT
/// handler); the state stays consistent at every step boundary, so an interrupted run can
/// still be saved. `on_step` receives every step's figures (progress bar).
pub fn run<R: Rasterizer>(
    tr: &mut Trainer,
    r: &R,
    views: &[View],
    stop: &std::sync::atomic::AtomicBool,
    mut on_step: impl FnMut(&StepInfo),
) -> RunSummary
where
    R::State: Send + 'static,
{
    let mut sum = RunSummary::default();
    while tr.iteration < tr.settings.iterations {
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            sum.interrupted = true;
            break;
        }
        let t0 = std::time::Instant::now();
        let before = tr.iteration;
        let info = tr.step(r, views);
        let dt = t0.elapsed().as_secs_f64();
        // More than one when the field's width probe ran in this step.
        let steps = tr.iteration - before;
        if info.field_on {
            sum.deform_steps += steps;
            sum.deform_seconds += dt;
        } else {
            sum.static_steps += steps;
            sum.static_seconds += dt;
        }
        sum.final_loss = info.loss;
        on_step(&info);
    }
    sum.iterations = tr.iteration;
    sum.gaussians = tr.splats.len();
    sum
}
