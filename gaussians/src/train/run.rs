//! The training run: the trainer's steps until the iteration budget or a stop request,
//! with the time per phase; when in the run the split, the sizing and the field's width
//! probe fall.

use super::{StepInfo, Trainer, View, field_probe, sizing};
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

impl super::TrainSettings {
    /// The iteration of the static/dynamic split (`None`: no split in this run).
    pub fn static_split_iteration(&self) -> Option<u32> {
        if !self.deform || self.dynamic_only || self.static_tolerance_px <= 0.0 {
            return None;
        }
        let field_its = self.iterations.saturating_sub(self.static_iterations) as f32;
        Some(self.static_iterations + (self.static_split_at.clamp(0.0, 1.0) * field_its) as u32)
    }

    /// The iteration of the sizing (`None`: no sizing in this run).
    pub fn sizing_iteration(&self) -> Option<u32> {
        sizing::iteration(&self.size, self.densify.until_iter, self.iterations)
    }
}

impl Trainer {
    /// The iteration of the static/dynamic split (`None`: no split in this run).
    pub fn static_split_iteration(&self) -> Option<u32> {
        self.settings.static_split_iteration()
    }

    /// The iteration of the sizing (`None`: no sizing in this run).
    pub fn sizing_iteration(&self) -> Option<u32> {
        self.settings.sizing_iteration()
    }

    /// The length of the field's width probe (`None`: no probe in this run).
    pub fn field_probe_iterations(&self) -> Option<u32> {
        let (split, sizing) = (self.static_split_iteration(), self.sizing_iteration());
        field_probe::iterations(&self.settings, split, sizing)
    }
}

/// The expected relative cost of each of the run's steps, for the time left the
/// progress shows (`stagekit::schedule`): half-resolution steps without the field cost 1;
/// with the field on every Gaussian 5.5; at full resolution 2 and 9; after the sizing
/// (or the early static split) the field runs on the dynamic Gaussians only, 3.5 (3 at
/// half resolution). Measured on the quiet 2-core machine at DAVIS346 size (0.036,
/// 0.20, 0.35 and 0.145 s per step, the second growing with the densification) and
/// close at 640×480 (BENCHMARKS.md); the runs' own recent steps set the seconds per unit.
pub fn work_schedule(s: &super::TrainSettings, pixels: usize) -> stagekit::Schedule {
    let field_from = if s.deform {
        s.static_iterations.min(s.iterations)
    } else {
        s.iterations
    };
    let coarse_end = s.coarse_end(pixels);
    let reduced_from = match (s.static_split_iteration(), s.sizing_iteration()) {
        (Some(a), Some(b)) => a.min(b),
        (a, b) => a.or(b).unwrap_or(u32::MAX),
    };
    let cost = |k: u32| match (k < coarse_end, k >= field_from, k >= reduced_from) {
        (true, false, _) => 1.0,
        (true, true, false) => 5.5,
        (true, true, true) => 3.0,
        (false, false, _) => 2.0,
        (false, true, false) => 9.0,
        (false, true, true) => 3.5,
    };
    let mut ends = vec![field_from, coarse_end, reduced_from, s.iterations];
    ends.retain(|&e| e > 0 && e <= s.iterations);
    ends.sort_unstable();
    ends.dedup();
    let mut start = 0;
    let phases = ends
        .into_iter()
        .map(|end| {
            let c = cost(start);
            start = end;
            (u64::from(end), c)
        })
        .collect();
    stagekit::Schedule::new(phases)
}
