//! Prediction: per-event flow for every event of every window (`flow/NNNN.evflow`, px/s,
//! `t_ref` = window start), dense previews, and a minimal flow evaluation.
//!
//! The network's dense flow `F` is the displacement over the window (px per window) on
//! the (undistorted) sensor grid. Event k takes `F` at the nearest pixel of its
//! undistorted position and divides by the window length: px/s. Previews per window:
//! `previews/NNNN.flo` (Middlebury, displacement over the window, px), `NNNN.exr`
//! (channels `U`,`V`, px/s, as the scenes' `gt/` flow) and `NNNN.png` (colour wheel).
//! A window without events gets zero flow (and a warning from the caller), never NaN.

use crate::flowfile::{EvFlow, write_evflow, write_flo};
use crate::net::{FlowNet, tensor4, to_f32};
use crate::source::{Source, Window};
use scene::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Dense flow of one window: displacement over the window, px, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseFlow {
    pub width: u32,
    pub height: u32,
    pub u: Vec<f32>,
    pub v: Vec<f32>,
}

/// Dense flow of `w` (zero for an empty window). `net` must be an inference copy
/// ([`crate::finetune::for_inference`]) or any network without autodiff.
pub fn dense_flow(net: &FlowNet, src: &Source, w: &Window) -> DenseFlow {
    let (wd, ht) = (src.width(), src.height());
    let n = wd as usize * ht as usize;
    if w.is_empty() {
        return DenseFlow {
            width: wd,
            height: ht,
            u: vec![0.0; n],
            v: vec![0.0; n],
        };
    }
    let bins = net.config.bins;
    let vox = src.voxel(w, bins);
    let x = tensor4(
        vox,
        [1, bins, ht as usize, wd as usize],
        &net.device,
        net.dtype,
    );
    let mut f = to_f32(net.forward(x));
    // The tanh heads bound the output; guard against a corrupted network anyway.
    f.iter_mut()
        .filter(|v| !v.is_finite())
        .for_each(|v| *v = 0.0);
    let v = f.split_off(n);
    DenseFlow {
        width: wd,
        height: ht,
        u: f,
        v,
    }
}

/// Per-event flow (px/s) of the window's events from its dense flow.
pub fn event_flow(src: &Source, w: &Window, dense: &DenseFlow) -> EvFlow {
    let span = w.duration();
    let inv = if span > 0.0 { (1.0 / span) as f32 } else { 0.0 };
    let mut out = EvFlow {
        width: src.width(),
        height: src.height(),
        t_a: w.t_a,
        t_b: w.t_b,
        t_ref: w.t_a,
        source_hash: src.source_hash,
        index: Vec::with_capacity(w.len()),
        u: Vec::with_capacity(w.len()),
        v: Vec::with_capacity(w.len()),
    };
    for i in w.range.clone() {
        let p = src.event_pixel(i);
        out.index.push(i as u64);
        out.u.push(dense.u[p] * inv);
        out.v.push(dense.v[p] * inv);
    }
    out
}

/// File name of window `index`: `NNNN` + extension.
pub fn window_file(index: usize, ext: &str) -> String {
    format!("{index:04}.{ext}")
}

/// Write the previews of one window into `dir`.
pub(crate) fn write_previews(dir: &Path, w: &Window, dense: &DenseFlow) -> Result<()> {
    let (wd, ht) = (dense.width, dense.height);
    write_flo(
        &dir.join(window_file(w.index, "flo")),
        wd,
        ht,
        &dense.u,
        &dense.v,
    )?;
    let span = w.duration();
    let inv = if span > 0.0 { (1.0 / span) as f32 } else { 0.0 };
    let us: Vec<f32> = dense.u.iter().map(|x| x * inv).collect();
    let vs: Vec<f32> = dense.v.iter().map(|x| x * inv).collect();
    scene::image_io::write_exr_flow(dir.join(window_file(w.index, "exr")), wd, ht, &us, &vs)?;
    let rgb = crate::flowfile::color_wheel(&dense.u, &dense.v, None);
    let img = scene::Image {
        width: wd,
        height: ht,
        channels: 3,
        data: rgb,
    };
    scene::image_io::write_png(dir.join(window_file(w.index, "png")), &img)
}

/// Quality figures of one window's flow.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct WindowEval {
    pub window: usize,
    pub events: usize,
    /// Flow-warp loss: IWE variance with the flow ÷ without (> 1 = sharper).
    pub warp_gain: f64,
    /// Mean end-point error against ground truth, px/s (events with ground truth).
    pub gt_mean_err_px_s: Option<f64>,
    /// The same as displacement over the window, px.
    pub gt_mean_err_px: Option<f64>,
    /// Fraction of events whose displacement error exceeds 3 px.
    pub outliers: Option<f64>,
    /// Events scored against ground truth (the weight of this window in the means).
    #[serde(default)]
    pub gt_events: usize,
}

