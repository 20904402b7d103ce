//! What a training loop reuses from one iteration to the next: the last rendered view
//! (deformed Gaussians, image, rasterizer state, field activations), the last gradients
//! and the field's scratch. Once warm, an iteration allocates no per-Gaussian or
//! per-pixel buffer of these (the figures: BENCHMARKS.md, "A cheaper iteration").

use super::{ModelGrads, ViewRender};
use crate::field;
use std::any::Any;
use std::sync::{Mutex, MutexGuard};

/// Views and gradients kept for reuse (the joint training renders two views a step).
const SPARE_MAX: usize = 2;

/// The trainer's spare buffers, shared by its `&self` renders and backward passes.
#[derive(Default)]
pub(super) struct Pool(Mutex<Spare>);

impl Pool {
    /// The buffers (still usable after a panic elsewhere held them).
    pub(super) fn lock(&self) -> MutexGuard<'_, Spare> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Drop the buffers (after the model's shape changed).
    pub(super) fn clear(&mut self) {
        *self.0.get_mut().unwrap_or_else(|e| e.into_inner()) = Spare::default();
    }
}

/// The buffers given back to the trainer.
#[derive(Default)]
pub(super) struct Spare {
    /// `ViewRender<R::State>`s of the rasterizer in use (at most [`SPARE_MAX`]).
    views: Vec<Box<dyn Any + Send>>,
    grads: Vec<ModelGrads>,
    pub(super) field: field::FieldWork,
    pub(super) delta_grads: field::Deltas,
    /// The isometry term of the last `Trainer::view_backward`.
    pub(super) rigidity_loss: f64,
}

impl Spare {
    /// The last view given back, when a rasterizer of state `S` rendered it.
    pub(super) fn take_view<S: Send + 'static>(&mut self) -> Option<Box<ViewRender<S>>> {
        self.views
            .pop()
            .and_then(|v| v.downcast::<ViewRender<S>>().ok())
    }

    pub(super) fn put_view<S: Send + 'static>(&mut self, v: ViewRender<S>) {
        if self.views.len() < SPARE_MAX {
            self.views.push(Box::new(v));
        }
    }

    /// The last gradients given back (empty ones when none).
    pub(super) fn take_grads(&mut self) -> ModelGrads {
        self.grads.pop().unwrap_or_default()
    }

    pub(super) fn put_grads(&mut self, g: ModelGrads) {
        if self.grads.len() < SPARE_MAX {
            self.grads.push(g);
        }
    }
}
