//! LoCM fine-tuning (paper Eq. 7–8, `docs/DESIGN.md` §5): adapt the pretrained flow
//! network to one recording with the contrast-maximisation loss only (no ground truth).
//!
//! Per step (one window): voxel grid → network → dense flow (px per window) →
//! [`crate::cm::cm_loss`] on the window's undistorted events with times normalised to
//! `[0, 1]` (so its flow unit is px per window too) → its exact f64 gradient is pushed
//! into burn's graph through [`crate::cm::cm_surrogate`] → Adam on the trainable
//! tensors. Modes: `lora` (adapters r = 16 on every conv, base frozen; default), `full`
//! (every base weight trainable; the paper's "Full Ft"), `none` (pretrained as is).
//! The budget ([`crate::budget`]) is a fixed number of epochs or, by default, a stopping
//! rule on the CM loss; the learning rate decays exponentially from `lr_start` to
//! `lr_end` over the planned steps (all epochs, or the rule's `max_steps`).
//! Windows without events are skipped (nothing to sharpen).

use crate::budget::{Budget, StopReason, StopRule};
use crate::net::io::BareWeights;
use crate::net::{FlowNet, NetConfig, adam_step, adam_step_conv, to_f64};
use crate::source::Source;
use burn::tensor::Tensor;
use scene::error::{Error, Result};
use serde::{Deserialize, Serialize};
use stagekit::Settings;
use stagekit::optim::Adam;
use std::path::PathBuf;
use std::time::Instant;

/// Which parameters LoCM trains.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// LoRA adapters only (the paper's LoCM).
    #[default]
    Lora,
    /// All base weights ("Full Ft").
    Full,
    /// No fine-tuning ("w/o Flow Ft").
    None,
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Mode, String> {
        match s.to_ascii_lowercase().as_str() {
            "lora" => Ok(Mode::Lora),
            "full" => Ok(Mode::Full),
            "none" => Ok(Mode::None),
            _ => Err(format!("mode '{s}' is not lora, full or none")),
        }
    }
}

/// Settings of the `evflow` stage (fine-tuning and prediction); every key optional in
/// `settings.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FlowSettings {
    pub mode: Mode,
    /// A fixed number of passes over the windows; unset (the default) = train until the
    /// CM loss stops improving ([`FlowSettings::stop`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub epochs: Option<usize>,
    /// The stopping rule used when `epochs` is unset.
    pub stop: StopRule,
    /// Adam learning rate at the first step.
    pub lr_start: f64,
    /// Learning rate at the last step (exponential decay in between).
    pub lr_end: f64,
    /// LoRA rank r.
    pub rank: usize,
    /// LoRA α (the update is scaled by α/r).
    pub alpha: f64,
    /// Weight λ of the TV term of the CM loss.
    pub lambda_tv: f64,
    /// Pyramid levels of the CM objective.
    pub cm_scales: usize,
    /// Coarse-to-fine: the first epoch uses only the coarsest CM pyramid level, the
    /// last all of them (the finest level used moves down linearly over the epochs;
    /// with the stopping rule, over the epochs of `stop.min_steps`).
    /// On by default: on large per-window motion it keeps LoRA from sharpening the
    /// events towards a wrong flow (docs/benchmarks/2026-11-23-locm-ablation.md).
    pub cm_coarse_to_fine: bool,
    /// Events per window used by the CM loss (even stride; 0 = all). Prediction always
    /// covers every event.
    pub max_cm_events: usize,
    /// Seed of the LoRA initialisation.
    pub seed: u64,
    /// Base weights (safetensors, with or without a JSON sidecar); `None` = the shipped
    /// weights.
    pub weights: Option<PathBuf>,
    /// Base width C that bare weights (no sidecar) must have; `None` = read it from
    /// `enc1.weight`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weights_width: Option<usize>,
    /// Scale of the tanh heads (px per window) for bare weights; `None` = 32.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weights_max_flow: Option<f64>,
    /// Write dense previews (`.flo`, EXR, colour-wheel PNG) per window.
    pub previews: bool,
    /// Scene windows: `S > 0` (default 0.05 s) = one of `S` seconds centred on each train
    /// frame (clamped to the recording and to the midpoints between frames), where
    /// `deform` binds events to Gaussians (within `assoc`'s δt = 10 ms); 0 = one per
    /// interval between consecutive train frames. The network assumes one flow per
    /// window, which a long interval of fast motion breaks (on `fast` at 4 fps: 92 %
    /// outliers with interval windows, 1 % with 50 ms windows;
    /// docs/benchmarks/2026-11-24-joint-training-sessions-17-19.md).
    pub frame_window: f64,
}

