//! A plain f64 renderer for tests: every Gaussian at every pixel, one global depth
//! sort, no tiles, the same cut-offs as [`super::TileRasterizer`]. Slow by design.

use super::alpha::{ALPHA_MAX, ALPHA_MIN, CULL_OPACITY, LOW_PASS, NEAR, SIGMA_CUTOFF, T_MIN};
use super::{project::jacobian_limits, sh};
use crate::splats::Splats;
use glam::{DMat3, DQuat, DVec3};
use scene::Camera;

/// Gaussian parameters in f64 (same layout and meaning as [`Splats`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gaussians64 {
    pub means: Vec<[f64; 3]>,
    pub log_scales: Vec<[f64; 3]>,
    pub rotations: Vec<[f64; 4]>,
    pub opacity_logits: Vec<f64>,
    pub sh_dc: Vec<[f64; 3]>,
    pub sh_rest: Vec<[f64; 45]>,
}

impl From<&Splats> for Gaussians64 {
    fn from(s: &Splats) -> Self {
        Gaussians64 {
            means: s.means.iter().map(|v| v.map(f64::from)).collect(),
            log_scales: s.log_scales.iter().map(|v| v.map(f64::from)).collect(),
            rotations: s.rotations.iter().map(|v| v.map(f64::from)).collect(),
            opacity_logits: s.opacity_logits.iter().map(|&v| v as f64).collect(),
            sh_dc: s.sh_dc.iter().map(|v| v.map(f64::from)).collect(),
            sh_rest: s.sh_rest.iter().map(|v| v.map(f64::from)).collect(),
        }
    }
}

/// Planar RGB `3×H×W`, depth and alpha `H×W`.
#[derive(Clone, Debug, Default)]
pub struct RenderedImage64 {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<f64>,
    pub depth: Vec<f64>,
    pub alpha: Vec<f64>,
}

struct Splat2 {
    mean: [f64; 2],
    conic: [f64; 3],
    opacity: f64,
    color: [f64; 3],
    depth: f64,
}

// Eq. 2: Σ = R S Sᵀ Rᵀ, then Σ₂ = J W Σ Wᵀ Jᵀ (+ low-pass).
fn splat2(g: &Gaussians64, i: usize, cam: &Camera, sh_degree: u32) -> Option<Splat2> {
    let k = &cam.intrinsics;
    let opacity = 1.0 / (1.0 + (-g.opacity_logits[i]).exp());
    if opacity < CULL_OPACITY as f64 {
        return None;
    }
    let [qw, qx, qy, qz] = g.rotations[i];
    let q = DQuat::from_xyzw(qx, qy, qz, qw);
    if q.length() < 1e-12 {
        return None;
    }
    let r = DMat3::from_quat(q.normalize());
    let s = DMat3::from_diagonal(DVec3::from(g.log_scales[i]).exp());
    let sigma = r * s * s * r.transpose();
    let world_to_cam = DMat3::from_quat(cam.cam_to_world.rotation.inverse());
    let mean = DVec3::from(g.means[i]);
    let pc = cam.cam_to_world.to_camera(mean);
    let d = -pc.z;
    if d <= NEAR as f64 {
        return None;
    }
    let lim = jacobian_limits(k.fx, k.fy, k.cx, k.cy, k.width as f64, k.height as f64);
    let tx = (pc.x / d).clamp(lim[0], lim[1]);
    let ty = (pc.y / d).clamp(lim[2], lim[3]);
    // Rows of J (u = cx + fx·x/d, v = cy − fy·y/d, d = −z).
    let j0 = DVec3::new(k.fx / d, 0.0, k.fx * tx / d);
    let j1 = DVec3::new(0.0, -k.fy / d, -k.fy * ty / d);
    let sc = world_to_cam * sigma * world_to_cam.transpose();
    let a = j0.dot(sc * j0) + LOW_PASS as f64;
    let b = j0.dot(sc * j1);
    let c = j1.dot(sc * j1) + LOW_PASS as f64;
    let det = a * c - b * b;
    if det <= 0.0 {
        return None;
    }
    let px = k.project(pc)?;
    let dir = (mean - cam.cam_to_world.translation).normalize();
    let basis = sh::basis_f64(dir.into(), sh_degree);
    let color = std::array::from_fn(|ch| {
        let mut v = 0.5 + basis[0] * g.sh_dc[i][ch];
        for (kk, bk) in basis
            .iter()
            .enumerate()
            .take(sh::num_coeffs(sh_degree))
            .skip(1)
        {
            v += bk * g.sh_rest[i][(kk - 1) * 3 + ch];
        }
        v.max(0.0)
    });
    Some(Splat2 {
        mean: [px.x, px.y],
        conic: [c / det, -b / det, a / det],
        opacity,
        color,
        depth: d,
    })
}

/// Render `g` from `cam`.
// Eq. 1: C = Σᵢ cᵢ αᵢ Πⱼ₍ⱼ<ᵢ₎ (1 − αⱼ) over the depth-sorted Gaussians.
pub fn render(
    g: &Gaussians64,
    cam: &Camera,
    sh_degree: u32,
    background: [f64; 3],
) -> RenderedImage64 {
    composite(g, cam, sh_degree, background, None, None, None)
}

/// Each Gaussian's blending weight `Σ_pixels αᵢ·Tᵢ` in the render of `g` at `cam`.
pub fn contributions(g: &Gaussians64, cam: &Camera) -> Vec<f64> {
    let mut w = vec![0.0; g.means.len()];
    composite(g, cam, 0, [0.0; 3], Some(&mut w), None, None);
    w
}

