//! The `gaussians` stage (`docs/DESIGN.md` §4): `train` (the RGB warm-up, or the
//! RGB-only baseline with more iterations) and `render` (a saved model at the frames of
//! a scene split).
//!
//! Outputs are written into a temp directory renamed at the end ([`AtomicDir`]):
//! the model ([`Model::save`]), `depth/NNNN.exr` (alpha-normalised depth at every train
//! frame, 0 where alpha < 0.5; NNNN = train frame index), `renders/NNNN.png` (every
//! test frame), `renders/novel/NNNN.png` (every frame of the scene's novel-view split,
//! if it has one), `settings.toml` (resolved settings) and `report.json` (PSNR/SSIM of
//! the test frames in `test`, of the novel views in `novel`).

use crate::evaluation::evaluate_writing;
use crate::model::Model;
use crate::raster::TileRasterizer;
use crate::train::settings::Init;
use crate::train::{StepInfo, TrainSettings, Trainer, View, init};
use scene::atomic::{AtomicDir, OutputRule, write_json_atomic};
use scene::error::{Error, Result};
use scene::image_io::{read_image, write_exr_depth};
use scene::manifest::{Manifest, Scene};
use scene::metrics;
use serde::Serialize;
use stagekit::report::{Phases, peak_rss_mib};
use stagekit::settings::{resolve, write_resolved};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// Options of `gaussians train` (flags override the config file).
#[derive(Clone, Debug, Default, clap::Args)]
pub struct TrainArgs {
    #[command(flatten)]
    pub stage: stagekit::StageArgs,
    #[command(flatten)]
    pub training: stagekit::TrainingArgs,
    /// Initial Gaussians from a 3DGS PLY (e.g. SfM points) instead of `--init`
    #[arg(long)]
    pub init_ply: Option<PathBuf>,
    /// Trajectories of the `--init-ply` Gaussians (safetensors, tensor `motion`, F32
    /// [n, 6]: velocity and acceleration per Gaussian about the recording's middle;
    /// `gaussians::motion`); without it the Gaussians start still
    #[arg(long, requires = "init_ply")]
    pub init_motion: Option<PathBuf>,
    /// Initial Gaussians without a PLY
    #[arg(long, value_enum)]
    pub init: Option<Init>,
    /// Hidden width of the deformation field MLP
    #[arg(long)]
    pub field_width: Option<usize>,
    /// Hidden layers of the deformation field MLP
    #[arg(long)]
    pub field_depth: Option<usize>,
    /// Static 3DGS: no deformation field
    #[arg(long)]
    pub no_deform: bool,
}

/// The flags of [`TrainArgs`] that override a setting, each with its key in
/// [`TrainSettings`] (their `--help` shows its default: [`stagekit::show_defaults`]).
pub const SETTING_FLAGS: &[(&str, &str)] = &[
    ("iterations", "iterations"),
    ("seed", "seed"),
    ("init", "init"),
    ("field_width", "field.width"),
    ("field_depth", "field.depth"),
];

/// Settings from the config file (if any) with the flags applied, validated.
pub fn resolve_settings(args: &TrainArgs) -> Result<TrainSettings> {
    resolve(
        args.stage.output.config.as_deref(),
        |s: &mut TrainSettings| {
            if let Some(n) = args.training.iterations {
                s.iterations = n;
            }
            if let Some(seed) = args.training.seed {
                s.seed = seed;
                s.field.seed = seed;
            }
            if let Some(init) = args.init {
                s.init = init;
            }
            if let Some(w) = args.field_width {
                s.field.width = w;
            }
            if let Some(d) = args.field_depth {
                s.field.depth = d;
            }
            if args.no_deform {
                s.deform = false;
            }
        },
    )
}

/// Hash of an input file (blake3, hex).
#[derive(Clone, Debug, Serialize)]
pub struct InputHash {
    pub path: PathBuf,
    pub blake3: String,
}

