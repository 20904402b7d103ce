//! Rigid parts (issue #30, `tracks.parts`): the Gaussians of one part share one rigid
//! motion over the whole recording, a pose per train frame (a *knot*) interpolated
//! between them,
//!
//! ```text
//! x_i(t) = R(q(t))·(x_i − o_p) + o_p + T(t),   q_i(t) = q(t) ⊗ q_i,
//! (q, T)(t) = Σ_k c_k(t)·(q_k, T_k)
//! ```
//!
//! `x_i`, `q_i` the Gaussian's centre and rotation as the field leaves them, `o_p` the
//! part's pivot, `c_k(t)` cubic Hermite weights with Catmull–Rom tangents over the knots'
//! times (so the pose passes through each knot's), `R(q)` the rotation of `q/|q|`.
//!
//! Why: one camera cannot tell an object from a copy `s` times as far and as large, and
//! a depth prior's error differs from frame to frame, so with a trajectory per Gaussian
//! each frame's copy of a moving object takes its own `s` (its own frame's error). A
//! rigid part has one shape for the whole recording, so its size is one number that the
//! prior sets as the mean over its frames (BENCHMARKS.md, "What of the prior costs the
//! moving pixels at 4 fps"), and its pose at a frame no track reached comes from the
//! frames its other members were seen in.
//!
//! The pose at the part's reference knot ([`Parts::fixed`], the one nearest the
//! recording's middle) stays the identity (the gauge: a part's shape and all its poses
//! could otherwise drift together).

use rayon::prelude::*;
use scene::real::Real;

/// A Gaussian in no part (an entry of [`crate::Splats::part`]).
pub const NO_PART: u32 = u32::MAX;

/// The parts' poses ([`crate::Splats::parts`]); empty when there are none.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Parts {
    /// The knots' normalised times, ascending (the train frames').
    pub knots: Vec<f32>,
    /// Per part: its pivot `o_p`.
    pub origin: Vec<[f32; 3]>,
    /// Per part and knot (part-major, `knots.len()` per part): the rotation `q_k`
    /// (w first, not necessarily unit).
    pub rot: Vec<[f32; 4]>,
    /// Per part and knot: the translation `T_k`.
    pub shift: Vec<[f32; 3]>,
    /// The knot whose pose is held at the identity.
    pub fixed: usize,
}

impl Parts {
    pub fn len(&self) -> usize {
        self.origin.len()
    }

    pub fn is_empty(&self) -> bool {
        self.origin.is_empty()
    }

    /// The rows of part `p` in [`Self::rot`] / [`Self::shift`].
    pub fn rows(&self, p: usize) -> std::ops::Range<usize> {
        let k = self.knots.len();
        p * k..(p + 1) * k
    }

    /// The pose of part `p` at normalised time `t`.
    pub fn pose(&self, p: usize, t: f32) -> ([f32; 4], [f32; 3]) {
        let r = self.rows(p);
        pose_at(&self.knots, &self.rot[r.clone()], &self.shift[r], t)
    }

    /// Whether the parts fit `n` Gaussians with `member` (one entry each or none).
    pub fn check(&self, member: &[u32], n: usize) -> Result<(), String> {
        if member.is_empty() {
            return Ok(());
        }
        if member.len() != n {
            return Err(format!("{} part entries for {n} Gaussians", member.len()));
        }
        let rows = self.len() * self.knots.len();
        if self.rot.len() != rows || self.shift.len() != rows {
            return Err(format!(
                "{} parts × {} knots need {rows} poses, found {} / {}",
                self.len(),
                self.knots.len(),
                self.rot.len(),
                self.shift.len()
            ));
        }
        if self.knots.windows(2).any(|w| w[1] <= w[0]) {
            return Err("the parts' knot times must ascend".into());
        }
        if let Some(&m) = member
            .iter()
            .find(|&&m| m != NO_PART && m as usize >= self.len())
        {
            return Err(format!("part {m} of {} parts", self.len()));
        }
        Ok(())
    }
}

