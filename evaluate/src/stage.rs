//! The `evaluate` stage: a model's renders (`MODEL/renders/`, `renders/novel/`,
//! `renders/novel_depth/`) against the scene's held-out test frames and novel views,
//! the 2D baselines on the test frames, the flow error against the scene's ground
//! truth. Writes `OUT/metrics.json` ([`scene::evaluation::Metrics`]), `OUT/novel_sheet.png`
//! and `OUT/settings.toml`, all at once or not at all.

use crate::baselines;
use crate::baselines::BaselineImages;
use crate::flow::{FlowError, find_epe, flow_error};
use crate::images::{images_in, pair_renders, score_pairs};
use crate::lpips_use::{LpipsUse, mean_all, score_sets};
use crate::masked::split_masks;
use crate::settings::EvalSettings;
use anyhow::{Context, Result};
use scene::atomic::{AtomicDir, OutputRule, write_json_atomic};
use scene::evaluation::{BaselineFigures, FrameMetrics, Metrics, PSNR_CAP, Score};
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
    let owned = |f: &[FrameMetrics]| -> Vec<(PathBuf, PathBuf)> {
        f.iter()
            .map(|f| (f.test_image.clone(), f.render.clone()))
            .collect()
    };
    let (test_owned, novel_owned) = (owned(&frames), owned(&novel_frames));
    let (test_pairs, novel_pairs) = (borrowed(&test_owned), borrowed(&novel_owned));
    let depth_dir = renders.as_ref().map(|r| r.join("novel_depth"));
    let cap = PSNR_CAP;
    let test_masks = split_masks(inputs.scene, "test", &test_pairs, None, cap)?;
    let masks = split_masks(
        inputs.scene,
        "novel",
        &novel_pairs,
        depth_dir.as_deref(),
        cap,
    )?;
    let novel_rows: Vec<(&Path, Vec<&Path>)> =
        novel_pairs.iter().map(|&(g, r)| (g, vec![r])).collect();
    let novel_sheet =
        crate::sheet::write_sheet(&novel_rows, &dir.join(SHEET))?.map(|_| PathBuf::from(SHEET));
    for (f, m) in frames.iter_mut().zip(&test_masks) {
        f.masks = *m;
    }
    for (f, m) in novel_frames.iter_mut().zip(&masks) {
        f.masks = *m;
    }
    let trajectory = inputs.model.and_then(crate::masked::trajectory);
    let (mut baselines, baselines_note, base_images) = model_baselines(&scene, dir);
    let test_images = images(&scene.test);
    let base_pairs: Vec<(&str, Vec<(&Path, &Path)>)> = base_images
        .iter()
        .map(|(name, paths)| {
            let p = test_images.iter().zip(paths);
            (*name, p.map(|(a, b)| (a.as_path(), b.as_path())).collect())
        })
        .collect();
    if let Some(b) = baselines.as_mut() {
        for (name, pairs) in &base_pairs {
            let m = split_masks(inputs.scene, "test", pairs, None, cap)?;
            if let Some(score) = baseline_score(b, name) {
                score.moving_psnr_mean = mean_of(m.iter().map(|f| f.moving_psnr));
                score.still_psnr_mean = mean_of(m.iter().map(|f| f.still_psnr));
            }
        }
    }
    let mut sets = vec![("test", test_pairs.clone()), ("novel", novel_pairs.clone())];
    sets.extend(base_pairs.iter().map(|(_, p)| ("test", p.clone())));
    let (lpips_net, lpips_note) = if sets.iter().all(|(_, p)| p.is_empty()) {
        (None, None)
    } else {
        match lpips_sets(&sets, s.lpips, &scene)? {
            Ok((net, mut scores)) => {
                let base_scores = scores.split_off(2);
                let novel_scores = scores.pop().unwrap_or_default();
                for (f, d) in frames.iter_mut().zip(scores.into_iter().flatten()) {
                    (f.lpips, f.masks.moving_lpips) = (Some(d.whole), d.moving);
                    f.masks.still_lpips = d.still;
                }
                for (f, d) in novel_frames.iter_mut().zip(novel_scores) {
                    f.lpips = Some(d.whole);
                    (f.masks.moving_lpips, f.masks.covisible_lpips) = (d.moving, d.covisible);
                    f.masks.still_lpips = d.still;
                }
                if let Some(b) = baselines.as_mut() {
                    for ((name, _), sc) in base_pairs.iter().zip(base_scores) {
                        if let Some(score) = baseline_score(b, name) {
                            score.lpips_mean = mean_all(sc.iter().map(|d| Some(d.whole)));
                            score.moving_lpips_mean = mean_of(sc.iter().map(|d| d.moving));
                            score.still_lpips_mean = mean_of(sc.iter().map(|d| d.still));
                        }
                    }
                }
                (Some(net), None)
            }
            Err(why) => (None, Some(why)),
        }
    };
    let (test_sheet, test_error_map) =
        crate::sheet::test_sheets(&test_images, &test_pairs, &base_images, dir)?;
    let mean = |frames: &[FrameMetrics], f: &dyn Fn(&FrameMetrics) -> f64| {
        (!frames.is_empty()).then(|| frames.iter().map(f).sum::<f64>() / frames.len() as f64)
    };
    let lpips_mean = |f: &[FrameMetrics]| mean_all(f.iter().map(|f| f.lpips));
    let (flow, flow_source) = eval_flow(inputs.flows, inputs.scene).unzip();
    Ok(Metrics {
        psnr_mean: mean(&frames, &|f| f.psnr),
        ssim_mean: mean(&frames, &|f| f.ssim),
        lpips_mean: lpips_mean(&frames),
        novel_lpips_mean: lpips_mean(&novel_frames),
        moving_psnr_mean: mean_of(frames.iter().map(|f| f.masks.moving_psnr)),
        moving_lpips_mean: mean_of(frames.iter().map(|f| f.masks.moving_lpips)),
        still_psnr_mean: mean_of(frames.iter().map(|f| f.masks.still_psnr)),
        still_lpips_mean: mean_of(frames.iter().map(|f| f.masks.still_lpips)),
        test_sheet,
        test_error_map,
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
        novel_covisible_still_psnr_mean: mean_of(
            novel_frames.iter().map(|f| f.masks.covisible_still_psnr),
        ),
        novel_covisible_still_ssim_mean: mean_of(
            novel_frames.iter().map(|f| f.masks.covisible_still_ssim),
        ),
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

fn borrowed(s: &[(PathBuf, PathBuf)]) -> Vec<(&Path, &Path)> {
    s.iter().map(|(a, b)| (a.as_path(), b.as_path())).collect()
}

/// The figures of baseline `name` (`nearest`, `blend`, `events`) in `b`.
fn baseline_score<'a>(b: &'a mut BaselineFigures, name: &str) -> Option<&'a mut Score> {
    match name {
        "nearest" => Some(&mut b.nearest),
        "blend" => Some(&mut b.blend),
        "events" => b.events.as_mut(),
        _ => None,
    }
}

