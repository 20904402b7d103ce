//! The model a trainer holds, as saved ([`Model`]).

use super::Trainer;
use crate::model::{Model, ModelInfo};

impl From<&Trainer> for Model {
    /// The model a trainer holds now (field included once it has been switched on, or
    /// whenever deformation is enabled and the run got past the static phase), at the
    /// SH degree it renders with now, with dynamic flags only when the field uses them.
    fn from(tr: &Trainer) -> Model {
        let s = &tr.settings;
        let field = tr.field_on().then(|| tr.field.clone());
        let mut splats = tr.splats.clone();
        // Dynamic flags are written only where the field reads them.
        if field.is_none() || !s.dynamic_only {
            splats.dynamic.clear();
        }
        let n = splats.len();
        Model {
            splats,
            info: ModelInfo {
                // The degree in use: the coefficients above it are zero, and the PLY
                // holds only the columns of this degree.
                sh_degree: tr.sh_degree().min(3),
                background: s.background,
                dynamic_only: s.dynamic_only,
                gaussians: n,
                has_field: field.is_some(),
                iterations: tr.iteration,
                gaussian_cap_before_sizing: tr.sizing.as_ref().map(|s| s.gaussian_cap_before),
                ..ModelInfo::default()
            },
            field,
        }
    }
}
