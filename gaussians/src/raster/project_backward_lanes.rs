//! [`project_backward`](super::project::project_backward) for `V::N` Gaussians at once:
//! the intermediates recomputed in lanes ([`geo_lanes`], as the forward pass made them),
//! then the chain from the screen gradient to every parameter and to the camera. Culled
//! Gaussians get zero gradients. The test beside it holds it to the one-at-a-time path.

use super::project::{CamSetup, ScreenGrad, intermediates, project_backward};
use super::project_lanes::{MAX, Row, Rows, geo_lanes, to_rows};
use super::sh;
use super::simd::{self, F4, Lanes, Mask};
use crate::splats::Splats;

/// Where one span's gradients go (each slice as long as the span).
pub(crate) struct Outs<'a> {
    pub means: &'a mut [[f32; 3]],
    pub log_scales: &'a mut [[f32; 3]],
    pub rotations: &'a mut [[f32; 4]],
    pub opacity_logits: &'a mut [f32],
    pub sh_dc: &'a mut [[f32; 3]],
    pub sh_rest: &'a mut [[f32; 45]],
    pub screen_grad_norm: &'a mut [f32],
}

/// What every Gaussian of a render shares: the camera, the SH degree, the projected
/// index of each Gaussian (`u32::MAX`: culled), the screen gradients, half the image size.
#[derive(Clone, Copy)]
pub(crate) struct Shared<'a> {
    pub cam: &'a CamSetup,
    pub sh_degree: u32,
    pub slot: &'a [u32],
    pub screen: &'a [ScreenGrad],
    pub half: [f32; 2],
}

