//! Adam on the network's burn tensors: [`stagekit::optim::Adam`] (f32 moments, PyTorch's
//! update) with one group per tensor, named after it.

use super::flownet::Conv;
use super::tensor::to_f32;
use burn::tensor::{Gradients, Tensor, TensorData};
use stagekit::optim::Adam;

/// Adam's ε (PyTorch's default).
pub(crate) const ADAM_EPS: f64 = 1e-8;

/// One Adam step at learning rate `lr` on the trainable tensor `t` from its gradient in
/// `grads`, with the moments of `adam`'s group `name` (created on first use). A tensor
/// without a gradient stays as it is; the new tensor requires a gradient again.
pub fn adam_step<const D: usize>(
    adam: &mut Adam,
    name: &str,
    t: &mut Tensor<D>,
    grads: &Gradients,
    lr: f64,
) {
    let Some(grad) = t.grad(grads) else {
        return;
    };
    let grad = to_f32(grad);
    let g = adam
        .group(name)
        .unwrap_or_else(|| adam.add_group(name, lr, ADAM_EPS, 1, grad.len()));
    adam.groups[g].lr = lr;
    let shape = t.dims();
    let (device, dtype) = (t.device(), t.dtype());
    let mut p = to_f32(t.clone().detach());
    adam.step(g, &mut p, &grad);
    *t = Tensor::<D>::from_data(
        TensorData::new(p, shape).convert_dtype(dtype),
        (&device, dtype),
    )
    .require_grad();
}

/// [`adam_step`] on a layer's weight and bias (groups `NAME.weight`, `NAME.bias`).
pub fn adam_step_conv(adam: &mut Adam, c: &mut Conv, grads: &Gradients, lr: f64) {
    adam_step(
        adam,
        &format!("{}.weight", c.name),
        &mut c.weight,
        grads,
        lr,
    );
    adam_step(adam, &format!("{}.bias", c.name), &mut c.bias, grads, lr);
}
