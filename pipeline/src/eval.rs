//! `degs eval RUN` and `degs compare RUN…`: image quality of the final renders on the
//! held-out test frames and on the novel views, the 2D baselines on the test frames
//! ([`crate::baselines`]), flow error where the stages report it.

use crate::baselines::{self, BaselineFigures};
use crate::record::RunRecord;
use crate::stages;
use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use scene::image_io::{Image, read_image};
use scene::manifest::Scene;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// metrics.json of a run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Metrics {
    pub experiment: String,
    /// The stage whose `renders/` were evaluated.
    pub render_stage: Option<String>,
    pub frames: Vec<FrameMetrics>,
    pub psnr_mean: Option<f64>,
    pub ssim_mean: Option<f64>,
    /// The same stage's renders of the novel views (`<renders>/novel/`) against the
    /// scene's novel-view images; empty when either has none.
    #[serde(default)]
    pub novel_frames: Vec<FrameMetrics>,
    #[serde(default)]
    pub novel_psnr_mean: Option<f64>,
    #[serde(default)]
    pub novel_ssim_mean: Option<f64>,
    /// The novel views beside their renders and the difference ([`crate::eval_sheet`]).
    #[serde(default)]
    pub novel_sheet: Option<PathBuf>,
    /// The novel views' PSNR over the pixels of moving objects and over the pixels some
    /// train view saw (means over the frames that have such pixels;
    /// [`crate::eval_masked`]); None where the scene cannot say.
    #[serde(default)]
    pub novel_moving_psnr_mean: Option<f64>,
    #[serde(default)]
    pub novel_covisible_psnr_mean: Option<f64>,
    /// The same means of SSIM over those pixels, and of the relative depth error over
    /// the moving objects' pixels ([`crate::eval_masked::MaskFigures`]).
    #[serde(default)]
    pub novel_moving_ssim_mean: Option<f64>,
    #[serde(default)]
    pub novel_covisible_ssim_mean: Option<f64>,
    #[serde(default)]
    pub novel_moving_depth_error_mean: Option<f64>,
    /// The render stage's Gaussians against the moving objects' true 3D motion.
    #[serde(default)]
    pub trajectory: Option<crate::eval_masked::Trajectory>,
    /// Mean LPIPS of the test frames and of the novel views (network `lpips_net`);
    /// None with the reason in `lpips_note` when the weights cannot be had.
    #[serde(default)]
    pub lpips_mean: Option<f64>,
    #[serde(default)]
    pub novel_lpips_mean: Option<f64>,
    #[serde(default)]
    pub lpips_net: Option<String>,
    #[serde(default)]
    pub lpips_note: Option<String>,
    /// The 2D baselines on the test frames (PSNR capped as the frames' are); None with
    /// the reason in `baselines_note` when they are not available.
    #[serde(default)]
    pub baselines: Option<BaselineFigures>,
    #[serde(default)]
    pub baselines_note: Option<String>,
    /// What the scene checks ([`scene::check`]) found: e.g. test frames that are train
    /// frames, whose scores are then not held-out scores.
    #[serde(default)]
    pub scene_findings: Vec<String>,
    /// Mean end-point error (px/s) of the per-event flow against the scene's ground
    /// truth (`gt/event_flow.bin`), over every non-noise event of every window; when
    /// the flow files cannot be read, the figure the evflow stage reported.
    pub flow_epe: Option<f64>,
    /// The same error in pixels over each event's window, and the fraction of events
    /// above 3 px.
    pub flow_err_px: Option<f64>,
    pub flow_outliers: Option<f64>,
    /// Events the flow figures are computed over.
    pub flow_events: usize,
    /// Where the flow figures come from: "gt/event_flow.bin" or "evflow report".
    pub flow_source: Option<String>,
    /// Total wall time of the stages that built this run's entries, seconds.
    pub total_stage_s: f64,
    pub stage_s: Vec<(String, f64)>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FrameMetrics {
    /// The held-out image (a test frame or a novel view).
    pub test_image: PathBuf,
    pub render: PathBuf,
    pub psnr: f64,
    pub ssim: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips: Option<f64>,
    /// Novel views: the scores on the moving objects' and the co-visible pixels.
    #[serde(flatten)]
    pub masks: crate::eval_masked::MaskFigures,
}

