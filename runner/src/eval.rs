//! `degs eval RUN` and `degs compare RUN…`: the `evaluate` stage (its own binary, crate
//! `degs-evaluate`) run over a finished run's outputs (the scene, the renders of the last
//! stage that wrote them, the per-event flow) and cached like any stage
//! (`cache/eval/<key>/`, its key from the `evaluate` binary's hash, its settings and its
//! inputs' keys and places). Its `metrics.json` ([`Metrics`]) is completed with the run's
//! name, render stage and stage times and written to `runs/<name>/metrics.json`, its
//! contact sheet copied to `runs/<name>/novel_sheet.png`.

use crate::baselines;
use crate::context::Context;
use crate::external::{self, External, Given};
use crate::progress::Progress;
use crate::record::RunRecord;
use crate::stages;
use anyhow::{Context as _, Result, bail};
pub use scene::evaluation::{FrameMetrics, Metrics, PSNR_CAP, Score};
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// The evaluation's node name and cache directory.
pub const STAGE: &str = "eval";
/// Its binary and the cargo package that builds it.
pub const BINARY: &str = "evaluate";
pub(crate) const PACKAGE: &str = "degs-evaluate";

/// How the evaluation gets the LPIPS weights, from `DEGS_LPIPS`: `fetch` (unset: download
/// at first use), `cached` (only weights already in the cache) or `off`.
pub(crate) fn lpips_from_env() -> Result<&'static str> {
    match std::env::var("DEGS_LPIPS").as_deref() {
        Err(_) | Ok("") | Ok("fetch") => Ok("fetch"),
        Ok("cached") => Ok("cached"),
        Ok("off") => Ok("off"),
        Ok(v) => bail!("DEGS_LPIPS={v}: expected fetch, cached or off"),
    }
}

/// Evaluate the run in `run_dir` (a `runs/<name>/` directory) and write its metrics.json;
/// LPIPS as `DEGS_LPIPS` says.
pub fn eval_run(run_dir: &Path, ctx: &Context, progress: &Progress) -> Result<Metrics> {
    eval_run_with(run_dir, ctx, lpips_from_env()?, progress)
}

/// The last stage in run order whose entry holds renders, with that entry.
fn render_entry(entry_of: &dyn Fn(&str) -> Option<PathBuf>) -> Option<(&'static str, PathBuf)> {
    stages::render_stages().find_map(|s| {
        let entry = entry_of(s.name)?;
        let dir = entry.join(s.renders?);
        let has_images = std::fs::read_dir(&dir).ok()?.flatten().any(|e| {
            let ext = e.path().extension().map(|x| x.to_ascii_lowercase());
            matches!(
                ext.as_ref().and_then(|x| x.to_str()),
                Some("png" | "jpg" | "jpeg")
            )
        });
        has_images.then_some((s.name, entry))
    })
}