impl Default for FlowSettings {
    fn default() -> Self {
        FlowSettings {
            mode: Mode::Lora,
            epochs: None,
            stop: StopRule::default(),
            lr_start: 1e-3,
            lr_end: 2e-4,
            rank: 16,
            alpha: 16.0,
            lambda_tv: 0.01,
            cm_scales: 3,
            cm_coarse_to_fine: true,
            max_cm_events: 200_000,
            seed: 0,
            weights: None,
            weights_width: None,
            weights_max_flow: None,
            previews: true,
            frame_window: 0.05,
        }
    }
}

impl Settings for FlowSettings {
    /// `Err` with a sentence when a setting is out of range.
    fn validate(&self) -> std::result::Result<(), String> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !pos(self.lr_start) || !pos(self.lr_end) {
            return Err("lr_start and lr_end must be finite and > 0".into());
        }
        if self.rank == 0 || !pos(self.alpha) {
            return Err("rank must be > 0 and alpha > 0".into());
        }
        if !(self.lambda_tv.is_finite() && self.lambda_tv >= 0.0) {
            return Err("lambda_tv must be finite and >= 0".into());
        }
        if self.cm_scales == 0 || self.cm_scales > 8 {
            return Err("cm_scales must be in 1..=8".into());
        }
        if !(self.frame_window.is_finite() && self.frame_window >= 0.0) {
            return Err("frame_window must be finite and >= 0 (seconds)".into());
        }
        if self.epochs.is_some_and(|e| e > 10_000) {
            return Err("epochs must be <= 10000".into());
        }
        self.stop.validate()
    }
}

impl FlowSettings {
    /// The file outside the stage graph these settings make `evflow finetune` read:
    /// the base weights (`weights`, else `$EVFLOW_WEIGHTS`, else the shipped file), when
    /// they exist (a missing file is the stage's error to report). `evflow settings
    /// --check` prints it so that the runner keys the stage on the weights' content.
    pub fn input_files(&self) -> Vec<(&'static str, PathBuf)> {
        crate::net::io::resolve_weights(self.weights.as_deref())
            .ok()
            .filter(|p| p.is_file())
            .map(|p| ("weights", p))
            .into_iter()
            .collect()
    }

    /// Settings for base weights without a sidecar.
    pub fn bare_weights(&self) -> BareWeights {
        BareWeights {
            base: self.weights_width,
            max_flow: self.weights_max_flow,
        }
    }

    /// Fixed epochs when set, else the stopping rule.
    pub fn budget(&self) -> Budget {
        match self.epochs {
            Some(e) => Budget::Epochs(e),
            None => Budget::Rule(self.stop.clone()),
        }
    }

    /// Whether this budget trains at all (`epochs = 0` does not).
    pub fn trains(&self) -> bool {
        self.mode != Mode::None && self.epochs != Some(0)
    }

    pub(crate) fn cm_config(&self) -> crate::cm::CmConfig {
        crate::cm::CmConfig {
            scales: self.cm_scales,
            lambda_tv: self.lambda_tv,
            first_level: 0,
        }
    }
}

/// A copy of `net` for inference: adapters merged, tensors off the autodiff graph.
pub fn for_inference(net: &FlowNet) -> FlowNet {
    let mut n = net.clone();
    n.merge_lora();
    for c in &mut n.convs {
        c.weight = c.weight.clone().detach().inner();
        c.bias = c.bias.clone().detach().inner();
    }
    n.device = n.device.clone().inner();
    n
}

/// Progress of one fine-tuning step.
#[derive(Clone, Copy, Debug)]
pub struct Step {
    pub epoch: usize,
    /// Epochs planned: all of them, or the most the stopping rule allows.
    pub epochs: usize,
    /// Step within the epoch (windows with events only).
    pub step: usize,
    pub steps: usize,
    pub window: usize,
    pub loss: f64,
    pub lr: f64,
}

/// What fine-tuning did.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct FinetuneReport {
    pub mode: Mode,
    pub net: Option<NetConfig>,
    /// Epochs (passes over the windows) that ran.
    pub epochs: usize,
    /// Steps that ran (epochs × trained windows).
    #[serde(default)]
    pub steps: usize,
    /// Why training stopped.
    #[serde(default)]
    pub stop_reason: StopReason,
    pub windows: usize,
    /// Windows with events (the steps per epoch).
    pub trained_windows: usize,
    /// Windows whose CM loss used a subsample (more than `max_cm_events` events).
    #[serde(default)]
    pub cm_subsampled_windows: Vec<usize>,
    pub trainable_params: usize,
    /// CM loss of every step, in order.
    pub loss_curve: Vec<f64>,
    /// Mean CM loss per epoch (during training).
    pub epoch_loss: Vec<f64>,
    /// Wall time per epoch, seconds.
    pub epoch_s: Vec<f64>,
    /// Mean wall time of one step (forward, CM loss, backward, Adam), seconds.
    pub step_s: f64,
    /// Mean CM loss over the windows before and after training (no gradient).
    pub cm_loss_before: f64,
    pub cm_loss_after: f64,
}

