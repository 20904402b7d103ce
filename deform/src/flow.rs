//! Image motion of the scene: camera ego-motion flow `F_ego` (Eq. 9) and Gaussian
//! scene flow `F_gs` (Eq. 10), forward and backward, generic over `f32`/`f64`.
//!
//! **Frames.** The paper's Eq. 9 is written in the computer-vision camera frame (x right,
//! y down, Z forward) with normalised image coordinates `(x, y) = (X/Z, Y/Z)` and the
//! camera's velocity `(v_c, ω_c)` in that frame. This crate's camera frame is OpenGL (x
//! right, y up, z backwards, `scene::camera`), and `CV = diag(1, −1, −1)·GL` is a proper
//! rotation, so both `v` and `ω` convert by negating y and z. The pixel of a CV
//! normalised point is `(cx + fx·x, cy + fy·y)`, the same pixel
//! `scene::camera::Intrinsics::project` gives, so `F_ego = (fx·ẋ, fy·ẏ)` in **px/s**, `u`
//! to the right and `v` downwards. `Z` is the depth (`−z` in OpenGL), `1/Z` the
//! inverse depth from the rasterizer. Velocities are those of
//! [`crate::camera_path::CameraVelocity`]: a static point's camera coordinates move at
//! `Ṗ = −v − ω × P`; the tests check `F_ego` against finite differences of the actual
//! projection of static points seen by a moving camera.
//!
//! **Validity.** An inverse depth that is negative, above `max_inv_depth` (the point is
//! nearer than `1/max_inv_depth`) or not finite gives zero flow, `valid = false` and no
//! gradient (`1/Z = 0`, a point at infinity, is valid: rotation only). [`inverse_depth`]
//! maps a rendered depth to `1/Z`, with `−1` for depths at or below the near plane.
//! A Gaussian centre at or behind the near plane of either camera gives an invalid `F_gs`.
//!
//! **F_gs** is `Proj(x(t1)) − Proj(x(t0))`, in px. [`GsCameras::Same`] is the paper's
//! form: both centres projected by one camera (the reference frame's), so `F_gs` is the
//! motion of the Gaussian alone and the camera's share is `F_ego`. [`GsCameras::Exact`]
//! projects `x(t1)` with the camera at `t1` and `x(t0)` with the camera at `t0`: that is
//! the *whole* image displacement, ego-motion included, so a motion loss built on it
//! must not add `F_ego` again. Camera gradients are camera-right twists
//! ([`crate::lie`]).
//!
//! Sums over points (the camera gradients) are added per fixed chunk in order, so the
//! results do not depend on the number of threads.

use rayon::prelude::*;
use scene::real::Real;
use scene::{Intrinsics, Pose};

/// Points per rayon task (the kernels are a few dozen flops per point).
const CHUNK: usize = 4096;

/// Pinhole intrinsics in the kernels' float type.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pinhole<R> {
    pub fx: R,
    pub fy: R,
    pub cx: R,
    pub cy: R,
}

impl<R: Real> Pinhole<R> {
    pub(crate) fn from_intrinsics(k: &Intrinsics) -> Self {
        Pinhole {
            fx: R::from_f64(k.fx),
            fy: R::from_f64(k.fy),
            cx: R::from_f64(k.cx),
            cy: R::from_f64(k.cy),
        }
    }
}

/// Per-point image flow (px/s for `F_ego`, px for `F_gs`) with a validity flag.
/// Reused between calls: the kernels resize it, so a kept buffer is not reallocated.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Flow2<R> {
    pub u: Vec<R>,
    pub v: Vec<R>,
    pub valid: Vec<bool>,
}

impl<R: Real> Flow2<R> {
    pub fn resize(&mut self, n: usize) {
        self.u.resize(n, R::ZERO);
        self.v.resize(n, R::ZERO);
        self.valid.resize(n, false);
    }
    pub fn len(&self) -> usize {
        self.u.len()
    }
    pub fn is_empty(&self) -> bool {
        self.u.is_empty()
    }
}

