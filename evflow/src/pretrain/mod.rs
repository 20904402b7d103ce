//! Pretraining of the flow network on synthetic scenes with ground-truth flow (issue 4
//! item 4, `docs/DESIGN.md` §5 "Pretrained weights").
//!
//! **Data.** For every `(preset, seed)` a synthetic world is built in memory from the
//! preset ([`synth::SynthConfig::preset`]) and randomised by the seed
//! ([`scene_config`]): textures (pattern, feature size, colours, texture seeds), camera
//! path, object placement, spin axes, a speed factor, the contrast threshold and sensor
//! noise. Its events and per-event ground-truth flow come from
//! [`synth::simulate_scene`]. A training sample is a random window
//! `[t_a, t_a + L]` (L uniform in `[window_min_s, window_max_s]`) of a random scene: input
//! the normalised voxel grid (Eq. 15), target the mean per-event ground-truth
//! displacement (px per window) of each pixel with non-noise events, randomly flipped
//! horizontally and vertically.
//!
//! **Loss.** `supervised_weight · mean EPE over pixels with events` (px per window, the
//! network's unit) `+ cm_weight · L_CM` ([`crate::cm::cm_loss`] on the window's events
//! with times normalised to `[0, 1]`, exact gradient through
//! [`crate::cm::cm_surrogate`]). Adam, learning rate decaying exponentially from
//! `lr` to `lr_final`.
//!
//! **Held-out evaluation.** Scenes from `eval_seeds` (which must not overlap
//! `train_seeds`; their textures, colours, placements and speeds come from those seeds)
//! at fixed, evenly spaced windows: EPE and % outliers (> 3 px) at pixels with events,
//! the EPE of zero flow for reference, the flow-warp loss and the forward time.
//!
//! Output directory (written under a temp name, renamed at the end): [`WEIGHTS_FILE`]
//! (+ its JSON sidecar, see [`FlowNet::save`]) and `report.json` ([`PretrainReport`]).

use crate::cm::{CmConfig, CmEvents, cm_loss};
use crate::eval::{FlowMetrics, FlowWarpLoss, flow_metrics, flow_warp_loss};
use crate::net::{FlowNet, NetConfig, adam_step_conv, tensor4, to_f64};
use burn::tensor::{DType, Device};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scene::error::{Error, Result};
use serde::{Deserialize, Serialize};
use stagekit::Settings;
use stagekit::optim::Adam;
use std::path::{Path, PathBuf};
use std::time::Instant;

mod data;
mod settings;
pub use data::{
    Augment, Sample, SceneData, make_held_out, make_scene, make_scenes, sample, scene_config,
};
pub use settings::PretrainSettings;

/// Name of the weights file inside the output directory.
pub const WEIGHTS_FILE: &str = "weights.safetensors";

/// Figures on the held-out scenes.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct HeldOut {
    /// Step after which this was measured.
    pub step: usize,
    /// The network's flow at pixels with events (px per window).
    pub metrics: FlowMetrics,
    /// Zero flow on the same pixels (EPE = mean gt magnitude).
    pub zero: FlowMetrics,
    /// Mean flow-warp ratio of the network's flow over the windows.
    pub flow_warp_ratio: f64,
    /// Mean forward time per window, seconds.
    pub forward_s: f64,
}

/// What a pretraining run did.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PretrainReport {
    pub settings: PretrainSettings,
    pub net: NetConfig,
    pub params: usize,
    pub train_scenes: Vec<String>,
    pub train_events: usize,
    pub eval_scenes: Vec<String>,
    /// Seconds spent simulating the scenes.
    pub data_s: f64,
    pub train_s: f64,
    /// Mean wall time of one step (batch build, forward, backward, Adam), seconds.
    pub step_s: f64,
    /// Training loss of every step.
    pub loss_curve: Vec<f64>,
    /// Held-out figures (at `eval_every` and at the end; the last is the final one).
    pub held_out: Vec<HeldOut>,
    /// The weights file written (inside the output directory).
    pub weights: PathBuf,
}

/// A copy of `net` on the inference (non-autodiff) device.
pub(crate) fn inference_copy(net: &FlowNet) -> FlowNet {
    let mut n = net.clone();
    for c in &mut n.convs {
        c.weight = c.weight.clone().detach().inner();
        c.bias = c.bias.clone().detach().inner();
    }
    n.device = n.device.clone().inner();
    n
}

/// Evenly spaced evaluation windows of a scene.
fn eval_windows(d: &SceneData, s: &PretrainSettings) -> Vec<(f64, f64)> {
    let len = 0.5 * (s.window_min_s + s.window_max_s);
    let n = s.eval_windows.max(1);
    let span = (d.duration - len).max(0.0);
    (0..n)
        .map(|k| {
            let t_a = span * (k as f64 + 0.5) / n as f64;
            (t_a, t_a + len)
        })
        .collect()
}