/// Dense flow (px per window) of a window as f64 `(u, v)`, and the output tensor.
fn flow_of(net: &FlowNet, src: &Source, w: &crate::source::Window) -> (Tensor<4>, Vec<f64>) {
    let (wd, ht) = (src.width() as usize, src.height() as usize);
    let bins = net.config.bins;
    let vox = src.voxel(w, bins);
    let x = crate::net::tensor4(vox, [1, bins, ht, wd], &net.device, net.dtype);
    let flow = net.forward(x);
    let vals = to_f64(flow.clone());
    (flow, vals)
}

/// The first pass at the finest CM level under `plan`: the stopping rule compares pass
/// losses from there on.
pub fn first_fine_pass(s: &FlowSettings, plan: &crate::budget::Schedule) -> usize {
    (0..plan.max_passes)
        .find(|&e| coarse_level(s, e, plan.coarse_passes) == 0)
        .unwrap_or(0)
}

/// Finest CM pyramid level used at `epoch` when coarse-to-fine runs over `passes`
/// epochs (0 unless `cm_coarse_to_fine`; 0 after them).
pub(crate) fn coarse_level(s: &FlowSettings, epoch: usize, passes: usize) -> usize {
    if !s.cm_coarse_to_fine || passes < 2 {
        return 0;
    }
    let left = (1.0 - epoch as f64 / (passes - 1) as f64).max(0.0);
    ((s.cm_scales - 1) as f64 * left).round() as usize
}

/// Windows with more events than the CM loss takes (`max_cm_events`).
pub(crate) fn subsampled_windows<'a>(
    src: &'a Source,
    s: &FlowSettings,
) -> impl Iterator<Item = &'a crate::source::Window> {
    let max = s.max_cm_events;
    src.windows.iter().filter(move |w| max > 0 && w.len() > max)
}