fn to_u8_levels(img: &Image) -> Vec<f32> {
    img.data
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round())
        .collect()
}

/// PSNR (dB) of two 8-bit images given as 0–255 levels; `f64::INFINITY` when equal.
/// The formula is `scene::metrics::psnr_u8`'s (levels ÷ 255 quantise back to the
/// same levels), so `degs eval` and the `gaussians` report agree.
pub fn psnr_u8(a: &[f32], b: &[f32]) -> f64 {
    let unit = |x: &[f32]| x.iter().map(|v| v / 255.0).collect::<Vec<f32>>();
    scene::metrics::psnr_u8(&unit(a), &unit(b))
}

/// Mean SSIM of interleaved images given as 0–255 levels: `scene::metrics::ssim_u8`
/// (11×11 Gaussian window, σ = 1.5, K1 = 0.01, K2 = 0.03, zero-padded windows averaged
/// over every pixel and channel, as the 3DGS/Deform-GS evaluation computes it), so
/// `degs eval` and the `gaussians` report give the same figure for the same renders.
pub fn ssim_u8(a: &[f32], b: &[f32], width: usize, height: usize, channels: usize) -> f64 {
    let planar = |x: &[f32]| {
        let unit: Vec<f32> = x.iter().map(|v| v / 255.0).collect();
        scene::metrics::interleaved_to_planar(&unit, width, height, channels)
    };
    scene::metrics::ssim_u8(&planar(a), &planar(b), width, height)
}

/// PSNR of identical images is reported as this (dB), so means and JSON stay finite.
pub const PSNR_CAP: f64 = 100.0;

/// Compare two images (3 channels after reading) on 8-bit levels: (PSNR, SSIM).
pub fn compare_images(test: &Path, render: &Path) -> Result<(f64, f64)> {
    let a = read_image(test)?;
    let b = read_image(render)?;
    if (a.width, a.height, a.channels) != (b.width, b.height, b.channels) {
        bail!(
            "{}: {}x{}x{} but the test image {} is {}x{}x{}",
            render.display(),
            b.width,
            b.height,
            b.channels,
            test.display(),
            a.width,
            a.height,
            a.channels
        );
    }
    let (qa, qb) = (to_u8_levels(&a), to_u8_levels(&b));
    Ok((
        psnr_u8(&qa, &qb).min(PSNR_CAP),
        ssim_u8(
            &qa,
            &qb,
            a.width as usize,
            a.height as usize,
            a.channels as usize,
        ),
    ))
}

/// Image files of `dir`, sorted by name.
fn images_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            matches!(
                p.extension()
                    .and_then(|e| e.to_str())
                    .map(str::to_ascii_lowercase)
                    .as_deref(),
                Some("png" | "jpg" | "jpeg")
            )
        })
        .collect();
    v.sort();
    v
}

/// Pair each test frame with a render: same file stem when the stage kept the names,
/// else in order when the counts agree.
fn pair_renders(tests: &[PathBuf], renders: &[PathBuf]) -> Result<Vec<(PathBuf, PathBuf)>> {
    let stem = |p: &Path| p.file_stem().map(|s| s.to_string_lossy().to_string());
    let by_stem: Vec<_> = tests
        .iter()
        .filter_map(|t| {
            renders
                .iter()
                .find(|r| stem(r) == stem(t))
                .map(|r| (t.clone(), r.clone()))
        })
        .collect();
    if by_stem.len() == tests.len() {
        return Ok(by_stem);
    }
    if renders.len() == tests.len() {
        return Ok(tests.iter().cloned().zip(renders.iter().cloned()).collect());
    }
    bail!(
        "{} test frames but {} renders, and their names do not match",
        tests.len(),
        renders.len()
    )
}