/// Up to four `(knot, weight)` pairs `c_k(t)` (cubic Hermite, Catmull–Rom tangents, one-
/// sided at the ends; `t` clamped to the knots' span), in `f64`.
pub fn weights(knots: &[f32], t: f32) -> [(usize, f64); 4] {
    let mut out = [(0, 0.0); 4];
    let n = knots.len();
    if n <= 1 {
        out[0] = (0, 1.0);
        return out;
    }
    let kt = |i: usize| knots[i] as f64;
    let t = (t as f64).clamp(kt(0), kt(n - 1));
    let j = (0..n - 1).rfind(|&i| kt(i) <= t).unwrap_or(0);
    let h = kt(j + 1) - kt(j);
    let u = (t - kt(j)) / h;
    let (u2, u3) = (u * u, u * u * u);
    let h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
    let h10 = u3 - 2.0 * u2 + u;
    let h01 = -2.0 * u3 + 3.0 * u2;
    let h11 = u3 - u2;
    // The tangent at knot i as (lo, hi, 1/(t_hi − t_lo)): (P_hi − P_lo)/(t_hi − t_lo).
    let tangent = |i: usize| {
        let (lo, hi) = (i.saturating_sub(1), (i + 1).min(n - 1));
        (lo, hi, 1.0 / (kt(hi) - kt(lo)))
    };
    let mut add = |k: usize, w: f64| {
        let slot = (k + 1).saturating_sub(j).min(3);
        out[slot] = (k, out[slot].1 + w);
    };
    add(j, h00);
    add(j + 1, h01);
    let (lo, hi, inv) = tangent(j);
    add(hi, h10 * h * inv);
    add(lo, -h10 * h * inv);
    let (lo, hi, inv) = tangent(j + 1);
    add(hi, h11 * h * inv);
    add(lo, -h11 * h * inv);
    out
}

/// The pose `(q, T)(t)` from one part's knot poses.
pub fn pose_at<T: Real>(
    knots: &[f32],
    rot: &[[T; 4]],
    shift: &[[T; 3]],
    t: f32,
) -> ([T; 4], [T; 3]) {
    let (mut q, mut s) = ([T::ZERO; 4], [T::ZERO; 3]);
    for (k, w) in weights(knots, t) {
        if w != 0.0 {
            let w = T::from_f64(w);
            (0..4).for_each(|a| q[a] += w * rot[k][a]);
            (0..3).for_each(|a| s[a] += w * shift[k][a]);
        }
    }
    (q, s)
}

/// Adds the gradient of the pose at `t` (`g_q`, `g_t`) to one part's knot poses'.
pub fn pose_backward<T: Real>(
    knots: &[f32],
    t: f32,
    g_q: [T; 4],
    g_t: [T; 3],
    rot: &mut [[T; 4]],
    shift: &mut [[T; 3]],
) {
    for (k, w) in weights(knots, t) {
        if w != 0.0 {
            let w = T::from_f64(w);
            (0..4).for_each(|a| rot[k][a] += w * g_q[a]);
            (0..3).for_each(|a| shift[k][a] += w * g_t[a]);
        }
    }
}

