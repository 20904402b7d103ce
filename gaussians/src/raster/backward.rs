//! Backward pass. Each tile walks its list back to front (recovering the transmittance
//! in front of each Gaussian by division, as 3DGS) and writes the screen-space gradient
//! of every (Gaussian, tile) pair into its own slice of one array, so there are no
//! shared writes; the pairs are then summed per Gaussian and chained through the
//! projection in parallel. The camera gradient is reduced in f64.

use super::alpha::{ALPHA_MAX, eval_alpha};
use super::forward::{BackScratch, Plane, RenderState, TILE, lane_bits, row_span};
use super::project::ScreenGrad;
use super::project_backward_lanes::{Outs, Shared, backward_span};
use super::rasterizer::{Anchor, Distortion, Planes};
use super::simd::{self, F4, Lanes, Mask};
use crate::splats::{SplatGrads, Splats};
use glam::{DMat3, DVec3};
use rayon::prelude::*;
use scene::Camera;

/// Per-pixel inputs of one tile's backward.
struct PixelGrads<'a> {
    d_rgb: &'a [f32],
    d_depth: Option<&'a [f32]>,
    d_alpha: Option<&'a [f32]>,
    distortion: Option<Distortion<'a>>,
    anchor: Option<Anchor<'a>>,
}

/// Back to front over one tile's list with the widest lanes this CPU has.
fn tile_backward(st: &RenderState, t: usize, g: &PixelGrads, out: &mut [ScreenGrad]) {
    #[cfg(target_arch = "x86_64")]
    if simd::use_wide() {
        // SAFETY: `use_wide` checked that the CPU has AVX-512F.
        return unsafe { tile_backward_avx512(st, t, g, out) };
    }
    tile_backward_lanes::<F4>(st, t, g, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn tile_backward_avx512(st: &RenderState, t: usize, g: &PixelGrads, out: &mut [ScreenGrad]) {
    tile_backward_lanes::<simd::F16>(st, t, g, out)
}

/// `out[k]` receives entry k's screen gradient (every entry is written). Per lane branch-free (lanes outside
/// the ellipse or past the pixel's last contributor get α = 0, which makes every update
/// a no-op), with per-lane accumulators summed once per Gaussian.
#[inline(always)]
fn tile_backward_lanes<V: Lanes>(
    st: &RenderState,
    t: usize,
    g: &PixelGrads,
    out: &mut [ScreenGrad],
) {
    let (w, h) = (st.cam.width, st.cam.height);
    let np = w * h;
    let r = st.tiles.rect(t, w, h);
    let list = st.tiles.of(t);
    let p = &st.proj;
    let bg = st.background;
    let z = [[0.0f32; TILE]; TILE];
    // Per pixel: transmittance (walked back), loss gradients of colour and depth, and
    // `behind` = Σ_ch ∂L/∂ch · (what lies behind the current entry in channel ch) −
    // ∂L/∂alpha · T_final: the one sum `∂L/∂α` needs of the pixels behind (Eq. 1 walked
    // back to front; `behind` starts with the background).
    let mut tt: Plane<f32> = z;
    let mut last: Plane<f32> = z;
    let mut behind: Plane<f32> = z;
    let mut dl: [Plane<f32>; 4] = [z; 4];
    // The distortion's (`Planes::distortion`): its weight λ, the pixel's Σ w (`A`) and
    // Σ w·z (`D`), and `ahead` = Σ w·z over the entries in front of the current one
    // (`D` less those behind it, walked back).
    let (mut lam, mut a_tot, mut d_tot, mut ahead) = (z, z, z, z);
    // The anchor's (`Planes::anchor`): its weight λ, depth ẑ and 1/(σẑ).
    let (mut lam_a, mut z_hat, mut inv_sz) = (z, z, z);
    let mut max_last = 0u32;
    for y in r[2]..r[3] {
        for x in r[0]..r[1] {
            let (ty, tx) = (y - r[2], x - r[0]);
            let pix = y * w + x;
            let tf = st.t_final[pix];
            tt[ty][tx] = tf;
            last[ty][tx] = st.last[pix] as f32;
            max_last = max_last.max(st.last[pix]);
            let mut b = -g.d_alpha.map_or(0.0, |d| d[pix]) * tf;
            for c in 0..3 {
                let d = g.d_rgb[c * np + pix];
                dl[c][ty][tx] = d;
                b += d * tf * bg[c];
            }
            behind[ty][tx] = b;
            dl[3][ty][tx] = g.d_depth.map_or(0.0, |d| d[pix]);
            if let Some(dist) = &g.distortion {
                lam[ty][tx] = dist.weight[pix];
                a_tot[ty][tx] = 1.0 - tf;
                d_tot[ty][tx] = dist.depth[pix];
                ahead[ty][tx] = dist.depth[pix];
            }
            if let Some(an) = &g.anchor {
                let zh = an.depth[pix];
                let on = an.weight[pix] > 0.0 && zh > 0.0;
                lam_a[ty][tx] = if on { an.weight[pix] } else { 0.0 };
                z_hat[ty][tx] = zh;
                inv_sz[ty][tx] = if on { 1.0 / (an.sigma * zh) } else { 0.0 };
            }
        }
    }
    let distortion = g.distortion.is_some();
    let anchor = g.anchor.is_some();
    let factors = g.anchor.map_or(&[][..], |a| a.gaussians);
    // Entries behind every pixel's last contributor get no gradient.
    out[max_last as usize..].fill([0.0; 10]);
    let n = V::N;
    let s = V::splat;
    let xs: [V; 4] = std::array::from_fn(|c| V::iota((r[0] + (c * n) % TILE) as f32));
    for k in (0..max_last as usize).rev() {
        let gi = list[k] as usize;
        let b = p.bbox[gi];
        let (x0, x1) = ((b[0] as usize).max(r[0]), (b[1] as usize + 1).min(r[1]));
        let (y0, y1) = ((b[2] as usize).max(r[2]), (b[3] as usize + 1).min(r[3]));
        let [u, v] = p.xy[gi];
        let (conic, op, col, dep) = (p.conic[gi], p.opacity[gi], p.color[gi], p.depth[gi]);
        let cv = [s(col[0]), s(col[1]), s(col[2]), s(dep)];
        let u4 = s(u);
        let kk = s(k as f32);
        // The anchor's factor of this Gaussian (`Anchor::gaussians`, by its Splats index).
        let factor = if anchor {
            factors.get(p.id[gi] as usize).copied().unwrap_or(1.0)
        } else {
            0.0
        };
        // Colour and depth gradients, and the moments of the α gradient (below).
        let mut acc = [s(0.0); 4];
        let mut mom = [s(0.0); 6];
        for y in y0..y1 {
            let ro = y - r[2];
            let dyf = y as f32 - v;
            // One vector covers the row: the ellipse test per lane is enough. Narrow
            // lanes skip the chunks outside the ellipse's span on this row.
            let (lo, hi) = if n == TILE {
                (x0 - r[0], x1 - r[0])
            } else {
                row_span(conic, p.cut[gi], u, dyf, [x0, x1, r[0]])
            };
            let inb = lane_bits(lo, hi);
            let dy = s(dyf);
            for c in lo / n..hi.div_ceil(n) {
                let l = n * c..n * c + n;
                let bits = (inb >> (n * c)) & V::load(&last[ro][l.clone()]).gt(kk).bits();
                if bits == 0 {
                    continue;
                }
                let dx = xs[c] - u4;
                let (a0, raw) = eval_alpha(conic, op, dx, dy);
                let a = a0.and(V::M::from_bits(bits));
                let inv = (s(1.0) - a).recip();
                let t_in = V::load(&tt[ro][l.clone()]) * inv;
                let wgt = a * t_in;
                // d·c: this entry's colour and depth against the pixel's loss gradients.
                let mut dc = s(0.0);
                for ch in 0..4 {
                    let d = V::load(&dl[ch][ro][l.clone()]);
                    dc = d.mul_add(cv[ch], dc);
                    acc[ch] = wgt.mul_add(d, acc[ch]);
                }
                if distortion {
                    // L = λ Σᵢ Σⱼ wᵢ wⱼ |zᵢ − zⱼ| with A_k = 1 − T_k and B_k = Σ_{j<k} wⱼ zⱼ
                    // in front: ∂L/∂w_k = 2λ(z_k(2A_k − A) + D − 2B_k) joins d·c as one
                    // more channel, ∂L/∂z_k = 2λ w_k (2A_k + w_k − A) the depth's.
                    let la = V::load(&lam[ro][l.clone()]);
                    let at = V::load(&a_tot[ro][l.clone()]);
                    let front = s(1.0) - t_in;
                    let b_k = V::load(&ahead[ro][l.clone()]) - wgt * cv[3];
                    b_k.store(&mut ahead[ro][l.clone()]);
                    let twice = s(2.0) * la;
                    let gw = cv[3] * (s(2.0) * front - at) + V::load(&d_tot[ro][l.clone()])
                        - s(2.0) * b_k;
                    dc = twice.mul_add(gw, dc);
                    let gz = wgt * (s(2.0) * front + wgt - at);
                    acc[3] = twice.mul_add(gz, acc[3]);
                }
                if factor != 0.0 {
                    // L = λ Σᵢ mᵢ wᵢ H(rᵢ), r = (z − ẑ)/(σẑ): ∂L/∂w_k = λ m_k H(r_k) joins
                    // d·c as one more channel, ∂L/∂z_k = λ m_k w_k H'(r_k)/(σẑ) the depth's.
                    let la = V::load(&lam_a[ro][l.clone()]) * s(factor);
                    let iv = V::load(&inv_sz[ro][l.clone()]);
                    let r = (cv[3] - V::load(&z_hat[ro][l.clone()])) * iv;
                    let hp = r.max(s(-1.0)).min(s(1.0));
                    let h = hp * (r - s(0.5) * hp);
                    dc = la.mul_add(h, dc);
                    acc[3] = (la * wgt * iv).mul_add(hp, acc[3]);
                }
                let bh = V::load(&behind[ro][l.clone()]);
                // ∂L/∂α = T·(d·c) − (d·behind)/(1 − α).
                let ga = t_in * dc - bh * inv;
                wgt.mul_add(dc, bh).store(&mut behind[ro][l.clone()]);
                t_in.store(&mut tt[ro][l]);
                // α = o·exp(−½ m), m = dᵀQd with d = pixel − mean; no gradient through
                // the clamp at ALPHA_MAX. With g = α·∂L/∂α: ∂L/∂o = Σ g / o and
                // ∂L/∂m = −½ g, so the mean and the conic need only the moments
                // Σ g·(dx, dy, dx², dx·dy, dy²), summed here and combined once below.
                let g = a * ga.and(raw.lt(s(ALPHA_MAX)));
                let (gx, gy) = (g * dx, g * dy);
                mom[0] = mom[0] + g;
                mom[1] = mom[1] + gx;
                mom[2] = mom[2] + gy;
                mom[3] = gx.mul_add(dx, mom[3]);
                mom[4] = gx.mul_add(dy, mom[4]);
                mom[5] = gy.mul_add(dy, mom[5]);
            }
        }
        let [g, gx, gy, gxx, gxy, gyy] = mom.map(|m| m.sum());
        let colour: [f32; 4] = std::array::from_fn(|c| acc[c].sum());
        // ∂m/∂u = −2(a·dx + b·dy), ∂m/∂v = −2(b·dx + c·dy); ∂m/∂(a, b, c) = (dx², 2dx·dy, dy²).
        out[k] = [
            conic[0] * gx + conic[1] * gy,
            conic[1] * gx + conic[2] * gy,
            -0.5 * gxx,
            -gxy,
            -0.5 * gyy,
            g / op,
            colour[0],
            colour[1],
            colour[2],
            colour[3],
        ];
    }
}

pub(crate) fn backward(
    s: &Splats,
    cam: &Camera,
    st: &RenderState,
    d_rgb: &[f32],
    planes: Planes,
) -> (SplatGrads, [f64; 6]) {
    let mut g = SplatGrads::default();
    let twist = backward_into(s, cam, st, d_rgb, planes, &mut g);
    (g, twist)
}

/// [`backward`] into `g` (overwritten, resized to the Gaussians; its buffers and the
/// state's scratch reused; the same values bit for bit).
pub(crate) fn backward_into(
    s: &Splats,
    cam: &Camera,
    st: &RenderState,
    d_rgb: &[f32],
    planes: Planes,
    g: &mut SplatGrads,
) -> [f64; 6] {
    let Planes {
        depth: d_depth,
        alpha: d_alpha,
        distortion,
        anchor,
    } = planes;
    let (w, h) = (st.cam.width, st.cam.height);
    assert_eq!(
        s.len(),
        st.n,
        "backward: Splats differ from the rendered ones"
    );
    assert_eq!(d_rgb.len(), 3 * w * h, "backward: d_rgb must be 3×H×W");
    assert!(
        d_depth.is_none_or(|d| d.len() == w * h),
        "backward: d_depth must be H×W"
    );
    assert!(
        d_alpha.is_none_or(|d| d.len() == w * h),
        "backward: d_alpha must be H×W"
    );
    assert!(
        distortion.is_none_or(|d| d.weight.len() == w * h && d.depth.len() == w * h),
        "backward: the distortion's planes must be H×W"
    );
    assert!(
        anchor.is_none_or(|a| a.weight.len() == w * h && a.depth.len() == w * h),
        "backward: the anchor's planes must be H×W"
    );
    assert!(
        anchor.is_none_or(|a| a.gaussians.is_empty() || a.gaussians.len() == s.len()),
        "backward: the anchor's factors must be one per Gaussian"
    );
    let pg = PixelGrads {
        d_rgb,
        d_depth,
        d_alpha,
        distortion,
        anchor,
    };
    let mut guard = st.back.lock().unwrap_or_else(|e| e.into_inner());
    let BackScratch {
        pairs,
        screen,
        slot,
    } = &mut *guard;
    // Screen gradients per (Gaussian, tile) pair; each tile owns its slice (every entry
    // is written).
    pairs.resize(st.tiles.list.len(), [0.0; 10]);
    let ntiles = st.tiles.nx * st.tiles.ny;
    let mut slices = Vec::with_capacity(ntiles);
    let mut rest = &mut pairs[..st.tiles.list.len()];
    for t in 0..ntiles {
        let len = (st.tiles.ranges[t + 1] - st.tiles.ranges[t]) as usize;
        let (a, b) = rest.split_at_mut(len);
        slices.push((t, a));
        rest = b;
    }
    slices
        .into_par_iter()
        .for_each(|(t, out)| tile_backward(st, t, &pg, out));
    let pairs = &pairs[..st.tiles.list.len()];
    sum_pairs(pairs, &st.tiles.list, st.proj.id.len(), screen);
    let screen = &screen[..];
    slot.clear();
    slot.resize(s.len(), u32::MAX);
    for (k, &id) in st.proj.id.iter().enumerate() {
        slot[id as usize] = k as u32;
    }

    let n = s.len();
    g.resize(n);
    g.radius.copy_from_slice(&st.radius);
    let shared = Shared {
        cam: &st.cam,
        sh_degree: st.sh_degree,
        slot,
        screen,
        half: [0.5 * w as f32, 0.5 * h as f32],
    };
    // Spans of 256 Gaussians (a multiple of every lane count) over the threads.
    const SPAN: usize = 256;
    let cam_grad = (
        g.means.par_chunks_mut(SPAN),
        g.log_scales.par_chunks_mut(SPAN),
        g.rotations.par_chunks_mut(SPAN),
        g.opacity_logits.par_chunks_mut(SPAN),
        g.sh_dc.par_chunks_mut(SPAN),
        g.sh_rest.par_chunks_mut(SPAN),
        g.screen_grad_norm.par_chunks_mut(SPAN),
    )
        .into_par_iter()
        .enumerate()
        .map(
            |(c, (means, log_scales, rotations, opacity_logits, sh_dc, sh_rest, sgn))| {
                let out = Outs {
                    means,
                    log_scales,
                    rotations,
                    opacity_logits,
                    sh_dc,
                    sh_rest,
                    screen_grad_norm: sgn,
                };
                backward_span(s, c * SPAN, shared, out)
            },
        )
        .reduce(
            || [0.0f64; 15],
            |mut a, b| {
                for k in 0..15 {
                    a[k] += b[k];
                }
                a
            },
        );
    pose_twist_grad(cam, &cam_grad)
}

/// `screen[k] = Σ pairs[j]` over the pairs j of projected Gaussian k (`list[j] = k`),
/// added in list order as one serial pass would. Each thread owns a range of k and
/// reads the whole list (sequential reads; the pairs it skips cost nothing).
fn sum_pairs(pairs: &[ScreenGrad], list: &[u32], nv: usize, screen: &mut Vec<ScreenGrad>) {
    screen.clear();
    screen.resize(nv, [0.0; 10]);
    let chunk = nv.div_ceil(rayon::current_num_threads().max(1)).max(1);
    screen
        .par_chunks_mut(chunk)
        .enumerate()
        .for_each(|(c, out)| {
            let lo = (c * chunk) as u32;
            let hi = lo + out.len() as u32;
            for (g, &k) in pairs.iter().zip(list) {
                if (lo..hi).contains(&k) {
                    let acc = &mut out[(k - lo) as usize];
                    for c in 0..10 {
                        acc[c] += g[c];
                    }
                }
            }
        });
}

/// `∂L/∂(W, t_w, C)` → `∂L/∂δ` for the right (camera-frame) twist of the module docs.
/// First for the world-frame left twist `a` (`W' ≈ W(I − [ω]×)`, `t_w' ≈ t_w − W v`,
/// `C' ≈ C + ω×C + v`); a right twist `b` is the left twist `a = (R·b_v + C × (R·b_ω),
/// R·b_ω)` to first order, so `∂L/∂b = (Rᵀ·∂L/∂a_v, Rᵀ·(∂L/∂a_ω − C × ∂L/∂a_v))`.
fn pose_twist_grad(cam: &Camera, c: &[f64; 15]) -> [f64; 6] {
    let inv = cam.cam_to_world.inverse();
    let wm = DMat3::from_quat(inv.rotation);
    let g_w = DMat3::from_cols_slice(&c[0..9]);
    let g_tw = DVec3::new(c[9], c[10], c[11]);
    let g_c = DVec3::new(c[12], c[13], c[14]);
    let centre = cam.cam_to_world.translation;
    let g_v = -(wm.transpose() * g_tw) + g_c;
    let m = wm.transpose() * g_w;
    let e = |i: usize, j: usize| m.col(j)[i];
    let g_omega =
        -DVec3::new(e(2, 1) - e(1, 2), e(0, 2) - e(2, 0), e(1, 0) - e(0, 1)) + centre.cross(g_c);
    // `wm` is Rᵀ (world-to-camera rotation).
    let (b_v, b_omega) = (wm * g_v, wm * (g_omega - centre.cross(g_v)));
    [b_v.x, b_v.y, b_v.z, b_omega.x, b_omega.y, b_omega.z]
}
