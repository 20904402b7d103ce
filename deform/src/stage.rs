//! The `deform` stage (docs/DESIGN.md §4): `deform train --scene DIR --model DIR
//! --flows DIR --assoc DIR --out DIR [--config settings.toml]`. Output directory (written
//! under a temporary name, renamed when complete):
//!
//! ```text
//! OUT/point_cloud.ply, model.json, dynamic.safetensors, field.*   the trained model
//! OUT/posenet.safetensors (+ .json)                               PoseNet weights
//! OUT/depth/NNNN.exr      depth at every train frame (for a later association)
//! OUT/renders/NNNN.png    every test frame
//! OUT/renders/novel/NNNN.png  every novel view (when the scene has that split)
//! OUT/settings.toml       the resolved settings
//! OUT/report.json         losses every `log_every` iterations, time per phase, test PSNR/SSIM/LPIPS
//!                         (`test`), novel-view PSNR/SSIM (`novel`), the 2D baselines on
//!                         the test frames (`baselines`)
//! ```
//!
//! The 2D baselines (nearest frame, linear blend, event pseudo image) predict an image
//! of the recorded camera only; they cannot render a new viewpoint, so the novel
//! section has no baselines.

use crate::baselines::{Baselines, Recording};
use crate::camera_check::CameraCheck;
use crate::contrast::ContrastReport;
use crate::fallbacks::Fallbacks;
use crate::inputs::Inputs;
use crate::posenet::PoseNet;
use crate::rate_outliers::TypicalRates;
use crate::settings::DeformSettings;
use crate::trainer::{JointStep, JointTrainer, Timings};
use gaussians::TileRasterizer;
use gaussians::model::Model;
use gaussians::stage::{Evaluation, evaluate, evaluate_novel, write_depths};
use safetensors::{Dtype, tensor::TensorView};
use scene::atomic::{AtomicDir, OutputRule, write_bytes_atomic, write_json_atomic};
use scene::error::{Error, Result};
use serde::Serialize;
use stagekit::report::{Phases, peak_rss_mib};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

/// Options of `deform train` (flags override the config file).
#[derive(Clone, Debug, Default, clap::Args)]
pub struct TrainArgs {
    #[command(flatten)]
    pub stage: stagekit::StageArgs,
    /// The warm-up's output directory (`gaussians train`)
    #[arg(long)]
    pub model: PathBuf,
    /// The per-event flow (`evflow finetune` output directory)
    #[arg(long)]
    pub flows: PathBuf,
    /// The bindings (`assoc` output directory)
    #[arg(long)]
    pub assoc: PathBuf,
    #[command(flatten)]
    pub training: stagekit::TrainingArgs,
    /// Plain interpolation of the camera path (no PoseNet)
    #[arg(long)]
    pub no_posenet: bool,
    /// Without the event loss (γ1 = 0)
    #[arg(long)]
    pub no_event_loss: bool,
    /// Without the motion loss (γ2 = 0)
    #[arg(long)]
    pub no_motion_loss: bool,
}

/// Settings from the config file (if any) with the flags applied, validated.
pub fn resolve_settings(a: &TrainArgs) -> Result<DeformSettings> {
    stagekit::settings::resolve(
        a.stage.output.config.as_deref(),
        |s: &mut DeformSettings| {
            if let Some(n) = a.training.iterations {
                s.iterations = n;
            }
            if let Some(n) = a.training.seed {
                s.seed = n;
            }
            if a.no_posenet {
                s.posenet = false;
            }
            if a.no_event_loss {
                s.schedule.gamma1 = 0.0;
            }
            if a.no_motion_loss {
                s.schedule.gamma2_max = 0.0;
            }
        },
    )
}