/// Where `F_ego` is evaluated: pixel coordinates and inverse depth, one entry per point.
#[derive(Clone, Copy, Debug)]
pub(crate) struct EgoPoints<'a, R> {
    pub u: &'a [R],
    pub v: &'a [R],
    pub inv_depth: &'a [R],
}

/// Gradients of [`ego_flow_backward`]: per point w.r.t. inverse depth and pixel
/// position, and w.r.t. the camera velocity `[v, ω]` (OpenGL camera frame), summed.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct EgoGrad<R> {
    pub inv_depth: Vec<R>,
    pub u: Vec<R>,
    pub v: Vec<R>,
    pub velocity: [R; 6],
}

/// `1/Z` of a rendered depth `Z` (distance along the viewing axis); `−1` (invalid) when
/// `Z ≤ near` or not finite.
pub fn inverse_depth<R: Real>(depth: R, near: R) -> R {
    if depth > near && depth.is_finite() {
        R::ONE / depth
    } else {
        -R::ONE
    }
}

#[inline(always)]
fn ego_valid<R: Real>(u: R, v: R, rho: R, max_inv_depth: R) -> bool {
    rho >= R::ZERO && rho <= max_inv_depth && u.is_finite() && v.is_finite()
}

/// OpenGL camera-frame twist → the CV frame of Eq. 9 (`diag(1, −1, −1)` on both halves).
#[inline(always)]
fn to_cv<R: Real>(vel: &[R; 6]) -> [R; 6] {
    [vel[0], -vel[1], -vel[2], vel[3], -vel[4], -vel[5]]
}

/// Eq. 9 at one pixel: the image velocity (px/s) of the static scene point seen at
/// pixel `(u, v)` with inverse depth `rho`, for the camera velocity `vel = [v, ω]`
/// (OpenGL camera frame, units/s and rad/s). No validity check.
#[inline]
pub(crate) fn ego_flow_at<R: Real>(k: &Pinhole<R>, u: R, v: R, rho: R, vel: &[R; 6]) -> [R; 2] {
    let [vx, vy, vz, wx, wy, wz] = to_cv(vel);
    let x = (u - k.cx) / k.fx;
    let y = (v - k.cy) / k.fy;
    let xd = rho * (x * vz - vx) + x * y * wx - (R::ONE + x * x) * wy + y * wz;
    let yd = rho * (y * vz - vy) + (R::ONE + y * y) * wx - x * y * wy - x * wz;
    [k.fx * xd, k.fy * yd]
}

/// Backward of [`ego_flow_at`] for an upstream gradient `g` on the flow: returns
/// `(∂/∂rho, ∂/∂u, ∂/∂v, ∂/∂vel)`.
#[inline]
pub(crate) fn ego_flow_at_backward<R: Real>(
    k: &Pinhole<R>,
    u: R,
    v: R,
    rho: R,
    vel: &[R; 6],
    g: [R; 2],
) -> (R, R, R, [R; 6]) {
    let [vx, vy, vz, wx, wy, wz] = to_cv(vel);
    let x = (u - k.cx) / k.fx;
    let y = (v - k.cy) / k.fy;
    let gx = k.fx * g[0];
    let gy = k.fy * g[1];
    let g_rho = gx * (x * vz - vx) + gy * (y * vz - vy);
    let g_x = gx * (rho * vz + y * wx - (x + x) * wy) + gy * (-(y * wy) - wz);
    let g_y = gx * (x * wx + wz) + gy * (rho * vz + (y + y) * wx - x * wy);
    let gv = [-(rho * gx), -(rho * gy), rho * (x * gx + y * gy)];
    let gw = [
        x * y * gx + (R::ONE + y * y) * gy,
        -((R::ONE + x * x) * gx) - x * y * gy,
        y * gx - x * gy,
    ];
    (
        g_rho,
        g_x / k.fx,
        g_y / k.fy,
        to_cv(&[gv[0], gv[1], gv[2], gw[0], gw[1], gw[2]]),
    )
}

