//! A saved dynamic Gaussian model (the warm-up's output, the joint training's input):
//! `point_cloud.ply` (canonical Gaussians, 3DGS layout), `dynamic.safetensors`
//! (per-Gaussian dynamic flags, when the Gaussians carry them), `field.safetensors` +
//! `field.json` (deformation field, when the model has one) and `model.json`
//! ([`ModelInfo`]: SH degree, background, Gaussian count, which files belong to it),
//! and `motion.safetensors` (per-Gaussian trajectories, when the Gaussians have them).
//!
//! `model.json` format 1 held the dynamic flags as a string of `'0'`/`'1'`; such
//! models still load.

pub mod dynamic_flags;
pub mod motion_file;
pub mod size;

use crate::field::{self, Mlp};
use crate::raster::{Rasterizer, RenderedImage, TileRasterizer};
use crate::splats::Splats;
use scene::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

pub use dynamic_flags::FLAGS_FILE;
pub use motion_file::MOTION_FILE;

pub const PLY_FILE: &str = "point_cloud.ply";
pub const INFO_FILE: &str = "model.json";
/// Version of the `model.json` layout (2: dynamic flags in [`FLAGS_FILE`]).
pub(crate) const FORMAT_VERSION: u32 = 2;
/// The layout that held the dynamic flags in `model.json` (still read).
const LEGACY_FORMAT_VERSION: u32 = 1;

/// The model's metadata (`model.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelInfo {
    pub format_version: u32,
    /// SH degree the model renders with (and the PLY stores).
    pub sh_degree: u32,
    pub background: [f32; 3],
    /// The field deforms only Gaussians flagged dynamic.
    pub dynamic_only: bool,
    /// Number of Gaussians (must match the PLY).
    pub gaussians: usize,
    /// Whether `field.safetensors` / `field.json` belong to the model.
    pub has_field: bool,
    /// Training iterations the model has seen.
    #[serde(default)]
    pub iterations: u32,
    /// Whether [`FLAGS_FILE`] (per-Gaussian dynamic flags) belongs to the model; without
    /// it every Gaussian counts as dynamic.
    #[serde(default)]
    pub has_dynamic_flags: bool,
    /// The Gaussian cap before the warm-up's sizing made its count the cap (absent: not
    /// sized); the joint training's `regrow` restores it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gaussian_cap_before_sizing: Option<usize>,
    /// Whether [`MOTION_FILE`] (per-Gaussian trajectories) belongs to the model.
    #[serde(default)]
    pub has_motion: bool,
}

impl Default for ModelInfo {
    fn default() -> Self {
        ModelInfo {
            format_version: FORMAT_VERSION,
            sh_degree: 3,
            background: [0.0; 3],
            dynamic_only: false,
            gaussians: 0,
            has_field: false,
            iterations: 0,
            has_dynamic_flags: false,
            gaussian_cap_before_sizing: None,
            has_motion: false,
        }
    }
}

/// Canonical Gaussians, optional deformation field and metadata.
#[derive(Clone, Debug)]
pub struct Model {
    pub splats: Splats,
    pub field: Option<Mlp<f32>>,
    pub info: ModelInfo,
}

impl Model {
    /// Write the model files into `dir` (created if missing); each file atomically.
    pub fn save(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let n = self.splats.len();
        let mut info = self.info.clone();
        info.format_version = FORMAT_VERSION;
        info.gaussians = n;
        info.has_field = self.field.is_some();
        let flags = &self.splats.dynamic;
        info.has_dynamic_flags = !flags.is_empty();
        if info.has_dynamic_flags && flags.len() != n {
            return Err(Error::invalid(
                dir.join(FLAGS_FILE),
                format!("{} dynamic flags for {n} Gaussians", flags.len()),
            ));
        }
        let (motion, life) = (&self.splats.motion, &self.splats.life);
        info.has_motion = !motion.is_empty();
        if info.has_motion && motion.len() != n || !life.is_empty() && motion.len() != n {
            return Err(Error::invalid(
                dir.join(MOTION_FILE),
                format!("{} trajectories for {n} Gaussians", motion.len()),
            ));
        }
        crate::ply::write(&dir.join(PLY_FILE), &self.splats, info.sh_degree)?;
        if info.has_motion {
            let (part, parts) = (&self.splats.part, &self.splats.parts);
            motion_file::write_with_parts(&dir.join(MOTION_FILE), motion, life, part, parts)?;
        }
        if info.has_dynamic_flags {
            dynamic_flags::write(&dir.join(FLAGS_FILE), flags)?;
        }
        if let Some(f) = &self.field {
            field::io::save(f, dir)?;
        }
        scene::atomic::write_json_atomic(&dir.join(INFO_FILE), &info)
    }

