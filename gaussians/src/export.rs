//! `gaussians export`: a dynamic model as a numbered sequence of standard 3DGS PLY files,
//! one per time, each the deformed Gaussians at that time in world coordinates
//! ([`crate::model::Model::at`], written by [`crate::ply::write`]): what SuperSplat plays
//! on a timeline (`frame_0001.ply`, `frame_0002.ply`, …), with the same files in one zip
//! (`sequence.zip`, which brush plays), `times.json` (each file's time) and
//! `report.json`.
//!
//! The times: every train and test frame's, or with `fps` a regular grid over the
//! recording's span at that rate. The model's time is the manifest's normalised `time`;
//! seconds come from the frames' timestamps (the line through the first and last train
//! frame's `(time, timestamp)`).

use crate::model::Model;
use scene::atomic::{AtomicDir, OutputRule, write_json_atomic};
use scene::manifest::Scene;
use scene::{Error, IoContext, Result};
use serde::{Deserialize, Serialize};
use stagekit::report::{Phases, peak_rss_mib};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The settings of `gaussians export` (`--config`; `degs export` writes them).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExportSettings {
    /// Frames per second over the recording; unset: the train and test frames' times.
    pub fps: Option<f64>,
}

impl stagekit::Settings for ExportSettings {
    fn validate(&self) -> std::result::Result<(), String> {
        match self.fps {
            Some(f) if !(f.is_finite() && f > 0.0) => Err(format!(
                "fps = {f}: give a positive number of frames per second"
            )),
            _ => Ok(()),
        }
    }
}

/// The command line of `gaussians export`.
#[derive(Clone, Debug, clap::Args)]
pub struct ExportArgs {
    /// `--scene` (the scene the model was trained on: its frames' times and clock),
    /// `--out`, `--force`, `--config` (TOML: `fps = N`)
    #[command(flatten)]
    pub stage: stagekit::StageArgs,
    /// Model directory (`gaussians train` or `deform train` output)
    #[arg(long)]
    pub model: PathBuf,
    /// Frames per second over the recording instead of the frames' times (overrides the
    /// settings file)
    #[arg(long)]
    pub fps: Option<f64>,
}

impl ExportArgs {
    /// Export with a progress display; one summary line on stderr.
    pub fn run(&self) -> Result<ExportReport> {
        let (scene, output) = (&self.stage.scene, &self.stage.output);
        let s = stagekit::settings::resolve::<ExportSettings>(output.config.as_deref(), |s| {
            s.fps = self.fps.or(s.fps)
        })?;
        let mut progress = stagekit::Progress::new("ply", 0);
        let r = export(
            &self.model,
            scene,
            &output.out,
            (s.fps, output.force),
            |k, n| {
                progress.set_length(n as u64);
                progress.set(k as u64, String::new);
            },
        )?;
        progress.finish();
        eprintln!(
            "{}: {} PLY files of {} Gaussians ({:.3}–{:.3} s), and {}",
            output.out.display(),
            r.frames.len(),
            r.gaussians,
            r.frames.first().map_or(0.0, |f| f.seconds),
            r.frames.last().map_or(0.0, |f| f.seconds),
            r.zip
        );
        Ok(r)
    }
}

/// One exported time.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ExportedFrame {
    /// The PLY file, relative to the output directory.
    pub file: String,
    /// Seconds on the frames' clock.
    pub seconds: f64,
    /// The model's normalised time.
    pub time: f64,
}

/// `report.json` of `gaussians export`.
#[derive(Clone, Debug, Serialize)]
pub struct ExportReport {
    pub stage: &'static str,
    pub version: &'static str,
    pub model: PathBuf,
    pub scene: PathBuf,
    pub gaussians: usize,
    pub sh_degree: u32,
    pub frames: Vec<ExportedFrame>,
    pub zip: String,
    pub phases: Phases,
    pub peak_memory_mib: Option<f64>,
}

/// The name of the `k`-th file of a sequence (1-based, as viewers number frames).
pub fn frame_file(k: usize) -> String {
    format!("frame_{k:04}.ply")
}

