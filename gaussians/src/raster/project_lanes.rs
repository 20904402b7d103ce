//! The forward pass's projection of `V::N` Gaussians at once: the arithmetic of
//! [`project::intermediates`](super::project::intermediates) in lanes (`exp` by
//! [`simd::fast_exp`], relative error < 1e-6), then per Gaussian the scalar culling and
//! pixel box of [`screen_extent`] and the SH colour of the visible ones. The test at the
//! bottom holds it to the one-at-a-time [`project`](super::project::project).

use super::alpha::{ALPHA_MIN, LOW_PASS, SIGMA_CUTOFF};
use super::project::{CamSetup, Geo, project, screen_extent, sh_colour};
use super::sh;
use super::simd::{self, F4, Lanes};
use crate::splats::Splats;

/// Widest lane count (AVX-512).
pub(super) const MAX: usize = 16;
pub(super) type Row = [f32; MAX];

/// What the tile passes need of one projected Gaussian.
#[derive(Clone, Copy)]
pub(crate) struct Splat2d {
    pub xy: [f32; 2],
    pub conic: [f32; 3],
    pub opacity: f32,
    pub color: [f32; 3],
    pub depth: f32,
    pub bbox: [u32; 4],
    pub cut: f32,
}

impl Splat2d {
    pub fn of(g: &Geo) -> Self {
        Splat2d {
            xy: g.uv,
            conic: g.conic,
            opacity: g.opacity,
            color: g.color,
            depth: g.depth,
            bbox: g.bbox,
            cut: g.cut,
        }
    }
}

/// What the forward pass keeps of Gaussian `i`: its screen radius (0 = culled) and,
/// when visible, what the tile kernels need.
pub(crate) type Projection = (f32, Option<Splat2d>);

