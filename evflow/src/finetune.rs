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

use crate::budget::StopReason;
use crate::net::{FlowNet, NetConfig, adam_step, adam_step_conv, to_f64};
use crate::settings::{FlowSettings, Mode};
use crate::source::Source;
use burn::tensor::Tensor;
use scene::error::{Error, Result};
use serde::{Deserialize, Serialize};
use stagekit::Settings;
use stagekit::optim::Adam;
use std::time::Instant;

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