/// Look for a number under a key containing "epe" in a stage report.
fn find_epe(v: &serde_json::Value) -> Option<f64> {
    match v {
        serde_json::Value::Object(m) => m
            .iter()
            .find_map(|(k, x)| {
                k.to_ascii_lowercase()
                    .contains("epe")
                    .then(|| x.as_f64())
                    .flatten()
            })
            .or_else(|| m.values().find_map(find_epe)),
        _ => None,
    }
}

/// Per-event flow error of a directory of `.evflow` files against ground truth.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FlowError {
    /// Mean end-point error, px/s.
    pub epe_px_s: f64,
    /// Mean error in pixels over each event's window.
    pub err_px: Option<f64>,
    /// Fraction of events whose error over the window exceeds 3 px.
    pub outliers: Option<f64>,
    pub events: usize,
}

/// Compare every `flow_dir/*.evflow` with `gt_path` (`gt/event_flow.bin`), matching
/// events by their index into the scene's stream; noise events (ground-truth object
/// [`NOISE_ID`](synth::gt::NOISE_ID)) are left out. None when no event matches.
pub fn flow_error(flow_dir: &Path, gt_path: &Path) -> Result<Option<FlowError>> {
    let gt = synth::gt::read_event_flow_gt(gt_path)?;
    let mut files: Vec<PathBuf> = std::fs::read_dir(flow_dir)
        .with_context(|| format!("{}: cannot list", flow_dir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "evflow"))
        .collect();
    files.sort();
    let mut sums = evflow::predict::GtErrorSums::default();
    for f in &files {
        let flow = evflow::flowfile::read_evflow(f)?;
        if (flow.width, flow.height) != (gt.width, gt.height) {
            bail!(
                "{}: flow is {}x{} but the ground truth {} is {}x{}",
                f.display(),
                flow.width,
                flow.height,
                gt_path.display(),
                gt.width,
                gt.height
            );
        }
        sums.add(&flow, &gt, flow.t_b - flow.t_a);
    }
    Ok(sums.means().map(|(epe, px, out)| FlowError {
        epe_px_s: epe,
        err_px: Some(px),
        outliers: Some(out),
        events: sums.events,
    }))
}

/// Evaluate the run in `run_dir` (a `runs/<name>/` directory) and write its metrics.json;
/// LPIPS as `DEGS_LPIPS` says ([`crate::eval_lpips::LpipsUse::from_env`]).
pub fn eval_run(run_dir: &Path) -> Result<Metrics> {
    eval_run_with(run_dir, crate::eval_lpips::LpipsUse::from_env()?)
}

