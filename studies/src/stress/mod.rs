//! `degs stress STRESS.toml`: stability where methods fail. Builds variants of the base
//! experiment's scene (lower frame rate, event noise, hot pixels, a wrong claimed
//! contrast threshold, motion blur, a gap without events, a burst, corrupt files:
//! [`variants`]), runs DEGS and RGB-only on each through the runner (the sweep loop:
//! shared stages run once, a re-run resumes), evaluates them and writes
//! `runs/<name>/stress.json`, `report.md` and one chart per stress.
//!
//! A transformed scene is a cache entry `cache/stress-scene/<key>/` written by `synth
//! stress` ([`synth::transform`]) run as a cached node, its key blake3 of the `synth`
//! binary's hash, the transform's settings and the clean scene's key and place; the runs
//! read it as a scene directory.

pub mod chart;
pub mod report;
pub mod variants;

use anyhow::{Context as _, Result, bail};
use report::{StressRecord, StressResult, VariantScene};
use runner::context::Context;
use runner::experiment::Experiment;
use runner::external::{self, External, Given};
use runner::progress::Progress;
use runner::record::{Action, RunRecord};
use runner::run::{self, RunOptions};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use synth::transform::{SceneTransform, TransformSummary};
use variants::{METHODS, Recipe, StressFile, StressKind, Variant};

/// The cache stage name of transformed scenes.
pub const STAGE: &str = "stress-scene";

/// The cache entry of `t` applied to the scene `base` (keyed `base_key`), made when
/// missing by `synth stress` run as a cached node ([`runner::external`]: its key from
/// the `synth` binary's hash, the transform's settings and the clean scene's key and
/// place; locked like any stage). `name` is the stress run's (its settings file goes
/// under `runs/<name>/`).
pub(crate) fn transformed_scene(
    ctx: &Context,
    (base, base_key): (&Path, &str),
    t: &SceneTransform,
    name: &str,
) -> Result<(PathBuf, TransformSummary)> {
    let settings = match toml::Value::try_from(t)? {
        toml::Value::Table(tb) => runner::canon::canonical_table(&tb),
        _ => toml::Table::new(),
    };
    let ext = External {
        what: "the stress transform (synth stress)",
        stage: STAGE,
        binary: runner::stages::SYNTH,
        package: "degs-synth",
        verb: Some("stress"),
        settings,
    };
    let given = vec![Given {
        flag: "--scene",
        name: runner::stages::SCENE.to_string(),
        entry: base.to_path_buf(),
        key: base_key.to_string(),
    }];
    let quiet = Progress::new(true);
    let done = external::run_external(&ext, given, (name, ctx.cache.root.clone()), ctx, &quiet)?;
    let entry = done.entry.unwrap_or_default();
    let p = entry.join("stress.json");
    let bytes = std::fs::read(&p).with_context(|| format!("{}: cannot read", p.display()))?;
    let summary = serde_json::from_slice(&bytes)
        .with_context(|| format!("{}: not a transform summary", p.display()))?;
    Ok((entry, summary))
}

/// Run the stress file; the record is also written to `runs/<name>/stress.json`.
pub fn run(
    file: &StressFile,
    ctx: &Context,
    opts: &RunOptions,
    progress: &Progress,
) -> Result<StressRecord> {
    let variants = file.variants()?;
    let out_dir = ctx.cache.run_dir(&file.name);
    std::fs::create_dir_all(&out_dir)
        .with_context(|| format!("{}: cannot create", out_dir.display()))?;

    // the clean scene first: every transform starts from it
    let clean = &variants[0];
    let clean_exps = file.experiments(clean, Path::new("/"))?;
    progress.note(&format!("stress {}: the clean scene", file.name));
    let scene_only = RunOptions {
        until: Some(0),
        ..opts.clone()
    };
    let rec = run::run(&clean_exps[0], ctx, &scene_only, progress)?;
    let scene_stage = &rec.stages[0];
    let (Some(base_dir), Some(base_key)) = (scene_stage.entry.clone(), scene_stage.key.clone())
    else {
        bail!("{}: the clean scene could not be made", file.file.display());
    };
    if !scene_stage.action.has_output() {
        bail!(
            "{}: the clean scene could not be made: {}",
            file.file.display(),
            scene_stage.error.clone().unwrap_or_default()
        );
    }

    let mut scenes = Vec::new();
    let mut exps: Vec<(Experiment, BTreeMap<String, serde_json::Value>)> = Vec::new();
    let mut owner: Vec<(usize, &str)> = Vec::new();
    for (vi, v) in variants.iter().enumerate() {
        let mut vs = VariantScene {
            variant: v.name.clone(),
            ..Default::default()
        };
        let dir = match &v.recipe {
            Recipe::Transform(t) => {
                progress.note(&format!("stress {}: scene {}", file.name, v.name));
                match transformed_scene(ctx, (&base_dir, &base_key), t, &file.name) {
                    Ok((d, s)) => {
                        vs.transform = Some(s);
                        Some(d)
                    }
                    Err(e) => {
                        vs.error = Some(format!("{e:#}"));
                        None
                    }
                }
            }
            _ => Some(PathBuf::from("/")),
        };
        if let Some(d) = &dir {
            if matches!(v.recipe, Recipe::Transform(_)) {
                vs.scene = Some(d.clone());
            }
            for (exp, (method, _)) in file.experiments(v, d)?.into_iter().zip(METHODS) {
                let mut values = BTreeMap::new();
                values.insert("variant".into(), serde_json::json!(v.name));
                values.insert("method".into(), serde_json::json!(method));
                exps.push((exp, values));
                owner.push((vi, method));
            }
        }
        scenes.push(vs);
    }
    let points: Vec<crate::sweep::Point> = exps
        .into_iter()
        .map(|(experiment, values)| crate::sweep::Point {
            values: values
                .into_iter()
                .map(|(k, v)| (k, toml::Value::String(v.as_str().unwrap_or("").into())))
                .collect(),
            experiment,
        })
        .collect();
    let written = crate::sweep_run::write_points(&file.name, points, ctx)?;
    let axes = vec![
        (
            "variant".to_string(),
            variants.iter().map(|v| serde_json::json!(v.name)).collect(),
        ),
        (
            "method".to_string(),
            METHODS.iter().map(|(m, _)| serde_json::json!(m)).collect(),
        ),
    ];
    crate::sweep_run::run_experiments(&file.sweep, axes, &written, ctx, opts, progress)?;

    let mut results = Vec::new();
    for (v, vs) in variants.iter().zip(&scenes) {
        for (method, _) in METHODS {
            let ran = owner
                .iter()
                .position(|&(vi, m)| variants[vi].name == v.name && m == method)
                .map(|i| &written[i].0);
            results.push(result_of(ctx, file, v, vs, method, ran));
        }
    }
    let record = StressRecord {
        stress: file.name.clone(),
        stress_file: file.file.clone(),
        base: match &file.base.scene {
            runner::experiment::SceneSource::Synth(c) => format!("synthetic `{}`", c.preset),
            runner::experiment::SceneSource::Dir(d) => d.display().to_string(),
        },
        sensor: file.sensor,
        neutral_levels: StressKind::ALL
            .iter()
            .filter_map(|&k| file.neutral_level(k).map(|l| (k, l)))
            .collect(),
        burst_note: file
            .stresses
            .iter()
            .find(|(k, _)| *k == StressKind::BurstEvents)
            .map(|_| {
                let [w, h] = file.settings.burst_reference_sensor;
                format!(
                    "a level counts events on a {w}×{h} sensor within {} s; on this {}×{} \
                     sensor the burst has as many events per pixel (10 M → {}).",
                    file.settings.burst_s,
                    file.sensor.0,
                    file.sensor.1,
                    file.scaled_burst(1e7)
                )
            }),
        scenes,
        results,
    };
    scene::atomic::write_json_atomic(&out_dir.join("stress.json"), &record)?;
    scene::atomic::write_bytes_atomic(
        &out_dir.join("report.md"),
        report::markdown(&record).as_bytes(),
    )?;
    chart::write_charts(&record, &out_dir)?;
    Ok(record)
}

