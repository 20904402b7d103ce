//! Bundle adjustment of one rigid part (`tracks.bundle`, called by `tracks::parts`): the
//! members' points in the part's frame and one pose per knot, fitted to where the members
//! were seen (their tracks' camera pixels) and to the depth prior at those pixels.
//!
//! Why: the poses `tracks::parts` chains from the members' lifted trajectories inherit
//! each trajectory's own error (a track's depth rows are its own pixels' prior values).
//! One rigid motion seen by a moving camera is a multi-view problem in the part's frame:
//! the pixels fix the shape and the motion up to one scale per part (scaling the part
//! about each frame's camera centre keeps it rigid and every pixel in place), and the
//! prior's depths fix that one number, though not as well as the lifts do (below).
//!
//! A network's depth is one image at a time, so its error is mostly one scale per frame
//! and object (`gaussians/examples/prior_error.rs`: on `rigid` 4 fps the box's signed
//! median error runs −9.5 … +3.0 % over its five frames). Fitted as they come, a frame's
//! hundreds of depth rows outvote its pixels and each frame's pose slides along the rays
//! to that frame's error (the part breathes). So each knot's depth rows carry a scale
//! `s_k` of their own, held at 0 by one row per knot: a frame's prior counts once for
//! the part's size, and its depth relative to the other frames comes from the pixels
//! (the part's apparent size, its shape being one). The depth rows compare logarithms:
//! scaling the part and every `s_k` together then changes no residual (with `(z − ẑ) /
//! ẑ` a smaller part had smaller residuals, and a test with depths noisy per
//! observation came out 4 % too near).
//!
//! ```text
//! x_mk = R_k a_m + t_k                               (member m at knot k)
//! r_px = π_k(x_mk) − u_mk                             (pixels)
//! r_z  = (ln z_k(x_mk) − ln ẑ_mk − s_k) / σ          (a relative error σ costs 1 px)
//! r_s  = s_k / σ                                      (one per knot with depths)
//! E    = Σ ρ(‖r_px‖) + Σ ρ(|r_z|) + ½ Σ r_s²,   ρ Huber at `huber` px
//! ```
//!
//! What the adjustment leaves loose is the part's size: its depth is the mean of the
//! frames' priors, off by their mean scale error (−3.0 % on `rigid` 4 fps's box, against
//! −1.5 % for the lifted trajectories at the middle frame). So its caller takes that one
//! number from the lifts at the reference knot and [`rescale`]s the fitted part to it
//! about each knot's camera centre, which keeps every pixel: the adjustment gives the
//! shape and the motion, the lifts the distance.
//!
//! Levenberg–Marquardt on the normal equations with the points eliminated (Schur
//! complement, each point's block 3 × 3), reweighted for Huber at every step; rotations
//! updated on the left, `R ← exp(ω) R`. The reference knot's pose is held (the gauge:
//! the points are the part's centres there; its scale `s_k` is not), and so is the pose
//! of a knot fewer than `MIN_SEEN` members were seen at.

use glam::{DMat3, DQuat, DVec2, DVec3};
use scene::Camera;

/// Members a knot's pose needs seen there to be fitted.
pub const MIN_SEEN: usize = 3;

/// One observation of a member: the knot, the camera pixel, the prior's depth there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Seen {
    pub knot: usize,
    pub pixel: DVec2,
    pub depth: Option<f64>,
}

/// A part's pose at one knot: `x = R a + t`.
pub type Pose = (DQuat, DVec3);

/// What is fitted, besides the unknowns.
pub struct Problem<'a> {
    /// One camera per knot.
    pub cameras: &'a [&'a Camera],
    /// Per member, where it was seen.
    pub seen: &'a [Vec<Seen>],
    /// The knot whose pose is held.
    pub fixed: usize,
    /// Relative depth error that costs one pixel (0: no depth rows).
    pub depth_sigma: f64,
    /// Huber threshold, pixels.
    pub huber: f64,
}

/// How a fit went.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Report {
    pub cost_before: f64,
    pub cost_after: f64,
    pub iterations: usize,
}

/// Columns of one knot's unknowns: the pose's `[ω, t]` and the prior's scale `s`.
const KNOT: usize = 7;

