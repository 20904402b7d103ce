//! Per-Gaussian EWA projection (3DGS; DEGS Eq. 2) and its backward, in f32.
//!
//! Forward: `Σ = R S Sᵀ Rᵀ`, camera point `p_c = W p + t_w`, depth `d = −z_c`,
//! perspective Jacobian `J = [[fx/d, 0, fx·x/d²], [0, −fy/d, −fy·y/d²]]` (the minus
//! signs because `v = cy − fy·y/d`), `Σ₂ = J W Σ Wᵀ Jᵀ + 0.3·I`, conic `Σ₂⁻¹`.
//! Colour from SH at the world-space view direction, `+0.5`, clamped at 0.

use super::alpha::{ALPHA_MIN, CULL_OPACITY, LOW_PASS, NEAR, SIGMA_CUTOFF};
use super::sh;
use crate::splats::Splats;
use glam::{Mat3, Vec3};
use scene::Camera;

/// The camera in the form the rasterizer uses (f32, world → camera).
#[derive(Clone, Copy, Debug)]
pub struct CamSetup {
    pub w: Mat3,
    pub tw: Vec3,
    pub centre: Vec3,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: usize,
    pub height: usize,
    /// Limits of x/d and y/d used in the Jacobian (1.3 × the field of view, as 3DGS).
    pub lim: [f32; 4],
}

/// Limits `[x_lo, x_hi, y_lo, y_hi]` on `x/d`, `y/d` for the Jacobian: the image plus a
/// 15 % margin on every side (3DGS's 1.3 × tan(fov/2) for a centred principal point).
pub(crate) fn jacobian_limits(fx: f64, fy: f64, cx: f64, cy: f64, w: f64, h: f64) -> [f64; 4] {
    [
        (-0.5 - 0.15 * w - cx) / fx,
        (w - 0.5 + 0.15 * w - cx) / fx,
        (cy - (h - 0.5 + 0.15 * h)) / fy,
        (cy + 0.5 + 0.15 * h) / fy,
    ]
}

impl CamSetup {
    pub fn new(cam: &Camera) -> Self {
        let inv = cam.cam_to_world.inverse();
        let k = &cam.intrinsics;
        let l = jacobian_limits(k.fx, k.fy, k.cx, k.cy, k.width as f64, k.height as f64);
        CamSetup {
            w: Mat3::from_quat(inv.rotation.as_quat()),
            tw: inv.translation.as_vec3(),
            centre: cam.cam_to_world.translation.as_vec3(),
            fx: k.fx as f32,
            fy: k.fy as f32,
            cx: k.cx as f32,
            cy: k.cy as f32,
            width: k.width as usize,
            height: k.height as usize,
            lim: l.map(|v| v as f32),
        }
    }
}

/// Rotation matrix of a unit quaternion `(w, x, y, z)`.
#[inline]
pub(crate) fn quat_to_mat(n: [f32; 4]) -> Mat3 {
    let [w, x, y, z] = n;
    Mat3::from_cols(
        Vec3::new(
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y + w * z),
            2.0 * (x * z - w * y),
        ),
        Vec3::new(
            2.0 * (x * y - w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z + w * x),
        ),
        Vec3::new(
            2.0 * (x * z + w * y),
            2.0 * (y * z - w * x),
            1.0 - 2.0 * (x * x + y * y),
        ),
    )
}