/// `report.json` of `deform train`.
#[derive(Clone, Debug, Serialize)]
pub struct TrainReport {
    pub stage: &'static str,
    pub version: &'static str,
    pub settings: DeformSettings,
    pub scene: PathBuf,
    pub phases: Phases,
    pub wall_seconds: f64,
    pub peak_memory_mib: Option<f64>,
    pub iterations: u32,
    pub warmup_iterations: u32,
    pub interrupted: bool,
    pub seconds_per_iteration: f64,
    /// Seconds per part of the joint iterations (RGB, event, motion, update, rebinding).
    pub timings: Timings,
    pub rebinds: u32,
    /// What the training left out on degenerate inputs (skipped `L_event`, dropped
    /// bindings, flows out of range, hot pixels and bursts; `deform::fallbacks`).
    pub fallbacks: Fallbacks,
    /// The typical rates the hot-pixel and burst tests compared with
    /// (`deform::rate_outliers`).
    pub rate_outliers: TypicalRates,
    /// The `C` used at the end (learned, estimated or given: see `contrast`).
    pub contrast_threshold: f64,
    /// The given `C`, its estimate from the recording with the spread, the `C` the
    /// training started from and the one it ended with.
    pub contrast: ContrastReport,
    pub frames_srgb: bool,
    pub gaussians: usize,
    /// The written model: Gaussians, SH degree, field shape, parameters and bytes (as the
    /// warm-up's report gives them).
    pub model_size: gaussians::model::size::ModelSize,
    /// Every `log_every`-th iteration's figures (losses, PSNR, bound Gaussians, …).
    pub curve: Vec<JointStep>,
    /// The camera at the test frames' times against their recorded poses.
    pub camera: CameraCheck,
    pub test: Evaluation,
    /// The same on the novel-view split; absent when the scene has none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub novel: Option<Evaluation>,
    /// The Gaussians' motion against the moving objects' true 3D motion (synthetic
    /// scenes; `gaussians::trajectory`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<gaussians::trajectory::TrajectoryError>,
    /// The 2D baselines on the same test frames (nearest frame, linear blend, event
    /// pseudo image with the `contrast_threshold` above, where `degs eval`'s uses the
    /// scene's); none on the novel views, which they cannot render.
    pub baselines: Baselines,
}

/// What a finished (or interrupted) run produced.
pub struct TrainOutcome {
    pub out: PathBuf,
    pub report: TrainReport,
}

/// Write `posenet.safetensors` (one tensor `params`) and `posenet.json` (its settings).
pub(crate) fn save_posenet(p: &PoseNet<f32>, dir: &Path) -> Result<()> {
    let path = dir.join("posenet.safetensors");
    let bytes: Vec<u8> = p.params().iter().flat_map(|v| v.to_le_bytes()).collect();
    let view = TensorView::new(Dtype::F32, vec![p.params().len()], &bytes)
        .map_err(|e| Error::invalid(&path, format!("tensor: {e}")))?;
    let data = safetensors::serialize(vec![("params".to_string(), view)], None)
        .map_err(|e| Error::invalid(&path, format!("serialising: {e}")))?;
    write_bytes_atomic(&path, &data)?;
    write_json_atomic(&dir.join("posenet.json"), p.settings())
}

/// The settings `deform train` runs with on `args`' scene: the file's and the flags',
/// `iterations = 0` and `schedule.motion = "auto"` made concrete by its train frames
/// ([`DeformSettings::iterations_for`], [`crate::schedule::LossSchedule::resolve_motion`]).
pub fn run_settings(args: &TrainArgs) -> Result<DeformSettings> {
    let mut s = resolve_settings(args)?;
    let scene = scene::manifest::Scene::open(&args.stage.scene)?;
    let times: Vec<f64> = scene.train.frames.iter().map(|f| f.timestamp).collect();
    resolve_auto(&mut s, &times, frame_pixels(&scene.train.camera));
    Ok(s)
}

/// The joint iterations `deform train` will run with `args` ([`run_settings`]).
pub fn joint_iterations(args: &TrainArgs) -> Result<u32> {
    Ok(run_settings(args)?.iterations)
}

/// `iterations = 0` and `schedule.motion = "auto"` made concrete for train frames at
/// `times` (seconds) of `pixels` each.
fn resolve_auto(s: &mut DeformSettings, times: &[f64], pixels: u64) {
    s.iterations = s.iterations_for(times, pixels);
    s.schedule.resolve_motion(times);
}

/// The pixels of one train frame.
fn frame_pixels(c: &scene::camera::Intrinsics) -> u64 {
    u64::from(c.width) * u64::from(c.height)
}