/// Sums of per-event flow errors against ground truth, matching events by their index
/// into the scene's stream; noise events (ground truth 0 by convention) are left out.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GtErrorSums {
    /// Σ |flow − gt|, px/s.
    pub err_px_s: f64,
    /// Σ |flow − gt| · window span, px.
    pub err_px: f64,
    /// Events whose error over the window exceeds 3 px.
    pub outliers: usize,
    /// Events scored.
    pub events: usize,
}

impl GtErrorSums {
    /// Add the errors of `flow` (one window, `span` seconds long).
    pub fn add(&mut self, flow: &EvFlow, gt: &synth::gt::EventFlowGt, span: f64) {
        for (k, &idx) in flow.index.iter().enumerate() {
            let Ok(j) = gt.index.binary_search(&idx) else {
                continue;
            };
            if gt.object[j] == synth::gt::NOISE_ID {
                continue;
            }
            let du = flow.u[k] as f64 - gt.u[j] as f64;
            let dv = flow.v[k] as f64 - gt.v[j] as f64;
            let err = du.hypot(dv);
            self.err_px_s += err;
            self.err_px += err * span;
            self.outliers += usize::from(err * span > 3.0);
            self.events += 1;
        }
    }

    /// Means per event: (px/s, px, outlier fraction); None when no event was scored.
    pub fn means(&self) -> Option<(f64, f64, f64)> {
        let n = self.events as f64;
        (self.events > 0).then(|| (self.err_px_s / n, self.err_px / n, self.outliers as f64 / n))
    }
}

/// Variance of the IWE at the window centre with the dense flow ÷ with zero flow.
pub fn warp_gain(src: &Source, w: &Window, dense: &DenseFlow) -> f64 {
    let (wd, ht) = (dense.width as usize, dense.height as usize);
    let ev = src.cm_events(w, 0);
    if ev.is_empty() {
        return 1.0;
    }
    let u: Vec<f64> = dense.u.iter().map(|&x| x as f64).collect();
    let v: Vec<f64> = dense.v.iter().map(|&x| x as f64).collect();
    let zero = vec![0.0; wd * ht];
    let with = crate::cm::variance(&crate::cm::iwe(&ev, &u, &v, 0.5, wd, ht));
    let without = crate::cm::variance(&crate::cm::iwe(&ev, &zero, &zero, 0.5, wd, ht));
    if without > 0.0 { with / without } else { 1.0 }
}

/// Ground-truth per-event flow of a synthetic scene (`gt/event_flow.bin`), if present.
pub fn scene_gt(scene_dir: &Path) -> Result<Option<synth::gt::EventFlowGt>> {
    let p = scene_dir.join("gt").join("event_flow.bin");
    if !p.is_file() {
        return Ok(None);
    }
    synth::gt::read_event_flow_gt(&p).map(Some)
}

/// Evaluate one window's per-event flow: flow-warp gain always, errors against `gt`
/// (noise events, whose ground truth is 0 by convention, are left out).
pub(crate) fn eval_window(
    src: &Source,
    w: &Window,
    dense: &DenseFlow,
    flow: &EvFlow,
    gt: Option<&synth::gt::EventFlowGt>,
) -> WindowEval {
    let mut e = WindowEval {
        window: w.index,
        events: w.len(),
        warp_gain: warp_gain(src, w, dense),
        ..Default::default()
    };
    let Some(gt) = gt else {
        return e;
    };
    let mut sums = GtErrorSums::default();
    sums.add(flow, gt, w.duration());
    if let Some((px_s, px, out)) = sums.means() {
        e.gt_mean_err_px_s = Some(px_s);
        e.gt_mean_err_px = Some(px);
        e.outliers = Some(out);
        e.gt_events = sums.events;
    }
    e
}

/// Per-event means of the windows' ground-truth errors (px/s, px, outlier fraction), all
/// windows pooled: each window's mean weighted by its scored events.
pub(crate) fn pooled_means(eval: &[WindowEval]) -> (Option<f64>, Option<f64>, Option<f64>) {
    let n: usize = eval.iter().map(|e| e.gt_events).sum();
    let pooled = |f: &dyn Fn(&WindowEval) -> Option<f64>| {
        (n > 0).then(|| {
            eval.iter()
                .filter_map(|e| f(e).map(|v| v * e.gt_events as f64))
                .sum::<f64>()
                / n as f64
        })
    };
    (
        pooled(&|e| e.gt_mean_err_px_s),
        pooled(&|e| e.gt_mean_err_px),
        pooled(&|e| e.outliers),
    )
}

/// What prediction wrote.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PredictReport {
    pub windows: usize,
    pub empty_windows: Vec<usize>,
    pub events: usize,
    pub files: Vec<PathBuf>,
    pub eval: Vec<WindowEval>,
    /// Mean over the events with ground truth, all windows pooled (px/s); `None`
    /// without ground truth. `degs eval` computes the same figure from the files.
    pub mean_err_px_s: Option<f64>,
    pub mean_err_px: Option<f64>,
    pub outliers: Option<f64>,
    pub warp_gain_mean: f64,
    /// Mean inference time per window, seconds.
    pub window_s: f64,
}