/// Per pixel, how far apart the depths blended into it lie: `Σᵢ Σⱼ wᵢ wⱼ |zᵢ − zⱼ|`
/// over the Gaussians' weights `wᵢ = αᵢ Tᵢ` and centre depths (the distortion of
/// Mip-NeRF 360 and 2DGS; 0 when one depth carries the pixel), divided by `(Σ w)² D̄`,
/// `D̄` the blended depth: the mean distance between two depths drawn by the weights,
/// relative (two equal layers `Δ` apart give `Δ / 2D̄`). 0 where nothing is drawn.
pub fn depth_spread(g: &Gaussians64, cam: &Camera) -> Vec<f64> {
    let (mut spread, f) = distortion(g, cam);
    for ((v, a), d) in spread.iter_mut().zip(&f.alpha).zip(&f.depth) {
        *v = if *d > 0.0 { *v / (a * d) } else { 0.0 };
    }
    spread
}

/// Per pixel, the depth distortion `Σᵢ Σⱼ wᵢ wⱼ |zᵢ − zⱼ|` (`raster::Distortion`'s loss
/// before its weights), and the render (SH degree 0, black background).
pub fn distortion(g: &Gaussians64, cam: &Camera) -> (Vec<f64>, RenderedImage64) {
    let n = (cam.intrinsics.width * cam.intrinsics.height) as usize;
    let mut out = vec![0.0; n];
    let f = composite(g, cam, 0, [0.0; 3], None, Some(&mut out), None);
    (out, f)
}

/// Per pixel, `Σᵢ mᵢ wᵢ H((zᵢ − ẑ_p)/(σ ẑ_p))` over the blending weights and centre
/// depths, `mᵢ = factors[i]` (1 for all when empty), `H` Huber at 1 (`raster::Anchor`'s
/// loss before its weights; 0 where `ẑ_p ≤ 0`).
pub fn anchored(
    g: &Gaussians64,
    cam: &Camera,
    z_hat: &[f64],
    sigma: f64,
    factors: &[f64],
) -> Vec<f64> {
    let mut out = vec![0.0; z_hat.len()];
    let anchor = Anchor64 {
        z_hat,
        sigma,
        factors,
        out: &mut out,
    };
    composite(g, cam, 0, [0.0; 3], None, None, Some(anchor));
    out
}

/// [`anchored`]'s inputs and output inside [`composite`].
struct Anchor64<'a> {
    z_hat: &'a [f64],
    sigma: f64,
    factors: &'a [f64],
    out: &'a mut Vec<f64>,
}

/// Huber at 1: `r²/2` up to 1, `|r| − ½` beyond.
fn huber(r: f64) -> f64 {
    if r.abs() <= 1.0 {
        0.5 * r * r
    } else {
        r.abs() - 0.5
    }
}

/// The render, and when `weights` is given each Gaussian's `α·T` summed into it.
fn composite(
    g: &Gaussians64,
    cam: &Camera,
    sh_degree: u32,
    background: [f64; 3],
    mut weights: Option<&mut Vec<f64>>,
    mut spread: Option<&mut Vec<f64>>,
    mut anchor: Option<Anchor64>,
) -> RenderedImage64 {
    let (w, h) = (
        cam.intrinsics.width as usize,
        cam.intrinsics.height as usize,
    );
    let sh_degree = sh_degree.min(3);
    let mut splats: Vec<(usize, Splat2)> = (0..g.means.len())
        .filter_map(|i| splat2(g, i, cam, sh_degree).map(|s| (i, s)))
        .collect();
    splats.sort_by(|a, b| a.1.depth.total_cmp(&b.1.depth).then(a.0.cmp(&b.0)));
    let np = w * h;
    let mut f = RenderedImage64 {
        width: w,
        height: h,
        rgb: vec![0.0; 3 * np],
        depth: vec![0.0; np],
        alpha: vec![0.0; np],
    };
    let cut2 = (SIGMA_CUTOFF * SIGMA_CUTOFF) as f64;
    for y in 0..h {
        for x in 0..w {
            let mut t = 1.0f64;
            let mut rgb = [0.0f64; 3];
            let mut depth = 0.0;
            // Σ w, and Σᵢ Σⱼ<ᵢ wᵢ wⱼ (zᵢ − zⱼ) (the splats come nearest first).
            let mut pairs = 0.0;
            for (i, s) in &splats {
                let dx = x as f64 - s.mean[0];
                let dy = y as f64 - s.mean[1];
                let m = s.conic[0] * dx * dx + 2.0 * s.conic[1] * dx * dy + s.conic[2] * dy * dy;
                if m > cut2 {
                    continue;
                }
                let alpha = (s.opacity * (-0.5 * m).exp()).min(ALPHA_MAX as f64);
                if alpha < ALPHA_MIN as f64 {
                    continue;
                }
                let next = t * (1.0 - alpha);
                if next < T_MIN as f64 {
                    break;
                }
                for c in 0..3 {
                    rgb[c] += alpha * t * s.color[c];
                }
                let wi = alpha * t;
                if let Some(an) = anchor.as_mut() {
                    let zh = an.z_hat[y * w + x];
                    let m = an.factors.get(*i).copied().unwrap_or(1.0);
                    if zh > 0.0 {
                        an.out[y * w + x] += m * wi * huber((s.depth - zh) / (an.sigma * zh));
                    }
                }
                pairs += wi * (s.depth * (1.0 - t) - depth);
                depth += wi * s.depth;
                if let Some(wts) = weights.as_deref_mut() {
                    wts[*i] += alpha * t;
                }
                t = next;
            }
            let p = y * w + x;
            for c in 0..3 {
                f.rgb[c * np + p] = rgb[c] + t * background[c];
            }
            f.depth[p] = depth;
            f.alpha[p] = 1.0 - t;
            if let Some(out) = spread.as_deref_mut() {
                out[p] = 2.0 * pairs;
            }
        }
    }
    f
}
