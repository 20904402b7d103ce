//! How long LoCM trains (`docs/DESIGN.md` §5, "LoCM budget"): a fixed number of epochs,
//! or (the default) until the contrast-maximisation loss has stopped improving.
//!
//! The rule looks at the loss of each pass over the windows (the mean over the
//! windows: one step per pass on a recording that makes one window). After pass `e`
//! it stops when at least `min_steps` steps ran and the relative improvement over the
//! last `window` passes, `(L[e−window] − L[e]) / |L[e−window]|`, is below
//! `tolerance`; it never runs a pass that would take it past `max_steps`. Passes at a
//! coarser CM pyramid level (coarse-to-fine) are never compared with finer ones: their
//! losses are on another scale.

use serde::{Deserialize, Serialize};

/// Settings of the stopping rule (`[evflow.stop]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StopRule {
    /// Steps that always run (the coarse-to-fine schedule runs within them).
    pub min_steps: usize,
    /// Steps that are never exceeded.
    pub max_steps: usize,
    /// Passes over which the improvement is measured.
    pub window: usize,
    /// Relative improvement over `window` passes below which training stops.
    pub tolerance: f64,
}

/// Defaults chosen on the real ECD `shapes_rotation` slice (BENCHMARKS.md, "LoCM
/// budget"): the rule stops there after 20 steps at 0.21 × the zero-flow EPE.
impl Default for StopRule {
    fn default() -> Self {
        StopRule {
            min_steps: 10,
            max_steps: 40,
            window: 3,
            tolerance: 0.02,
        }
    }
}

impl StopRule {
    /// `Err` with a sentence when a setting is out of range.
    pub fn validate(&self) -> Result<(), String> {
        if self.max_steps == 0 || self.min_steps > self.max_steps {
            return Err("stop.max_steps must be > 0 and >= stop.min_steps".into());
        }
        if self.max_steps > 1_000_000 {
            return Err("stop.max_steps must be <= 1000000".into());
        }
        if self.window == 0 {
            return Err("stop.window must be > 0".into());
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err("stop.tolerance must be finite and >= 0".into());
        }
        Ok(())
    }
}

/// Why training stopped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// The fixed number of epochs ran.
    #[default]
    Epochs,
    /// The loss stopped improving (the rule).
    Converged,
    /// `max_steps` reached before the loss stopped improving.
    MaxSteps,
    /// Nothing to train (mode none, no windows with events, or 0 epochs).
    NotTrained,
}

/// The budget of one fine-tuning run: passes to plan for, and when to stop.
#[derive(Clone, Debug, PartialEq)]
pub enum Budget {
    Epochs(usize),
    Rule(StopRule),
}

impl Budget {
    /// Passes over `windows` windows the schedules (learning rate, coarse-to-fine) are
    /// laid out over: every pass for fixed epochs; for the rule, the learning rate
    /// decays over `max_steps` and coarse-to-fine runs within `min_steps`.
    pub fn schedule(&self, windows: usize) -> Schedule {
        let w = windows.max(1);
        match self {
            Budget::Epochs(e) => Schedule {
                lr_passes: *e,
                coarse_passes: *e,
                max_passes: *e,
            },
            Budget::Rule(r) => Schedule {
                lr_passes: (r.max_steps / w).max(1),
                coarse_passes: r.min_steps.div_ceil(w).max(1),
                max_passes: (r.max_steps / w).max(1),
            },
        }
    }

    /// Whether to stop after the passes whose mean losses are `pass_loss` (one entry
    /// per pass run so far, `fine_from` = the first pass at the finest CM level), with
    /// `steps` steps run; `None` = go on.
    pub fn stop_after(
        &self,
        pass_loss: &[f64],
        fine_from: usize,
        steps: usize,
        steps_per_pass: usize,
    ) -> Option<StopReason> {
        match self {
            Budget::Epochs(e) => (pass_loss.len() >= *e).then_some(StopReason::Epochs),
            Budget::Rule(r) => {
                let e = pass_loss.len();
                if e == 0 {
                    return None;
                }
                if steps >= r.min_steps && e > r.window && e - 1 - r.window >= fine_from {
                    let (old, new) = (pass_loss[e - 1 - r.window], pass_loss[e - 1]);
                    let gain = (old - new) / old.abs().max(f64::MIN_POSITIVE);
                    if gain < r.tolerance {
                        return Some(StopReason::Converged);
                    }
                }
                (steps + steps_per_pass.max(1) > r.max_steps).then_some(StopReason::MaxSteps)
            }
        }
    }
}

