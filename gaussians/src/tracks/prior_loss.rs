//! The depth-prior term `L_depth` (issue #30): each train view's rendered depth pulled
//! to that frame's aligned prior ([`super::depth::Aligned`]), as the depth loss of Shape
//! of Motion (Wang et al. 2025):
//!
//! ```text
//! L_depth = w · (1/N) Σ_p H(r_p),   r_p = (D_p / α_p − z_p) / (σ · z_p)
//! ```
//!
//! over the `N` pixels where the prior has a depth (`z_p > 0`) and the render covers
//! (`α_p ≥ ½`): `D` the alpha-blended depth, `α` the accumulated alpha (so `D/α` is the
//! depth of what the pixel shows), `σ = depth_sigma` (a relative error of `σ` is one
//! unit, the scale at which the tracks' lift weighs a depth as one pixel), `H` Huber at
//! 1 (`r²/2` up to 1, `|r| − ½` beyond: where the network blurs an edge, or a frame keeps
//! some misalignment, the prior pulls no harder than `σ`). With `q = w·H'(r_p)/N`:
//!
//! ```text
//! ∂L/∂D_p = q / (σ z_p α_p),   ∂L/∂α_p = −q · D_p / (σ z_p α_p²)
//! ```
//!
//! The still scene's distance is fixed by parallax already; what the term adds is the
//! distance of the moving objects at every train time, which one moving camera cannot
//! tell: the rendering loss lets their Gaussians slide along the rays (DESIGN §5).

use super::depth::Aligned;
use crate::raster::{Anchor, Distortion, Planes, RenderedImage};

/// Alpha below which a pixel is not compared (the render shows nothing there).
pub const MIN_ALPHA: f32 = 0.5;

/// Whether `L_depth` (and the anchor) compare a pixel: the prior has a depth there and
/// the render covers it.
fn compared(prior: f32, alpha: f32) -> bool {
    prior > 0.0 && prior.is_finite() && alpha >= MIN_ALPHA
}

/// `L_depth` of one view: its rendered `depth` and `alpha` against the aligned `prior`
/// (`H×W` each, 0 for no prior), weight `weight`, relative scale `sigma`. Writes
/// `∂L/∂depth` and `∂L/∂alpha` into `d_depth` and `d_alpha` (resized; zero off the
/// compared pixels). Returns the loss, `N` and the mean relative difference
/// `|D/α − z|/z` over those pixels.
pub fn at_view(
    depth: &[f32],
    alpha: &[f32],
    prior: &[f32],
    weight: f64,
    sigma: f64,
    d_depth: &mut Vec<f32>,
    d_alpha: &mut Vec<f32>,
) -> (f64, usize, f64) {
    let n = depth.len();
    assert!(
        alpha.len() == n && prior.len() == n,
        "prior_loss: plane sizes differ"
    );
    d_depth.clear();
    d_depth.resize(n, 0.0);
    d_alpha.clear();
    d_alpha.resize(n, 0.0);
    let on = |p: usize| compared(prior[p], alpha[p]);
    let count = (0..n).filter(|&p| on(p)).count();
    if count == 0 || weight <= 0.0 || sigma <= 0.0 {
        return (0.0, 0, 0.0);
    }
    let scale = weight / count as f64;
    let (mut loss, mut rel) = (0.0, 0.0);
    for p in (0..n).filter(|&p| on(p)) {
        let (d, a, z) = (depth[p] as f64, alpha[p] as f64, prior[p] as f64);
        let r = (d / a - z) / (sigma * z);
        let (h, dh) = if r.abs() <= 1.0 {
            (0.5 * r * r, r)
        } else {
            (r.abs() - 0.5, r.signum())
        };
        (loss, rel) = (loss + h, rel + r.abs() * sigma);
        let q = scale * dh / (sigma * z);
        d_depth[p] = (q / a) as f32;
        d_alpha[p] = (-q * d / (a * a)) as f32;
    }
    (loss * scale, count, rel / count as f64)
}

/// The trainer's depth-prior term: each train view's aligned prior (`None` for a view
/// without one) and reused gradient planes.
#[derive(Clone, Debug, Default)]
pub struct PriorTerm {
    pub maps: Vec<Option<Aligned>>,
    d_depth: Vec<f32>,
    d_alpha: Vec<f32>,
    /// The distortion's weights at the last view.
    lambda: Vec<f32>,
    /// The anchor's weights at the last view, and its factor per Gaussian.
    lambda_anchor: Vec<f32>,
    movers: Vec<f32>,
    /// `L_depth` and the pixels it compared at the last view.
    pub last: (f64, usize),
    /// The mean relative difference `|D/α − z|/z` over those pixels.
    pub last_rel_error: f64,
}

impl PriorTerm {
    pub fn new(maps: Vec<Option<Aligned>>) -> Self {
        PriorTerm {
            maps,
            ..Self::default()
        }
    }