/// Backward of [`quat_to_mat`]: `g = ∂L/∂R` → `∂L/∂n`.
#[inline]
fn quat_to_mat_backward(n: [f32; 4], g: Mat3) -> [f32; 4] {
    let [w, x, y, z] = n;
    let e = |i: usize, j: usize| g.col(j)[i];
    let gw =
        2.0 * (-z * e(0, 1) + y * e(0, 2) + z * e(1, 0) - x * e(1, 2) - y * e(2, 0) + x * e(2, 1));
    let gx = 2.0
        * (y * e(0, 1) + z * e(0, 2) + y * e(1, 0) - 2.0 * x * e(1, 1) - w * e(1, 2)
            + z * e(2, 0)
            + w * e(2, 1)
            - 2.0 * x * e(2, 2));
    let gy = 2.0
        * (-2.0 * y * e(0, 0) + x * e(0, 1) + w * e(0, 2) + x * e(1, 0) + z * e(1, 2)
            - w * e(2, 0)
            + z * e(2, 1)
            - 2.0 * y * e(2, 2));
    let gz = 2.0
        * (-2.0 * z * e(0, 0) - w * e(0, 1) + x * e(0, 2) + w * e(1, 0) - 2.0 * z * e(1, 1)
            + y * e(1, 2)
            + x * e(2, 0)
            + y * e(2, 1));
    [gw, gx, gy, gz]
}