/// One observation's residual rows (2, or 3 with a depth) and their derivatives by the
/// knot's unknowns (`[ω, t, s]`: the pose, left perturbation, then the prior's scale at
/// the knot, a log scale) and by the point; `None` behind the camera. `scale` is `s_k`.
#[allow(clippy::type_complexity)]
pub fn rows(
    p: &Problem,
    pose: Pose,
    scale: f64,
    a: DVec3,
    o: &Seen,
) -> Option<(Vec<f64>, Vec<[f64; KNOT]>, Vec<[f64; 3]>)> {
    let cam = p.cameras[o.knot];
    let (q, t) = pose;
    let ra = q * a;
    let x = ra + t;
    let rc = cam.cam_to_world.rotation;
    let pc = rc.conjugate() * (x - cam.cam_to_world.centre());
    let d = -pc.z;
    if d <= 1e-9 {
        return None;
    }
    let k = &cam.intrinsics;
    let u = DVec2::new(k.cx + k.fx * pc.x / d, k.cy - k.fy * pc.y / d);
    let mut r = vec![u.x - o.pixel.x, u.y - o.pixel.y];
    // ∂(u, v, r_z)/∂pc, and ∂/∂s.
    let mut dpc = vec![
        (DVec3::new(k.fx / d, 0.0, k.fx * pc.x / (d * d)), 0.0),
        (DVec3::new(0.0, -k.fy / d, -k.fy * pc.y / (d * d)), 0.0),
    ];
    if let Some(z) = o.depth.filter(|z| p.depth_sigma > 0.0 && *z > 0.0) {
        let w = 1.0 / p.depth_sigma;
        r.push((d.ln() - z.ln() - scale) * w);
        dpc.push((DVec3::new(0.0, 0.0, -w / d), -w));
    }
    // pc = Rcᵀ (x − C): a row g of ∂/∂pc is Rc g of ∂/∂x.
    let m = DMat3::from_quat(q);
    let (mut jk, mut ja) = (Vec::with_capacity(3), Vec::with_capacity(3));
    for (g, ds) in dpc {
        let gx = rc * g;
        // ∂x/∂ω = −[R a]×, so the row is (R a) × gx; ∂x/∂a = R, the row is Rᵀ gx.
        let w = ra.cross(gx);
        jk.push([w.x, w.y, w.z, gx.x, gx.y, gx.z, ds]);
        ja.push((m.transpose() * gx).to_array());
    }
    Some((r, jk, ja))
}

/// Huber's cost of a residual of norm `s` and its reweighting factor.
fn huber(s: f64, delta: f64) -> (f64, f64) {
    if s <= delta {
        (0.5 * s * s, 1.0)
    } else {
        (delta * (s - 0.5 * delta), delta / s)
    }
}

/// The robust cost `E` at the knots' prior scales `scales` (infinite when a point falls
/// behind a camera it was seen by).
pub fn cost(p: &Problem, poses: &[Pose], scales: &[f64], points: &[DVec3]) -> f64 {
    let mut e = 0.0;
    for (seen, &a) in p.seen.iter().zip(points) {
        for o in seen {
            let Some((r, _, _)) = rows(p, poses[o.knot], scales[o.knot], a, o) else {
                return f64::INFINITY;
            };
            e += huber(r[0].hypot(r[1]), p.huber).0;
            if let Some(&z) = r.get(2) {
                e += huber(z.abs(), p.huber).0;
            }
        }
    }
    if p.depth_sigma > 0.0 {
        e += scales
            .iter()
            .map(|s| 0.5 * (s / p.depth_sigma).powi(2))
            .sum::<f64>();
    }
    e
}

/// Dense Cholesky solve of `m x = b` (`m` symmetric positive definite, `n × n` row-major);
/// `None` when it is not.
pub(crate) fn cholesky_solve(mut m: Vec<f64>, mut b: Vec<f64>, n: usize) -> Option<Vec<f64>> {
    for j in 0..n {
        let mut d = m[j * n + j];
        for k in 0..j {
            d -= m[j * n + k] * m[j * n + k];
        }
        if d.is_nan() || d <= 0.0 {
            return None;
        }
        let d = d.sqrt();
        m[j * n + j] = d;
        for i in j + 1..n {
            let mut s = m[i * n + j];
            for k in 0..j {
                s -= m[i * n + k] * m[j * n + k];
            }
            m[i * n + j] = s / d;
        }
    }
    for i in 0..n {
        let s: f64 = (0..i).map(|k| m[i * n + k] * b[k]).sum();
        b[i] = (b[i] - s) / m[i * n + i];
    }
    for i in (0..n).rev() {
        let s: f64 = (i + 1..n).map(|k| m[k * n + i] * b[k]).sum();
        b[i] = (b[i] - s) / m[i * n + i];
    }
    b.iter().all(|v| v.is_finite()).then_some(b)
}

