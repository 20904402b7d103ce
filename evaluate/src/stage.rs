//! The `evaluate` stage: a model's renders (`MODEL/renders/`, `renders/novel/`,
//! `renders/novel_depth/`) against the scene's held-out test frames and novel views,
//! the 2D baselines on the test frames, the flow error against the scene's ground
//! truth. Writes `OUT/metrics.json` ([`scene::evaluation::Metrics`]), `OUT/novel_sheet.png`
//! and `OUT/settings.toml`, all at once or not at all.

use crate::baselines;
use crate::flow::{FlowError, find_epe, flow_error};
use crate::images::{images_in, pair_renders, score_pairs};
use crate::lpips_use::{LpipsUse, mean_all, score_sets};
use crate::settings::EvalSettings;
use anyhow::{Context, Result};
use scene::atomic::{AtomicDir, OutputRule, write_json_atomic};
use scene::evaluation::{BaselineFigures, FrameMetrics, Metrics, PSNR_CAP};
use scene::manifest::{Manifest, Scene};
use std::path::{Path, PathBuf};

/// The binary's name, which its outputs are marked with.
pub const BINARY: &str = "evaluate";

/// The novel views' contact sheet in the output directory.
pub(crate) const SHEET: &str = "novel_sheet.png";

/// What is evaluated.
#[derive(Clone, Copy, Debug)]
pub struct Inputs<'a> {
    /// The scene directory (its test frames, novel views and ground truth).
    pub scene: &'a Path,
    /// A render stage's output (`renders/`, its `report.json`); None: no model renders,
    /// only the baselines and the flow.
    pub model: Option<&'a Path>,
    /// The flow stage's output (`flow/*.evflow`, `report.json`).
    pub flows: Option<&'a Path>,
}

/// Evaluate into `out` (a directory that appears complete or not at all; an earlier
/// output of `evaluate` is replaced only with `force`).
pub fn run(inputs: Inputs, s: &EvalSettings, out: &Path, force: bool) -> Result<Metrics> {
    let mut rule = OutputRule::new(BINARY).force(force).source(inputs.scene);
    for dir in inputs.model.iter().chain(inputs.flows.iter()) {
        rule = rule.source(dir);
    }
    rule.check(out)?;
    let dir = AtomicDir::new(out, &rule)?;
    let metrics = evaluate(inputs, s, dir.path())?;
    stagekit::settings::write_resolved(dir.path(), s)?;
    write_json_atomic(&dir.path().join("metrics.json"), &metrics)?;
    dir.commit()?;
    Ok(metrics)
}

/// The figures of `inputs`; the novel views' sheet is written into `dir` (and named
/// relative to it in [`Metrics::novel_sheet`]).
pub fn evaluate(inputs: Inputs, s: &EvalSettings, dir: &Path) -> Result<Metrics> {
    let scene = Scene::open(inputs.scene)?;
    let scene_findings = scene::check::check_scene(&scene)?
        .iter()
        .map(ToString::to_string)
        .collect();
    let images =
        |m: &Manifest| -> Vec<PathBuf> { m.frames.iter().map(|f| scene.image_path(f)).collect() };
    let renders = inputs.model.map(|m| m.join("renders"));
    let mut frames = match &renders {
        Some(r) => score_dir(r, &images(&scene.test))?,
        None => Vec::new(),
    };
    let mut novel_frames = match &renders {
        Some(r) if !scene.novel.frames.is_empty() => {
            score_dir(&r.join("novel"), &images(&scene.novel))?
        }
        _ => Vec::new(),
    };
    let novel_pairs = pairs(&novel_frames);
    let depth_dir = renders.as_ref().map(|r| r.join("novel_depth"));
    let masks =
        crate::masked::novel_masks(inputs.scene, &novel_pairs, depth_dir.as_deref(), PSNR_CAP)?;
    let novel_sheet =
        crate::sheet::write_sheet(&novel_pairs, &dir.join(SHEET))?.map(|_| PathBuf::from(SHEET));
    for (f, m) in novel_frames.iter_mut().zip(&masks) {
        f.masks = *m;
    }
    let trajectory = inputs.model.and_then(crate::masked::trajectory);
    let (lpips_net, lpips_note) = add_lpips(&mut frames, &mut novel_frames, s.lpips, &scene)?;
    let mean = |frames: &[FrameMetrics], f: &dyn Fn(&FrameMetrics) -> f64| {
        (!frames.is_empty()).then(|| frames.iter().map(f).sum::<f64>() / frames.len() as f64)
    };
    let lpips_mean = |f: &[FrameMetrics]| mean_all(f.iter().map(|f| f.lpips));
    let (baselines, baselines_note) = model_baselines(inputs.model, &scene);
    let (flow, flow_source) = eval_flow(inputs.flows, inputs.scene).unzip();
    Ok(Metrics {
        psnr_mean: mean(&frames, &|f| f.psnr),
        ssim_mean: mean(&frames, &|f| f.ssim),
        lpips_mean: lpips_mean(&frames),
        novel_lpips_mean: lpips_mean(&novel_frames),
        lpips_net,
        lpips_note,
        frames,
        novel_psnr_mean: mean(&novel_frames, &|f| f.psnr),
        novel_sheet,
        novel_moving_psnr_mean: mean_of(novel_frames.iter().map(|f| f.masks.moving_psnr)),
        novel_covisible_psnr_mean: mean_of(novel_frames.iter().map(|f| f.masks.covisible_psnr)),
        novel_moving_ssim_mean: mean_of(novel_frames.iter().map(|f| f.masks.moving_ssim)),
        novel_covisible_ssim_mean: mean_of(novel_frames.iter().map(|f| f.masks.covisible_ssim)),
        trajectory,
        novel_moving_depth_error_mean: mean_of(
            novel_frames.iter().map(|f| f.masks.moving_depth_error),
        ),
        novel_moving_lpips_mean: mean_of(novel_frames.iter().map(|f| f.masks.moving_lpips)),
        novel_covisible_lpips_mean: mean_of(novel_frames.iter().map(|f| f.masks.covisible_lpips)),
        novel_ssim_mean: mean(&novel_frames, &|f| f.ssim),
        novel_frames,
        baselines,
        baselines_note,
        scene_findings,
        flow_epe: flow.as_ref().map(|f| f.epe_px_s),
        flow_err_px: flow.as_ref().and_then(|f| f.err_px),
        flow_outliers: flow.as_ref().and_then(|f| f.outliers),
        flow_events: flow.as_ref().map_or(0, |f| f.events),
        flow_source,
        ..Metrics::default()
    })
}

