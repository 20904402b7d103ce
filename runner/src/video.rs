//! `degs render RUN`: the run's last model rendered along a camera path over the
//! recording (`gaussians video`, run as a cached node over the run's scene and model,
//! [`crate::export::on_last_model`]); the frames and previews are linked into
//! `runs/<name>/video/`.

use crate::context::Context;
use crate::external::External;
use crate::progress::Progress;
use anyhow::{Context as _, Result};
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// The node name and the run's folder for the renders.
pub const STAGE: &str = "video";

/// What to render: `path` is `recorded`, `orbit` or a cameras file; `fps` the rendered
/// frames per second of recording time (None: the stage's default).
#[derive(Clone, Debug)]
pub struct VideoRequest {
    pub path: String,
    pub fps: Option<f64>,
    pub playback_fps: Option<f64>,
}

/// Render the run in `run_dir`; the folder the files are in and the model's stage.
pub fn render_run(
    run_dir: &Path,
    ctx: &Context,
    req: &VideoRequest,
    progress: &Progress,
) -> Result<(PathBuf, &'static str)> {
    let mut settings = Table::new();
    let path = match req.path.as_str() {
        "recorded" | "orbit" => req.path.clone(),
        file => {
            let abs = std::path::absolute(file).with_context(|| format!("--path {file}"))?;
            let bytes = std::fs::read(&abs).with_context(|| {
                format!("--path {}: cannot read the cameras file", abs.display())
            })?;
            let hash = blake3::hash(&bytes).to_hex().to_string();
            settings.insert("cameras_blake3".into(), Value::String(hash));
            abs.display().to_string()
        }
    };
    settings.insert("path".into(), Value::String(path));
    for (name, v) in [("fps", req.fps), ("playback_fps", req.playback_fps)] {
        if let Some(f) = v {
            crate::export::check_fps(f).with_context(|| format!("--{}", name.replace('_', "-")))?;
            settings.insert(name.into(), Value::Float(f));
        }
    }
    let ext = External {
        what: "the video",
        stage: STAGE,
        binary: "gaussians",
        package: "degs-gaussians",
        verb: Some("video"),
        settings,
    };
    crate::export::on_last_model(run_dir, ctx, ext, progress)
}
