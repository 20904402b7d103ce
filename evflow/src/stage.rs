//! The `evflow` stage (`docs/DESIGN.md` §4): fine-tune then predict, or predict only,
//! into an output directory that appears complete or not at all:
//!
//! ```text
//! OUT/adapter.safetensors(.json)   LoRA adapters (mode lora)
//! OUT/weights.safetensors(.json)   fine-tuned weights (mode full)
//! OUT/flow/NNNN.evflow             per-event flow of window NNNN (train interval), px/s
//! OUT/previews/NNNN.{flo,exr,png}  dense flow: displacement (px), px/s, colour wheel
//! OUT/settings.toml                the resolved settings
//! OUT/report.json                  settings, input hashes, phases, peak memory, loss
//!                                  curve, time per epoch, flow figures
//! ```

use crate::finetune::{FinetuneReport, Step, for_inference};
use crate::predict::PredictReport;
use crate::settings::{FlowSettings, Mode};
use crate::source::{Source, WindowSpec};
use burn::tensor::{DType, Device};
use scene::error::{Error, IoContext, Result};
use serde::Serialize;
use stagekit::Settings;
use std::path::{Path, PathBuf};

/// Where the events come from.
#[derive(Clone, Debug)]
pub enum Input {
    /// A scene directory: windows between consecutive train frames.
    Scene(PathBuf),
    /// A bare event file.
    Events {
        path: PathBuf,
        /// None: the size the file stores.
        sensor: Option<(u32, u32)>,
        calib: Option<PathBuf>,
        spec: WindowSpec,
    },
}

impl Input {
    /// The events cut into windows (`frame_window`: [`FlowSettings::frame_window`], for
    /// scenes).
    pub fn open(&self, frame_window: f64) -> Result<Source> {
        match self {
            Input::Scene(dir) => Source::from_scene(dir, frame_window),
            Input::Events {
                path,
                sensor,
                calib,
                spec,
            } => Source::from_events(path, *sensor, calib.as_deref(), spec),
        }
    }

    fn scene_dir(&self) -> Option<&Path> {
        match self {
            Input::Scene(d) => Some(d),
            Input::Events { .. } => None,
        }
    }
}

