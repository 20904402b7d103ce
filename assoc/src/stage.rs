//! The `assoc` stage: bindings at every train-frame time of a scene, from the warm-up
//! model's Gaussians and the depth maps it rendered (DESIGN §2–§4).
//!
//! Reads `MODEL/depth/NNNN.exr` (camera depth at train frame NNNN, 0 where alpha < 0.5:
//! DESIGN §3) and the model's Gaussians deformed to each frame time; writes into `OUT`
//! (built under a temp name, renamed at the end): `assoc.bin`, `report.json`,
//! `settings.toml` and `preview/NNNN.png` (bound events coloured by their Gaussian over
//! the dimmed train image).

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use crate::frame::{FrameStats, associate_alive};
use crate::{AssocSettings, Bindings, FrameBindings, write_assoc};
use gaussians::model::Model;
use scene::atomic::{AtomicDir, OutputRule, write_json_atomic};
use scene::image_io::{Image, read_exr_depth, read_image, write_png};
use scene::{Error, Result, Scene};
use stagekit::report::{Phases, peak_rss_mib};
use stagekit::{Settings, settings::write_resolved};

/// Depth map the warm-up wrote at train frame `index`.
pub fn depth_path(model_dir: &Path, index: usize) -> PathBuf {
    model_dir.join("depth").join(format!("{index:04}.exr"))
}

/// Everything `report.json` holds.
#[derive(Clone, Debug, Serialize)]
pub struct AssocReport {
    pub stage: &'static str,
    pub version: &'static str,
    pub settings: AssocSettings,
    pub scene: PathBuf,
    pub model: PathBuf,
    pub events_file: PathBuf,
    pub events_total: usize,
    pub gaussians: usize,
    /// Mean over frames of the fraction of Gaussians bound.
    pub bound_fraction_mean: f64,
    pub frames: Vec<FrameStats>,
    pub phases: Vec<(String, f64)>,
    pub wall_s: f64,
    pub peak_rss_mib: Option<f64>,
}

/// Runs the stage. `progress(done, total)` is called after each frame.
pub fn run(
    scene_dir: &Path,
    model_dir: &Path,
    out_dir: &Path,
    settings: &AssocSettings,
    force: bool,
    mut progress: impl FnMut(usize, usize),
) -> Result<AssocReport> {
    let start = Instant::now();
    let mut phases = Phases::new();
    settings
        .validate()
        .map_err(|e| Error::Other(format!("assoc settings: {e}")))?;
    let rule = OutputRule::new("assoc")
        .force(force)
        .source(scene_dir)
        .source(model_dir);
    rule.check(out_dir)?;
    phases.start("load");
    let scene = Scene::open(scene_dir)?;
    let events_file = scene.events_path().ok_or_else(|| {
        Error::invalid(
            scene_dir.join(scene::manifest::TRAIN_FILE),
            "the scene has no events entry",
        )
    })?;
    let events = scene.load_events()?;
    let model = Model::load(model_dir)?;
    if model.splats.is_empty() {
        return Err(Error::invalid(model_dir, "the model has no Gaussians"));
    }
    let out = AtomicDir::new(out_dir, &rule)?;
    std::fs::create_dir_all(out.path().join("preview"))
        .map_err(|e| Error::io(out.path().join("preview"), e))?;
    let frames = &scene.train.frames;
    let mut sections = Vec::with_capacity(frames.len());
    let mut stats = Vec::with_capacity(frames.len());
    for (i, frame) in frames.iter().enumerate() {
        phases.start("associate");
        let camera = scene.camera(frame);
        let path = depth_path(model_dir, i);
        let (w, h, depth) = read_exr_depth(&path)?;
        let (cw, ch) = (camera.intrinsics.width, camera.intrinsics.height);
        if (w, h) != (cw, ch) {
            return Err(Error::invalid(
                &path,
                format!("depth map is {w}x{h} but the camera is {cw}x{ch}"),
            ));
        }
        // The file holds 0 where alpha < 0.5, so "has depth" stands for the alpha test.
        let alpha: Vec<f32> = depth.iter().map(|&d| f32::from(d > 0.0)).collect();
        let t0 = frame.timestamp;
        // |t − t0| ≤ δt, both ends included (`window` is half-open).
        let window = events.window(t0 - settings.delta_t, (t0 + settings.delta_t).next_up());
        let t = frame.time as f32;
        let splats = model.at(t);
        // A Gaussian outside its life (`Splats::life`) is not drawn then: no events bind.
        let (bindings, s) = associate_alive(
            &camera,
            &depth,
            &alpha,
            &window,
            &splats.means,
            &model.splats.life,
            (t, t0),
            settings,
        )
        .map_err(|e| Error::invalid(&events_file, format!("frame {i} (t0 = {t0} s): {e}")))?;
        phases.start("preview");
        let image = read_image(scene.image_path(frame))?;
        let preview = preview_image(&image, &bindings, &window);
        write_png(
            out.path().join("preview").join(format!("{i:04}.png")),
            &preview,
        )?;
        sections.push(FrameBindings {
            t0,
            delta_t: settings.delta_t,
            k: settings.k as u32,
            bindings,
        });
        stats.push(s);
        progress(i + 1, frames.len());
    }
    phases.start("write");
    write_assoc(&out.path().join("assoc.bin"), &sections)?;
    write_resolved(out.path(), settings)?;
    phases.stop();
    let n = model.splats.len();
    let report = AssocReport {
        stage: "assoc",
        version: env!("CARGO_PKG_VERSION"),
        settings: settings.clone(),
        scene: scene_dir.to_path_buf(),
        model: model_dir.to_path_buf(),
        events_file,
        events_total: events.len(),
        gaussians: n,
        bound_fraction_mean: stats
            .iter()
            .map(|s| s.gaussians_bound as f64 / n as f64)
            .sum::<f64>()
            / stats.len().max(1) as f64,
        frames: stats,
        phases: phases.seconds.clone(),
        wall_s: start.elapsed().as_secs_f64(),
        peak_rss_mib: peak_rss_mib(),
    };
    write_json_atomic(&out.path().join("report.json"), &report)?;
    out.commit()?;
    Ok(report)
}

/// A distinct, bright colour per Gaussian index (golden-ratio hue walk).
fn gaussian_colour(g: usize) -> [f32; 3] {
    let h = (g as f32 * 0.618_034).fract() * 6.0;
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    match h as u32 {
        0 => [1.0, x, 0.2],
        1 => [x, 1.0, 0.2],
        2 => [0.2, 1.0, x],
        3 => [0.2, x, 1.0],
        4 => [x, 0.2, 1.0],
        _ => [1.0, 0.2, x],
    }
}

/// The train image dimmed to a third, with every bound event's pixel painted in the
/// colour of (the first) Gaussian it is bound to.
fn preview_image(image: &Image, bindings: &Bindings, window: &scene::EventSlice<'_>) -> Image {
    let (w, h) = (image.width, image.height);
    let mut out = Image::new(w, h, 3);
    let c = image.channels as usize;
    for p in 0..(w * h) as usize {
        for k in 0..3 {
            out.data[p * 3 + k] = image.data[p * c + k.min(c - 1)] / 3.0;
        }
    }
    for g in 0..bindings.gaussians() {
        let colour = gaussian_colour(g);
        for &e in bindings.of(g).0 {
            let i = e as usize - window.offset;
            let (x, y) = (window.x[i] as usize, window.y[i] as usize);
            let p = (y * w as usize + x) * 3;
            out.data[p..p + 3].copy_from_slice(&colour);
        }
    }
    out
}
