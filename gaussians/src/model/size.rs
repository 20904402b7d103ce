//! The size of a saved model (`report.json`'s `model_size`): Gaussians, SH degree, the
//! field's shape, parameter counts and the bytes of the files written.

use super::{FLAGS_FILE, INFO_FILE, Model, PLY_FILE};
use crate::field::io::{SETTINGS_FILE, WEIGHTS_FILE};
use crate::raster::sh::num_coeffs;
use scene::error::{Error, Result};
use serde::Serialize;
use std::path::Path;

/// What a model holds and what its files weigh.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ModelSize {
    pub gaussians: usize,
    pub sh_degree: u32,
    /// The field's hidden layers × width (absent: no field).
    pub field: Option<[usize; 2]>,
    /// Gaussians the field moves (all of them without dynamic flags; 0 without a
    /// field).
    pub dynamic_gaussians: usize,
    pub parameters: Parameters,
    pub bytes: Bytes,
}

/// Trainable values (`f32` each).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Parameters {
    /// Per Gaussian `3 + 3 + 4 + 1 + 3·(deg + 1)²` (mean, scale, rotation, opacity, SH).
    pub gaussians: usize,
    pub field: usize,
    pub total: usize,
}

/// Bytes of each file of the model (0 when absent).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Bytes {
    pub ply: u64,
    /// `field.safetensors` + `field.json`.
    pub field: u64,
    pub dynamic_flags: u64,
    pub model_json: u64,
    pub total: u64,
}

/// Trainable values per Gaussian at SH degree `degree`.
pub(crate) fn parameters_per_gaussian(degree: u32) -> usize {
    3 + 3 + 4 + 1 + 3 * num_coeffs(degree.min(3))
}

impl ModelSize {
    /// The size of `model` as saved in `dir` (by [`Model::save`]).
    pub fn of(model: &Model, dir: &Path) -> Result<ModelSize> {
        let len = |name: &str| -> Result<u64> {
            let p = dir.join(name);
            match std::fs::metadata(&p) {
                Ok(m) => Ok(m.len()),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(0),
                Err(e) => Err(Error::io(&p, e)),
            }
        };
        let has_field = model.field.is_some();
        let bytes = Bytes {
            ply: len(PLY_FILE)?,
            field: if has_field {
                len(WEIGHTS_FILE)? + len(SETTINGS_FILE)?
            } else {
                0
            },
            // `Model::save` writes the flags whenever the Gaussians carry them.
            dynamic_flags: if !model.splats.dynamic.is_empty() {
                len(FLAGS_FILE)?
            } else {
                0
            },
            model_json: len(INFO_FILE)?,
            total: 0,
        };
        let n = model.splats.len();
        let gaussians = n * parameters_per_gaussian(model.info.sh_degree);
        let field = model.field.as_ref().map_or(0, |f| f.params.len());
        let dynamic = match (&model.field, model.info.dynamic_only) {
            (None, _) => 0,
            (Some(_), false) => n,
            (Some(_), true) => (0..n).filter(|&i| model.splats.is_dynamic(i)).count(),
        };
        Ok(ModelSize {
            gaussians: n,
            sh_degree: model.info.sh_degree,
            field: model
                .field
                .as_ref()
                .map(|f| [f.settings.depth, f.settings.width]),
            dynamic_gaussians: dynamic,
            parameters: Parameters {
                gaussians,
                field,
                total: gaussians + field,
            },
            bytes: Bytes {
                total: bytes.ply + bytes.field + bytes.dynamic_flags + bytes.model_json,
                ..bytes
            },
        })
    }
}