/// What the stage tells its caller while it runs.
pub enum Event<'a> {
    Phase(&'a str),
    Step(&'a Step),
    Predicted(usize, usize),
    Warning(&'a str),
}

/// Hashes of the inputs (hex BLAKE3).
#[derive(Clone, Debug, Serialize)]
pub struct Inputs {
    pub events: PathBuf,
    pub events_hash: String,
    pub weights: PathBuf,
    pub weights_hash: String,
    pub adapter: Option<PathBuf>,
    pub adapter_hash: Option<String>,
}

/// report.json of the stage.
#[derive(Clone, Debug, Serialize)]
pub struct StageReport {
    pub stage: String,
    pub settings: FlowSettings,
    pub inputs: Inputs,
    pub width: u32,
    pub height: u32,
    pub windows: usize,
    pub events: usize,
    /// Mean end-point error against the scene's ground truth, px/s (synthetic scenes).
    pub flow_epe_px_s: Option<f64>,
    /// The same as displacement over each window, px.
    pub flow_err_px: Option<f64>,
    /// Fraction of events with displacement error > 3 px.
    pub flow_outliers: Option<f64>,
    /// Mean flow-warp gain (IWE variance with flow ÷ without).
    pub warp_gain: f64,
    pub phases: Vec<(String, f64)>,
    pub wall_s: f64,
    pub peak_rss_mib: Option<f64>,
    pub finetune: FinetuneReport,
    pub predict: PredictReport,
}

/// Hex of a 32-byte hash.
pub fn hex(h: &[u8; 32]) -> String {
    h.iter().map(|b| format!("{b:02x}")).collect()
}

/// BLAKE3 of a file's bytes, hex.
pub(crate) fn file_hash(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).at(path)?;
    Ok(blake3::hash(&bytes).to_hex().to_string())
}

/// Run the stage: fine-tune (`train`, per `s.mode`) then predict into `out`. `adapter`
/// loads LoRA adapters onto the base weights before (predict-only runs): an adapter
/// file or the output directory of `evflow finetune` ([`crate::net::io::adapter_file`]).
pub fn run(
    input: &Input,
    out: &Path,
    s: &FlowSettings,
    train: bool,
    adapter: Option<&Path>,
    force: bool,
    on: impl FnMut(Event),
) -> Result<StageReport> {
    let on = std::cell::RefCell::new(on);
    let emit = |e: Event| (on.borrow_mut())(e);
    s.validate()
        .map_err(|e| Error::Other(format!("settings: {e}")))?;
    let command = if train {
        "evflow finetune"
    } else {
        "evflow predict"
    };
    let mut rule = scene::atomic::OutputRule::new(command).force(force);
    match input {
        Input::Scene(d) => rule = rule.source(d),
        Input::Events { path, calib, .. } => {
            rule = rule.source(path);
            if let Some(c) = calib {
                rule = rule.source(c);
            }
        }
    }
    for p in adapter.into_iter().chain(s.weights.as_deref()) {
        rule = rule.source(p);
    }
    rule.check(out)?;
    let start = std::time::Instant::now();
    let mut phases = stagekit::report::Phases::new();
    phases.start("load");
    emit(Event::Phase("load"));
    let src = input.open(s.frame_window)?;
    let weights = crate::net::io::resolve_weights(s.weights.as_deref())?;
    if !weights.is_file() {
        return Err(Error::invalid(
            &weights,
            "flow-network weights not found; pass --weights FILE",
        ));
    }
    let device = Device::flex().autodiff();
    let loaded = crate::net::io::load(&weights, &s.bare_weights(), &device, DType::F32)?;
    if let Some(note) = loaded.note(&weights) {
        emit(Event::Warning(&note));
    }
    let mut net = loaded.net;
    let adapter = adapter.map(crate::net::io::adapter_file).transpose()?;
    let adapter = adapter.as_deref();
    if let Some(a) = adapter {
        crate::net::io::load_adapters(&mut net, a)?;
    }
    let inputs = Inputs {
        events: src.events_path.clone(),
        events_hash: hex(&src.source_hash),
        weights_hash: file_hash(&weights)?,
        weights: weights.clone(),
        adapter: adapter.map(Path::to_path_buf),
        adapter_hash: adapter.map(file_hash).transpose()?,
    };
    let gt = match input.scene_dir() {
        Some(d) => crate::predict::scene_gt(d)?,
        None => None,
    };
    let dir = scene::atomic::AtomicDir::new(out, &rule)?;
    let mut ft = FinetuneReport {
        mode: Mode::None,
        ..Default::default()
    };
    if train
        && s.trains()
        && let Some(note) = subsample_note(&src, s)
    {
        emit(Event::Warning(&note));
    }
    if train {
        phases.start("finetune");
        emit(Event::Phase("finetune"));
        ft = crate::finetune::finetune(&mut net, &src, s, |st| emit(Event::Step(st)))?;
        match s.mode {
            Mode::Lora if ft.trainable_params > 0 => {
                crate::net::io::save_adapters(&net, &dir.path().join(crate::net::io::ADAPTER_FILE))?
            }
            Mode::Full if ft.trainable_params > 0 => net.save(
                &dir.path().join("weights.safetensors"),
                "evflow finetune --mode full",
            )?,
            _ => {}
        }
    }
    phases.start("predict");
    emit(Event::Phase("predict"));
    let inf = for_inference(&net);
    let pr = crate::predict::predict_all(
        &inf,
        &src,
        dir.path(),
        s.previews,
        gt.as_ref(),
        |d, t| emit(Event::Predicted(d, t)),
        |w| emit(Event::Warning(w)),
    )?;
    phases.start("write");
    let mut resolved = s.clone();
    resolved.weights = Some(weights.clone());
    stagekit::settings::write_resolved(dir.path(), &resolved)?;
    phases.stop();
    let report = StageReport {
        stage: if train { "finetune" } else { "predict" }.into(),
        settings: resolved,
        inputs,
        width: src.width(),
        height: src.height(),
        windows: src.windows.len(),
        events: src.window_events(),
        flow_epe_px_s: pr.mean_err_px_s,
        flow_err_px: pr.mean_err_px,
        flow_outliers: pr.outliers,
        warp_gain: pr.warp_gain_mean,
        phases: phases.seconds.clone(),
        wall_s: start.elapsed().as_secs_f64(),
        peak_rss_mib: stagekit::report::peak_rss_mib(),
        finetune: ft,
        predict: pr,
    };
    scene::atomic::write_json_atomic(&dir.path().join("report.json"), &report)?;
    dir.commit()?;
    Ok(report)
}

/// One line saying which windows the CM loss subsamples (`None` when none is).
fn subsample_note(src: &Source, s: &FlowSettings) -> Option<String> {
    let big: Vec<_> = crate::finetune::subsampled_windows(src, s).collect();
    let largest = big
        .iter()
        .max_by_key(|w| (w.len(), std::cmp::Reverse(w.index)))?;
    let tail = "prediction covers every event";
    Some(if big.len() == 1 {
        format!(
            "window {} has {} events; the CM loss uses an even-stride subsample of {} \
             (max_cm_events = {}); {tail}",
            largest.index,
            largest.len(),
            src.cm_events(largest, s.max_cm_events).len(),
            s.max_cm_events
        )
    } else {
        format!(
            "{} windows have more than {} events (up to {} in window {}); the CM loss \
             uses an even-stride subsample of each (max_cm_events); {tail}",
            big.len(),
            s.max_cm_events,
            largest.len(),
            largest.index
        )
    })
}

/// Figures of one window from `evflow eval` (computed with [`crate::eval`]).
#[derive(Clone, Debug, Serialize)]
pub struct EvalWindow {
    pub window: usize,
    pub events: usize,
    /// Per-event end-point error in px of displacement over the window (> 3 px =
    /// outlier) against the scene's `gt/event_flow.bin` or a dense `--gt-flow`.
    pub metrics: Option<crate::eval::FlowMetrics>,
    /// Flow-warp loss at the window centre (ratio > 1 = the flow sharpens the events).
    pub flow_warp: crate::eval::FlowWarpLoss,
}

/// `evflow eval`: the windows' figures and their means.
#[derive(Clone, Debug, Serialize)]
pub struct EvalReport {
    pub flows: PathBuf,
    pub windows: Vec<EvalWindow>,
    /// Mean per-event EPE over the events with ground truth (windows pooled), px over
    /// the window.
    pub mean_epe_px: Option<f64>,
    pub mean_outliers_pct: Option<f64>,
    pub mean_flow_warp_ratio: f64,
}

/// Evaluate existing `.evflow` files of `flows_dir/flow/` against the windows of
/// `input`: ground truth from the scene's `gt/` where present, or from `gt_flow` (a
/// `.npy` `1×2×H×W`, px of displacement over the window, sampled at each event's
/// pixel); flow-warp loss always.
/// `frame_window` must be the one the flows were computed with (their `settings.toml`).
pub fn eval_flows(
    input: &Input,
    flows_dir: &Path,
    gt_flow: Option<&Path>,
    frame_window: f64,
) -> Result<EvalReport> {
    let src = input.open(frame_window)?;
    let gt = match input.scene_dir() {
        Some(d) => crate::predict::scene_gt(d)?,
        None => None,
    };
    let (wd, ht) = (src.width(), src.height());
    let size = (wd as usize, ht as usize);
    let dense_gt = gt_flow.map(crate::eval::read_flow_npy).transpose()?;
    if let (Some((w, h, _, _)), Some(p)) = (&dense_gt, gt_flow)
        && (*w, *h) != size
    {
        return Err(Error::invalid(
            p,
            format!("flow is {w}x{h}, the sensor {wd}x{ht}"),
        ));
    }
    let mut windows = Vec::new();
    for w in &src.windows {
        let path = flows_dir
            .join("flow")
            .join(crate::predict::window_file(w.index, "evflow"));
        let f = crate::flowfile::read_evflow(&path)?;
        if (f.width, f.height) != (wd, ht) || f.source_hash != src.source_hash {
            return Err(Error::invalid(
                &path,
                "flow was computed from a different event stream or sensor",
            ));
        }
        if f.index.iter().any(|&i| i as usize >= src.events.len()) {
            return Err(Error::invalid(
                &path,
                "event index beyond the source stream",
            ));
        }
        windows.push(score_window(
            &src,
            w,
            &f,
            gt.as_ref(),
            dense_gt.as_ref(),
            &path,
        )?);
    }
    let scored: Vec<_> = windows
        .iter()
        .filter_map(|w| w.metrics)
        .filter(|m| m.count > 0)
        .collect();
    // Per-event means, windows pooled (each weighted by its scored events), as the
    // stage report and `degs eval` compute them.
    let n: usize = scored.iter().map(|m| m.count).sum();
    let mean = |f: &dyn Fn(&crate::eval::FlowMetrics) -> f64| {
        (n > 0).then(|| scored.iter().map(|m| f(m) * m.count as f64).sum::<f64>() / n as f64)
    };
    Ok(EvalReport {
        flows: flows_dir.to_path_buf(),
        mean_epe_px: mean(&|m| m.epe),
        mean_outliers_pct: mean(&|m| m.outliers_pct),
        mean_flow_warp_ratio: windows.iter().map(|w| w.flow_warp.ratio).sum::<f64>()
            / windows.len().max(1) as f64,
        windows,
    })
}

/// The figures of one window's per-event flow `f` (px/s): against the scene's ground
/// truth `gt` or the dense `dense_gt` (`w, h, u, v`, px per window) when given, and the
/// flow-warp loss. `path` names the flow in errors.
pub fn score_window(
    src: &Source,
    w: &crate::source::Window,
    f: &crate::flowfile::EvFlow,
    gt: Option<&synth::gt::EventFlowGt>,
    dense_gt: Option<&(usize, usize, Vec<f64>, Vec<f64>)>,
    path: &Path,
) -> Result<EvalWindow> {
    let size = (src.width() as usize, src.height() as usize);
    let span = w.duration();
    // Dense flow (px/s) from the per-event flow, at the pixel each event uses.
    let n = size.0 * size.1;
    let (mut du, mut dv) = (vec![0.0; n], vec![0.0; n]);
    let mut ev = crate::cm::CmEvents::default();
    let (mut pu, mut pv) = (Vec::new(), Vec::new());
    for (k, &i) in f.index.iter().enumerate() {
        let i = i as usize;
        let p = src.event_pixel(i);
        du[p] = f.u[k] as f64;
        dv[p] = f.v[k] as f64;
        ev.x.push(src.xu[i] as f64);
        ev.y.push(src.yu[i] as f64);
        ev.t.push(src.events.t[i]);
        pu.push(f.u[k] as f64 * span);
        pv.push(f.v[k] as f64 * span);
    }
    let flow_warp = crate::eval::flow_warp_loss(&ev, &du, &dv, size, 0.5 * (w.t_a + w.t_b));
    let (gu, gv): (Vec<f64>, Vec<f64>) = if let Some(g) = gt {
        f.index
            .iter()
            .map(|idx| match g.index.binary_search(idx) {
                Ok(j) if g.object[j] != synth::gt::NOISE_ID => {
                    (g.u[j] as f64 * span, g.v[j] as f64 * span)
                }
                _ => (f64::NAN, f64::NAN),
            })
            .unzip()
    } else if let Some((_, _, u, v)) = dense_gt {
        crate::eval::sample_at_events(u, v, size, &ev)
    } else {
        (Vec::new(), Vec::new())
    };
    let metrics = if gt.is_some() || dense_gt.is_some() {
        Some(
            crate::eval::flow_metrics((&pu, &pv), (&gu, &gv), None)
                .map_err(|m| Error::invalid(path, m))?,
        )
    } else {
        None
    };
    Ok(EvalWindow {
        window: w.index,
        events: f.len(),
        metrics,
        flow_warp,
    })
}