/// The normal equations' share of one point: its 3 × 3 block, its gradient, and per
/// knot it was seen at with unknowns, `H_ka` (the knot's columns × 3).
struct PointBlock {
    haa: DMat3,
    ga: DVec3,
    hka: Vec<(usize, [[f64; KNOT]; 3])>,
}

/// Fit `poses` (one per knot) and `points` (one per member) in place, at most
/// `iterations` Levenberg–Marquardt steps; returns the knots' prior scales with the
/// report.
pub fn adjust(
    p: &Problem,
    poses: &mut [Pose],
    points: &mut [DVec3],
    iterations: usize,
) -> (Report, Vec<f64>) {
    let n_knots = poses.len();
    let (mut count, mut depths) = (vec![0usize; n_knots], vec![0usize; n_knots]);
    for o in p.seen.iter().flatten() {
        count[o.knot] += 1;
        if o.depth.is_some() && p.depth_sigma > 0.0 {
            depths[o.knot] += 1;
        }
    }
    // Each knot's unknowns' global indices: its pose's six when it is fitted, its scale
    // when it has depth rows.
    let mut index = vec![[None; KNOT]; n_knots];
    let mut n = 0;
    for k in 0..n_knots {
        if k != p.fixed && count[k] >= MIN_SEEN {
            for slot in &mut index[k][..6] {
                *slot = Some(n);
                n += 1;
            }
        }
        if depths[k] > 0 {
            index[k][6] = Some(n);
            n += 1;
        }
    }
    let mut scales = vec![0.0; n_knots];
    let mut e = cost(p, poses, &scales, points);
    let mut report = Report {
        cost_before: e,
        cost_after: e,
        iterations: 0,
    };
    if !e.is_finite() {
        return (report, scales);
    }
    let mut lambda = 1e-4;
    for it in 0..iterations {
        // Normal equations at the current estimate, Huber weights from its residuals.
        let mut hkk = vec![0.0; n * n];
        let mut gk = vec![0.0; n];
        for k in 0..n_knots {
            if let Some(i) = index[k][6] {
                let w = 1.0 / (p.depth_sigma * p.depth_sigma);
                hkk[i * n + i] += w;
                gk[i] += w * scales[k];
            }
        }
        let mut blocks = Vec::with_capacity(points.len());
        for (seen, &a) in p.seen.iter().zip(points.iter()) {
            let mut b = PointBlock {
                haa: DMat3::ZERO,
                ga: DVec3::ZERO,
                hka: Vec::new(),
            };
            for o in seen {
                let Some((r, jk, ja)) = rows(p, poses[o.knot], scales[o.knot], a, o) else {
                    continue;
                };
                let w_px = huber(r[0].hypot(r[1]), p.huber).1;
                let w_z = r.get(2).map_or(1.0, |z| huber(z.abs(), p.huber).1);
                let idx = index[o.knot];
                let mut block = [[0.0; KNOT]; 3];
                for (row, ((ri, jki), jai)) in r.iter().zip(&jk).zip(&ja).enumerate() {
                    let w = if row < 2 { w_px } else { w_z };
                    let jav = DVec3::from_array(*jai);
                    b.haa += DMat3::from_cols(jav * jav.x, jav * jav.y, jav * jav.z) * w;
                    b.ga += jav * (w * ri);
                    for u in 0..KNOT {
                        let Some(iu) = idx[u] else { continue };
                        gk[iu] += w * jki[u] * ri;
                        for v in 0..KNOT {
                            if let Some(iv) = idx[v] {
                                hkk[iu * n + iv] += w * jki[u] * jki[v];
                            }
                        }
                        for c in 0..3 {
                            block[c][u] += w * jki[u] * jai[c];
                        }
                    }
                }
                b.hka.push((o.knot, block));
            }
            blocks.push(b);
        }
        // Damped steps until one lowers the cost.
        loop {
            let damp = |v: f64| v * (1.0 + lambda) + 1e-12;
            let mut sm = hkk.clone();
            for i in 0..n {
                sm[i * n + i] = damp(sm[i * n + i]);
            }
            let mut rhs: Vec<f64> = gk.iter().map(|g| -g).collect();
            // Per point: H_aa⁻¹ and H_aa⁻¹ (−g_a); S −= H_ka H_aa⁻¹ H_ak, rhs −= H_ka H_aa⁻¹ (−g_a).
            let mut inverses = Vec::with_capacity(blocks.len());
            for b in &blocks {
                let mut h = b.haa;
                for c in 0..3 {
                    h.col_mut(c)[c] = damp(h.col(c)[c]);
                }
                let inv = if h.determinant().abs() > 1e-300 {
                    h.inverse()
                } else {
                    DMat3::ZERO
                };
                let ia = inv * (-b.ga);
                for (k, bl) in &b.hka {
                    for u in 0..KNOT {
                        let Some(iu) = index[*k][u] else { continue };
                        let x = DVec3::new(bl[0][u], bl[1][u], bl[2][u]);
                        rhs[iu] -= x.dot(ia);
                        let xi = inv * x;
                        for (k2, bl2) in &b.hka {
                            for v in 0..KNOT {
                                if let Some(iv) = index[*k2][v] {
                                    let y = DVec3::new(bl2[0][v], bl2[1][v], bl2[2][v]);
                                    sm[iu * n + iv] -= xi.dot(y);
                                }
                            }
                        }
                    }
                }
                inverses.push((inv, ia));
            }
            let step = match n {
                0 => Some(Vec::new()),
                _ => cholesky_solve(sm, rhs, n),
            };
            if let Some(dk) = step {
                let at = |k: usize, c: usize| index[k][c].map_or(0.0, |i| dk[i]);
                let mut new_poses = poses.to_vec();
                let mut new_scales = scales.clone();
                for k in 0..n_knots {
                    let (q, t) = poses[k];
                    let dq = DQuat::from_scaled_axis(DVec3::new(at(k, 0), at(k, 1), at(k, 2)));
                    let dt = DVec3::new(at(k, 3), at(k, 4), at(k, 5));
                    new_poses[k] = ((dq * q).normalize(), t + dt);
                    new_scales[k] += at(k, 6);
                }
                let new_points: Vec<DVec3> = (points.iter().zip(&blocks).zip(&inverses))
                    .map(|((a, b), (inv, ia))| {
                        // δa = H_aa⁻¹ (−g_a − H_ak δk).
                        let mut h = DVec3::ZERO;
                        for (k, bl) in &b.hka {
                            for c in 0..3 {
                                h[c] += (0..KNOT).map(|u| bl[c][u] * at(*k, u)).sum::<f64>();
                            }
                        }
                        *a + *ia - *inv * h
                    })
                    .collect();
                let e_new = cost(p, &new_poses, &new_scales, &new_points);
                if e_new < e {
                    let small = e - e_new < 1e-10 * e;
                    poses.copy_from_slice(&new_poses);
                    points.copy_from_slice(&new_points);
                    scales = new_scales;
                    e = e_new;
                    lambda = (lambda / 3.0).max(1e-9);
                    report.iterations = it + 1;
                    if small {
                        report.cost_after = e;
                        return (report, scales);
                    }
                    break;
                }
            }
            lambda *= 4.0;
            if lambda > 1e8 {
                report.cost_after = e;
                return (report, scales);
            }
        }
    }
    report.cost_after = e;
    (report, scales)
}