/// Eq. 9 at many points (rayon over chunks): `out` is resized to the number of points.
pub(crate) fn ego_flow<R: Real>(
    k: &Pinhole<R>,
    vel: &[R; 6],
    pts: EgoPoints<'_, R>,
    max_inv_depth: R,
    out: &mut Flow2<R>,
) {
    let n = pts.u.len();
    assert!(
        pts.v.len() == n && pts.inv_depth.len() == n,
        "ego_flow: lengths differ"
    );
    ego_flow_points(k, vel, n, CHUNK, max_inv_depth, out, |i| {
        (pts.u[i], pts.v[i], pts.inv_depth[i])
    });
}

/// Eq. 9 on a whole `width × height` inverse-depth map (row-major, pixel centres at
/// integer coordinates); `out` is resized to `width·height`.
pub fn ego_flow_image<R: Real>(
    k: &Pinhole<R>,
    vel: &[R; 6],
    width: usize,
    inv_depth: &[R],
    max_inv_depth: R,
    out: &mut Flow2<R>,
) {
    let n = inv_depth.len();
    assert!(width > 0 && n.is_multiple_of(width), "ego_flow_image: size");
    // One row per chunk.
    ego_flow_points(k, vel, n, width, max_inv_depth, out, |i| {
        let (u, v) = (i % width, i / width);
        (R::from_f64(u as f64), R::from_f64(v as f64), inv_depth[i])
    });
}

/// Eq. 9 at the `n` points `point(i) = (u, v, ρ)`, rayon over chunks of `chunk` points;
/// invalid points ([`ego_valid`]) get zero flow. `out` is resized to `n`.
fn ego_flow_points<R: Real>(
    k: &Pinhole<R>,
    vel: &[R; 6],
    n: usize,
    chunk: usize,
    max_inv_depth: R,
    out: &mut Flow2<R>,
    point: impl Fn(usize) -> (R, R, R) + Sync,
) {
    out.resize(n);
    out.u
        .par_chunks_mut(chunk)
        .zip(out.v.par_chunks_mut(chunk))
        .zip(out.valid.par_chunks_mut(chunk))
        .enumerate()
        .for_each(|(c, ((fu, fv), ok))| {
            let o = c * chunk;
            for j in 0..fu.len() {
                let (u, v, rho) = point(o + j);
                ok[j] = ego_valid(u, v, rho, max_inv_depth);
                let f = if ok[j] {
                    ego_flow_at(k, u, v, rho, vel)
                } else {
                    [R::ZERO; 2]
                };
                fu[j] = f[0];
                fv[j] = f[1];
            }
        });
}