/// [`eval_run`] with LPIPS `lpips` (`fetch`, `cached` or `off`): the `evaluate` stage
/// over the run's outputs, from the cache when it ran on the same inputs before.
pub fn eval_run_with(
    run_dir: &Path,
    ctx: &Context,
    lpips: &str,
    progress: &Progress,
) -> Result<Metrics> {
    let record = RunRecord::read(&run_dir.join("run.json"))?;
    let output = |stage: &str| external::output_of(&record, stage);
    let scene = external::scene_of(&record)
        .with_context(|| format!("{}: the run has no scene", run_dir.display()))?;
    let render = render_entry(&|s| output(s).map(|(e, _)| e));
    let flows = stages::STAGES
        .iter()
        .find(|s| s.event_flow.is_some())
        .and_then(|s| output(s.name));

    // The run's outputs as they are, then the evaluation over them.
    let given = |flag: &'static str, name: &str, (entry, key): (PathBuf, String)| Given {
        flag,
        name: name.to_string(),
        entry,
        key,
    };
    let mut inputs = vec![given("--scene", stages::SCENE, scene)];
    if let Some((stage, entry)) = &render {
        let key = output(stage).map(|(_, k)| k).unwrap_or_default();
        inputs.push(given("--model", stage, (entry.clone(), key)));
    }
    if let Some(f) = flows {
        inputs.push(given("--flows", "evflow", f));
    }
    let mut settings = Table::new();
    settings.insert("lpips".into(), Value::String(lpips.into()));
    let ext = External {
        what: "the evaluation",
        stage: STAGE,
        binary: BINARY,
        package: PACKAGE,
        verb: None,
        settings,
    };
    let where_ = (record.experiment.as_str(), record.cache_root.clone());
    let done = external::run_external(&ext, inputs, where_, ctx, progress)?;
    let entry = done.entry.clone().unwrap_or_default();
    let path = entry.join("metrics.json");
    let bytes = std::fs::read(&path).with_context(|| format!("{}: cannot read", path.display()))?;
    let mut metrics: Metrics = serde_json::from_slice(&bytes)
        .with_context(|| format!("{}: not the evaluation's metrics", path.display()))?;
    metrics.experiment = record.experiment.clone();
    metrics.render_stage = render.map(|(s, _)| s.to_string());
    metrics.stage_s = record
        .stages
        .iter()
        .filter(|s| s.action.has_output())
        .map(|s| (s.stage.clone(), s.built_wall_s.unwrap_or(s.wall_s)))
        .collect();
    metrics.total_stage_s = metrics.stage_s.iter().map(|(_, t)| t).sum();
    let mut stages = record.stages.clone();
    for s in stages.iter_mut().filter(|s| s.action.has_output()) {
        if let Some(entry) = &s.entry {
            s.warnings = crate::record::report_warnings(entry);
        }
    }
    metrics.warnings = crate::record::warning_lines(&stages);
    for sheet in [
        &mut metrics.novel_sheet,
        &mut metrics.test_sheet,
        &mut metrics.test_error_map,
    ] {
        if let Some(name) = sheet.as_ref() {
            let to = run_dir.join(name);
            std::fs::copy(entry.join(name), &to)
                .with_context(|| format!("{}: cannot write", to.display()))?;
            *sheet = Some(to);
        }
    }
    copy_baselines(&entry.join("baselines"), &run_dir.join("baselines"))?;
    scene::atomic::write_json_atomic(&run_dir.join("metrics.json"), &metrics)?;
    Ok(metrics)
}

/// The 2D baselines' images of the evaluation (`baselines/NAME/NNNN.png`) into the run
/// directory, replacing an earlier evaluation's; nothing when it wrote none.
fn copy_baselines(from: &Path, to: &Path) -> Result<()> {
    if to.is_dir() {
        std::fs::remove_dir_all(to).with_context(|| format!("{}: cannot replace", to.display()))?;
    }
    if !from.is_dir() {
        return Ok(());
    }
    for dir in std::fs::read_dir(from).with_context(|| format!("{}", from.display()))? {
        let dir = dir?.path();
        let out = to.join(dir.file_name().unwrap_or_default());
        std::fs::create_dir_all(&out)
            .with_context(|| format!("{}: cannot write", out.display()))?;
        for f in std::fs::read_dir(&dir).with_context(|| format!("{}", dir.display()))? {
            let f = f?.path();
            let dest = out.join(f.file_name().unwrap_or_default());
            std::fs::copy(&f, &dest)
                .with_context(|| format!("{}: cannot write", dest.display()))?;
        }
    }
    Ok(())
}

/// What `degs eval` prints under its table: the model's figures on the test frames
/// beside the 2D baselines', and on the novel views.
pub fn baseline_block(m: &Metrics) -> String {
    let both = |p: Option<f64>, s: Option<f64>, l: Option<f64>, moving, still| {
        let ((mp, ml), (sp, sl)) = (moving, still);
        p.zip(s).map(|(psnr_mean, ssim_mean)| Score {
            psnr_mean,
            ssim_mean,
            lpips_mean: l,
            moving_psnr_mean: mp,
            moving_lpips_mean: ml,
            still_psnr_mean: sp,
            still_lpips_mean: sl,
        })
    };
    let baselines = m
        .baselines
        .as_ref()
        .ok_or(m.baselines_note.as_deref().unwrap_or("unknown"));
    baselines::format_block(
        m.render_stage.as_deref().unwrap_or("no"),
        both(
            m.psnr_mean,
            m.ssim_mean,
            m.lpips_mean,
            (m.moving_psnr_mean, m.moving_lpips_mean),
            (m.still_psnr_mean, m.still_lpips_mean),
        ),
        both(
            m.novel_psnr_mean,
            m.novel_ssim_mean,
            m.novel_lpips_mean,
            (m.novel_moving_psnr_mean, m.novel_moving_lpips_mean),
            (None, None),
        ),
        baselines,
    )
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