    /// Read a model saved by [`Model::save`]; errors name the offending file.
    pub fn load(dir: &Path) -> Result<Model> {
        let ipath = dir.join(INFO_FILE);
        let text = std::fs::read_to_string(&ipath).map_err(|e| Error::io(&ipath, e))?;
        let (mut info, legacy_flags) = parse_info(&ipath, &text)?;
        if info.sh_degree > 3 || info.background.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid(
                &ipath,
                "sh_degree must be ≤ 3 and background finite",
            ));
        }
        let ppath = dir.join(PLY_FILE);
        let (mut splats, degree) = crate::ply::read(&ppath)?;
        // A disagreement between the two files names both: either may be the wrong one.
        if splats.len() != info.gaussians {
            return Err(Error::invalid(
                &ppath,
                format!(
                    "{} Gaussians but {} says {}",
                    splats.len(),
                    ipath.display(),
                    info.gaussians
                ),
            ));
        }
        if degree != info.sh_degree {
            return Err(Error::invalid(
                &ppath,
                format!(
                    "SH degree {degree} but {} says {}",
                    ipath.display(),
                    info.sh_degree
                ),
            ));
        }
        if let Some(text) = legacy_flags {
            splats.dynamic = dynamic_flags::parse_legacy(&ipath, &text, info.gaussians)?;
        } else if info.has_dynamic_flags {
            splats.dynamic = dynamic_flags::read(&dir.join(FLAGS_FILE), info.gaussians)?;
        }
        if info.has_motion {
            let path = dir.join(MOTION_FILE);
            motion_file::read_into(&path, &mut splats)?;
        }
        // In memory the model is in the current layout (what `save` writes).
        info.format_version = FORMAT_VERSION;
        info.has_dynamic_flags = !splats.dynamic.is_empty();
        let field = if info.has_field {
            Some(field::io::load(dir)?)
        } else {
            None
        };
        Ok(Model {
            splats,
            field,
            info,
        })
    }

    /// The Gaussians deformed to normalised time `t` (the manifest's `time`): the field's
    /// deltas and each centre's trajectory; the canonical ones when it has neither.
    pub fn at(&self, t: f32) -> Splats {
        let field = self.field.as_ref();
        crate::motion::at_time(&self.splats, field, self.info.dynamic_only, t).into_owned()
    }

    /// Render colour, depth and alpha at a camera and normalised time.
    pub fn render(&self, cam: &scene::Camera, t: f32) -> RenderedImage {
        TileRasterizer
            .render(&self.at(t), cam, self.info.sh_degree, self.info.background)
            .0
    }
}

/// `model.json` of either format: the description and, from format 1, the dynamic
/// flags' string.
fn parse_info(path: &Path, text: &str) -> Result<(ModelInfo, Option<String>)> {
    let bad = |e: serde_json::Error| Error::invalid(path, format!("not a model description: {e}"));
    let mut value: serde_json::Value = serde_json::from_str(text).map_err(bad)?;
    let version = value.get("format_version").and_then(|v| v.as_u64());
    let mut legacy_flags = None;
    if version == Some(LEGACY_FORMAT_VERSION as u64)
        && let Some(obj) = value.as_object_mut()
    {
        legacy_flags = match obj.remove("dynamic") {
            None => None,
            Some(serde_json::Value::String(s)) => Some(s),
            Some(_) => return Err(Error::invalid(path, "`dynamic` must be a string")),
        };
    }
    let info: ModelInfo = serde_json::from_value(value).map_err(bad)?;
    if info.format_version != FORMAT_VERSION && info.format_version != LEGACY_FORMAT_VERSION {
        return Err(Error::invalid(
            path,
            format!(
                "format version {} (expected {FORMAT_VERSION}, or {LEGACY_FORMAT_VERSION})",
                info.format_version
            ),
        ));
    }
    Ok((info, legacy_flags))
}

#[cfg(test)]
mod tests;