/// Backward of [`ego_flow`] from `g_u`, `g_v` (∂L/∂F_ego per point); invalid points get
/// zero gradient. `grad` is resized and overwritten.
pub(crate) fn ego_flow_backward<R: Real>(
    k: &Pinhole<R>,
    vel: &[R; 6],
    pts: EgoPoints<'_, R>,
    fwd: &Flow2<R>,
    g_u: &[R],
    g_v: &[R],
    grad: &mut EgoGrad<R>,
) {
    let n = pts.u.len();
    assert!(
        fwd.len() == n && g_u.len() == n && g_v.len() == n,
        "ego_flow_backward: lengths"
    );
    grad.inv_depth.resize(n, R::ZERO);
    grad.u.resize(n, R::ZERO);
    grad.v.resize(n, R::ZERO);
    grad.velocity = grad
        .inv_depth
        .par_chunks_mut(CHUNK)
        .zip(grad.u.par_chunks_mut(CHUNK))
        .zip(grad.v.par_chunks_mut(CHUNK))
        .enumerate()
        .map(|(c, ((gr, gu), gv))| {
            let o = c * CHUNK;
            let mut acc = [R::ZERO; 6];
            for j in 0..gr.len() {
                let i = o + j;
                if !fwd.valid[i] {
                    (gr[j], gu[j], gv[j]) = (R::ZERO, R::ZERO, R::ZERO);
                    continue;
                }
                let (a, b, d, gvel) = ego_flow_at_backward(
                    k,
                    pts.u[i],
                    pts.v[i],
                    pts.inv_depth[i],
                    vel,
                    [g_u[i], g_v[i]],
                );
                (gr[j], gu[j], gv[j]) = (a, b, d);
                for (s, x) in acc.iter_mut().zip(gvel) {
                    *s += x;
                }
            }
            acc
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold([R::ZERO; 6], add6);
}

fn add6<R: Real>(a: [R; 6], b: [R; 6]) -> [R; 6] {
    std::array::from_fn(|i| a[i] + b[i])
}

/// A camera for projecting Gaussian centres: world-to-camera rotation `Rᵀ` (rows),
/// centre `c`, intrinsics, and the near plane (depth) below which a point is invalid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProjCam<R> {
    pub rt: [[R; 3]; 3],
    pub centre: [R; 3],
    pub k: Pinhole<R>,
    pub near: R,
}

impl<R: Real> ProjCam<R> {
    pub fn new(pose: &Pose, k: &Intrinsics, near: f64) -> Self {
        let m = glam::DMat3::from_quat(pose.rotation.inverse());
        let c = pose.translation;
        ProjCam {
            rt: std::array::from_fn(|r| std::array::from_fn(|j| R::from_f64(m.col(j)[r]))),
            centre: [c.x, c.y, c.z].map(R::from_f64),
            k: Pinhole::from_intrinsics(k),
            near: R::from_f64(near),
        }
    }

    /// Camera-space point `Rᵀ(x − c)`.
    #[inline]
    pub fn to_camera(&self, x: &[R; 3]) -> [R; 3] {
        let d = [
            x[0] - self.centre[0],
            x[1] - self.centre[1],
            x[2] - self.centre[2],
        ];
        std::array::from_fn(|r| self.rt[r][0] * d[0] + self.rt[r][1] * d[1] + self.rt[r][2] * d[2])
    }

    /// Pixel of world point `x` and its camera-space point, `None` at or behind the near
    /// plane (or not finite).
    #[inline]
    pub fn project(&self, x: &[R; 3]) -> Option<([R; 2], [R; 3])> {
        let p = self.to_camera(x);
        let d = -p[2];
        if d <= self.near || !d.is_finite() || !p[0].is_finite() || !p[1].is_finite() {
            return None;
        }
        let px = [
            self.k.cx + self.k.fx * p[0] / d,
            self.k.cy - self.k.fy * p[1] / d,
        ];
        Some((px, p))
    }

    /// Backward of [`Self::project`] at camera point `p` for pixel gradient `g`:
    /// `(∂/∂x world, ∂/∂ε camera-right twist)`.
    #[inline]
    pub fn project_backward(&self, p: &[R; 3], g: [R; 2]) -> ([R; 3], [R; 6]) {
        let id = R::ONE / -p[2];
        let (a, b) = (g[0] * self.k.fx * id, g[1] * self.k.fy * id);
        let gp = [a, -b, (a * p[0] - b * p[1]) * id];
        // ∂p/∂x = Rᵀ, so ∂/∂x = R·gp.
        let gx = std::array::from_fn(|j| {
            self.rt[0][j] * gp[0] + self.rt[1][j] * gp[1] + self.rt[2][j] * gp[2]
        });
        // p' = p − ε_v + p × ε_ω: ∂/∂ε_v = −gp, ∂/∂ε_ω = gp × p.
        let cam = [
            -gp[0],
            -gp[1],
            -gp[2],
            gp[1] * p[2] - gp[2] * p[1],
            gp[2] * p[0] - gp[0] * p[2],
            gp[0] * p[1] - gp[1] * p[0],
        ];
        (gx, cam)
    }
}

/// The camera(s) of Eq. 10 (module docs).
#[derive(Clone, Copy, Debug)]
pub(crate) enum GsCameras<'a, R> {
    /// The paper's form: both centres projected by one camera.
    Same(&'a ProjCam<R>),
    /// `x(t0)` by the camera at `t0`, `x(t1)` by the camera at `t1`.
    Exact(&'a ProjCam<R>, &'a ProjCam<R>),
}

impl<'a, R> GsCameras<'a, R> {
    fn pair(&self) -> (&'a ProjCam<R>, &'a ProjCam<R>) {
        match *self {
            GsCameras::Same(c) => (c, c),
            GsCameras::Exact(a, b) => (a, b),
        }
    }
}

/// Gradients of [`gaussian_flow_backward`]: per Gaussian w.r.t. the two centres, and
/// w.r.t. the camera-right twists of the cameras at `t0` and `t1` (for
/// [`GsCameras::Same`] the whole camera gradient is in `cam0`, `cam1` is zero).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct GsGrad<R> {
    pub x0: Vec<[R; 3]>,
    pub x1: Vec<[R; 3]>,
    pub cam0: [R; 6],
    pub cam1: [R; 6],
}