/// Project Gaussians `start..start + out.len()` into `out`, lanes where the CPU has
/// them (AVX-512: 16 at once, else SSE2: 4), the last few one at a time.
pub(crate) fn project_span(
    s: &Splats,
    start: usize,
    cam: &CamSetup,
    sh_degree: u32,
    out: &mut [Projection],
) {
    #[cfg(target_arch = "x86_64")]
    if simd::use_wide() {
        // SAFETY: `use_wide` checked that the CPU has AVX-512F.
        unsafe { project_span_avx512(s, start, cam, sh_degree, out) };
        return;
    }
    project_span_lanes::<F4>(s, start, cam, sh_degree, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn project_span_avx512(
    s: &Splats,
    start: usize,
    cam: &CamSetup,
    sh_degree: u32,
    out: &mut [Projection],
) {
    project_span_lanes::<simd::F16>(s, start, cam, sh_degree, out)
}

#[inline(always)]
fn project_span_lanes<V: Lanes>(
    s: &Splats,
    start: usize,
    cam: &CamSetup,
    sh_degree: u32,
    out: &mut [Projection],
) {
    let mut blocks = out.chunks_exact_mut(V::N);
    let mut at = start;
    for block in &mut blocks {
        project_block::<V>(s, at, cam, sh_degree, block);
        at += V::N;
    }
    for (k, o) in blocks.into_remainder().iter_mut().enumerate() {
        *o = match project(s, at + k, cam, sh_degree) {
            None => (0.0, None),
            Some(g) => (g.radius, Some(Splat2d::of(&g))),
        };
    }
}

/// `exp(x)` for any `x`: [`simd::fast_exp`] below 0, its reciprocal at `−x` above.
#[inline(always)]
fn exp_any<V: Lanes>(x: V) -> V {
    let s = V::splat;
    let pos = s(1.0) / simd::fast_exp(s(0.0) - x);
    V::select(x.gt(s(0.0)), pos, simd::fast_exp(x))
}

/// One block's parameters as rows (struct of arrays), lane `l` = Gaussian `start + l`.
pub(super) struct Rows {
    pub logit: Row,
    pub q: [Row; 4],
    pub mean: [Row; 3],
    pub ls: [Row; 3],
}

impl Rows {
    #[inline(always)]
    pub fn gather(s: &Splats, start: usize, n: usize) -> Rows {
        let mut r = Rows {
            logit: [0.0; MAX],
            q: [[0.0; MAX]; 4],
            mean: [[0.0; MAX]; 3],
            ls: [[0.0; MAX]; 3],
        };
        for l in 0..n {
            let i = start + l;
            r.logit[l] = s.opacity_logits[i];
            for k in 0..4 {
                r.q[k][l] = s.rotations[i][k];
            }
            for k in 0..3 {
                r.mean[k][l] = s.means[i][k];
                r.ls[k][l] = s.log_scales[i][k];
            }
        }
        r
    }
}

/// The intermediates of [`project::intermediates`](super::project::intermediates) in
/// lanes (matrices `[row][column]`), plus `cut` = [`reach`](super::project::reach)`(o)`.
pub(super) struct GeoLanes<V> {
    pub opacity: V,
    pub cut: V,
    pub qnorm: V,
    /// Unit quaternion `(w, x, y, z)`.
    pub n: [V; 4],
    pub r: [[V; 3]; 3],
    pub sc: [V; 3],
    pub m: [[V; 3]; 3],
    pub p: [V; 3],
    /// `W Σ`.
    pub wsig: [[V; 3]; 3],
    pub sigc: [[V; 3]; 3],
    pub pc: [V; 3],
    pub depth: V,
    pub rx: V,
    pub ry: V,
    pub tx: V,
    pub ty: V,
    /// The Jacobian's non-zero entries `J00, J02, J11, J12`.
    pub j: [V; 4],
    pub cov: [V; 3],
    pub det: V,
    pub conic: [V; 3],
    pub uv: [V; 2],
    pub dir: [V; 3],
    pub dir_len: V,
    pub basis: [V; 16],
}

/// Gaussians `start..start + V::N` into `out` (`V::N` long).
#[inline(always)]
fn project_block<V: Lanes>(
    s: &Splats,
    start: usize,
    cam: &CamSetup,
    sh_degree: u32,
    out: &mut [Projection],
) {
    let n = V::N;
    let g = geo_lanes::<V>(&Rows::gather(s, start, n), cam, sh_degree);
    // Back to rows, then culling, box and colour per Gaussian.
    let [o, cut, qnorm, det, px, py, pz, c0, c1, c2, q0, q1, q2, u, v] = to_rows([
        g.opacity, g.cut, g.qnorm, g.det, g.pc[0], g.pc[1], g.pc[2], g.cov[0], g.cov[1], g.cov[2],
        g.conic[0], g.conic[1], g.conic[2], g.uv[0], g.uv[1],
    ]);
    let basis = to_rows(g.basis);
    let nc = sh::num_coeffs(sh_degree);
    for (l, slot) in out.iter_mut().enumerate().take(n) {
        let (pc, cov, uv) = ([px[l], py[l], pz[l]], [c0[l], c1[l], c2[l]], [u[l], v[l]]);
        *slot = match screen_extent(o[l], cut[l], qnorm[l], pc, det[l], cov, uv, cam) {
            None => (0.0, None),
            Some((bbox, cut, radius)) => {
                let mut bl = [0.0; 16];
                for k in 0..nc {
                    bl[k] = basis[k][l];
                }
                let mut color = sh_colour(s, start + l, &bl, sh_degree);
                for c in &mut color {
                    *c = c.max(0.0);
                }
                let splat = Splat2d {
                    xy: uv,
                    conic: [q0[l], q1[l], q2[l]],
                    opacity: o[l],
                    color,
                    depth: -pc[2],
                    bbox,
                    cut,
                };
                (radius, Some(splat))
            }
        };
    }
}

/// Lane vectors back to rows: lane `l` of vector `k` at `[k][l]`.
#[inline(always)]
pub(super) fn to_rows<V: Lanes, const K: usize>(vs: [V; K]) -> [Row; K] {
    let mut rows = [[0.0; MAX]; K];
    for k in 0..K {
        vs[k].store(&mut rows[k][..]);
    }
    rows
}

/// The arithmetic of the projection for one block of rows (Eq. 2).
#[inline(always)]
pub(super) fn geo_lanes<V: Lanes>(rows: &Rows, cam: &CamSetup, sh_degree: u32) -> GeoLanes<V> {
    let Rows { logit, q, mean, ls } = rows;
    // No closures below: they would not inherit the caller's target features, and
    // every intrinsic in them would become a call.
    let sp = V::splat;
    let zero = sp(0.0);
    let one = sp(1.0);
    let two = sp(2.0);

    // Opacity: the sigmoid through exp(−|x|) ≤ 1.
    let x = V::load(&logit[..]);
    let e = simd::fast_exp(zero - x.max(zero - x));
    let opacity = V::select(zero.le(x), one, e) / (one + e);
    // `reach(opacity)` with ln(o) = −max(−x, 0) − ln(1 + e), e ∈ (0, 1]:
    // ln(1 + e) = 2·atanh(u), u = e / (2 + e) ≤ ⅓, six odd terms (error < 3e-7).
    let u = e / (two + e);
    let u2 = u * u;
    let mut poly = sp(1.0 / 11.0);
    for c in [1.0 / 9.0, 1.0 / 7.0, 1.0 / 5.0, 1.0 / 3.0, 1.0] {
        poly = poly.mul_add(u2, sp(c));
    }
    let ln_o = zero - (zero - x).max(zero) - two * u * poly;
    let m = (two * (ln_o - sp(ALPHA_MIN.ln()))).min(sp(SIGMA_CUTOFF * SIGMA_CUTOFF));
    let cut = m.max(zero) * sp(1.001) + sp(0.01);

    // Unit quaternion → R (the columns of `quat_to_mat`).
    let mut qv = [zero; 4];
    for k in 0..4 {
        qv[k] = V::load(&q[k][..]);
    }
    let qnorm = (qv[0] * qv[0] + qv[1] * qv[1] + qv[2] * qv[2] + qv[3] * qv[3]).sqrt();
    let inv = one / qnorm;
    let (w, x, y, z) = (qv[0] * inv, qv[1] * inv, qv[2] * inv, qv[3] * inv);
    let r = [
        [
            one - two * (y * y + z * z),
            two * (x * y - w * z),
            two * (x * z + w * y),
        ],
        [
            two * (x * y + w * z),
            one - two * (x * x + z * z),
            two * (y * z - w * x),
        ],
        [
            two * (x * z - w * y),
            two * (y * z + w * x),
            one - two * (x * x + y * y),
        ],
    ];
    // M = R diag(s), Σ = M Mᵀ (Eq. 2).
    let mut sc = [zero; 3];
    let mut p = [zero; 3];
    for k in 0..3 {
        sc[k] = exp_any(V::load(&ls[k][..]));
        p[k] = V::load(&mean[k][..]);
    }
    let mut m = [[zero; 3]; 3];
    for a in 0..3 {
        for c in 0..3 {
            m[a][c] = r[a][c] * sc[c];
        }
    }
    let mut sigma = [[zero; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            sigma[a][b] = dot3(m[a], m[b]);
        }
    }
    // Camera frame: p_c = W p + t_w, Σc = W Σ Wᵀ (W[a][k] = w.col(k)[a]).
    let mut wm = [[zero; 3]; 3];
    for a in 0..3 {
        for k in 0..3 {
            wm[a][k] = sp(cam.w.col(k)[a]);
        }
    }
    let mut pc = [zero; 3];
    let mut t = [[zero; 3]; 3];
    for a in 0..3 {
        pc[a] = dot3(wm[a], p) + sp(cam.tw[a]);
        for b in 0..3 {
            t[a][b] = dot3(wm[a], [sigma[0][b], sigma[1][b], sigma[2][b]]);
        }
    }
    let mut sigc = [[zero; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            sigc[a][b] = dot3(t[a], wm[b]);
        }
    }
    // Perspective Jacobian with the clamped x/d, y/d; Σ₂ = J Σc Jᵀ + low-pass.
    let depth = zero - pc[2];
    let (rx, ry) = (pc[0] / depth, pc[1] / depth);
    let tx = rx.max(sp(cam.lim[0])).min(sp(cam.lim[1]));
    let ty = ry.max(sp(cam.lim[2])).min(sp(cam.lim[3]));
    let (j0x, j0z) = (sp(cam.fx) / depth, sp(cam.fx) * tx / depth);
    let (j1y, j1z) = (sp(-cam.fy) / depth, sp(-cam.fy) * ty / depth);
    let mut t0 = [zero; 3];
    let mut t1 = [zero; 3];
    for a in 0..3 {
        t0[a] = sigc[a][0] * j0x + sigc[a][2] * j0z;
        t1[a] = sigc[a][1] * j1y + sigc[a][2] * j1z;
    }
    let cov = [
        j0x * t0[0] + j0z * t0[2] + sp(LOW_PASS),
        j0x * t1[0] + j0z * t1[2],
        j1y * t1[1] + j1z * t1[2] + sp(LOW_PASS),
    ];
    let det = cov[0] * cov[2] - cov[1] * cov[1];
    let conic = [cov[2] / det, (zero - cov[1]) / det, cov[0] / det];
    let uv = [sp(cam.cx) + sp(cam.fx) * rx, sp(cam.cy) - sp(cam.fy) * ry];
    // View direction for the SH colour.
    let mut dir = [zero; 3];
    for a in 0..3 {
        dir[a] = p[a] - sp(cam.centre[a]);
    }
    let len = dot3(dir, dir).sqrt().max(sp(1e-12));
    let basis = sh::basis_lanes([dir[0] / len, dir[1] / len, dir[2] / len], sh_degree);

    GeoLanes {
        opacity,
        cut,
        qnorm,
        n: [w, x, y, z],
        r,
        sc,
        m,
        p,
        wsig: t,
        sigc,
        pc,
        depth,
        rx,
        ry,
        tx,
        ty,
        j: [j0x, j0z, j1y, j1z],
        cov,
        det,
        conic,
        uv,
        dir,
        dir_len: len,
        basis,
    }
}

/// `a · b` over three lanes vectors.
#[inline(always)]
fn dot3<V: Lanes>(a: [V; 3], b: [V; 3]) -> V {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[cfg(test)]
pub(super) mod tests;
