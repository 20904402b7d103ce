//! Differentiable tile rasterizer for 3D Gaussians on the CPU (3DGS; DEGS Eq. 1–2).
//!
//! [`TileRasterizer`] renders colour (SH up to degree 3), alpha-blended camera depth and
//! accumulated alpha, and back-propagates gradients of all three to every Gaussian
//! parameter and to the camera pose. [`reference`](mod@reference) is a plain f64 renderer with the same
//! cut-offs, used by the tests.
//!
//! Cut-offs (shared with the reference): near plane `d > 0.01`, low-pass `0.3 px²` on
//! the 2-D covariance, Gaussians evaluated only inside their 3σ ellipse
//! (`dᵀΣ⁻¹d ≤ 9`), `α = min(0.99, o·exp(−½dᵀΣ⁻¹d))`, contributions with `α < 1/255`
//! skipped, a pixel stops before the Gaussian that would take its transmittance below
//! `1e-4`.
//!
//! **Pose gradient convention** (the one of every crate of degs): the camera twist
//! `δ = (v, ω)` perturbs the camera-to-world pose on the right, `T(δ) = T · [exp([ω]×) |
//! v]`, i.e. `R' = R·exp([ω]×)`, `c' = c + R·v`: the camera turns about its own centre
//! and moves by `v`, both in its own (OpenGL) axes; [`apply_twist`] implements it. The
//! gradient returned by [`TileRasterizer::backward_full`] is `∂L/∂δ` at `δ = 0`,
//! ordered `[v_x, v_y, v_z, ω_x, ω_y, ω_z]`.

// Index loops mirror the math; negated comparisons deliberately reject NaN.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

mod alpha;
mod backward;
mod contribution;
mod forward;
pub mod project;
mod project_backward_lanes;
mod project_lanes;
mod rasterizer;
pub mod reference;
pub mod sh;
pub mod simd;

pub use alpha::{ALPHA_MAX, ALPHA_MIN, CULL_OPACITY, LOW_PASS, NEAR, SIGMA_CUTOFF, T_MIN};
pub use contribution::add_contributions;
pub use forward::{Projected, RenderState, TILE};
pub use rasterizer::{Anchor, Distortion, Planes, Rasterizer, RenderedImage};

use crate::splats::{SplatGrads, Splats};
use glam::{DQuat, DVec3};
use project::CamSetup;
use scene::{Camera, Pose};

/// Apply a twist `δ = (v, ω)` to a camera-to-world pose by right perturbation (see the
/// module docs): `R' = R·exp([ω]×)`, `c' = c + R·v`.
pub fn apply_twist(pose: &Pose, twist: [f64; 6]) -> Pose {
    let v = DVec3::new(twist[0], twist[1], twist[2]);
    let w = DVec3::new(twist[3], twist[4], twist[5]);
    let dq = DQuat::from_scaled_axis(w);
    Pose {
        rotation: (pose.rotation * dq).normalize(),
        translation: pose.translation + pose.rotation * v,
    }
}

/// The CPU tile rasterizer (rayon over tiles and Gaussians).
#[derive(Clone, Copy, Debug, Default)]
pub struct TileRasterizer;

impl TileRasterizer {
    pub fn new() -> Self {
        TileRasterizer
    }

    /// Render colour, depth and alpha.
    pub fn render_full(
        &self,
        s: &Splats,
        cam: &Camera,
        sh_degree: u32,
        background: [f32; 3],
    ) -> (RenderedImage, RenderState) {
        forward::render(s, &CamSetup::new(cam), sh_degree.min(3), background)
    }

    /// Backward from `∂L/∂rgb` (planar `3×H×W`), and optionally `∂L/∂depth` and
    /// `∂L/∂alpha` (`H×W`), to every Gaussian parameter and the camera twist
    /// (convention in the module docs).
    pub fn backward_full(
        &self,
        s: &Splats,
        cam: &Camera,
        state: &RenderState,
        d_rgb: &[f32],
        d_depth: Option<&[f32]>,
        d_alpha: Option<&[f32]>,
    ) -> (SplatGrads, [f64; 6]) {
        let planes = Planes {
            depth: d_depth,
            alpha: d_alpha,
            distortion: None,
            anchor: None,
        };
        backward::backward(s, cam, state, d_rgb, planes)
    }
}

impl Rasterizer for TileRasterizer {
    type State = RenderState;

    fn render(
        &self,
        s: &Splats,
        cam: &Camera,
        sh_degree: u32,
        background: [f32; 3],
    ) -> (RenderedImage, RenderState) {
        self.render_full(s, cam, sh_degree, background)
    }

    fn backward_view(
        &self,
        s: &Splats,
        cam: &Camera,
        state: &RenderState,
        d_rgb: &[f32],
        d_planes: Planes,
    ) -> (SplatGrads, [f64; 6]) {
        backward::backward(s, cam, state, d_rgb, d_planes)
    }

    fn render_reusing(
        &self,
        s: &Splats,
        cam: &Camera,
        sh_degree: u32,
        background: [f32; 3],
        reuse: Option<(RenderedImage, RenderState)>,
    ) -> (RenderedImage, RenderState) {
        let cs = CamSetup::new(cam);
        let (mut image, mut state) =
            reuse.unwrap_or_else(|| (RenderedImage::default(), RenderState::empty(&cs)));
        forward::render_into(s, &cs, sh_degree.min(3), background, &mut image, &mut state);
        (image, state)
    }

    /// The forward pass at SH degree 0 (colour does not change the weights), then
    /// [`add_contributions`] on its state.
    fn add_contributions(&self, s: &Splats, cam: &Camera, acc: &mut [f64]) -> bool {
        let (_, st) = forward::render(s, &CamSetup::new(cam), 0, [0.0; 3]);
        add_contributions(&st, acc);
        true
    }

    fn backward_view_into(
        &self,
        s: &Splats,
        cam: &Camera,
        state: &RenderState,
        d_rgb: &[f32],
        d_planes: Planes,
        grads: &mut SplatGrads,
    ) -> [f64; 6] {
        backward::backward_into(s, cam, state, d_rgb, d_planes, grads)
    }
}