fn dot<T: Real>(a: [T; 3], b: [T; 3]) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross<T: Real>(a: [T; 3], b: [T; 3]) -> [T; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `R(q)·v` for any non-zero `q` (w first): `((w² − u·u)v + 2(u·v)u + 2w(u × v)) / |q|²`.
pub fn rotate<T: Real>(q: [T; 4], v: [T; 3]) -> [T; 3] {
    let (w, u) = (q[0], [q[1], q[2], q[3]]);
    let s = w * w + dot(u, u);
    let (a, b, c) = (w * w - dot(u, u), T::from_f64(2.0) * dot(u, v), cross(u, v));
    let two_w = T::from_f64(2.0) * w;
    std::array::from_fn(|i| (a * v[i] + b * u[i] + two_w * c[i]) / s)
}

/// `R(q)ᵀ·v` (the rotation of the conjugate).
pub fn rotate_back<T: Real>(q: [T; 4], v: [T; 3]) -> [T; 3] {
    rotate([q[0], -q[1], -q[2], -q[3]], v)
}

/// The quaternion product `a ⊗ b` (w first).
pub fn mul<T: Real>(a: [T; 4], b: [T; 4]) -> [T; 4] {
    let (ua, ub) = ([a[1], a[2], a[3]], [b[1], b[2], b[3]]);
    let c = cross(ua, ub);
    [
        a[0] * b[0] - dot(ua, ub),
        a[0] * ub[0] + b[0] * ua[0] + c[0],
        a[0] * ub[1] + b[0] * ua[1] + c[1],
        a[0] * ub[2] + b[0] * ua[2] + c[2],
    ]
}

/// One Gaussian moved by a pose `(q, t)` about pivot `o`: `(R(q)(x − o) + o + t, q ⊗ r)`.
pub fn place<T: Real>(q: [T; 4], t: [T; 3], o: [T; 3], x: [T; 3], r: [T; 4]) -> ([T; 3], [T; 4]) {
    let v: [T; 3] = std::array::from_fn(|i| x[i] - o[i]);
    let rv = rotate(q, v);
    (std::array::from_fn(|i| rv[i] + o[i] + t[i]), mul(q, r))
}

/// The gradients of [`place`]: from `g_x`, `g_r` (on the placed centre and rotation) to
/// `(g_q, g_t, g_x, g_r)` on the pose and the Gaussian's own centre and rotation.
#[allow(clippy::type_complexity)]
pub fn place_backward<T: Real>(
    q: [T; 4],
    o: [T; 3],
    x: [T; 3],
    r: [T; 4],
    g_x: [T; 3],
    g_r: [T; 4],
) -> ([T; 4], [T; 3], [T; 3], [T; 4]) {
    let two = T::from_f64(2.0);
    let v: [T; 3] = std::array::from_fn(|i| x[i] - o[i]);
    let (w, u) = (q[0], [q[1], q[2], q[3]]);
    let s = w * w + dot(u, u);
    let (uu, uv, ug, vg) = (dot(u, u), dot(u, v), dot(u, g_x), dot(v, g_x));
    let uxv = cross(u, v);
    let n: [T; 3] =
        std::array::from_fn(|i| (w * w - uu) * v[i] + two * uv * u[i] + two * w * uxv[i]);
    let gn = dot(g_x, n);
    // ∂(N/s)/∂q · g = (∂N/∂q · g)/s − (g·N)·2q/s².
    let vxg = cross(v, g_x);
    let mut g_q = [T::ZERO; 4];
    g_q[0] = (two * w * vg + two * dot(uxv, g_x)) / s - gn * two * w / (s * s);
    for j in 0..3 {
        let d = -two * u[j] * vg + two * v[j] * ug + two * uv * g_x[j] + two * w * vxg[j];
        g_q[1 + j] = d / s - gn * two * u[j] / (s * s);
    }
    // q ⊗ r: ∂/∂q_w = g_w r_w + g_u·r_u, ∂/∂q_u = −g_w r_u + r_w g_u + r_u × g_u;
    // ∂/∂r_w = g_w q_w + g_u·q_u, ∂/∂r_u = −g_w q_u + q_w g_u + g_u × q_u.
    let (gw, gu, ru) = (g_r[0], [g_r[1], g_r[2], g_r[3]], [r[1], r[2], r[3]]);
    g_q[0] += gw * r[0] + dot(gu, ru);
    let rxg = cross(ru, gu);
    (0..3).for_each(|j| g_q[1 + j] += -gw * ru[j] + r[0] * gu[j] + rxg[j]);
    let gxq = cross(gu, u);
    let g_own_r = [
        gw * w + dot(gu, u),
        -gw * u[0] + w * gu[0] + gxq[0],
        -gw * u[1] + w * gu[1] + gxq[1],
        -gw * u[2] + w * gu[2] + gxq[2],
    ];
    (g_q, g_x, rotate_back(q, g_x), g_own_r)
}

/// Move the parts' members of `out` (the Gaussians as the field and the trajectories
/// left them, one row per Gaussian of the model) to time `t`.
pub fn advance(parts: &Parts, member: &[u32], t: f32, out: &mut crate::Splats) {
    if member.is_empty() || parts.is_empty() {
        return;
    }
    assert_eq!(member.len(), out.len(), "parts: one entry per Gaussian");
    let poses: Vec<([f32; 4], [f32; 3])> = (0..parts.len()).map(|p| parts.pose(p, t)).collect();
    (
        out.means.as_mut_slice(),
        out.rotations.as_mut_slice(),
        member,
    )
        .into_par_iter()
        .with_min_len(4096)
        .filter(|(_, _, m)| **m != NO_PART)
        .for_each(|(x, r, &m)| {
            let (q, s) = poses[m as usize];
            (*x, *r) = place(q, s, parts.origin[m as usize], *x, *r);
        });
}

/// The parts' share of a view's backward at time `t`: `placed` the rendered Gaussians
/// (after [`advance`]), `g.means` / `g.rotations` their gradients, turned in place into
/// the gradients of the Gaussians before the parts moved them; the knot poses' gradients
/// go into `g.part_rot` / `g.part_shift` (resized and zeroed first; the fixed knot's
/// stay 0).
pub fn backward(
    parts: &Parts,
    member: &[u32],
    t: f32,
    placed: &crate::Splats,
    g: &mut crate::SplatGrads,
) {
    let (g_means, g_rotations) = (&mut g.means, &mut g.rotations);
    let (g_rot, g_shift) = (&mut g.part_rot, &mut g.part_shift);
    g_rot.clear();
    g_shift.clear();
    if member.is_empty() || parts.is_empty() {
        return;
    }
    g_rot.resize(parts.rot.len(), [0.0; 4]);
    g_shift.resize(parts.shift.len(), [0.0; 3]);
    let n = parts.len();
    let poses: Vec<([f32; 4], [f32; 3])> = (0..n).map(|p| parts.pose(p, t)).collect();
    // Each member's pose gradient, summed per part (f64: thousands of members).
    let sums = (
        member,
        &placed.means,
        &placed.rotations,
        g_means,
        g_rotations,
    )
        .into_par_iter()
        .with_min_len(1024)
        .fold(
            || vec![[0.0f64; 7]; n],
            |mut acc, (&m, x, r, gx, gr)| {
                if m != NO_PART {
                    let (q, s) = poses[m as usize];
                    let o = parts.origin[m as usize];
                    // The Gaussian before the part moved it: x = R(q)ᵀ(x' − o − T) + o.
                    let back = rotate_back(q, std::array::from_fn(|i| x[i] - o[i] - s[i]));
                    let x0: [f32; 3] = std::array::from_fn(|i| back[i] + o[i]);
                    let qn = q.iter().map(|c| c * c).sum::<f32>();
                    let conj = [q[0] / qn, -q[1] / qn, -q[2] / qn, -q[3] / qn];
                    let r0 = mul(conj, *r);
                    let (g_q, g_t, g_x, g_r) = place_backward(q, o, x0, r0, *gx, *gr);
                    (*gx, *gr) = (g_x, g_r);
                    let a = &mut acc[m as usize];
                    (0..4).for_each(|i| a[i] += g_q[i] as f64);
                    (0..3).for_each(|i| a[4 + i] += g_t[i] as f64);
                }
                acc
            },
        )
        .reduce(
            || vec![[0.0f64; 7]; n],
            |mut a, b| {
                a.iter_mut()
                    .zip(&b)
                    .for_each(|(x, y)| (0..7).for_each(|i| x[i] += y[i]));
                a
            },
        );
    for (p, g) in sums.iter().enumerate() {
        let r = parts.rows(p);
        let gq = [g[0], g[1], g[2], g[3]].map(|v| v as f32);
        let gt = [g[4], g[5], g[6]].map(|v| v as f32);
        pose_backward(
            &parts.knots,
            t,
            gq,
            gt,
            &mut g_rot[r.clone()],
            &mut g_shift[r.clone()],
        );
        let f = r.start + parts.fixed.min(parts.knots.len().saturating_sub(1));
        (g_rot[f], g_shift[f]) = ([0.0; 4], [0.0; 3]);
    }
}

/// The rotation (w first) and translation of the rigid motion that takes points `a`
/// onto `b` best in least squares (Horn's quaternion method: the eigenvector of the
/// largest eigenvalue of a 4 × 4 symmetric matrix of the cross-covariance); `None` for
/// fewer than three pairs.
pub fn kabsch(a: &[[f64; 3]], b: &[[f64; 3]]) -> Option<([f64; 4], [f64; 3])> {
    let n = a.len().min(b.len());
    if n < 3 {
        return None;
    }
    let mean = |p: &[[f64; 3]]| {
        let mut m = [0.0; 3];
        p[..n]
            .iter()
            .for_each(|x| (0..3).for_each(|i| m[i] += x[i] / n as f64));
        m
    };
    let (ca, cb) = (mean(a), mean(b));
    let mut s = [[0.0; 3]; 3];
    for (x, y) in a[..n].iter().zip(&b[..n]) {
        for i in 0..3 {
            for j in 0..3 {
                s[i][j] += (x[i] - ca[i]) * (y[j] - cb[j]);
            }
        }
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let m = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let q = top_eigenvector(m);
    let rc = rotate(q, ca);
    Some((q, std::array::from_fn(|i| cb[i] - rc[i])))
}

/// The unit eigenvector of the largest eigenvalue of a symmetric 4 × 4 matrix (cyclic
/// Jacobi rotations).
fn top_eigenvector(mut a: [[f64; 4]; 4]) -> [f64; 4] {
    let mut v = [[0.0; 4]; 4];
    (0..4).for_each(|i| v[i][i] = 1.0);
    for _ in 0..50 {
        let off: f64 = (0..4)
            .flat_map(|i| (0..4).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        if off < 1e-30 {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut() {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - s * akq;
                    row[q] = s * akp + c * akq;
                }
                let (rp, rq) = (a[p], a[q]);
                a[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
                a[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    let best = (0..4)
        .max_by(|&i, &j| a[i][i].total_cmp(&a[j][j]))
        .unwrap_or(0);
    let e = [v[0][best], v[1][best], v[2][best], v[3][best]];
    let norm = e.iter().map(|x| x * x).sum::<f64>().sqrt();
    let sign = if e[0] < 0.0 { -1.0 } else { 1.0 };
    e.map(|x| sign * x / norm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_pass_through_the_knots_and_sum_to_one() {
        let knots = [0.0, 0.25, 0.5, 0.8, 1.0];
        for (i, &k) in knots.iter().enumerate() {
            let w = weights(&knots, k);
            let at: f64 = w.iter().filter(|(j, _)| *j == i).map(|(_, w)| w).sum();
            assert!((at - 1.0).abs() < 1e-12, "knot {i}: {w:?}");
        }
        for t in [0.1f32, 0.3, 0.61, 0.95] {
            let s: f64 = weights(&knots, t).iter().map(|(_, w)| w).sum();
            assert!((s - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn kabsch_recovers_a_rigid_motion() {
        let q = [0.9f64, 0.2, -0.3, 0.25];
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        let q = q.map(|x| x / n);
        let t = [0.3, -1.0, 2.0];
        let a: Vec<[f64; 3]> = (0..7)
            .map(|i| {
                let f = i as f64;
                [f.sin(), (2.0 * f).cos(), 0.3 * f]
            })
            .collect();
        let b: Vec<[f64; 3]> = (a.iter())
            .map(|p| {
                let r = rotate(q, *p);
                std::array::from_fn(|i| r[i] + t[i])
            })
            .collect();
        let (qe, te) = kabsch(&a, &b).expect("seven points");
        let same = (0..4).all(|i| (qe[i] - q[i]).abs() < 1e-9);
        assert!(same, "{qe:?} against {q:?}");
        assert!((0..3).all(|i| (te[i] - t[i]).abs() < 1e-9), "{te:?}");
    }
}