/// `deform train`: load everything, train until done or until `stop` is set, write
/// every output. `on_step` sees each iteration's figures (progress display).
pub fn train(
    args: &TrainArgs,
    stop: &AtomicBool,
    mut on_step: impl FnMut(&JointStep),
) -> Result<TrainOutcome> {
    let start = std::time::Instant::now();
    let mut phases = Phases::new();
    phases.start("load");
    let mut settings = resolve_settings(args)?;
    let rule = OutputRule::new("deform train")
        .force(args.stage.output.force)
        .source(&args.stage.scene)
        .source(&args.model)
        .source(&args.flows)
        .source(&args.assoc);
    rule.check(&args.stage.output.out)?;
    let d = Inputs::load(
        &args.stage.scene,
        &args.model,
        &args.flows,
        &args.assoc,
        &settings,
    )?;
    resolve_auto(&mut settings, &d.times, frame_pixels(&d.scene.train.camera));
    let out = AtomicDir::new(&args.stage.output.out, &rule)?;
    phases.start("train");
    let mut tr = JointTrainer::new(&d, settings.clone());
    let warmup_iterations = tr.inner.iteration;
    let r = TileRasterizer;
    let mut curve = Vec::new();
    let mut interrupted = false;
    let train_clock = std::time::Instant::now();
    while tr.iteration < settings.iterations {
        if stop.load(Ordering::Relaxed) {
            interrupted = true;
            break;
        }
        let s = tr.step(&r, &d);
        if s.iteration.is_multiple_of(settings.log_every) || s.iteration == settings.iterations {
            curve.push(s);
        }
        on_step(&s);
    }
    let train_seconds = train_clock.elapsed().as_secs_f64();
    let camera = tr.camera_check(&r, &d);
    phases.start("save");
    let model = Model::from(&tr.inner);
    model.save(out.path())?;
    let model_size = gaussians::model::size::ModelSize::of(&model, out.path())?;
    if let Some(p) = &tr.posenet {
        save_posenet(p, out.path())?;
    }
    stagekit::settings::write_resolved(out.path(), &settings)?;
    phases.start("depth");
    write_depths(&model, &d.views, &out.path().join("depth"))?;
    phases.start("evaluate");
    let lpips = gaussians::stage::stage_lpips();
    let renders = out.path().join("renders");
    let test = evaluate(&model, &d.test, "test", Some(&renders), &lpips)?;
    let novel = evaluate_novel(&model, &d.scene, out.path(), &lpips)?;
    phases.start("baselines");
    let test_times: Vec<f64> = d.scene.test.frames.iter().map(|f| f.timestamp).collect();
    let rec = Recording {
        train: &d.views,
        times: &d.times,
        events: Some(&d.events),
        contrast: d.contrast,
        srgb: d.srgb,
    };
    // LPIPS beside the model's only when the model's test frames have it.
    let lpips = lpips.ok().filter(|_| test.lpips_mean.is_some());
    let baselines = crate::baselines::evaluate(&rec, &d.test, &test_times, lpips.as_ref());
    phases.stop();
    let report = TrainReport {
        stage: "deform train",
        version: env!("CARGO_PKG_VERSION"),
        scene: args.stage.scene.clone(),
        phases,
        wall_seconds: start.elapsed().as_secs_f64(),
        peak_memory_mib: peak_rss_mib(),
        iterations: tr.iteration,
        warmup_iterations,
        interrupted,
        seconds_per_iteration: train_seconds / tr.iteration.max(1) as f64,
        timings: tr.timings,
        rebinds: tr.rebinds,
        fallbacks: tr.fallbacks,
        rate_outliers: d.rate_outliers.typical,
        contrast_threshold: tr.contrast,
        contrast: ContrastReport {
            mode: settings.contrast,
            given: d.contrast_given,
            estimate: d.contrast_estimate.clone().ok(),
            estimate_error: d.contrast_estimate.clone().err(),
            initial: d.contrast,
            last: tr.contrast,
        },
        frames_srgb: d.srgb,
        gaussians: model.splats.len(),
        model_size,
        curve,
        camera,
        test,
        novel,
        trajectory: gaussians::trajectory::trajectory_error(&model, &d.scene),
        baselines,
        settings,
    };
    write_json_atomic(&out.path().join("report.json"), &report)?;
    let out = out.commit()?;
    Ok(TrainOutcome { out, report })
}
