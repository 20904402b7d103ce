//! `gaussians video`: a saved model rendered anywhere in space and time, as numbered PNG
//! frames, an animated preview (`preview.gif`) and, when `ffmpeg` is on the PATH,
//! `preview.mp4`. The cameras:
//! - `recorded`: the recorded camera path, its pose interpolated at each time
//!   ([`scene::camera::Trajectory::pose_at`]); at more frames per second than the
//!   recording's frames this is a slow-motion video, the main use of events + frames;
//! - `orbit`: the middle train camera swung about the scene's centre (the median depth of
//!   the Gaussians it sees, on its axis), `±orbit_deg` about its up axis and back, while
//!   time runs over the recording;
//! - a cameras file: a manifest in the scene's format (`transforms_*.json`: the camera,
//!   each frame's `transform_matrix` and `time`; image paths are not read), rendered at
//!   its frames' poses and times.
//!
//! The times are [`crate::export::export_times`]'s grid at `fps` (default: four times
//! the train frames' rate). `cameras.json` records every rendered pose and time in the
//! manifest format, so that a path can be rendered again or edited.

use crate::model::Model;
use glam::{DQuat, DVec3};
use scene::atomic::{AtomicDir, OutputRule, write_json_atomic};
use scene::camera::{Camera, Pose};
use scene::manifest::{Manifest, Scene};
use scene::{Error, IoContext, Result};
use serde::{Deserialize, Serialize};
use stagekit::report::{Phases, peak_rss_mib};
use std::path::{Path, PathBuf};

/// The settings of `gaussians video` (`--config`; `degs render` writes them).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VideoSettings {
    /// The cameras: `recorded`, `orbit`, or the path of a cameras file (a manifest in
    /// the scene's format).
    pub path: String,
    /// Rendered frames per second of recording time (recorded and orbit paths); unset:
    /// four times the train frames' rate.
    pub fps: Option<f64>,
    /// Frames per second of the preview animation.
    pub playback_fps: f64,
    /// The orbit's swing either side of the middle train camera, degrees.
    pub orbit_deg: f64,
    /// The cameras file's content hash (BLAKE3, hex), when `path` is a file: `degs
    /// render` sets it so that its cache tells an edited file from the old one; the file
    /// must match it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cameras_blake3: Option<String>,
}

impl Default for VideoSettings {
    fn default() -> Self {
        VideoSettings {
            path: "recorded".into(),
            fps: None,
            playback_fps: 10.0,
            orbit_deg: 20.0,
            cameras_blake3: None,
        }
    }
}

impl stagekit::Settings for VideoSettings {
    fn validate(&self) -> std::result::Result<(), String> {
        if let Some(f) = self.fps
            && !(f.is_finite() && f > 0.0)
        {
            return Err(format!(
                "fps = {f}: give a positive number of frames per second"
            ));
        }
        if !(self.playback_fps.is_finite() && self.playback_fps > 0.0) {
            return Err(format!(
                "playback_fps = {}: give a positive rate",
                self.playback_fps
            ));
        }
        if !(self.orbit_deg.is_finite() && self.orbit_deg.abs() < 90.0) {
            return Err(format!(
                "orbit_deg = {}: give an angle below 90°",
                self.orbit_deg
            ));
        }
        Ok(())
    }
}

/// The command line of `gaussians video`.
#[derive(Clone, Debug, clap::Args)]
pub struct VideoArgs {
    /// `--scene` (the scene the model was trained on: its cameras and clock), `--out`,
    /// `--force`, `--config` (TOML: `path`, `fps`, `playback_fps`, `orbit_deg`)
    #[command(flatten)]
    pub stage: stagekit::StageArgs,
    /// Model directory (`gaussians train` or `deform train` output)
    #[arg(long)]
    pub model: PathBuf,
    /// recorded | orbit | FILE (a manifest in the scene's format); overrides the settings
    #[arg(long)]
    pub path: Option<String>,
    /// Rendered frames per second of recording time (default: 4× the train frames')
    #[arg(long)]
    pub fps: Option<f64>,
}