/// `report.json` of `gaussians train`.
#[derive(Clone, Debug, Serialize)]
pub struct TrainReport {
    pub stage: &'static str,
    pub version: &'static str,
    pub settings: TrainSettings,
    pub scene: PathBuf,
    pub inputs: Vec<InputHash>,
    pub phases: Phases,
    pub wall_seconds: f64,
    pub peak_memory_mib: Option<f64>,
    pub iterations: u32,
    pub interrupted: bool,
    pub seconds_per_iteration: f64,
    /// Steps trained on the views at half resolution (`coarse_end`; 0: none).
    pub coarse_steps: u32,
    pub static_seconds: f64,
    pub deform_seconds: f64,
    pub final_loss: f64,
    pub gaussians: usize,
    pub field_parameters: usize,
    /// The static/dynamic split (absent when none was made).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub static_split: Option<crate::train::static_split::SplitSummary>,
    /// What the sizing decided (absent when `size.tolerance_db = 0`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sizing: Option<crate::train::sizing::SizingSummary>,
    /// What the field's width probe measured and chose (absent when none ran).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field_probe: Option<crate::train::field_probe::FieldProbeSummary>,
    /// The written model: Gaussians, SH degree, field shape, parameters and bytes.
    pub model_size: crate::model::size::ModelSize,
    pub train_frames: usize,
    /// Initial Gaussians placed on surfaces (from the PLY or stereo; the rest random).
    pub init_surface_points: usize,
    /// Gaussians of `--init-ply` dropped because their opacity logit is −inf (fully
    /// transparent; other tools write these); 0 without a PLY.
    pub init_ply_dropped_transparent: usize,
    pub test: Evaluation,
    /// The same on the novel-view split; absent when the scene has none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub novel: Option<Evaluation>,
    /// The Gaussians' motion against the moving objects' true 3D motion (synthetic
    /// scenes; [`crate::trajectory`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<crate::trajectory::TrajectoryError>,
    /// What the tracks init did (absent for the other inits and with a PLY).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tracks_init: Option<crate::train::init::TracksSummary>,
    /// What a user must know about this result, in words (`degs run` and `degs eval`
    /// print them): the moving objects placed without a depth prior.
    pub warnings: Vec<String>,
}

/// Planar RGB of a frame's image, checked against the camera size.
fn load_rgb(
    scene: &Scene,
    frame: &scene::manifest::Frame,
    cam: &scene::Camera,
) -> Result<Vec<f32>> {
    let path = scene.image_path(frame);
    let img = read_image(&path)?;
    let (w, h) = (cam.intrinsics.width, cam.intrinsics.height);
    if (img.width, img.height) != (w, h) {
        return Err(Error::invalid(
            &path,
            format!(
                "image is {}x{} but the camera is {w}x{h}",
                img.width, img.height
            ),
        ));
    }
    Ok(metrics::interleaved_to_planar(
        &img.data, w as usize, h as usize, 3,
    ))
}

/// Views (camera, time, planar RGB) of a manifest's frames.
pub fn load_views(scene: &Scene, m: &Manifest) -> Result<Vec<View>> {
    m.frames
        .iter()
        .map(|f| {
            let camera = scene::Camera {
                intrinsics: m.camera,
                cam_to_world: f.cam_to_world,
            };
            let rgb = load_rgb(scene, f, &camera)?;
            Ok(View {
                camera,
                time: f.time as f32,
                rgb,
            })
        })
        .collect()
}

fn hash_file(path: &Path) -> Result<InputHash> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    Ok(InputHash {
        path: path.to_path_buf(),
        blake3: blake3::hash(&bytes).to_hex().to_string(),
    })
}

/// Hashes of the manifests, every image, the initial point cloud and its trajectories,
/// and the events file when the init reads it (`events`).
fn input_hashes(scene: &Scene, init: [Option<&Path>; 2], events: bool) -> Result<Vec<InputHash>> {
    let mut out = Vec::new();
    use scene::manifest::{NOVEL_FILE, TEST_FILE, TRAIN_FILE};
    for name in [TRAIN_FILE, TEST_FILE, NOVEL_FILE] {
        let p = scene.root.join(name);
        if p.is_file() {
            out.push(hash_file(&p)?);
        }
    }
    let frames = scene.train.frames.iter().chain(&scene.test.frames);
    for f in frames.chain(&scene.novel.frames) {
        out.push(hash_file(&scene.image_path(f))?);
    }
    for p in init.into_iter().flatten() {
        out.push(hash_file(p)?);
    }
    if let Some(p) = events.then(|| scene.events_path()).flatten() {
        out.push(hash_file(&p)?);
    }
    Ok(out)
}

pub use crate::evaluation::{Evaluation, PSNR_CAP, StageLpips, evaluate, stage_lpips};

/// PSNR/SSIM/LPIPS of `model` on the scene's novel-view split, its renders written to
/// `renders/novel/NNNN.png` and their depth to `renders/novel_depth/NNNN.exr` under
/// `out` (`degs eval` scores the depth of moving objects on it); None when the scene
/// has no novel views.
pub fn evaluate_novel(
    model: &Model,
    scene: &Scene,
    out: &Path,
    lpips: &StageLpips,
) -> Result<Option<Evaluation>> {
    if scene.novel.frames.is_empty() {
        return Ok(None);
    }
    let views = load_views(scene, &scene.novel)?;
    let dir = out.join("renders").join("novel");
    let depth = out.join("renders").join("novel_depth");
    evaluate_writing(model, &views, "novel", Some((&dir, Some(&depth))), lpips).map(Some)
}

