//! What any differentiable renderer of [`Splats`] offers the trainer: the
//! [`Rasterizer`] trait and the [`RenderedImage`] it produces.

use crate::splats::{SplatGrads, Splats};
use scene::Camera;
use scene::image_io::Image;

/// A rendered image: planar RGB `3 × H × W`, alpha-blended camera depth and
/// accumulated alpha `H × W`.
#[derive(Clone, Debug, Default)]
pub struct RenderedImage {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<f32>,
    pub depth: Vec<f32>,
    pub alpha: Vec<f32>,
}

impl RenderedImage {
    /// Alpha-normalised depth (`depth / alpha`; 0 where alpha < 0.5), as the warm-up
    /// writes it to `depth/NNNN.exr`.
    pub fn normalised_depth(&self) -> Vec<f32> {
        self.depth
            .iter()
            .zip(&self.alpha)
            .map(|(&d, &a)| if a >= 0.5 { d / a } else { 0.0 })
            .collect()
    }

    /// The colour as an interleaved image clamped to [0, 1] (ready for a PNG).
    pub fn rgb_image(&self) -> Image {
        let n = self.width * self.height;
        let mut data = Vec::with_capacity(3 * n);
        for p in 0..n {
            for c in 0..3 {
                data.push(self.rgb[c * n + p].clamp(0.0, 1.0));
            }
        }
        Image {
            width: self.width as u32,
            height: self.height as u32,
            channels: 3,
            data,
        }
    }
}

/// Loss gradients on the planes a render has beside its colour (`H×W` each): the
/// alpha-blended depth and the accumulated alpha.
#[derive(Clone, Copy, Debug, Default)]
pub struct Planes<'a> {
    pub depth: Option<&'a [f32]>,
    pub alpha: Option<&'a [f32]>,
    /// The depth distortion's weight per pixel, where one is on ([`Distortion`]).
    pub distortion: Option<Distortion<'a>>,
    /// Every blended Gaussian's depth pulled to a depth per pixel ([`Anchor`]).
    pub anchor: Option<Anchor<'a>>,
}

/// The depth distortion of Mip-NeRF 360 and 2DGS as a loss, `Σ_p λ_p Σᵢ Σⱼ wᵢ wⱼ |zᵢ − zⱼ|`
/// over each pixel's blending weights `wᵢ = αᵢ Tᵢ` and the Gaussians' view depths
/// (`raster::reference::distortion` is its f64 value): 0 where one depth carries a pixel.
#[derive(Clone, Copy, Debug)]
pub struct Distortion<'a> {
    /// `λ_p` per pixel (`H×W`).
    pub weight: &'a [f32],
    /// The render's alpha-blended depth `Σ wᵢ zᵢ` per pixel (`H×W`), which the backward
    /// needs and the forward does not keep.
    pub depth: &'a [f32],
}

/// Each blended Gaussian's depth against a depth per pixel, as a loss:
/// `Σ_p λ_p Σᵢ mᵢ wᵢ H((zᵢ − ẑ_p)/(σ ẑ_p))` over the blending weights `wᵢ = αᵢ Tᵢ` and the
/// Gaussians' view depths, `mᵢ` a factor per Gaussian, `H` Huber at 1 (`raster::reference::anchored` is its f64
/// value). Where the blended depth `Σ wᵢ zᵢ` can land on `ẑ` with layers in front and
/// behind, this asks every layer to lie there (the ray-termination loss of DS-NeRF,
/// Deng et al. 2022, on the Gaussians' weights).
#[derive(Clone, Copy, Debug)]
pub struct Anchor<'a> {
    /// `λ_p` per pixel (`H×W`, 0 where the pixel has no depth).
    pub weight: &'a [f32],
    /// `ẑ_p` per pixel (`H×W`).
    pub depth: &'a [f32],
    /// `σ`, the relative depth difference that is one unit of `H`.
    pub sigma: f32,
    /// A factor per Gaussian on its share of the loss (as rendered, one per Gaussian;
    /// empty: 1 for every Gaussian).
    pub gaussians: &'a [f32],
}

impl Planes<'_> {
    /// No loss on depth or alpha.
    pub const NONE: Planes<'static> = Planes {
        depth: None,
        alpha: None,
        distortion: None,
        anchor: None,
    };
}

/// A differentiable renderer.
pub trait Rasterizer: Sync {
    /// What the backward needs from the forward pass.
    type State;
    fn render(
        &self,
        s: &Splats,
        cam: &Camera,
        sh_degree: u32,
        background: [f32; 3],
    ) -> (RenderedImage, Self::State);
    /// Backward from `∂L/∂rgb` (planar `3×H×W`) and `∂L/∂depth` and `∂L/∂alpha` where
    /// given (`d_planes`) to every Gaussian parameter and to the camera as a
    /// camera-frame right twist (`raster::apply_twist`).
    fn backward_view(
        &self,
        s: &Splats,
        cam: &Camera,
        state: &Self::State,
        d_rgb: &[f32],
        d_planes: Planes,
    ) -> (SplatGrads, [f64; 6]);
    /// [`Self::render`] reusing the buffers of an earlier image and state (a training
    /// loop passes back the last iteration's; the result does not depend on them).
    fn render_reusing(
        &self,
        s: &Splats,
        cam: &Camera,
        sh_degree: u32,
        background: [f32; 3],
        reuse: Option<(RenderedImage, Self::State)>,
    ) -> (RenderedImage, Self::State) {
        drop(reuse);
        self.render(s, cam, sh_degree, background)
    }
    /// [`Self::backward_view`] into `grads` (overwritten and resized; its buffers reused).
    fn backward_view_into(
        &self,
        s: &Splats,
        cam: &Camera,
        state: &Self::State,
        d_rgb: &[f32],
        d_planes: Planes,
        grads: &mut SplatGrads,
    ) -> [f64; 6] {
        let (g, twist) = self.backward_view(s, cam, state, d_rgb, d_planes);
        *grads = g;
        twist
    }
    /// Add each Gaussian's blending weight `Σ_pixels α·T` in the render of `s` at `cam`
    /// to `acc` (one entry per Gaussian); false (and `acc` untouched) when this
    /// renderer cannot tell them.
    fn add_contributions(&self, s: &Splats, cam: &Camera, acc: &mut [f64]) -> bool {
        let _ = (s, cam, acc);
        false
    }
    /// Backward from the gradient of the loss w.r.t. the planar RGB image.
    fn backward(&self, s: &Splats, cam: &Camera, state: &Self::State, d_rgb: &[f32]) -> SplatGrads {
        self.backward_view(s, cam, state, d_rgb, Planes::NONE).0
    }
}