#[inline]
fn outer(a: Vec3, b: Vec3) -> Mat3 {
    Mat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// `floor` without a libm call (SSE2 has no rounding instruction); exact for
/// |x| < 2^23, saturating beyond (only used on pixel coordinates).
#[inline(always)]
fn floor(x: f32) -> f32 {
    let t = x as i32 as f32;
    if t > x { t - 1.0 } else { t }
}

#[inline(always)]
fn ceil(x: f32) -> f32 {
    -floor(-x)
}

/// Every intermediate of one Gaussian's projection (kept for the backward).
#[derive(Clone, Copy, Debug)]
pub struct Geo {
    pub n: [f32; 4],
    pub qnorm: f32,
    pub r: Mat3,
    pub s: Vec3,
    pub m: Mat3,
    pub sigma: Mat3,
    pub p: Vec3,
    pub pc: Vec3,
    pub depth: f32,
    pub sigc: Mat3,
    pub tx: f32,
    pub ty: f32,
    pub clamp_x: bool,
    pub clamp_y: bool,
    /// Rows of the 2×3 Jacobian.
    pub j0: Vec3,
    pub j1: Vec3,
    /// 2-D covariance (a, b, c) including the low-pass term.
    pub cov: [f32; 3],
    pub det: f32,
    pub conic: [f32; 3],
    pub uv: [f32; 2],
    pub dir: Vec3,
    pub dir_len: f32,
    pub basis: [f32; 16],
    /// Colour before the clamp at 0.
    pub color_raw: [f32; 3],
    pub color: [f32; 3],
    pub opacity: f32,
    /// Inclusive pixel bounding box `[x0, x1, y0, y1]` of the 3σ ellipse (clipped).
    pub bbox: [u32; 4],
    /// Largest `dᵀΣ⁻¹d` at which the Gaussian can still be composited (plus a margin).
    pub cut: f32,
    /// 3DGS screen radius in pixels: ceil(3·sqrt(λ_max)).
    pub radius: f32,
}

/// `min(9, 2·ln(o/ALPHA_MIN))` plus a margin: beyond it `α < ALPHA_MIN` (or the pixel is
/// outside the 3σ ellipse), so nothing there is composited.
#[inline]
pub fn reach(opacity: f32) -> f32 {
    let m = (2.0 * (opacity / ALPHA_MIN).ln()).min(SIGMA_CUTOFF * SIGMA_CUTOFF);
    m.max(0.0) * 1.001 + 0.01
}

/// Every intermediate of Gaussian `i`'s projection, whether or not it is visible (NaN
/// or infinite where it is degenerate); `bbox`, `cut` and `radius` are left 0. The
/// backward recomputes a visible Gaussian's intermediates this way, so it never depends
/// on re-taking the forward pass's culling decisions.
// Eq. 2: Σ = R S Sᵀ Rᵀ, then its 2-D projection Σ₂ = J W Σ Wᵀ Jᵀ (+ low-pass).
#[inline]
pub fn intermediates(s: &Splats, i: usize, cam: &CamSetup, sh_degree: u32) -> Geo {
    let opacity = 1.0 / (1.0 + (-s.opacity_logits[i]).exp());
    let q = s.rotations[i];
    let qnorm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let n = q.map(|v| v / qnorm);
    let p = Vec3::from(s.means[i]);
    let pc = cam.w * p + cam.tw;
    let depth = -pc.z;
    let r = quat_to_mat(n);
    let sc = Vec3::from(s.log_scales[i]).exp();
    let m = Mat3::from_cols(r.x_axis * sc.x, r.y_axis * sc.y, r.z_axis * sc.z);
    let sigma = m * m.transpose();
    let sigc = cam.w * sigma * cam.w.transpose();
    let (rx, ry) = (pc.x / depth, pc.y / depth);
    let tx = rx.clamp(cam.lim[0], cam.lim[1]);
    let ty = ry.clamp(cam.lim[2], cam.lim[3]);
    let j0 = Vec3::new(cam.fx / depth, 0.0, cam.fx * tx / depth);
    let j1 = Vec3::new(0.0, -cam.fy / depth, -cam.fy * ty / depth);
    let t0 = sigc * j0; // Σc symmetric: (J Σc)ᵀ rows
    let t1 = sigc * j1;
    let cov = [j0.dot(t0) + LOW_PASS, j0.dot(t1), j1.dot(t1) + LOW_PASS];
    let det = cov[0] * cov[2] - cov[1] * cov[1];
    let conic = [cov[2] / det, -cov[1] / det, cov[0] / det];
    let uv = [cam.cx + cam.fx * rx, cam.cy - cam.fy * ry];
    let dir = p - cam.centre;
    let dir_len = dir.length().max(1e-12);
    let dn = dir / dir_len;
    let basis = sh::basis_f32(dn.into(), sh_degree);
    let color_raw = sh_colour(s, i, &basis, sh_degree);
    Geo {
        n,
        qnorm,
        r,
        s: sc,
        m,
        sigma,
        p,
        pc,
        depth,
        sigc,
        tx,
        ty,
        clamp_x: tx != rx,
        clamp_y: ty != ry,
        j0,
        j1,
        cov,
        det,
        conic,
        uv,
        dir,
        dir_len,
        basis,
        color_raw,
        color: color_raw.map(|c| c.max(0.0)),
        opacity,
        bbox: [0; 4],
        cut: 0.0,
        radius: 0.0,
    }
}

/// `0.5 + Σ_k coeff_k · Y_k` per channel, before the clamp at 0.
#[inline(always)]
pub(crate) fn sh_colour(s: &Splats, i: usize, basis: &[f32; 16], sh_degree: u32) -> [f32; 3] {
    let nc = sh::num_coeffs(sh_degree);
    let (dc, rest) = (&s.sh_dc[i], &s.sh_rest[i]);
    let mut c = [0.5; 3];
    for ch in 0..3 {
        c[ch] += basis[0] * dc[ch];
        for k in 1..nc {
            c[ch] += basis[k] * rest[(k - 1) * 3 + ch];
        }
    }
    c
}

/// Where a projected Gaussian lands: `(bbox, cut, radius)` (see [`Geo`]), or `None` when
/// it is culled (transparent, degenerate, behind the near plane, or its ellipse misses
/// the image). `cut` is [`reach`]`(opacity)`. Shared by [`project`] and the forward
/// pass's lanes.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn screen_extent(
    opacity: f32,
    cut: f32,
    qnorm: f32,
    pc: [f32; 3],
    det: f32,
    cov: [f32; 3],
    uv: [f32; 2],
    cam: &CamSetup,
) -> Option<([u32; 4], f32, f32)> {
    if !(opacity >= CULL_OPACITY) || !(qnorm > 1e-12) || !qnorm.is_finite() {
        return None;
    }
    if !(-pc[2] > NEAR) || !pc.iter().all(|v| v.is_finite()) {
        return None;
    }
    if !(det > 0.0) || !det.is_finite() {
        return None;
    }
    // Pixels can only receive α ≥ ALPHA_MIN where dᵀΣ⁻¹d ≤ min(9, 2·ln(o/ALPHA_MIN)):
    // the box (and the kernels' per-row spans) use that, with a margin for rounding.
    let ex = (cut * cov[0]).sqrt() + 1e-3;
    let ey = (cut * cov[2]).sqrt() + 1e-3;
    let x0 = ceil(uv[0] - ex).max(0.0);
    let x1 = floor(uv[0] + ex).min(cam.width as f32 - 1.0);
    let y0 = ceil(uv[1] - ey).max(0.0);
    let y1 = floor(uv[1] + ey).min(cam.height as f32 - 1.0);
    if !(x0 <= x1 && y0 <= y1) {
        return None;
    }
    let mid = 0.5 * (cov[0] + cov[2]);
    let lmax = mid + (mid * mid - det).max(0.1).sqrt();
    let radius = ceil(SIGMA_CUTOFF * lmax.sqrt());
    let bbox = [x0 as u32, x1 as u32, y0 as u32, y1 as u32];
    Some((bbox, cut, radius))
}

