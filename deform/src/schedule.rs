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
//!
//! **`L_motion` only where the frames leave the motion open** (`motion = "auto"`, the
//! default): on when the train frames' median interval is longer than
//! [`AUTO_MOTION_INTERVAL_S`] (slower than 9 fps), off otherwise. Measured with and
//! without it (BENCHMARKS.md, "`L_motion` by the frame rate"): at 10 and 20 fps every
//! realistic row gains without it (+0.1 to +1.5 dB, LPIPS lower) or is level, at 4 and
//! 8 fps no row gains (`fast` 4 fps −1.6 dB, `rigid` 8 fps −0.2 dB, `nonrigid` 4 fps
//! level).

use serde::{Deserialize, Serialize};

/// Train frames further apart than this (seconds; slower than 9 fps) use `L_motion`
/// under `motion = "auto"`: between the 8 fps rows that lose without it and the 10 fps
/// rows that gain.
pub const AUTO_MOTION_INTERVAL_S: f64 = 1.0 / 9.0;

/// Whether the joint training uses `L_motion`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MotionUse {
    /// By the train frames' median interval ([`LossSchedule::resolve_motion`]); `on`
    /// where unresolved.
    #[default]
    Auto,
    On,
    Off,
}

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
    /// Whether `L_motion` is used at all: `auto` (by the frames' interval, module docs),
    /// `on` (the paper's), `off`.
    pub motion: MotionUse,
    /// Time constant of γ2 in iterations (4000 in the paper); `≤ 0` or not finite gives
    /// `γ2 = gamma2_max` from the first iteration.
    pub gamma2_iters: f64,
}

impl Default for LossSchedule {
    fn default() -> Self {
        LossSchedule {
            gamma1: 2.0,
            gamma2_max: 1.0,
            motion: MotionUse::Auto,
            gamma2_iters: 4000.0,
        }
    }
}

impl LossSchedule {
    /// γ1 (constant).
    pub fn gamma1(&self, _iter: u64) -> f64 {
        self.gamma1
    }

    /// `motion = "auto"` made `on` or `off` for train frames at `times` (seconds): on
    /// when their median interval is longer than [`AUTO_MOTION_INTERVAL_S`].
    pub fn resolve_motion(&mut self, times: &[f64]) {
        if self.motion == MotionUse::Auto {
            let dt = scene::manifest::median_interval(times);
            self.motion = if dt > AUTO_MOTION_INTERVAL_S {
                MotionUse::On
            } else {
                MotionUse::Off
            };
        }
    }

    /// Whether `L_motion` takes part at all (γ2 not identically 0).
    pub fn uses_motion(&self) -> bool {
        self.motion != MotionUse::Off && self.gamma2_max > 0.0
    }

    /// Eq. 13: `γ2(iter) = gamma2_max·(1 − exp(−iter/gamma2_iters))`; 0 with `motion`
    /// off.
    pub fn gamma2(&self, iter: u64) -> f64 {
        if self.motion == MotionUse::Off {
            return 0.0;
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Train frames at `fps` over one second.
    fn frames(fps: f64) -> Vec<f64> {
        (0..=fps as usize).map(|k| k as f64 / fps).collect()
    }

    fn resolved(motion: MotionUse, times: &[f64]) -> MotionUse {
        let mut s = LossSchedule {
            motion,
            ..LossSchedule::default()
        };
        s.resolve_motion(times);
        s.motion
    }

    #[test]
    fn the_motion_loss_is_on_only_below_nine_frames_a_second() {
        assert_eq!(LossSchedule::default().motion, MotionUse::Auto);
        for fps in [1.0, 4.0, 8.0, 8.9] {
            assert_eq!(
                resolved(MotionUse::Auto, &frames(fps)),
                MotionUse::On,
                "{fps}"
            );
        }
        for fps in [9.1, 10.0, 20.0, 40.0] {
            assert_eq!(
                resolved(MotionUse::Auto, &frames(fps)),
                MotionUse::Off,
                "{fps}"
            );
        }
        // the median interval: one long gap among 20 fps frames changes nothing
        let mut t = frames(20.0);
        t.push(3.0);
        assert_eq!(resolved(MotionUse::Auto, &t), MotionUse::Off);
        // one frame: no interval to supervise
        assert_eq!(resolved(MotionUse::Auto, &[0.5]), MotionUse::Off);
        // a choice made is kept
        assert_eq!(resolved(MotionUse::On, &frames(20.0)), MotionUse::On);
        assert_eq!(resolved(MotionUse::Off, &frames(4.0)), MotionUse::Off);
    }

    #[test]
    fn gamma2_follows_eq_13_unless_the_motion_loss_is_off() {
        let on = LossSchedule {
            motion: MotionUse::On,
            ..LossSchedule::default()
        };
        // 1 − e^(−1) at iteration 4000, by hand
        assert!((on.gamma2(4000) - 0.632_120_558_828_557_7).abs() < 1e-12);
        assert_eq!(on.gamma2(0), 0.0);
        let off = LossSchedule {
            motion: MotionUse::Off,
            ..on
        };
        assert_eq!(off.gamma2(4000), 0.0);
        assert!(on.uses_motion() && !off.uses_motion());
        let zero = LossSchedule {
            gamma2_max: 0.0,
            ..on
        };
        assert!(!zero.uses_motion() && zero.gamma2(4000) == 0.0);
        assert_eq!(off.total(4000, 1.0, 0.5, 7.0), 1.0 + 2.0 * 0.5);
        assert!((on.total(4000, 1.0, 0.5, 7.0) - (2.0 + 7.0 * on.gamma2(4000))).abs() < 1e-12);
    }
}
