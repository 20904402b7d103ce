//! Bridge from the hand-written CM gradient (plain Rust, `cm_loss`) into a burn graph:
//! the scalar `Σ flow · g` with `g` a constant has gradient exactly `g` with respect to
//! the flow, so `cm_surrogate(flow, ..).backward()` pushes dL/dflow into the network.

use burn::tensor::{Tensor, TensorData};

/// `sum(flow · g)` for a flow tensor of shape `[1, 2, H, W]` (u then v) and the CM
/// gradient `(grad_u, grad_v)` (row-major `H·W` each). Its value is meaningless; only
/// its gradient matters.
pub fn cm_surrogate(flow: Tensor<4>, grad_u: &[f64], grad_v: &[f64]) -> Tensor<1> {
    let [b, c, h, w] = flow.dims();
    assert!(b == 1 && c == 2, "flow must have shape [1, 2, H, W]");
    assert!(
        grad_u.len() == h * w && grad_v.len() == h * w,
        "CM gradient has the wrong size"
    );
    let g: Vec<f32> = grad_u.iter().chain(grad_v).map(|&x| x as f32).collect();
    let g = Tensor::<4>::from_data(TensorData::new(g, [1, 2, h, w]), &flow.device());
    (flow * g).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Device;

    #[test]
    fn surrogate_backward_returns_the_cm_gradient() {
        let (h, w) = (3, 4);
        let device = Device::flex().autodiff();
        let flow: Vec<f32> = (0..2 * h * w).map(|i| i as f32 * 0.1 - 1.0).collect();
        let flow =
            Tensor::<4>::from_data(TensorData::new(flow, [1, 2, h, w]), &device).require_grad();
        let gu: Vec<f64> = (0..h * w).map(|i| i as f64 * 0.5 - 2.0).collect();
        let gv: Vec<f64> = (0..h * w).map(|i| 1.0 - i as f64 * 0.25).collect();
        let s = cm_surrogate(flow.clone(), &gu, &gv);
        let grads = s.backward();
        let g = flow.grad(&grads).expect("flow has a gradient");
        let g: Vec<f32> = g.into_data().try_to_vec().unwrap();
        for (i, want) in gu.iter().chain(&gv).enumerate() {
            assert!(
                (g[i] as f64 - want).abs() < 1e-6,
                "entry {i}: {} vs {want}",
                g[i]
            );
        }
    }
}