/// Gradients of Gaussians `start..start + len` into `out`; returns the span's part of
/// the camera gradient `[∂L/∂W (column-major), ∂L/∂t_w, ∂L/∂centre]`.
pub(crate) fn backward_span(s: &Splats, start: usize, sh: Shared, out: Outs) -> [f64; 15] {
    #[cfg(target_arch = "x86_64")]
    if simd::use_wide() {
        // SAFETY: `use_wide` checked that the CPU has AVX-512F.
        return unsafe { backward_span_avx512(s, start, sh, out) };
    }
    backward_span_lanes::<F4>(s, start, sh, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn backward_span_avx512(s: &Splats, start: usize, sh: Shared, out: Outs) -> [f64; 15] {
    backward_span_lanes::<simd::F16>(s, start, sh, out)
}

#[inline(always)]
fn backward_span_lanes<V: Lanes>(s: &Splats, start: usize, sh: Shared, mut out: Outs) -> [f64; 15] {
    let len = out.opacity_logits.len();
    let mut acc = [V::splat(0.0); 15];
    let mut at = 0;
    while at + V::N <= len {
        backward_block::<V>(s, start + at, at, &sh, &mut out, &mut acc);
        at += V::N;
    }
    let mut c = [0.0f64; 15];
    for k in 0..15 {
        c[k] = acc[k].sum() as f64;
    }
    for a in at..len {
        one_at_a_time(s, start + a, a, &sh, &mut out, &mut c);
    }
    c
}

/// The scalar path for the last few Gaussians of a span.
fn one_at_a_time(s: &Splats, i: usize, a: usize, sh: &Shared, out: &mut Outs, c: &mut [f64; 15]) {
    let k = sh.slot[i];
    if k == u32::MAX {
        zero(out, a);
        return;
    }
    let sg = &sh.screen[k as usize];
    let geo = intermediates(s, i, sh.cam, sh.sh_degree);
    let gg = project_backward(s, i, &geo, sh.cam, sh.sh_degree, sg);
    out.means[a] = gg.mean;
    out.log_scales[a] = gg.log_scale;
    out.rotations[a] = gg.rotation;
    out.opacity_logits[a] = gg.opacity_logit;
    out.sh_dc[a] = gg.sh[0];
    for kk in 1..16 {
        out.sh_rest[a][(kk - 1) * 3..kk * 3].copy_from_slice(&gg.sh[kk]);
    }
    out.screen_grad_norm[a] = screen_norm(sg[0], sg[1], sh.half);
    for col in 0..3 {
        for row in 0..3 {
            c[col * 3 + row] += gg.w.col(col)[row] as f64;
        }
    }
    for j in 0..3 {
        c[9 + j] += gg.tw[j] as f64;
        c[12 + j] += gg.centre[j] as f64;
    }
}

/// 3DGS measures the mean's gradient in NDC (pixels · 2 / size).
#[inline(always)]
fn screen_norm(gu: f32, gv: f32, half: [f32; 2]) -> f32 {
    ((gu * half[0]).powi(2) + (gv * half[1]).powi(2)).sqrt()
}

fn zero(out: &mut Outs, a: usize) {
    out.means[a] = [0.0; 3];
    out.log_scales[a] = [0.0; 3];
    out.rotations[a] = [0.0; 4];
    out.opacity_logits[a] = 0.0;
    out.sh_dc[a] = [0.0; 3];
    out.sh_rest[a] = [0.0; 45];
    out.screen_grad_norm[a] = 0.0;
}

/// `V::N` Gaussians from `start` (written at `at` of the span's outputs).
#[inline(always)]
fn backward_block<V: Lanes>(
    s: &Splats,
    start: usize,
    at: usize,
    sh: &Shared,
    out: &mut Outs,
    acc: &mut [V; 15],
) {
    let n = V::N;
    let mut sg = [[0.0f32; MAX]; 10];
    let mut vis = 0u32;
    for l in 0..n {
        let k = sh.slot[start + l];
        if k != u32::MAX {
            vis |= 1 << l;
            for j in 0..10 {
                sg[j][l] = sh.screen[k as usize][j];
            }
        }
    }
    if vis == 0 {
        for l in 0..n {
            zero(out, at + l);
        }
        return;
    }
    let deg = sh.sh_degree;
    let cam = sh.cam;
    let g = geo_lanes::<V>(&Rows::gather(s, start, n), cam, deg);
    let nc = sh::num_coeffs(deg);
    let mut dc = [[0.0f32; MAX]; 3];
    let mut rest = [[0.0f32; MAX]; 45];
    for l in 0..n {
        let i = start + l;
        for ch in 0..3 {
            dc[ch][l] = s.sh_dc[i][ch];
        }
        for j in 0..(nc - 1) * 3 {
            rest[j][l] = s.sh_rest[i][j];
        }
    }
    let sp = V::splat;
    let zero = sp(0.0);
    let two = sp(2.0);
    let mut gv = [zero; 10];
    for j in 0..10 {
        gv[j] = V::load(&sg[j][..]);
    }
    let vis = V::M::from_bits(vis);

    // Opacity (sigmoid).
    let g_logit = gv[5] * g.opacity * (sp(1.0) - g.opacity);
    // Colour → SH coefficients (a clamped channel passes nothing) and view direction.
    let mut gc = [zero; 3];
    for ch in 0..3 {
        let mut c = sp(0.5) + g.basis[0] * ld(&dc[ch]);
        for k in 1..nc {
            c = c + g.basis[k] * ld(&rest[(k - 1) * 3 + ch]);
        }
        gc[ch] = gv[6 + ch].and(zero.lt(c));
    }
    let mut g_p = [zero; 3];
    let mut g_centre = [zero; 3];
    if deg > 0 {
        let mut gb = [zero; 16];
        for k in 1..nc {
            let j = (k - 1) * 3;
            gb[k] = gc[0] * ld(&rest[j]) + gc[1] * ld(&rest[j + 1]) + gc[2] * ld(&rest[j + 2]);
        }
        let dn = [
            g.dir[0] / g.dir_len,
            g.dir[1] / g.dir_len,
            g.dir[2] / g.dir_len,
        ];
        let g_dn = sh::basis_grad_lanes(dn, deg, &gb);
        let dd = dot3(dn, g_dn);
        for a in 0..3 {
            g_p[a] = (g_dn[a] - dn[a] * dd) / g.dir_len;
            g_centre[a] = zero - g_p[a];
        }
    }

    // Conic → 2-D covariance: ∂L/∂Σ₂ = −Q G Q.
    let [qa, qb, qc] = g.conic;
    let (ga, gb, gcc) = (gv[2], sp(0.5) * gv[3], gv[4]);
    let (t00, t01) = (qa * ga + qb * gb, qa * gb + qb * gcc);
    let (t10, t11) = (qb * ga + qc * gb, qb * gb + qc * gcc);
    let s00 = zero - (t00 * qa + t01 * qb);
    let s01 = zero - (t00 * qb + t01 * qc);
    let s11 = zero - (t10 * qb + t11 * qc);
    // Σ₂ = J Σc Jᵀ: ∂L/∂Σc = Jᵀ G₂ J, ∂L/∂J = 2 G₂ J Σc.
    let j0 = [g.j[0], zero, g.j[1]];
    let j1 = [zero, g.j[2], g.j[3]];
    let mut gsc = [[zero; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            gsc[r][c] =
                j0[r] * j0[c] * s00 + (j0[r] * j1[c] + j1[r] * j0[c]) * s01 + j1[r] * j1[c] * s11;
        }
    }
    let a0 = [
        dot3(g.sigc[0], j0),
        dot3(g.sigc[1], j0),
        dot3(g.sigc[2], j0),
    ];
    let a1 = [
        dot3(g.sigc[0], j1),
        dot3(g.sigc[1], j1),
        dot3(g.sigc[2], j1),
    ];
    let mut g_j0 = [zero; 3];
    let mut g_j1 = [zero; 3];
    for r in 0..3 {
        g_j0[r] = (a0[r] * s00 + a1[r] * s01) * two;
        g_j1[r] = (a0[r] * s01 + a1[r] * s11) * two;
    }
    // J entries → camera point (x, y, d); J02 = fx·tx/d with tx = x/d unless clamped.
    let d = g.depth;
    let (d2, fx, fy) = (d * d, sp(cam.fx), sp(cam.fy));
    let d3 = d2 * d;
    let [pcx, pcy, _] = g.pc;
    let mut gd = g_j0[0] * (zero - fx) / d2 + g_j1[1] * fy / d2;
    let clamp_x = V::M::from_bits(g.rx.lt(sp(cam.lim[0])).bits() | g.rx.gt(sp(cam.lim[1])).bits());
    let clamp_y = V::M::from_bits(g.ry.lt(sp(cam.lim[2])).bits() | g.ry.gt(sp(cam.lim[3])).bits());
    let mut gx = V::select(clamp_x, zero, g_j0[2] * fx / d2);
    gd = gd
        + V::select(
            clamp_x,
            zero - g_j0[2] * fx * g.tx / d2,
            zero - g_j0[2] * two * fx * pcx / d3,
        );
    let mut gy = V::select(clamp_y, zero, zero - g_j1[2] * fy / d2);
    gd = gd
        + V::select(
            clamp_y,
            g_j1[2] * fy * g.ty / d2,
            g_j1[2] * two * fy * pcy / d3,
        );
    // Projected mean and depth.
    gx = gx + gv[0] * fx / d;
    gd = gd - gv[0] * fx * pcx / d2;
    gy = gy - gv[1] * fy / d;
    gd = gd + gv[1] * fy * pcy / d2 + gv[9];
    let g_pc = [gx, gy, zero - gd];

    // Σc = W Σ Wᵀ, p_c = W p + t_w (W[a][k] = w.col(k)[a]).
    let mut wm = [[zero; 3]; 3];
    for a in 0..3 {
        for k in 0..3 {
            wm[a][k] = sp(cam.w.col(k)[a]);
        }
    }
    let mut u = [[zero; 3]; 3]; // G W
    for k in 0..3 {
        for b in 0..3 {
            u[k][b] = gsc[k][0] * wm[0][b] + gsc[k][1] * wm[1][b] + gsc[k][2] * wm[2][b];
        }
    }
    let mut g_sigma = [[zero; 3]; 3]; // Wᵀ G W
    for a in 0..3 {
        for b in 0..3 {
            g_sigma[a][b] = wm[0][a] * u[0][b] + wm[1][a] * u[1][b] + wm[2][a] * u[2][b];
        }
    }
    for a in 0..3 {
        g_p[a] = g_p[a] + wm[0][a] * g_pc[0] + wm[1][a] * g_pc[1] + wm[2][a] * g_pc[2];
    }
    // The camera: ∂L/∂W = 2 G W Σ + g_pc pᵀ, ∂L/∂t_w = g_pc, ∂L/∂centre.
    for r in 0..3 {
        for c in 0..3 {
            let wsig_c = [g.wsig[0][c], g.wsig[1][c], g.wsig[2][c]];
            let w = two * dot3(gsc[r], wsig_c) + g_pc[r] * g.p[c];
            acc[c * 3 + r] = acc[c * 3 + r] + w.and(vis);
        }
        acc[9 + r] = acc[9 + r] + g_pc[r].and(vis);
        acc[12 + r] = acc[12 + r] + g_centre[r].and(vis);
    }

    // Σ = M Mᵀ, M = R diag(s).
    let mut g_r = [[zero; 3]; 3];
    let mut g_ls = [zero; 3];
    for c in 0..3 {
        let mut gs = zero;
        for a in 0..3 {
            let gm = two
                * (g_sigma[a][0] * g.m[0][c]
                    + g_sigma[a][1] * g.m[1][c]
                    + g_sigma[a][2] * g.m[2][c]);
            g_r[a][c] = gm * g.sc[c];
            gs = gs + gm * g.r[a][c];
        }
        g_ls[c] = gs * g.sc[c];
    }
    let g_n = quat_backward(g.n, &g_r);
    let dot = g_n[0] * g.n[0] + g_n[1] * g.n[1] + g_n[2] * g.n[2] + g_n[3] * g.n[3];
    let mut g_rot = [zero; 4];
    for k in 0..4 {
        g_rot[k] = (g_n[k] - g.n[k] * dot) / g.qnorm;
    }
    let sgn = ((gv[0] * sp(sh.half[0])) * (gv[0] * sp(sh.half[0]))
        + (gv[1] * sp(sh.half[1])) * (gv[1] * sp(sh.half[1])))
    .sqrt();

    // Back to rows (zero where culled), then to each Gaussian.
    let mut lanes = [
        g_p[0], g_p[1], g_p[2], g_ls[0], g_ls[1], g_ls[2], g_rot[0], g_rot[1], g_rot[2], g_rot[3],
        g_logit, sgn, gc[0], gc[1], gc[2],
    ];
    for v in &mut lanes {
        *v = v.and(vis);
    }
    let rows = to_rows(lanes);
    let mut basis = g.basis;
    for v in &mut basis {
        *v = v.and(vis);
    }
    let basis = to_rows(basis);
    for l in 0..n {
        let a = at + l;
        let v = |k: usize| rows[k][l];
        out.means[a] = [v(0), v(1), v(2)];
        out.log_scales[a] = [v(3), v(4), v(5)];
        out.rotations[a] = [v(6), v(7), v(8), v(9)];
        out.opacity_logits[a] = v(10);
        out.screen_grad_norm[a] = v(11);
        let gcl = [v(12), v(13), v(14)];
        out.sh_dc[a] = [
            gcl[0] * basis[0][l],
            gcl[1] * basis[0][l],
            gcl[2] * basis[0][l],
        ];
        let r = &mut out.sh_rest[a];
        *r = [0.0; 45];
        for k in 1..nc {
            for ch in 0..3 {
                r[(k - 1) * 3 + ch] = gcl[ch] * basis[k][l];
            }
        }
    }
}

#[inline(always)]
fn ld<V: Lanes>(r: &Row) -> V {
    V::load(&r[..])
}

#[inline(always)]
fn dot3<V: Lanes>(a: [V; 3], b: [V; 3]) -> V {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Backward of the rotation matrix of a unit quaternion `(w, x, y, z)`:
/// `e[i][j] = ∂L/∂R_ij` → `∂L/∂n` (as `quat_to_mat_backward`).
#[inline(always)]
fn quat_backward<V: Lanes>(n: [V; 4], e: &[[V; 3]; 3]) -> [V; 4] {
    let [w, x, y, z] = n;
    let two = V::splat(2.0);
    let gw = z * (e[1][0] - e[0][1]) + y * (e[0][2] - e[2][0]) + x * (e[2][1] - e[1][2]);
    let gx = y * (e[0][1] + e[1][0]) + z * (e[0][2] + e[2][0]) + w * (e[2][1] - e[1][2])
        - two * x * (e[1][1] + e[2][2]);
    let gy = x * (e[0][1] + e[1][0]) + z * (e[1][2] + e[2][1]) + w * (e[0][2] - e[2][0])
        - two * y * (e[0][0] + e[2][2]);
    let gz = x * (e[0][2] + e[2][0]) + y * (e[1][2] + e[2][1]) + w * (e[1][0] - e[0][1])
        - two * z * (e[0][0] + e[1][1]);
    [two * gw, two * gx, two * gy, two * gz]
}

#[cfg(test)]
mod tests;
