//! Contrast maximisation (`docs/DESIGN.md` §5, paper Eq. 4–8) in plain Rust, and the
//! bridge that pushes its gradient into a burn graph.
//!
//! Each event k is warped to a reference time with the flow of its own pixel,
//! `x'_k = x_k − (t_k − t_ref)·v(x_k)` (flow in px/s), and splatted bilinearly into the
//! image of warped events (IWE). The sharpness objective is the mean squared gradient
//! magnitude (GM) of the IWE, with central differences `(I[x+1] − I[x−1])/2` over the
//! interior pixels, averaged over `scales` levels of 2×2 average pooling.
//! Following Shiba et al. the loss is the normalised GM, `GM(unwarped)/GM(warped)`,
//! averaged over the references start, middle (weight 2) and end, plus `λ·TV(flow)`
//! where TV is the mean Charbonnier norm `sqrt(d² + ε²)` (ε = 1e-3 px/s) of the forward
//! differences of u and v (smooth, so the gradient is exact everywhere).
//!
//! Everything is f64; [`cm_loss`] returns the exact gradient with respect to the dense
//! flow (hand-written backward, checked against finite differences in the tests).
//!
//! - [`warp`]: the events, the warp and the IWE (independent of burn);
//! - [`loss`]: GM, TV and the loss with its gradient (independent of burn);
//! - [`surrogate`]: that gradient into a burn graph.

pub mod loss;
pub mod surrogate;
pub mod warp;

pub use loss::{
    CmConfig, CmLoss, cm_loss, gradient_magnitude, gradient_magnitude_from, references,
};
pub use surrogate::cm_surrogate;
pub use warp::{CmEvents, event_pixel, iwe, variance};