/// Eq. 10: `F_gs^i = Proj(x_i(t1)) − Proj(x_i(t0))` in px for every Gaussian (`x0`,
/// `x1`: its deformed centres at `t0` and `t1`); `out` is resized.
pub(crate) fn gaussian_flow<R: Real>(
    cams: GsCameras<'_, R>,
    x0: &[[R; 3]],
    x1: &[[R; 3]],
    out: &mut Flow2<R>,
) {
    let n = x0.len();
    assert_eq!(x1.len(), n, "gaussian_flow: lengths differ");
    let (c0, c1) = cams.pair();
    out.resize(n);
    out.u
        .par_chunks_mut(CHUNK)
        .zip(out.v.par_chunks_mut(CHUNK))
        .zip(out.valid.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(c, ((fu, fv), ok))| {
            let o = c * CHUNK;
            for j in 0..fu.len() {
                let (a, b) = (c0.project(&x0[o + j]), c1.project(&x1[o + j]));
                (fu[j], fv[j], ok[j]) = match (a, b) {
                    (Some((pa, _)), Some((pb, _))) => (pb[0] - pa[0], pb[1] - pa[1], true),
                    _ => (R::ZERO, R::ZERO, false),
                };
            }
        });
}

/// Backward of [`gaussian_flow`] from `g_u`, `g_v` (∂L/∂F_gs per Gaussian); invalid
/// Gaussians get zero gradient. `grad` is resized and overwritten.
pub(crate) fn gaussian_flow_backward<R: Real>(
    cams: GsCameras<'_, R>,
    x0: &[[R; 3]],
    x1: &[[R; 3]],
    fwd: &Flow2<R>,
    g_u: &[R],
    g_v: &[R],
    grad: &mut GsGrad<R>,
) {
    let n = x0.len();
    assert!(
        x1.len() == n && fwd.len() == n && g_u.len() == n && g_v.len() == n,
        "gaussian_flow_backward: lengths differ"
    );
    let (c0, c1) = cams.pair();
    grad.x0.resize(n, [R::ZERO; 3]);
    grad.x1.resize(n, [R::ZERO; 3]);
    let zero = || ([R::ZERO; 6], [R::ZERO; 6]);
    let (g0, g1) = grad
        .x0
        .par_chunks_mut(CHUNK)
        .zip(grad.x1.par_chunks_mut(CHUNK))
        .enumerate()
        .map(|(c, (gx0, gx1))| {
            let o = c * CHUNK;
            let (mut a0, mut a1) = zero();
            for j in 0..gx0.len() {
                let i = o + j;
                let pair = (c0.project(&x0[i]), c1.project(&x1[i]));
                let (Some((_, p0)), Some((_, p1)), true) = (pair.0, pair.1, fwd.valid[i]) else {
                    gx0[j] = [R::ZERO; 3];
                    gx1[j] = [R::ZERO; 3];
                    continue;
                };
                let g = [g_u[i], g_v[i]];
                let (gb, cb) = c1.project_backward(&p1, g);
                let (ga, ca) = c0.project_backward(&p0, [-g[0], -g[1]]);
                gx1[j] = gb;
                gx0[j] = ga;
                for k in 0..6 {
                    a0[k] += ca[k];
                    a1[k] += cb[k];
                }
            }
            (a0, a1)
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold(zero(), |a, b| (add6(a.0, b.0), add6(a.1, b.1)));
    match cams {
        GsCameras::Same(_) => {
            grad.cam0 = add6(g0, g1);
            grad.cam1 = [R::ZERO; 6];
        }
        GsCameras::Exact(..) => {
            grad.cam0 = g0;
            grad.cam1 = g1;
        }
    }
}