/// Score `net` (inference device) on fixed windows of the held-out scenes.
pub fn evaluate(
    net: &FlowNet,
    scenes: &[SceneData],
    s: &PretrainSettings,
    step: usize,
) -> Result<HeldOut> {
    let (mut pu, mut pv, mut gu, mut gv, mut mask) = (vec![], vec![], vec![], vec![], vec![]);
    let (mut fwl_sum, mut forward_s, mut windows) = (0.0, 0.0, 0usize);
    for d in scenes {
        let (w, h) = (d.events.width as usize, d.events.height as usize);
        for win in eval_windows(d, s) {
            let smp = sample(d, win, s.bins, Augment::default());
            let start = Instant::now();
            let x = tensor4(smp.voxel.clone(), [1, s.bins, h, w], &net.device, net.dtype);
            let flow = to_f64(net.forward(x));
            forward_s += start.elapsed().as_secs_f64();
            let fw: FlowWarpLoss =
                flow_warp_loss(&smp.cm, &flow[..w * h], &flow[w * h..], (w, h), 0.5);
            fwl_sum += fw.ratio;
            windows += 1;
            pu.extend_from_slice(&flow[..w * h]);
            pv.extend_from_slice(&flow[w * h..]);
            gu.extend(smp.target[..w * h].iter().map(|&x| x as f64));
            gv.extend(smp.target[w * h..].iter().map(|&x| x as f64));
            mask.extend(smp.mask.iter().map(|&m| m > 0.0));
        }
    }
    let bad = |e: String| Error::Other(format!("held-out evaluation: {e}"));
    let metrics = flow_metrics((&pu, &pv), (&gu, &gv), Some(&mask)).map_err(bad)?;
    let zeros = vec![0.0; pu.len()];
    let zero = flow_metrics((&zeros, &zeros), (&gu, &gv), Some(&mask)).map_err(bad)?;
    let n = windows.max(1) as f64;
    Ok(HeldOut {
        step,
        metrics,
        zero,
        flow_warp_ratio: fwl_sum / n,
        forward_s: forward_s / n,
    })
}