/// Project Gaussian `i`; `None` when it is culled (see [`screen_extent`]). The plain
/// one-at-a-time path: the forward pass projects `V::N` at once (`project_lanes`).
#[inline]
pub fn project(s: &Splats, i: usize, cam: &CamSetup, sh_degree: u32) -> Option<Geo> {
    let mut g = intermediates(s, i, cam, sh_degree);
    let (bbox, cut, radius) = screen_extent(
        g.opacity,
        reach(g.opacity),
        g.qnorm,
        g.pc.into(),
        g.det,
        g.cov,
        g.uv,
        cam,
    )?;
    (g.bbox, g.cut, g.radius) = (bbox, cut, radius);
    Some(g)
}

/// Gradients reaching one Gaussian from the image: `[u, v, conic a, b, c, opacity,
/// r, g, b, depth]` (conic `b` is the off-diagonal entry, counted once).
pub(crate) type ScreenGrad = [f32; 10];

/// Parameter gradients of one Gaussian plus its contribution to the camera gradient.
#[derive(Clone, Copy, Debug, Default)]
pub struct GaussGrad {
    pub mean: [f32; 3],
    pub log_scale: [f32; 3],
    pub rotation: [f32; 4],
    pub opacity_logit: f32,
    pub sh: [[f32; 3]; 16],
    /// ∂L/∂W (world → camera rotation), ∂L/∂t_w, ∂L/∂(camera centre).
    pub w: Mat3,
    pub tw: Vec3,
    pub centre: Vec3,
}