impl VideoArgs {
    /// Render with a progress display; one summary line on stderr.
    pub fn run(&self) -> Result<VideoReport> {
        let (scene, output) = (&self.stage.scene, &self.stage.output);
        let s = stagekit::settings::resolve::<VideoSettings>(output.config.as_deref(), |s| {
            s.fps = self.fps.or(s.fps);
            if let Some(p) = &self.path {
                s.path = p.clone();
            }
        })?;
        let mut progress = stagekit::Progress::new("frame", 0);
        let r = render_video(&self.model, scene, &output.out, &s, output.force, |k, n| {
            progress.set_length(n as u64);
            progress.set(k as u64, String::new);
        })?;
        progress.finish();
        eprintln!(
            "{}: {} frames ({} path) in frames/, {}{}",
            output.out.display(),
            r.frames,
            r.path,
            r.gif,
            r.mp4
                .as_ref()
                .map_or_else(|| format!("; {}", r.mp4_note), |m| format!(", {m}"))
        );
        Ok(r)
    }
}

/// `report.json` of `gaussians video`.
#[derive(Clone, Debug, Serialize)]
pub struct VideoReport {
    pub stage: &'static str,
    pub version: &'static str,
    pub model: PathBuf,
    pub scene: PathBuf,
    pub path: String,
    pub frames: usize,
    pub width: usize,
    pub height: usize,
    pub playback_fps: f64,
    pub gif: String,
    /// `preview.mp4`, or None with why in `mp4_note`.
    pub mp4: Option<String>,
    pub mp4_note: String,
    pub phases: Phases,
    pub peak_memory_mib: Option<f64>,
}

/// One view to render: a camera at a normalised time.
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub camera: Camera,
    pub time: f64,
    pub seconds: f64,
}

/// The views of `s.path` over `scene` (the model gives the orbit's centre).
pub fn views(scene: &Scene, model: &Model, s: &VideoSettings) -> Result<Vec<View>> {
    let train = &scene.train;
    let manifest_path = scene.root.join(scene::manifest::TRAIN_FILE);
    let fps = match s.fps {
        Some(f) => f,
        None => {
            let (a, b) = match (train.frames.first(), train.frames.last()) {
                (Some(a), Some(b)) if b.timestamp > a.timestamp => (a, b),
                _ => {
                    return Err(Error::invalid(
                        &manifest_path,
                        "fewer than two train frame times",
                    ));
                }
            };
            4.0 * (train.frames.len() - 1) as f64 / (b.timestamp - a.timestamp)
        }
    };
    let intrinsics = train.camera;
    match s.path.as_str() {
        "recorded" | "orbit" => {
            let path = train
                .trajectory()
                .map_err(|e| Error::invalid(&manifest_path, e))?;
            let times = crate::export::export_times(scene, Some(fps))?;
            let middle = train.frames[train.frames.len() / 2].cam_to_world;
            let orbit = (s.path == "orbit").then(|| Orbit::new(model, middle, &intrinsics));
            let n = times.len();
            Ok(times
                .into_iter()
                .enumerate()
                .map(|(k, (seconds, time))| {
                    let cam_to_world = match &orbit {
                        None => path.pose_at(seconds),
                        Some(o) => {
                            let phase = std::f64::consts::TAU * k as f64 / n as f64;
                            o.at(s.orbit_deg.to_radians() * phase.sin())
                        }
                    };
                    View {
                        camera: Camera {
                            intrinsics,
                            cam_to_world,
                        },
                        time,
                        seconds,
                    }
                })
                .collect())
        }
        file => {
            if let Some(want) = &s.cameras_blake3 {
                let bytes = std::fs::read(file).at(Path::new(file))?;
                let got = blake3::hash(&bytes).to_hex();
                if got.as_str() != want {
                    return Err(Error::invalid(
                        file,
                        format!("changed since it was given (BLAKE3 {got}, settings say {want})"),
                    ));
                }
            }
            let m = Manifest::read(file)?;
            if m.frames.is_empty() {
                return Err(Error::invalid(file, "no frames: no cameras to render"));
            }
            Ok(m.frames
                .iter()
                .map(|f| View {
                    camera: Camera {
                        intrinsics: m.camera,
                        cam_to_world: f.cam_to_world,
                    },
                    time: f.time,
                    seconds: f.timestamp,
                })
                .collect())
        }
    }
}

/// A camera pose swung about a vertical axis through the scene's centre.
struct Orbit {
    pose: Pose,
    centre: DVec3,
    up: DVec3,
}