/// Lengths, in passes over the windows, of the schedules of one run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Schedule {
    /// The learning rate decays from `lr_start` to `lr_end` over these passes.
    pub lr_passes: usize,
    /// Coarse-to-fine moves from the coarsest to the finest level over these passes.
    pub coarse_passes: usize,
    /// At most this many passes run.
    pub max_passes: usize,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feed `losses` one pass at a time (one window: one step per pass) until the rule
    /// stops: (passes run, reason).
    fn run(
        rule: &StopRule,
        losses: impl Fn(usize) -> f64,
        fine_from: usize,
    ) -> (usize, StopReason) {
        let b = Budget::Rule(rule.clone());
        let mut curve = Vec::new();
        for step in 1..=10_000 {
            curve.push(losses(step - 1));
            if let Some(r) = b.stop_after(&curve, fine_from, step, 1) {
                return (step, r);
            }
        }
        panic!("the rule never stopped");
    }

    fn rule(min: usize, max: usize, window: usize, tol: f64) -> StopRule {
        StopRule {
            min_steps: min,
            max_steps: max,
            window,
            tolerance: tol,
        }
    }

    #[test]
    fn stops_when_the_loss_flattens() {
        // Falls 10 % per step until step 20 (index 19), flat after: the first window of
        // 5 steps with no gain ends at index 24, i.e. after 25 steps.
        let loss = |i: usize| 0.9f64.powi(i.min(19) as i32);
        assert_eq!(
            run(&rule(3, 1000, 5, 0.01), loss, 0),
            (25, StopReason::Converged)
        );
        // A 1 % tolerance over 3 steps on a loss falling 0.2 % per step stops as soon
        // as the window fits after the minimum: 3 + 1 passes, minimum 4.
        let slow = |i: usize| 0.998f64.powi(i as i32);
        assert_eq!(
            run(&rule(4, 1000, 3, 0.01), slow, 0),
            (4, StopReason::Converged)
        );
        // ... but with a 0.5 % tolerance it improves enough (0.6 % over 3) to go on.
        assert_eq!(
            run(&rule(4, 50, 3, 0.005), slow, 0),
            (50, StopReason::MaxSteps)
        );
    }

    #[test]
    fn respects_the_minimum_and_the_maximum() {
        let flat = |_: usize| 1.0;
        assert_eq!(
            run(&rule(12, 100, 2, 0.01), flat, 0),
            (12, StopReason::Converged)
        );
        // Always improving by 10 %: only the maximum stops it.
        let falling = |i: usize| 0.9f64.powi(i as i32);
        assert_eq!(
            run(&rule(1, 37, 5, 0.01), falling, 0),
            (37, StopReason::MaxSteps)
        );
        // min = max: exactly that many.
        assert_eq!(
            run(&rule(7, 7, 2, 0.0), falling, 0),
            (7, StopReason::MaxSteps)
        );
    }

    #[test]
    fn a_rising_loss_stops_and_coarse_passes_are_not_compared() {
        let rising = |i: usize| 1.0 + 0.1 * i as f64;
        assert_eq!(
            run(&rule(2, 100, 1, 0.0), rising, 0),
            (2, StopReason::Converged)
        );
        // Passes 0..3 at coarse levels (losses on another scale, here much higher):
        // the first comparison is between passes 3 and 3 + window.
        let coarse_then_flat = |i: usize| if i < 3 { 5.0 } else { 1.0 };
        assert_eq!(
            run(&rule(1, 100, 2, 0.01), coarse_then_flat, 3),
            (6, StopReason::Converged)
        );
    }

    #[test]
    fn passes_of_several_windows() {
        // 8 windows per pass, max 30 steps: 3 passes (24 steps), never a 4th (32).
        let b = Budget::Rule(rule(8, 30, 1, 0.0));
        let falling = [1.0, 0.9, 0.8];
        assert_eq!(b.stop_after(&falling[..2], 0, 16, 8), None);
        assert_eq!(b.stop_after(&falling, 0, 24, 8), Some(StopReason::MaxSteps));
        assert_eq!(
            b.schedule(8),
            Schedule {
                lr_passes: 3,
                coarse_passes: 1,
                max_passes: 3
            }
        );
        let e = Budget::Epochs(3);
        assert_eq!(e.stop_after(&falling[..2], 0, 16, 8), None);
        assert_eq!(e.stop_after(&falling, 0, 24, 8), Some(StopReason::Epochs));
    }

    #[test]
    fn invalid_rules_are_refused() {
        assert!(rule(10, 60, 5, 0.01).validate().is_ok());
        assert!(rule(61, 60, 5, 0.01).validate().is_err());
        assert!(rule(0, 0, 5, 0.01).validate().is_err());
        assert!(rule(1, 60, 0, 0.01).validate().is_err());
        assert!(rule(1, 60, 5, f64::NAN).validate().is_err());
        assert!(rule(1, 60, 5, -0.1).validate().is_err());
    }
}