    /// The gradient planes of `L_depth` at train view `view` of its render `image`
    /// ([`at_view`]; not where the term is off, the view has no prior or a size other
    /// than the prior's, a coarse view) and of the depth distortion (`tracks.distortion`,
    /// [`distortion_weights`]) and of the prior on every blended depth
    /// (`tracks.depth_samples`, [`anchor_weights`], on the moving Gaussians of `splats`:
    /// [`movers`]); `None` when none is on.
    pub fn gradient<'a>(
        &'a mut self,
        image: &'a RenderedImage,
        view: usize,
        st: &super::TrackSettings,
        splats: &crate::Splats,
    ) -> Option<Planes<'a>> {
        (self.last, self.last_rel_error) = ((0.0, 0), 0.0);
        let map = (self.maps.get(view).and_then(Option::as_ref))
            .filter(|m| (m.width, m.height) == (image.width, image.height));
        let anchor = (map.filter(|_| st.depth_samples > 0.0)).map(|m| {
            anchor_weights(
                &image.alpha,
                &m.z,
                st.depth_samples,
                &mut self.lambda_anchor,
            );
            movers(splats, &mut self.movers);
            Anchor {
                weight: &self.lambda_anchor,
                depth: &m.z,
                sigma: st.depth_samples_sigma as f32,
                gaussians: &self.movers,
            }
        });
        if let Some(map) = map.filter(|_| st.depth_weight > 0.0) {
            let (w, s) = (st.depth_weight, st.depth_sigma);
            let (dd, da) = (&mut self.d_depth, &mut self.d_alpha);
            let (loss, count, rel) = at_view(&image.depth, &image.alpha, &map.z, w, s, dd, da);
            (self.last, self.last_rel_error) = ((loss, count), rel);
        }
        let distortion = (st.distortion > 0.0).then(|| {
            distortion_weights(&image.depth, &image.alpha, st.distortion, &mut self.lambda);
            Distortion {
                weight: &self.lambda,
                depth: &image.depth,
            }
        });
        let prior = self.last.1 > 0;
        (prior || distortion.is_some() || anchor.is_some()).then_some(Planes {
            depth: prior.then_some(&self.d_depth[..]),
            alpha: prior.then_some(&self.d_alpha[..]),
            distortion,
            anchor,
        })
    }
}

/// The anchor's factor per Gaussian: 1 for the moving ones (a part's member, or a
/// trajectory of its own), 0 for the others. The still scene's depth is pinned by
/// parallax, and over the whole image the term lost (BENCHMARKS.md, "The prior on every
/// blended depth").
pub fn movers(s: &crate::Splats, out: &mut Vec<f32>) {
    out.clear();
    out.extend((0..s.len()).map(|i| {
        let parted = s.part.get(i).is_some_and(|&p| p != crate::parts::NO_PART);
        let own = s.motion.get(i).is_some_and(crate::motion::has_trajectory);
        if parted || own { 1.0 } else { 0.0 }
    }));
}

/// The anchor's weight per pixel (`raster::Anchor`): `w / N` on the `N` pixels that
/// `L_depth` compares (the prior has a depth, the render covers: `α ≥ ½`), 0 elsewhere,
/// so that one layer at the pixel costs what `L_depth` does.
pub fn anchor_weights(alpha: &[f32], prior: &[f32], w: f64, out: &mut Vec<f32>) {
    let on = |p: usize| compared(prior[p], alpha[p]);
    let n = (0..prior.len()).filter(|&p| on(p)).count();
    out.clear();
    out.resize(prior.len(), 0.0);
    if n > 0 {
        let lam = (w / n as f64) as f32;
        for (p, o) in out.iter_mut().enumerate() {
            if on(p) {
                *o = lam;
            }
        }
    }
}

/// The depth distortion's weight per pixel (`raster::Distortion`): `w / (N·D̄_p)` where the
/// render covers the pixel (`α ≥ ½`; `D̄ = D/α` its depth, held constant so that `w` is
/// free of the scene's scale, `N` the pixels), 0 elsewhere.
pub fn distortion_weights(depth: &[f32], alpha: &[f32], w: f64, out: &mut Vec<f32>) {
    out.clear();
    out.resize(depth.len(), 0.0);
    let scale = w / depth.len().max(1) as f64;
    for ((o, &d), &a) in out.iter_mut().zip(depth).zip(alpha) {
        if a >= MIN_ALPHA && d > 0.0 {
            *o = (scale * a as f64 / d as f64) as f32;
        }
    }
}

#[cfg(test)]
mod distortion_tests {
    use super::distortion_weights;

    /// `w / (N·D/α)` where α ≥ ½, by hand; nothing where the render does not cover.
    #[test]
    fn weights_are_free_of_the_scale() {
        let (depth, alpha) = ([2.0, 1.0, 3.0, 0.0], [1.0, 0.5, 0.4, 0.9]);
        let mut out = Vec::new();
        distortion_weights(&depth, &alpha, 0.8, &mut out);
        let want = [0.8 / 4.0 / 2.0, 0.8 / 4.0 / 2.0, 0.0, 0.0];
        for (a, b) in out.iter().zip(want) {
            assert!((*a as f64 - b).abs() < 1e-7, "{out:?}");
        }
        // The same scene twice as far: the same weights times ½, so λ·Σ w w |Δz| is unchanged.
        distortion_weights(&depth.map(|d| 2.0 * d), &alpha, 0.8, &mut out);
        assert!((out[0] as f64 - 0.05).abs() < 1e-7);
    }
}