impl Orbit {
    /// About the point on `pose`'s axis at the median depth of the model's Gaussians in
    /// front of it and inside its image (opacity ≥ ½), at the recording's middle time.
    fn new(model: &Model, pose: Pose, intrinsics: &scene::camera::Intrinsics) -> Orbit {
        let cam = Camera {
            intrinsics: *intrinsics,
            cam_to_world: pose,
        };
        let splats = model.at(0.5);
        let mut depths: Vec<f64> = (splats.means.iter().zip(&splats.opacity_logits))
            .filter(|(_, o)| **o >= 0.0)
            .filter_map(|(m, _)| {
                let p = DVec3::new(m[0] as f64, m[1] as f64, m[2] as f64);
                let (px, d) = cam.project_world(p)?;
                intrinsics.contains(px).then_some(d)
            })
            .collect();
        depths.sort_by(f64::total_cmp);
        let depth = depths.get(depths.len() / 2).copied().unwrap_or(1.0);
        let forward = pose.rotation * DVec3::NEG_Z;
        Orbit {
            pose,
            centre: pose.translation + depth * forward,
            up: pose.rotation * DVec3::Y,
        }
    }

    fn at(&self, angle: f64) -> Pose {
        let q = DQuat::from_axis_angle(self.up, angle);
        Pose {
            rotation: q * self.pose.rotation,
            translation: self.centre + q * (self.pose.translation - self.centre),
        }
    }
}

/// Render `model_dir` along `s.path` into `out_dir`: `frames/NNNN.png` (from 0001),
/// `preview.gif`, `preview.mp4` when `ffmpeg` is on the PATH, `cameras.json`,
/// `report.json`; `progress(done, total)` after each frame.
pub fn render_video(
    model_dir: &Path,
    scene_dir: &Path,
    out_dir: &Path,
    s: &VideoSettings,
    force: bool,
    mut progress: impl FnMut(usize, usize),
) -> Result<VideoReport> {
    let mut rule = OutputRule::new("gaussians video")
        .force(force)
        .source(model_dir)
        .source(scene_dir);
    if !matches!(s.path.as_str(), "recorded" | "orbit") {
        rule = rule.source(Path::new(&s.path));
    }
    rule.check(out_dir)?;
    let mut phases = Phases::new();
    phases.start("load");
    let model = Model::load(model_dir)?;
    let scene = Scene::open(scene_dir)?;
    let views = views(&scene, &model, s)?;
    let out = AtomicDir::new(out_dir, &rule)?;
    let frames_dir = out.path().join("frames");
    std::fs::create_dir_all(&frames_dir).at(&frames_dir)?;
    phases.start("render");
    let mut images = Vec::with_capacity(views.len());
    for (k, v) in views.iter().enumerate() {
        let img = model.render(&v.camera, v.time as f32).rgb_image();
        scene::image_io::write_png(frames_dir.join(frame_file(k + 1)), &img)?;
        images.push(img);
        progress(k + 1, views.len());
    }
    phases.start("encode");
    let gif = "preview.gif".to_string();
    crate::preview::write_gif(&out.path().join(&gif), &images, s.playback_fps)?;
    let (mp4, mp4_note) = match crate::preview::write_mp4(out.path(), "preview.mp4", s.playback_fps)
    {
        Ok(()) => (Some("preview.mp4".to_string()), String::new()),
        Err(why) => (None, why),
    };
    cameras_manifest(&views).write(out.path().join("cameras.json"))?;
    phases.stop();
    let (width, height) = images
        .first()
        .map_or((0, 0), |i| (i.width as usize, i.height as usize));
    let report = VideoReport {
        stage: "gaussians video",
        version: env!("CARGO_PKG_VERSION"),
        model: model_dir.to_path_buf(),
        scene: scene_dir.to_path_buf(),
        path: s.path.clone(),
        frames: views.len(),
        width,
        height,
        playback_fps: s.playback_fps,
        gif,
        mp4,
        mp4_note,
        phases,
        peak_memory_mib: peak_rss_mib(),
    };
    write_json_atomic(&out.path().join("report.json"), &report)?;
    out.commit()?;
    Ok(report)
}

/// The `k`-th frame's file name in `frames/` (1-based, as `ffmpeg`'s `%04d` reads).
pub fn frame_file(k: usize) -> String {
    format!("{k:04}.png")
}

/// The rendered views as a manifest in the scene's format (readable as a cameras file).
fn cameras_manifest(views: &[View]) -> Manifest {
    Manifest {
        camera: views[0].camera.intrinsics,
        frames: (views.iter().enumerate())
            .map(|(k, v)| scene::manifest::Frame {
                file_path: format!("frames/{}", frame_file(k + 1)),
                timestamp: v.seconds,
                time: v.time,
                cam_to_world: v.camera.cam_to_world,
            })
            .collect(),
        events: None,
        frame_encoding: None,
    }
}
