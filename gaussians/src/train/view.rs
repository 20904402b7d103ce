//! What the trainer takes and gives: a training [`View`], the model's render of one
//! ([`ViewRender`], with what its backward pass needs), the gradients of a loss on the
//! model ([`ModelGrads`]) and a step's figures ([`StepInfo`]).

use crate::field;
use crate::raster::RenderedImage;
use crate::splats::{SplatGrads, Splats};
use scene::Camera;

/// A training view: camera, normalised time, planar RGB target.
#[derive(Clone, Debug)]
pub struct View {
    pub camera: Camera,
    pub time: f32,
    pub rgb: Vec<f32>,
}

/// A view rendered by the current model, with what its backward needs.
pub struct ViewRender<S> {
    pub image: RenderedImage,
    pub camera: Camera,
    /// Normalised time of the view.
    pub time: f32,
    /// The Gaussians as rendered (deformed to the view's time).
    pub deformed: Splats,
    pub(super) deltas: Option<(field::Deltas, field::MlpCache<f32>)>,
    pub(super) state: S,
}

/// Gradients of a loss on the model: canonical Gaussians (with the densification
/// statistics of the render they came from), the field's parameters (empty when the
/// field is off) and the camera (camera-frame right twist, `raster::apply_twist`).
#[derive(Clone, Debug, Default)]
pub struct ModelGrads {
    pub splats: SplatGrads,
    pub field: Vec<f32>,
    pub camera: [f64; 6],
}

/// Per-step figures.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepInfo {
    pub iteration: u32,
    pub loss: f64,
    pub psnr: f64,
    pub gaussians: usize,
    pub field_on: bool,
}