/// The figures (or the error) of one variant run with one method.
fn result_of(
    ctx: &Context,
    file: &StressFile,
    v: &Variant,
    vs: &VariantScene,
    method: &str,
    exp: Option<&Experiment>,
) -> StressResult {
    let mut r = StressResult {
        variant: v.name.clone(),
        stress: v.kind,
        level: v.level,
        label: v.label.clone(),
        method: method.into(),
        experiment: file.experiment_name(v, method),
        status: "not run".into(),
        train_frames: vs.transform.as_ref().map(|t| t.train_frames),
        error: vs.error.clone(),
        ..Default::default()
    };
    let Some(exp) = exp else { return r };
    let run_dir = ctx.cache.run_dir(&exp.name);
    let record = match RunRecord::read(&run_dir.join("run.json")) {
        Ok(rec) => rec,
        Err(e) => {
            r.error = Some(format!("{e:#}"));
            return r;
        }
    };
    r.status = record.status.clone();
    if let Some(s) = record.stages.iter().find(|s| s.action == Action::Failed) {
        r.error = Some(format!(
            "{}: {}",
            s.stage,
            s.error.clone().unwrap_or_default()
        ));
        return r;
    }
    r.deform_s = record
        .stage("deform")
        .filter(|s| s.action.has_output())
        .map(|s| s.built_wall_s.unwrap_or(s.wall_s));
    let quiet = runner::progress::Progress::new(true);
    match runner::eval::eval_run(&run_dir, ctx, &quiet) {
        Ok(m) => {
            let mut keep = |name: &str, v: Option<f64>| -> Option<f64> {
                let v = v?;
                if v.is_finite() {
                    Some(v)
                } else {
                    r.non_finite.push(name.into());
                    None
                }
            };
            r.psnr = keep("psnr", m.psnr_mean);
            r.ssim = keep("ssim", m.ssim_mean);
            r.lpips = keep("lpips", m.lpips_mean);
            r.lpips_note = m.lpips_note.clone();
            r.novel_psnr = keep("novel_psnr", m.novel_psnr_mean);
            let b = m.baselines.as_ref();
            r.nearest_lpips = keep("nearest_lpips", b.and_then(|b| b.nearest.lpips_mean));
            r.blend_lpips = keep("blend_lpips", b.and_then(|b| b.blend.lpips_mean));
            r.events_lpips = keep(
                "events_lpips",
                b.and_then(|b| b.events.as_ref()).and_then(|e| e.lpips_mean),
            );
            r.nearest_psnr = keep("nearest_psnr", b.map(|b| b.nearest.psnr_mean));
            r.blend_psnr = keep("blend_psnr", b.map(|b| b.blend.psnr_mean));
            r.events_psnr = keep(
                "events_psnr",
                b.and_then(|b| b.events.as_ref()).map(|e| e.psnr_mean),
            );
            r.total_s = keep("total_s", Some(m.total_stage_s));
            if r.train_frames.is_none() {
                r.train_frames = record
                    .stages
                    .first()
                    .and_then(|s| s.entry.as_ref())
                    .and_then(|d| {
                        scene::manifest::Manifest::read(d.join(scene::manifest::TRAIN_FILE)).ok()
                    })
                    .map(|m| m.frames.len());
            }
        }
        Err(e) => r.error = Some(format!("eval: {e:#}")),
    }
    r
}

#[cfg(test)]
mod tests;