/// One pair's LPIPS: the whole image's, and the map's mean over the view's moving-object,
/// co-visible and still (no moving object) pixels (None where the scene lacks the mask).
struct PairLpips {
    whole: f64,
    moving: Option<f64>,
    covisible: Option<f64>,
    still: Option<f64>,
}

/// LPIPS of each `(split, pairs)` set, per pair ([`PairLpips`]; masks `gt/SPLIT/…`);
/// `Ok(Err(why))` when LPIPS cannot be had. `Err` only for a mask that cannot be read.
type Lpipsed = Vec<Vec<PairLpips>>;
fn lpips_sets(
    sets: &[(&str, Vec<(&Path, &Path)>)],
    how: LpipsUse,
    scene: &Scene,
) -> Result<std::result::Result<(String, Lpipsed), String>> {
    let pairs: Vec<Vec<(&Path, &Path)>> = sets.iter().map(|(_, p)| p.clone()).collect();
    let (net, scores) = match score_sets(&pairs, how) {
        Ok(found) => found,
        Err(why) => return Ok(Err(why)),
    };
    let ids = crate::masked::moving_ids(&scene.root)?;
    let mut out = Vec::with_capacity(sets.len());
    for ((split, _), set) in sets.iter().zip(scores) {
        let mut figures = Vec::with_capacity(set.len());
        for (k, d) in set.into_iter().enumerate() {
            let masks = crate::masked::ViewMasks::read(&scene.root, split, k, &ids)?;
            let masked = |m: Option<&Vec<bool>>| m.map(|m| d.masked_mean(m)).transpose();
            let still = masks.moving.as_deref().map(crate::masked::still_of);
            figures.push(PairLpips {
                whole: d.distance,
                moving: masked(masks.moving.as_ref())?.flatten(),
                covisible: masked(masks.covisible.as_ref())?.flatten(),
                still: masked(still.as_ref())?.flatten(),
            });
        }
        out.push(figures);
    }
    Ok(Ok((net, out)))
}

/// The 2D baselines computed from the scene, their images under `dir/baselines/`; else
/// None and why. (The deform stage's report holds its own figures of them, at its
/// contrast threshold; the evaluation scores them itself, so that each comes with its
/// images, LPIPS and the moving pixels' figures.)
fn model_baselines(
    scene: &Scene,
    dir: &Path,
) -> (Option<BaselineFigures>, Option<String>, BaselineImages) {
    match baselines::compute(scene, dir) {
        Ok(Some((b, images))) => (Some(b.capped(PSNR_CAP)), None, images),
        Ok(None) => (
            None,
            Some("the scene has no test frames".into()),
            Vec::new(),
        ),
        Err(e) => (None, Some(format!("{e:#}")), Vec::new()),
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
