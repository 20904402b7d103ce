//! Loss weights of the joint training over iterations (Eq. 13):
//! `L = L_rgb + γ1·L_event + γ2(iter)·L_motion`, `γ2(iter) = 1 − exp(−iter/4000)`; the
//! paper's `γ1 = 1` weighs its per-channel `L_event`, ours defaults to `γ1 = 2` for the
//! luminance form (the luminance of an error is never larger than the luma-weighted mean
//! of its channels' errors, `|Σ w_c e_c| ≤ Σ w_c |e_c|`; measured better on all eight
//! rows of the DEGS-against-RGB-only table:
//! docs/benchmarks/2026-11-24-joint-training-sessions-17-19.md, "γ1 = 2").
//!
//! `iter` counts the iterations of the joint phase (0 at its first iteration, the
//! warm-up not included), so the motion loss starts at zero weight whatever the length
//! of the warm-up.

use serde::{Deserialize, Serialize};

/// Settings of the loss weights (serde, every field optional in files).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossSchedule {
    /// γ1, the constant weight of `L_event` (0 disables it: the "w/o L_event" ablation);
    /// 2 by default for the luminance `L_event` (1 is the paper's, for its per-channel
    /// form: `event_channels = "rgb"`).
    pub gamma1: f64,
    /// The value γ2 tends to (0 disables `L_motion`: the "w/o L_motion" ablation).
    pub gamma2_max: f64,
    /// Time constant of γ2 in iterations (4000 in the paper); `≤ 0` or not finite gives
    /// `γ2 = gamma2_max` from the first iteration.
    pub gamma2_iters: f64,
}

impl Default for LossSchedule {
    fn default() -> Self {
        LossSchedule {
            gamma1: 2.0,
            gamma2_max: 1.0,
            gamma2_iters: 4000.0,
        }
    }
}

impl LossSchedule {
    /// γ1 (constant).
    pub fn gamma1(&self, _iter: u64) -> f64 {
        self.gamma1
    }

    /// Eq. 13: `γ2(iter) = gamma2_max·(1 − exp(−iter/gamma2_iters))`.
    pub fn gamma2(&self, iter: u64) -> f64 {
        if !(self.gamma2_iters > 0.0 && self.gamma2_iters.is_finite()) {
            return self.gamma2_max;
        }
        self.gamma2_max * -(-(iter as f64) / self.gamma2_iters).exp_m1()
    }

    /// Eq. 13: the total loss at `iter`.
    pub fn total(&self, iter: u64, l_rgb: f64, l_event: f64, l_motion: f64) -> f64 {
        l_rgb + self.gamma1(iter) * l_event + self.gamma2(iter) * l_motion
    }
}