/// Pretrain a network with `settings`, writing [`WEIGHTS_FILE`] (+ sidecar) and
/// `report.json` into `out_dir` (atomically: all or nothing). `progress(step, steps,
/// loss)` is called after every step.
pub fn run(
    settings: &PretrainSettings,
    out_dir: &Path,
    force: bool,
    progress: &mut dyn FnMut(usize, usize, f64),
) -> Result<PretrainReport> {
    let rule = scene::atomic::OutputRule::new("evflow pretrain").force(force);
    rule.check(out_dir)?;
    settings
        .validate()
        .map_err(|e| Error::Other(format!("pretrain settings: {e}")))?;
    let s = settings;
    let t0 = Instant::now();
    let (train, held) = make_scenes(s)?;
    let data_s = t0.elapsed().as_secs_f64();
    let train_events = train.iter().map(|d| d.events.len()).sum();

    let device = Device::flex().autodiff();
    let mut net = FlowNet::new(s.net_config(), s.seed, &device, DType::F32);
    net.set_trainable(true, false);
    let mut adam = Adam::default();
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed ^ 0xda7a);
    let res = s.resolution as usize;
    let (bins, nb) = (s.bins, s.batch);
    let cm_cfg = CmConfig::default();
    let mut loss_curve = Vec::with_capacity(s.iterations);
    let mut held_out = Vec::new();
    let t_train = Instant::now();
    for step in 0..s.iterations {
        let frac = if s.iterations > 1 {
            step as f64 / (s.iterations - 1) as f64
        } else {
            0.0
        };
        let lr = s.lr * (s.lr_final / s.lr).powf(frac);
        let mut samples = Vec::with_capacity(nb);
        while samples.len() < nb {
            let d = &train[rng.random_range(0..train.len())];
            let len = rng.random_range(s.window_min_s..=s.window_max_s);
            let t_a = rng.random_range(0.0..=(d.duration - len).max(0.0));
            let flip = (rng.random_bool(0.5), rng.random_bool(0.5));
            // Draws only for what is enabled, so older settings give the same stream.
            let transpose = s.augment_transpose && rng.random_bool(0.5);
            let reverse = s.augment_reverse && rng.random_bool(0.5);
            let (w, h) = (d.events.width as usize, d.events.height as usize);
            let crop = (w > res || h > res).then(|| {
                let x0 = rng.random_range(0..=w - res);
                (x0, rng.random_range(0..=h - res), res)
            });
            let aug = Augment {
                flip,
                transpose,
                reverse,
                crop,
            };
            let smp = sample(d, (t_a, t_a + len), bins, aug);
            if smp.mask.iter().any(|&m| m > 0.0) {
                samples.push(smp);
            }
        }
        let cat = |f: &dyn Fn(&Sample) -> &Vec<f32>| {
            samples
                .iter()
                .flat_map(|x| f(x).iter().copied())
                .collect::<Vec<f32>>()
        };
        let x = tensor4(
            cat(&|x| &x.voxel),
            [nb, bins, res, res],
            &device,
            DType::F32,
        );
        let target = tensor4(cat(&|x| &x.target), [nb, 2, res, res], &device, DType::F32);
        let mask = tensor4(cat(&|x| &x.mask), [nb, 1, res, res], &device, DType::F32);
        let flow = net.forward(x);
        let diff = flow.clone() - target;
        let epe = (diff.clone() * diff).sum_dim(1).add_scalar(1e-6).sqrt();
        let msum = mask.clone().sum().into_scalar::<f32>().max(1.0) as f64;
        let sup = (epe * mask).sum().div_scalar(msum);
        let mut loss_value = s.supervised_weight * sup.clone().into_scalar::<f32>() as f64;
        let mut total = sup.mul_scalar(s.supervised_weight);
        if s.cm_weight > 0.0 {
            for (k, smp) in samples.iter().enumerate() {
                let ev = subsample(&smp.cm, s.cm_max_events);
                let fk = flow.clone().slice([k..k + 1, 0..2, 0..res, 0..res]);
                let f = to_f64(fk.clone().detach());
                let l = cm_loss(
                    &ev,
                    &f[..res * res],
                    &f[res * res..],
                    (res, res),
                    (0.0, 1.0),
                    &cm_cfg,
                );
                if !l.loss.is_finite() {
                    continue;
                }
                let wgt = s.cm_weight / nb as f64;
                loss_value += wgt * l.loss;
                let gu: Vec<f64> = l.grad_u.iter().map(|g| g * wgt).collect();
                let gv: Vec<f64> = l.grad_v.iter().map(|g| g * wgt).collect();
                total = total + crate::cm::cm_surrogate(fk, &gu, &gv);
            }
        }
        if !loss_value.is_finite() {
            return Err(Error::Other(format!(
                "pretraining diverged at step {step} (loss {loss_value})"
            )));
        }
        let grads = total.backward();
        for c in &mut net.convs {
            adam_step_conv(&mut adam, c, &grads, lr);
        }
        loss_curve.push(loss_value);
        progress(step + 1, s.iterations, loss_value);
        if s.eval_every > 0
            && (step + 1) % s.eval_every == 0
            && step + 1 < s.iterations
            && !held.is_empty()
        {
            held_out.push(evaluate(&inference_copy(&net), &held, s, step + 1)?);
        }
    }
    let train_s = t_train.elapsed().as_secs_f64();
    let inf = inference_copy(&net);
    if !held.is_empty() {
        held_out.push(evaluate(&inf, &held, s, s.iterations)?);
    }
    let dir = scene::atomic::AtomicDir::new(out_dir, &rule)?;
    let trained_by = format!(
        "evflow pretrain (evflow::pretrain::run) with settings {}",
        serde_json::to_string(s).unwrap_or_default()
    );
    inf.save(&dir.path().join(WEIGHTS_FILE), &trained_by)?;
    let report = PretrainReport {
        settings: s.clone(),
        net: s.net_config(),
        params: inf.param_count(),
        train_scenes: train.iter().map(|d| d.name.clone()).collect(),
        train_events,
        eval_scenes: held.iter().map(|d| d.name.clone()).collect(),
        data_s,
        train_s,
        step_s: train_s / s.iterations.max(1) as f64,
        loss_curve,
        held_out,
        weights: out_dir.join(WEIGHTS_FILE),
    };
    scene::atomic::write_json_atomic(&dir.path().join("report.json"), &report)?;
    dir.commit()?;
    Ok(report)
}

/// At most `max` events at an even stride (all when `max == 0`).
fn subsample(ev: &CmEvents, max: usize) -> CmEvents {
    let n = ev.len();
    if max == 0 || n <= max {
        return ev.clone();
    }
    let stride = n.div_ceil(max);
    let mut out = CmEvents::default();
    for k in (0..n).step_by(stride) {
        out.x.push(ev.x[k]);
        out.y.push(ev.y[k]);
        out.t.push(ev.t[k]);
    }
    out
}

#[cfg(test)]
mod tests;