/// PSNR/SSIM of the renders in `dir` against `held_out`; empty when `dir` has none.
fn score_dir(dir: &Path, held_out: &[PathBuf]) -> Result<Vec<FrameMetrics>> {
    let renders = images_in(dir);
    if renders.is_empty() || held_out.is_empty() {
        return Ok(Vec::new());
    }
    let pairs = pair_renders(held_out, &renders).with_context(|| format!("{}", dir.display()))?;
    score_pairs(&pairs)
}

/// The mean of the values present; None when none is.
fn mean_of(v: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let v: Vec<f64> = v.flatten().collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

fn pairs(s: &[FrameMetrics]) -> Vec<(&Path, &Path)> {
    s.iter()
        .map(|f| (f.test_image.as_path(), f.render.as_path()))
        .collect()
}

/// LPIPS of the test and novel frames in place, and of the novel views over their masks
/// ([`crate::masked::NovelMasks`]); the network, or why none. `Err` only for a mask
/// that cannot be read.
fn add_lpips(
    test: &mut [FrameMetrics],
    novel: &mut [FrameMetrics],
    how: LpipsUse,
    scene: &Scene,
) -> Result<(Option<String>, Option<String>)> {
    if test.is_empty() && novel.is_empty() {
        return Ok((None, None));
    }
    let (net, mut scores) = match score_sets(&[pairs(test), pairs(novel)], how) {
        Ok(found) => found,
        Err(why) => return Ok((None, Some(why))),
    };
    let novel_scores = scores.pop().unwrap_or_default();
    for (f, d) in test.iter_mut().zip(scores.concat()) {
        f.lpips = Some(d.distance);
    }
    let ids = crate::masked::moving_ids(&scene.root);
    for (k, (f, d)) in novel.iter_mut().zip(novel_scores).enumerate() {
        f.lpips = Some(d.distance);
        let masks = crate::masked::NovelMasks::read(&scene.root, k, ids.as_deref())?;
        let masked = |m: Option<Vec<bool>>| m.map(|m| d.masked_mean(&m)).transpose();
        f.masks.moving_lpips = masked(masks.moving)?.flatten();
        f.masks.covisible_lpips = masked(masks.covisible)?.flatten();
    }
    Ok((Some(net), None))
}

/// The 2D baselines: the model's report's when it has them (the deform stage writes
/// them), else computed from the scene; else None and why.
fn model_baselines(
    model: Option<&Path>,
    scene: &Scene,
) -> (Option<BaselineFigures>, Option<String>) {
    let reported = model
        .and_then(|e| std::fs::read(e.join("report.json")).ok())
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|v| baselines::from_report(&v));
    let found = match reported {
        Some(b) => Ok(Some(b)),
        None => baselines::compute(scene),
    };
    match found {
        Ok(Some(b)) => (Some(b.capped(PSNR_CAP)), None),
        Ok(None) => (None, Some("the scene has no test frames".into())),
        Err(e) => (None, Some(format!("{e:#}"))),
    }
}

/// The flow error of the flow stage's output against the scene's ground truth
/// (`gt/event_flow.bin`), else the EPE its report gives; and where it came from.
fn eval_flow(flows: Option<&Path>, scene_dir: &Path) -> Option<(FlowError, String)> {
    let gt_path = scene_dir.join("gt").join("event_flow.bin");
    if !gt_path.is_file() {
        return None;
    }
    let entry = flows?;
    if let Ok(Some(f)) = flow_error(&entry.join("flow"), &gt_path) {
        return Some((f, "gt/event_flow.bin".to_string()));
    }
    let epe = std::fs::read(entry.join("report.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|v| find_epe(&v))?;
    let flow = FlowError {
        epe_px_s: epe,
        ..FlowError::default()
    };
    Some((flow, "evflow report".to_string()))
}