/// Write `depth/NNNN.exr` for every view.
pub fn write_depths(model: &Model, views: &[View], dir: &Path) -> Result<()> {
    for (i, v) in views.iter().enumerate() {
        let f = model.render(&v.camera, v.time);
        write_exr_depth(
            dir.join(format!("{i:04}.exr")),
            f.width as u32,
            f.height as u32,
            &f.normalised_depth(),
        )?;
    }
    Ok(())
}

/// The run's iterations and their expected relative costs for the progress display's
/// time left (`train::work_schedule`, at the scene's frame size).
pub fn work_schedule(args: &TrainArgs) -> Result<(u32, stagekit::Schedule)> {
    let settings = resolve_settings(args)?;
    let camera = Scene::open(&args.stage.scene)?.train.camera;
    let pixels = camera.width as usize * camera.height as usize;
    let schedule = crate::train::work_schedule(&settings, pixels);
    Ok((settings.iterations, schedule))
}

/// The extent that scales learning rates and densification: the setting, or the larger
/// of the 3DGS camera extent and the half-size of the box the cameras look at (cameras
/// close together, as along one trajectory, would otherwise give a tiny extent).
pub fn scene_extent(settings: &TrainSettings, cams: &[scene::Camera]) -> f32 {
    if settings.scene_extent > 0.0 {
        return settings.scene_extent;
    }
    let (_, half) = init::camera_bounds(cams);
    init::camera_extent(cams).max(half as f32)
}

/// What a finished (or interrupted) training run produced.
#[derive(Debug)]
pub struct TrainOutcome {
    pub out: PathBuf,
    pub report: TrainReport,
    pub model: Model,
}

/// `gaussians train`: load the scene, train until done or until `stop` is set, write
/// every output. `on_step` sees each step's figures (progress display).
pub fn train(
    args: &TrainArgs,
    stop: &AtomicBool,
    on_step: impl FnMut(&StepInfo),
) -> Result<TrainOutcome> {
    let start = std::time::Instant::now();
    let mut phases = Phases::new();
    phases.start("load");
    let settings = resolve_settings(args)?;
    let mut rule = OutputRule::new("gaussians train")
        .force(args.stage.output.force)
        .source(&args.stage.scene);
    for p in args.init_ply.iter().chain(&args.init_motion) {
        rule = rule.source(p);
    }
    rule.check(&args.stage.output.out)?;
    let scene = Scene::open(&args.stage.scene)?;
    let views = load_views(&scene, &scene.train)?;
    let test_views = load_views(&scene, &scene.test)?;
    let reads_events = init::reads_events(&settings, &scene, args.init_ply.as_deref());
    let inputs = input_hashes(
        &scene,
        [args.init_ply.as_deref(), args.init_motion.as_deref()],
        reads_events,
    )?;
    phases.start("init");
    let mut tracks = crate::tracks::loss::TrackTerm::default();
    let init::Initial {
        mut splats,
        surface_points: init_surface_points,
        dropped_transparent: init_ply_dropped_transparent,
        tracks: tracks_init,
        warnings,
    } = init::initial_splats(
        &settings,
        &views,
        args.init_ply.as_deref(),
        &mut tracks,
        &scene,
    )?;
    if let (Some(m), Some(p)) = (&args.init_motion, &args.init_ply) {
        if init_ply_dropped_transparent > 0 {
            return Err(Error::invalid(
                m,
                format!(
                    "{} dropped {init_ply_dropped_transparent} fully transparent Gaussians, \
                     so its rows no longer match the trajectories'",
                    p.display()
                ),
            ));
        }
        crate::model::motion_file::read_into(m, &mut splats)?;
    }
    let cams: Vec<_> = views.iter().map(|v| v.camera).collect();
    let extent = scene_extent(&settings, &cams);
    let out = AtomicDir::new(&args.stage.output.out, &rule)?;

    phases.start("train");
    let mut trainer = Trainer::new(settings, splats, extent);
    trainer.tracks = tracks;
    let summary = crate::train::run(&mut trainer, &TileRasterizer, &views, stop, on_step);

    phases.start("save");
    let model = Model::from(&trainer);
    // The settings as trained (the automatic Gaussian cap resolved).
    let settings = trainer.settings.clone();
    let split = trainer.split;
    let sizing = trainer.sizing.take();
    let field_probe = trainer.field_probe.take();
    let tracks = std::mem::take(&mut trainer.tracks.table);
    let priors = std::mem::take(&mut trainer.tracks.priors.maps);
    drop(trainer);
    model.save(out.path())?;
    let ids = &model.splats.track;
    if !tracks.is_empty() && ids.len() == model.splats.len() {
        let path = out.path().join(crate::tracks::file::TRACKS_FILE);
        crate::tracks::file::write(&path, ids, &tracks)?;
    }
    if settings.tracks.depth_weight > 0.0 && priors.iter().any(Option::is_some) {
        let path = out.path().join(crate::tracks::file::PRIORS_FILE);
        let k = &views[0].camera.intrinsics;
        crate::tracks::file::write_priors(&path, &priors, k.width as usize, k.height as usize)?;
    }
    let model_size = crate::model::size::ModelSize::of(&model, out.path())?;
    write_resolved(out.path(), &settings)?;
    phases.start("depth");
    write_depths(&model, &views, &out.path().join("depth"))?;
    phases.start("evaluate");
    let lpips = stage_lpips();
    let renders = out.path().join("renders");
    let test = evaluate(&model, &test_views, "test", Some(&renders), &lpips)?;
    let novel = evaluate_novel(&model, &scene, out.path(), &lpips)?;
    phases.stop();
    let report = TrainReport {
        stage: "gaussians train",
        version: env!("CARGO_PKG_VERSION"),
        scene: args.stage.scene.clone(),
        inputs,
        phases,
        wall_seconds: start.elapsed().as_secs_f64(),
        peak_memory_mib: peak_rss_mib(),
        iterations: summary.iterations,
        interrupted: summary.interrupted,
        seconds_per_iteration: (summary.static_seconds + summary.deform_seconds)
            / summary.iterations.max(1) as f64,
        coarse_steps: (settings.coarse_end(views.first().map_or(0, View::pixels)))
            .min(summary.iterations),
        static_seconds: summary.static_seconds,
        deform_seconds: summary.deform_seconds,
        final_loss: summary.final_loss,
        gaussians: model.splats.len(),
        field_parameters: model.field.as_ref().map_or(0, |f| f.params.len()),
        static_split: split,
        sizing,
        field_probe,
        model_size,
        train_frames: views.len(),
        init_surface_points,
        init_ply_dropped_transparent,
        test,
        novel,
        trajectory: crate::trajectory::trajectory_error(&model, &scene),
        warnings,
        tracks_init,
        settings,
    };
    write_json_atomic(&out.path().join("report.json"), &report)?;
    let out = out.commit()?;
    Ok(TrainOutcome { out, report, model })
}