/// [`eval_run`] with LPIPS computed as `lpips` says.
pub fn eval_run_with(run_dir: &Path, lpips: crate::eval_lpips::LpipsUse) -> Result<Metrics> {
    let record = RunRecord::read(&run_dir.join("run.json"))?;
    let entry_of = |stage: &str| {
        record
            .stage(stage)
            .filter(|s| s.action.has_output())
            .and_then(|s| s.entry.clone())
    };
    let scene_dir = record
        .stages
        .first()
        .filter(|s| s.action.has_output())
        .and_then(|s| s.entry.clone())
        .with_context(|| format!("{}: the run has no scene", run_dir.display()))?;
    let scene = Scene::open(&scene_dir)?;
    let scene_findings = scene::check::check_scene(&scene)?
        .iter()
        .map(ToString::to_string)
        .collect();
    let images = |m: &scene::manifest::Manifest| -> Vec<PathBuf> {
        m.frames.iter().map(|f| scene.image_path(f)).collect()
    };

    let (render_stage, mut frames) = eval_renders(&entry_of, &images(&scene.test))?;
    let mut novel_frames = match &render_stage {
        Some(stage) => eval_novel(&entry_of, stage, &images(&scene.novel))?,
        None => Vec::new(),
    };
    let novel_pairs = pairs(&novel_frames);
    let depth_dir = render_stage.as_deref().and_then(|st| {
        Some(
            entry_of(st)?
                .join(stages::find(st)?.renders?)
                .join("novel_depth"),
        )
    });
    let masks =
        crate::eval_masked::novel_masks(&scene_dir, &novel_pairs, depth_dir.as_deref(), PSNR_CAP)?;
    let novel_sheet =
        crate::eval_sheet::write_sheet(&novel_pairs, &run_dir.join("novel_sheet.png"))?;
    for (f, m) in novel_frames.iter_mut().zip(&masks) {
        f.masks = *m;
    }
    let trajectory = render_stage
        .as_deref()
        .and_then(entry_of)
        .and_then(|e| crate::eval_masked::trajectory(&e));
    let (lpips_net, lpips_note) = add_lpips(&mut frames, &mut novel_frames, lpips);
    let mean = |frames: &[FrameMetrics], f: &dyn Fn(&FrameMetrics) -> f64| {
        (!frames.is_empty()).then(|| frames.iter().map(f).sum::<f64>() / frames.len() as f64)
    };
    let lpips_mean = |f: &[FrameMetrics]| crate::eval_lpips::mean_all(f.iter().map(|f| f.lpips));
    let (baselines, baselines_note) = run_baselines(&entry_of, &scene);
    let (flow, flow_source) = eval_flow(&entry_of, &scene_dir).unzip();
    let stage_s: Vec<(String, f64)> = record
        .stages
        .iter()
        .filter(|s| s.action.has_output())
        .map(|s| (s.stage.clone(), s.built_wall_s.unwrap_or(s.wall_s)))
        .collect();
    let metrics = Metrics {
        experiment: record.experiment.clone(),
        render_stage,
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
        total_stage_s: stage_s.iter().map(|(_, t)| t).sum(),
        stage_s,
    };
    scene::atomic::write_json_atomic(&run_dir.join("metrics.json"), &metrics)?;
    Ok(metrics)
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

/// LPIPS of the test and novel frames in place; the network, or why none.
fn add_lpips(
    test: &mut [FrameMetrics],
    novel: &mut [FrameMetrics],
    how: crate::eval_lpips::LpipsUse,
) -> (Option<String>, Option<String>) {
    if test.is_empty() && novel.is_empty() {
        return (None, None);
    }
    match crate::eval_lpips::score_sets(&[pairs(test), pairs(novel)], how) {
        Ok((net, scores)) => {
            for (f, d) in test.iter_mut().chain(novel.iter_mut()).zip(scores.concat()) {
                f.lpips = Some(d);
            }
            (Some(net), None)
        }
        Err(why) => (None, Some(why)),
    }
}

/// PSNR/SSIM of the renders of the last stage in run order that has them (its name and
/// the figures per test frame).
fn eval_renders(
    entry_of: &dyn Fn(&str) -> Option<PathBuf>,
    tests: &[PathBuf],
) -> Result<(Option<String>, Vec<FrameMetrics>)> {
    for stage in stages::render_stages() {
        let (Some(entry), Some(dir)) = (entry_of(stage.name), stage.renders) else {
            continue;
        };
        let renders = images_in(&entry.join(dir));
        if renders.is_empty() {
            continue;
        }
        let pairs = pair_renders(tests, &renders)
            .with_context(|| format!("{}", entry.join(dir).display()))?;
        return Ok((Some(stage.name.to_string()), score_pairs(&pairs)?));
    }
    Ok((None, Vec::new()))
}

/// PSNR/SSIM of each (held-out image, render) pair.
fn score_pairs(pairs: &[(PathBuf, PathBuf)]) -> Result<Vec<FrameMetrics>> {
    pairs
        .par_iter()
        .map(|(t, r)| {
            let (psnr, ssim) = compare_images(t, r)?;
            Ok(FrameMetrics {
                test_image: t.clone(),
                render: r.clone(),
                psnr,
                ssim,
                lpips: None,
                masks: Default::default(),
            })
        })
        .collect()
}

/// PSNR/SSIM of stage `stage`'s renders of the novel views (`<renders>/novel/`);
/// empty when the scene has no novel views or the stage rendered none (an entry
/// built before the split existed).
fn eval_novel(
    entry_of: &dyn Fn(&str) -> Option<PathBuf>,
    stage: &str,
    novel: &[PathBuf],
) -> Result<Vec<FrameMetrics>> {
    let dir =
        stages::find(stage).and_then(|s| Some(entry_of(stage)?.join(s.renders?).join("novel")));
    let Some(dir) = dir.filter(|_| !novel.is_empty()) else {
        return Ok(Vec::new());
    };
    let renders = images_in(&dir);
    if renders.is_empty() {
        return Ok(Vec::new());
    }
    let pairs = pair_renders(novel, &renders).with_context(|| format!("{}", dir.display()))?;
    score_pairs(&pairs)
}

/// The run's 2D baselines: the deform stage's report's when it ran, else computed from
/// the scene; else None and why.
fn run_baselines(
    entry_of: &dyn Fn(&str) -> Option<PathBuf>,
    scene: &Scene,
) -> (Option<BaselineFigures>, Option<String>) {
    let reported = entry_of("deform")
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

/// What `degs eval` prints under its table: the model's figures on the test frames
/// beside the 2D baselines', and on the novel views.
pub fn baseline_block(m: &Metrics) -> String {
    let both = |p: Option<f64>, s: Option<f64>| p.zip(s);
    let baselines = m
        .baselines
        .as_ref()
        .ok_or(m.baselines_note.as_deref().unwrap_or("unknown"));
    baselines::format_block(
        m.render_stage.as_deref().unwrap_or("no"),
        both(m.psnr_mean, m.ssim_mean),
        both(m.novel_psnr_mean, m.novel_ssim_mean),
        baselines,
    )
}

/// The flow error of the stage that writes per-event flow, against the scene's ground
/// truth (`gt/event_flow.bin`), else the EPE its report gives; and where it came from.
fn eval_flow(
    entry_of: &dyn Fn(&str) -> Option<PathBuf>,
    scene_dir: &Path,
) -> Option<(FlowError, String)> {
    let gt_path = scene_dir.join("gt").join("event_flow.bin");
    if !gt_path.is_file() {
        return None;
    }
    let stage = stages::STAGES.iter().find(|s| s.event_flow.is_some())?;
    let entry = entry_of(stage.name)?;
    let flow_dir = entry.join(stage.event_flow?);
    if let Ok(Some(f)) = flow_error(&flow_dir, &gt_path) {
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
    Some((flow, format!("{} report", stage.name)))
}

/// The table of `degs compare`.
pub fn compare_table(runs: &[(String, Metrics)]) -> String {
    let f = |v: Option<f64>, p: usize| v.map_or("-".to_string(), |x| format!("{x:.p$}"));
    let mut s = format!(
        "{:<24} {:>8} {:>7} {:>7} {:>9} {:>10} {:>11} {:>8} {:>9} {:>10} {:>8} {:>7} {:>11}\n",
        "run",
        "PSNR dB",
        "SSIM",
        "frames",
        "novel dB",
        "novel SSIM",
        "EPE px/s",
        "EPE px",
        "outliers",
        "renders",
        "time s",
        "LPIPS",
        "novel LPIPS"
    );
    for (name, m) in runs {
        s += &format!(
            "{:<24} {:>8} {:>7} {:>7} {:>9} {:>10} {:>11} {:>8} {:>9} {:>10} {:>8.1} {:>7} {:>11}\n",
            name,
            f(m.psnr_mean, 2),
            f(m.ssim_mean, 4),
            m.frames.len(),
            f(m.novel_psnr_mean, 2),
            f(m.novel_ssim_mean, 4),
            f(m.flow_epe, 3),
            f(m.flow_err_px, 3),
            m.flow_outliers
                .map_or("-".to_string(), |x| format!("{:.1}%", 100.0 * x)),
            m.render_stage.as_deref().unwrap_or("-"),
            m.total_stage_s,
            f(m.lpips_mean, 4),
            f(m.novel_lpips_mean, 4)
        );
    }
    s
}

#[cfg(test)]
#[path = "eval_tests.rs"]
mod tests;