/// Chain the screen-space gradient `g` of a projected Gaussian back to its parameters.
pub fn project_backward(
    s: &Splats,
    i: usize,
    geo: &Geo,
    cam: &CamSetup,
    sh_degree: u32,
    g: &ScreenGrad,
) -> GaussGrad {
    let mut out = GaussGrad {
        // Opacity (sigmoid).
        opacity_logit: g[5] * geo.opacity * (1.0 - geo.opacity),
        ..Default::default()
    };

    // Colour → SH coefficients and view direction (clamped channels pass nothing).
    let gc: [f32; 3] = std::array::from_fn(|ch| {
        if geo.color_raw[ch] > 0.0 {
            g[6 + ch]
        } else {
            0.0
        }
    });
    let nc = sh::num_coeffs(sh_degree);
    let mut g_basis = [0.0f32; 16];
    for k in 0..nc {
        out.sh[k] = gc.map(|v| v * geo.basis[k]);
    }
    let mut g_p = Vec3::ZERO;
    if sh_degree > 0 && gc.iter().any(|&v| v != 0.0) {
        let rest = &s.sh_rest[i];
        for (k, gb) in g_basis.iter_mut().enumerate().take(nc).skip(1) {
            *gb = (0..3).map(|ch| gc[ch] * rest[(k - 1) * 3 + ch]).sum();
        }
        let dn = geo.dir / geo.dir_len;
        let g_dn = Vec3::from(sh::basis_grad_f32(dn.into(), sh_degree, &g_basis));
        let g_dir = (g_dn - dn * dn.dot(g_dn)) / geo.dir_len;
        g_p += g_dir;
        out.centre = -g_dir;
    }

    // Conic → 2-D covariance: ∂L/∂Σ₂ = −Q G Q (G the symmetric conic gradient).
    let [qa, qb, qc] = geo.conic;
    let (ga, gb, gcc) = (g[2], 0.5 * g[3], g[4]);
    // M = Q G Q for symmetric 2×2.
    let t00 = qa * ga + qb * gb;
    let t01 = qa * gb + qb * gcc;
    let t10 = qb * ga + qc * gb;
    let t11 = qb * gb + qc * gcc;
    let s00 = -(t00 * qa + t01 * qb);
    let s01 = -(t00 * qb + t01 * qc);
    let s11 = -(t10 * qb + t11 * qc);
    // Σ₂ = J Σc Jᵀ: ∂L/∂Σc = Jᵀ G₂ J, ∂L/∂J = 2 G₂ J Σc.
    let (j0, j1) = (geo.j0, geo.j1);
    let g_sigc = outer(j0, j0) * s00 + (outer(j0, j1) + outer(j1, j0)) * s01 + outer(j1, j1) * s11;
    let a0 = geo.sigc * j0;
    let a1 = geo.sigc * j1;
    let g_j0 = (a0 * s00 + a1 * s01) * 2.0;
    let g_j1 = (a0 * s01 + a1 * s11) * 2.0;
    // J entries → camera point (x, y, d).
    let d = geo.depth;
    let (fx, fy) = (cam.fx, cam.fy);
    let (mut gx, mut gy, mut gd) = (0.0f32, 0.0f32, 0.0f32);
    gd += g_j0.x * (-fx / (d * d));
    gd += g_j1.y * (fy / (d * d));
    // J02 = fx·tx/d with tx = x/d unless clamped.
    if geo.clamp_x {
        gd += g_j0.z * (-fx * geo.tx / (d * d));
    } else {
        gx += g_j0.z * fx / (d * d);
        gd += g_j0.z * (-2.0 * fx * geo.pc.x / (d * d * d));
    }
    if geo.clamp_y {
        gd += g_j1.z * (fy * geo.ty / (d * d));
    } else {
        gy += g_j1.z * (-fy / (d * d));
        gd += g_j1.z * (2.0 * fy * geo.pc.y / (d * d * d));
    }
    // Projected mean and depth.
    gx += g[0] * fx / d;
    gd += g[0] * (-fx * geo.pc.x / (d * d));
    gy += g[1] * (-fy / d);
    gd += g[1] * (fy * geo.pc.y / (d * d));
    gd += g[9];
    let g_pc = Vec3::new(gx, gy, -gd);

    // Σc = W Σ Wᵀ.
    let w = cam.w;
    let g_sigma = w.transpose() * g_sigc * w;
    out.w = g_sigc * w * geo.sigma * 2.0 + outer(g_pc, geo.p);
    out.tw = g_pc;
    g_p += w.transpose() * g_pc;

    // Σ = M Mᵀ, M = R diag(s).
    let g_m = g_sigma * geo.m * 2.0;
    let g_r = Mat3::from_cols(
        g_m.x_axis * geo.s.x,
        g_m.y_axis * geo.s.y,
        g_m.z_axis * geo.s.z,
    );
    let g_s = Vec3::new(
        g_m.x_axis.dot(geo.r.x_axis),
        g_m.y_axis.dot(geo.r.y_axis),
        g_m.z_axis.dot(geo.r.z_axis),
    );
    out.log_scale = (g_s * geo.s).into();
    let g_n = quat_to_mat_backward(geo.n, g_r);
    let dot: f32 = (0..4).map(|k| g_n[k] * geo.n[k]).sum();
    out.rotation = std::array::from_fn(|k| (g_n[k] - geo.n[k] * dot) / geo.qnorm);

    out.mean = g_p.into();
    out
}