/// Which frames `gaussians render` uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    #[default]
    Test,
    Train,
    /// The novel-view split (`transforms_novel.json`).
    Novel,
}

/// `report.json` of `gaussians render`.
#[derive(Clone, Debug, Serialize)]
pub struct RenderReport {
    pub stage: &'static str,
    pub version: &'static str,
    pub model: PathBuf,
    pub scene: PathBuf,
    pub split: Split,
    pub gaussians: usize,
    pub phases: Phases,
    pub peak_memory_mib: Option<f64>,
    pub evaluation: Evaluation,
}

/// `gaussians render`: `renders/NNNN.png` and `depth/NNNN.exr` of a saved model at every
/// frame of a split, with PSNR/SSIM against the split's images in `report.json`.
pub fn render(
    model_dir: &Path,
    scene_dir: &Path,
    out_dir: &Path,
    split: Split,
    force: bool,
) -> Result<RenderReport> {
    let rule = OutputRule::new("gaussians render")
        .force(force)
        .source(model_dir)
        .source(scene_dir);
    rule.check(out_dir)?;
    let mut phases = Phases::new();
    phases.start("load");
    let model = Model::load(model_dir)?;
    let scene = Scene::open(scene_dir)?;
    let (m, name) = match split {
        Split::Test => (&scene.test, "test"),
        Split::Train => (&scene.train, "train"),
        Split::Novel => (&scene.novel, "novel"),
    };
    if m.frames.is_empty() {
        let file = match split {
            Split::Test => scene::manifest::TEST_FILE,
            Split::Train => scene::manifest::TRAIN_FILE,
            Split::Novel => scene::manifest::NOVEL_FILE,
        };
        return Err(Error::invalid(
            scene.root.join(file),
            format!("the scene has no {name} frames to render"),
        ));
    }
    let views = load_views(&scene, m)?;
    let out = AtomicDir::new(out_dir, &rule)?;
    phases.start("render");
    let renders = out.path().join("renders");
    let evaluation = evaluate(&model, &views, name, Some(&renders), &stage_lpips())?;
    write_depths(&model, &views, &out.path().join("depth"))?;
    phases.stop();
    let report = RenderReport {
        stage: "gaussians render",
        version: env!("CARGO_PKG_VERSION"),
        model: model_dir.to_path_buf(),
        scene: scene_dir.to_path_buf(),
        split,
        gaussians: model.splats.len(),
        phases,
        peak_memory_mib: peak_rss_mib(),
        evaluation,
    };
    write_json_atomic(&out.path().join("report.json"), &report)?;
    out.commit()?;
    Ok(report)
}
