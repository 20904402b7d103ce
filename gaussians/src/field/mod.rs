//! Deformation field (DEGS Eq. 3, after Deform-GS): an MLP maps the encoded canonical
//! position and time to `(δx, δq, δs)`, applied after activation:
//! `μ' = μ + δx`, `s' = exp(log s) + δs`, `q' = q/‖q‖ + δq` (the rasterizer renormalises);
//! with `color` also `δc`, added to the SH DC coefficients (`c' = c + δc`).
//!
//! [`settings`] (hyper-parameters) ← [`mlp`] (the network, on [`linalg`]) ← [`io`]
//! (`field.safetensors`); [`deltas`] (the output and its application to one Gaussian's
//! parameters) ← [`on_splats`] (the field evaluated on [`crate::Splats`], restricted to
//! the dynamic ones when asked).

pub mod deltas;
pub mod io;
pub mod linalg;
pub mod mlp;
pub mod on_splats;
pub mod settings;

pub use deltas::{
    DeformMlp, Deformation, Deformed, DeltaGrads, Deltas, MIN_SCALE, apply_color_deltas,
    apply_deltas, apply_deltas_backward, apply_deltas_backward_in_place, apply_deltas_in_place,
};
pub use mlp::{HEAD_OUT, Mlp, MlpCache, MlpScratch};
pub use on_splats::{
    FieldWork, deform_splats, deform_splats_into, evaluated_indices, splat_deltas,
    splat_deltas_backward, splat_deltas_backward_into, splat_deltas_into,
};
pub use settings::FieldSettings;