/// Predict every window of `src` into `out_dir/flow/NNNN.evflow` (+ previews in
/// `out_dir/previews/` when `previews`), evaluating against `gt` where given.
/// `progress(done, total)` after each window; `warn` for empty windows.
pub(crate) fn predict_all(
    net: &FlowNet,
    src: &Source,
    out_dir: &Path,
    previews: bool,
    gt: Option<&synth::gt::EventFlowGt>,
    mut progress: impl FnMut(usize, usize),
    mut warn: impl FnMut(&str),
) -> Result<PredictReport> {
    if net.device.is_autodiff() {
        return Err(Error::Other(
            "predict_all needs an inference network (for_inference)".into(),
        ));
    }
    let flow_dir = out_dir.join("flow");
    let prev_dir = out_dir.join("previews");
    std::fs::create_dir_all(&flow_dir).map_err(|e| Error::io(&flow_dir, e))?;
    if previews {
        std::fs::create_dir_all(&prev_dir).map_err(|e| Error::io(&prev_dir, e))?;
    }
    let mut r = PredictReport {
        windows: src.windows.len(),
        ..Default::default()
    };
    let start = std::time::Instant::now();
    for (i, w) in src.windows.iter().enumerate() {
        if w.is_empty() {
            warn(&format!(
                "window {} [{}, {}] has no events: zero flow",
                w.index, w.t_a, w.t_b
            ));
            r.empty_windows.push(w.index);
        }
        let dense = dense_flow(net, src, w);
        let flow = event_flow(src, w, &dense);
        let path = flow_dir.join(window_file(w.index, "evflow"));
        write_evflow(&path, &flow)?;
        r.files
            .push(PathBuf::from("flow").join(window_file(w.index, "evflow")));
        r.events += flow.len();
        if previews {
            write_previews(&prev_dir, w, &dense)?;
        }
        r.eval.push(eval_window(src, w, &dense, &flow, gt));
        progress(i + 1, src.windows.len());
    }
    r.window_s = start.elapsed().as_secs_f64() / src.windows.len().max(1) as f64;
    let mean = |f: &dyn Fn(&WindowEval) -> Option<f64>| {
        let v: Vec<f64> = r.eval.iter().filter_map(f).collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    (r.mean_err_px_s, r.mean_err_px, r.outliers) = pooled_means(&r.eval);
    r.warp_gain_mean = mean(&|e| Some(e.warp_gain)).unwrap_or(1.0);
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two windows with 1 and 3 scored events: the report's mean is the mean over the
    /// 4 events (what `degs eval` computes from the files), not the mean of 2 means.
    #[test]
    fn flow_errors_are_pooled_over_events() {
        let gt = synth::gt::EventFlowGt {
            width: 8,
            height: 8,
            index: vec![0, 1, 2, 3, 4],
            u: vec![0.0; 5],
            v: vec![0.0; 5],
            object: vec![1, 1, 1, 1, synth::gt::NOISE_ID],
        };
        let flow = |index: Vec<u64>, u: Vec<f32>| EvFlow {
            width: 8,
            height: 8,
            t_a: 0.0,
            t_b: 0.5,
            t_ref: 0.0,
            source_hash: [0; 32],
            v: vec![0.0; index.len()],
            index,
            u,
        };
        // Window A: event 0 off by 10 px/s. Window B: events 1..3 off by 2 px/s, and a
        // noise event (4) that is not scored however wrong.
        let a = flow(vec![0], vec![10.0]);
        let b = flow(vec![1, 2, 3, 4], vec![2.0, -2.0, 2.0, 99.0]);
        let mut all = GtErrorSums::default();
        let mut evals = Vec::new();
        for f in [&a, &b] {
            let mut one = GtErrorSums::default();
            one.add(f, &gt, 0.5);
            all.add(f, &gt, 0.5);
            let (px_s, px, out) = one.means().unwrap();
            evals.push(WindowEval {
                gt_mean_err_px_s: Some(px_s),
                gt_mean_err_px: Some(px),
                outliers: Some(out),
                gt_events: one.events,
                ..Default::default()
            });
        }
        assert_eq!(all.events, 4);
        let (px_s, px, out) = pooled_means(&evals);
        assert!((px_s.unwrap() - 4.0).abs() < 1e-12, "{px_s:?}"); // (10 + 3·2) / 4
        assert_eq!(all.means().unwrap().0, 4.0);
        assert!((px.unwrap() - 2.0).abs() < 1e-12);
        assert!((out.unwrap() - 0.25).abs() < 1e-12); // only the 5 px error of A
        assert_eq!(pooled_means(&[]), (None, None, None));
    }
}