/// The times to export as `(seconds, normalised time)`, in increasing order: the train
/// and test frames' (each time once), or with `fps` every `1/fps` s from the first
/// train frame to the last.
pub fn export_times(scene: &Scene, fps: Option<f64>) -> Result<Vec<(f64, f64)>> {
    let train = &scene.train.frames;
    let (Some(first), Some(last)) = (train.first(), train.last()) else {
        return Err(Error::invalid(
            scene.root.join(scene::manifest::TRAIN_FILE),
            "no train frames: no time span to export",
        ));
    };
    let seconds_per_unit = match last.time - first.time {
        d if d > 0.0 => (last.timestamp - first.timestamp) / d,
        _ => 0.0,
    };
    let seconds = |time: f64| first.timestamp + (time - first.time) * seconds_per_unit;
    match fps {
        None => {
            let mut times: Vec<f64> = train
                .iter()
                .chain(&scene.test.frames)
                .map(|f| f.time)
                .collect();
            times.sort_by(f64::total_cmp);
            times.dedup();
            Ok(times.into_iter().map(|t| (seconds(t), t)).collect())
        }
        Some(fps) if !(fps.is_finite() && fps > 0.0) => Err(Error::Other(format!(
            "--fps {fps}: give a positive number of frames per second"
        ))),
        Some(fps) => {
            let span = last.timestamp - first.timestamp;
            let n = (span * fps + 1e-9).floor() as usize + 1;
            Ok((0..n)
                .map(|k| {
                    let s = first.timestamp + k as f64 / fps;
                    let t = match seconds_per_unit {
                        0.0 => first.time,
                        r => first.time + (s - first.timestamp) / r,
                    };
                    (s, t.clamp(0.0, 1.0))
                })
                .collect())
        }
    }
}

/// Write the sequence of `model_dir` at the times of `scene_dir` (or `fps`) to
/// `out_dir`; `progress(done, total)` after each file.
pub fn export(
    model_dir: &Path,
    scene_dir: &Path,
    out_dir: &Path,
    (fps, force): (Option<f64>, bool),
    mut progress: impl FnMut(usize, usize),
) -> Result<ExportReport> {
    let rule = OutputRule::new("gaussians export")
        .force(force)
        .source(model_dir)
        .source(scene_dir);
    rule.check(out_dir)?;
    let mut phases = Phases::new();
    phases.start("load");
    let model = Model::load(model_dir)?;
    let scene = Scene::open(scene_dir)?;
    let times = export_times(&scene, fps)?;
    let out = AtomicDir::new(out_dir, &rule)?;
    phases.start("write");
    let degree = model.info.sh_degree;
    let mut frames = Vec::with_capacity(times.len());
    for (k, &(seconds, time)) in times.iter().enumerate() {
        let file = frame_file(k + 1);
        crate::ply::write(&out.path().join(&file), &model.at(time as f32), degree)?;
        frames.push(ExportedFrame {
            file,
            seconds,
            time,
        });
        progress(k + 1, times.len());
    }
    let zip = "sequence.zip".to_string();
    write_zip(out.path(), &frames, &out.path().join(&zip))?;
    write_json_atomic(&out.path().join("times.json"), &frames)?;
    phases.stop();
    let report = ExportReport {
        stage: "gaussians export",
        version: env!("CARGO_PKG_VERSION"),
        model: model_dir.to_path_buf(),
        scene: scene_dir.to_path_buf(),
        gaussians: model.splats.len(),
        sh_degree: degree,
        frames,
        zip,
        phases,
        peak_memory_mib: peak_rss_mib(),
    };
    write_json_atomic(&out.path().join("report.json"), &report)?;
    out.commit()?;
    Ok(report)
}

/// The PLY files, stored (not compressed: they barely compress) in one zip, in order.
fn write_zip(dir: &Path, frames: &[ExportedFrame], path: &Path) -> Result<()> {
    let file = std::fs::File::create(path).at(path)?;
    let mut zip = zip::ZipWriter::new(std::io::BufWriter::new(file));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .large_file(true);
    let bad = |e: zip::result::ZipError| Error::invalid(path, format!("cannot write: {e}"));
    for f in frames {
        let bytes = std::fs::read(dir.join(&f.file)).at(dir.join(&f.file))?;
        zip.start_file(f.file.as_str(), options).map_err(bad)?;
        zip.write_all(&bytes).at(path)?;
    }
    zip.finish().map_err(bad)?.flush().at(path)?;
    Ok(())
}