/// Scale a fitted part by `s` about each knot's camera centre, `x_k ← C_k + s (x_k −
/// C_k)`: every pixel stays where it was and every depth is `s` times as far. The part
/// stays rigid (its points scale by `s`, each pose's translation moves) and the
/// `reference` knot's pose is kept, so the points stay the part's centres there.
pub fn rescale(
    cameras: &[&Camera],
    reference: usize,
    poses: &mut [Pose],
    points: &mut [DVec3],
    s: f64,
) {
    let (q0, t0) = poses[reference];
    let c0 = cameras[reference].cam_to_world.centre();
    // The points scaled, then moved so that the reference pose carries them as before.
    let delta = q0.conjugate() * ((c0 - t0) * (1.0 - s));
    for a in points.iter_mut() {
        *a = *a * s + delta;
    }
    for (k, (q, t)) in poses.iter_mut().enumerate() {
        let c = cameras[k].cam_to_world.centre();
        *t = *t * s + c * (1.0 - s) - *q * delta;
    }
}

/// Median reprojection error (pixels) of each member over where it was seen.
pub fn misfit(p: &Problem, poses: &[Pose], points: &[DVec3]) -> Vec<f64> {
    (p.seen.iter().zip(points))
        .map(|(seen, &a)| {
            let mut e: Vec<f64> = (seen.iter())
                .map(|o| {
                    rows(p, poses[o.knot], 0.0, a, o)
                        .map_or(f64::INFINITY, |r| r.0[0].hypot(r.0[1]))
                })
                .collect();
            e.sort_by(f64::total_cmp);
            e.get(e.len() / 2).copied().unwrap_or(f64::INFINITY)
        })
        .collect()
}