/// Mean CM loss of `net` over the windows with events (no gradient).
pub(crate) fn mean_cm_loss(net: &FlowNet, src: &Source, s: &FlowSettings) -> f64 {
    let (wd, ht) = (src.width() as usize, src.height() as usize);
    let n = wd * ht;
    let cfg = s.cm_config();
    let mut sum = 0.0;
    let mut count = 0;
    for w in src.windows.iter().filter(|w| !w.is_empty()) {
        let (_, f) = flow_of(net, src, w);
        let ev = src.cm_events(w, s.max_cm_events);
        sum += crate::cm::cm_loss(&ev, &f[..n], &f[n..], (wd, ht), (0.0, 1.0), &cfg).loss;
        count += 1;
    }
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// Fine-tune `net` (on an autodiff device for `lora`/`full`) on the windows of `src`.
/// `progress` is called after every step. With `lora`, fresh adapters are attached.
pub fn finetune(
    net: &mut FlowNet,
    src: &Source,
    s: &FlowSettings,
    mut progress: impl FnMut(&Step),
) -> Result<FinetuneReport> {
    finetune_observed(net, src, s, |st, _| progress(st))
}

/// [`finetune`] whose callback also sees the network after each step (to score it
/// along the way: `evflow/examples/locm_budget.rs`).
pub fn finetune_observed(
    net: &mut FlowNet,
    src: &Source,
    s: &FlowSettings,
    mut progress: impl FnMut(&Step, &FlowNet),
) -> Result<FinetuneReport> {
    s.validate()
        .map_err(|e| Error::Other(format!("settings: {e}")))?;
    let mut report = FinetuneReport {
        mode: s.mode,
        net: Some(net.config),
        stop_reason: StopReason::NotTrained,
        windows: src.windows.len(),
        ..Default::default()
    };
    let plain = for_inference(net);
    report.cm_loss_before = mean_cm_loss(&plain, src, s);
    report.cm_loss_after = report.cm_loss_before;
    let trained: Vec<_> = src.windows.iter().filter(|w| !w.is_empty()).collect();
    report.trained_windows = trained.len();
    report.cm_subsampled_windows = subsampled_windows(src, s).map(|w| w.index).collect();
    if !s.trains() || trained.is_empty() {
        return Ok(report);
    }
    if !net.device.is_autodiff() {
        return Err(Error::Other(
            "fine-tuning needs an autodiff device (Device::flex().autodiff())".into(),
        ));
    }
    match s.mode {
        Mode::Lora => {
            net.attach_lora(s.rank, s.alpha, s.seed);
            net.set_trainable(false, true);
        }
        _ => net.set_trainable(true, false),
    }
    report.trainable_params = net
        .convs
        .iter()
        .map(|c| match (&c.lora, s.mode) {
            (Some(l), Mode::Lora) => {
                l.a.dims().iter().product::<usize>() + l.b.dims().iter().product::<usize>()
            }
            _ => c.shape().iter().product::<usize>() + c.shape()[0],
        })
        .sum();
    let (wd, ht) = (src.width() as usize, src.height() as usize);
    let n = wd * ht;
    let cfg = s.cm_config();
    let budget = s.budget();
    let plan = budget.schedule(trained.len());
    let total = (plan.lr_passes * trained.len()) as f64;
    let fine_from = first_fine_pass(s, &plan);
    let mut adam = Adam::default();
    let mut k = 0usize;
    let mut step_time = 0.0;
    for epoch in 0..plan.max_passes {
        let start = Instant::now();
        let cfg = crate::cm::CmConfig {
            first_level: coarse_level(s, epoch, plan.coarse_passes),
            ..cfg.clone()
        };
        let mut epoch_sum = 0.0;
        for (i, w) in trained.iter().enumerate() {
            let t0 = Instant::now();
            let frac = if total > 1.0 {
                (k as f64 / (total - 1.0)).min(1.0)
            } else {
                0.0
            };
            let lr = s.lr_start * (s.lr_end / s.lr_start).powf(frac);
            let (flow, f) = flow_of(net, src, w);
            let ev = src.cm_events(w, s.max_cm_events);
            let l = crate::cm::cm_loss(&ev, &f[..n], &f[n..], (wd, ht), (0.0, 1.0), &cfg);
            if !l.loss.is_finite() || l.grad_u.iter().chain(&l.grad_v).any(|g| !g.is_finite()) {
                return Err(Error::Other(format!(
                    "CM loss is not finite at epoch {epoch}, window {}",
                    w.index
                )));
            }
            let grads = crate::cm::cm_surrogate(flow, &l.grad_u, &l.grad_v).backward();
            k += 1;
            for c in &mut net.convs {
                let name = &c.name;
                match (s.mode, c.lora.as_mut()) {
                    (Mode::Lora, Some(lo)) => {
                        adam_step(&mut adam, &format!("{name}.lora_a"), &mut lo.a, &grads, lr);
                        adam_step(&mut adam, &format!("{name}.lora_b"), &mut lo.b, &grads, lr);
                    }
                    _ => adam_step_conv(&mut adam, c, &grads, lr),
                }
            }
            step_time += t0.elapsed().as_secs_f64();
            report.loss_curve.push(l.loss);
            epoch_sum += l.loss;
            progress(
                &Step {
                    epoch,
                    epochs: plan.max_passes,
                    step: i,
                    steps: trained.len(),
                    window: w.index,
                    loss: l.loss,
                    lr,
                },
                net,
            );
        }
        report.epoch_loss.push(epoch_sum / trained.len() as f64);
        report.epoch_s.push(start.elapsed().as_secs_f64());
        report.epochs = epoch + 1;
        if let Some(why) = budget.stop_after(&report.epoch_loss, fine_from, k, trained.len()) {
            report.stop_reason = why;
            break;
        }
    }
    report.steps = k;
    report.step_s = step_time / k.max(1) as f64;
    report.cm_loss_after = mean_cm_loss(&for_inference(net), src, s);
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coarse_to_fine_schedule() {
        let s = |epochs, scales, on| FlowSettings {
            epochs: Some(epochs),
            cm_scales: scales,
            cm_coarse_to_fine: on,
            ..FlowSettings::default()
        };
        let levels = |f: &FlowSettings| {
            let n = f.epochs.unwrap();
            (0..n).map(|e| coarse_level(f, e, n)).collect::<Vec<_>>()
        };
        assert_eq!(levels(&s(3, 3, true)), [2, 1, 0]);
        assert_eq!(levels(&s(5, 3, true)), [2, 2, 1, 1, 0]);
        assert_eq!(levels(&s(3, 3, false)), [0, 0, 0]);
        assert_eq!(
            levels(&s(1, 3, true)),
            [0],
            "a single epoch uses every level"
        );
        assert_eq!(levels(&s(3, 1, true)), [0, 0, 0]);
        assert!(FlowSettings::default().cm_coarse_to_fine);
        // The rule's schedule runs over its first passes, then stays at the finest.
        let f = s(3, 3, true);
        let over_2 = (0..5).map(|e| coarse_level(&f, e, 2)).collect::<Vec<_>>();
        assert_eq!(over_2, [2, 0, 0, 0, 0]);
    }
}
