//! The tracked Gaussians keep their size over time (`tracks.rigidity`, issue #30): the
//! isometry term of Dynamic 3D Gaussians (Luiten et al., 3DV 2024) on the trajectories.
//!
//! Why: one camera cannot tell a moving object from a copy `s` times as far and as
//! large, and a copy whose `s` changes from frame to frame draws every train view the
//! same. A depth prior's error differs from frame to frame (a network's output is one
//! image at a time), so `L_depth` pulls each train view's copy of a moving object to its
//! own `s`: the object breathes along the rays, and from elsewhere it is off by the
//! frame's error. Holding the distances between neighbouring tracked Gaussians constant
//! over time makes `s` one number per object, which the prior then sets as the mean of
//! its frames.
//!
//! ```text
//! L = w · (1/P) Σ_(i,j) ((‖x_i(τ) − x_j(τ)‖ − ‖x_i(τ_r) − x_j(τ_r)‖) / h)²
//! ```
//!
//! over pairs of tracked Gaussians of the same life (`Splats::life`), `j` one of the
//! `k` nearest to `i` at the life's middle `τ_r`, with `x(τ) = μ + v·τ + a·τ²` the
//! trajectory alone (`motion`), `P` the pairs and `h` the mean distance of the nearest
//! pairs when the lists were built (so `w` is free of the scene's scale). Both ends of
//! each distance are trained: the gradient reaches `μ`, `v` and `a` through `τ` and `τ_r`.
//!
//! Near pairs alone hold an object's size only weakly: a breath of 5 % changes a
//! neighbour's distance by 5 % of `h`, where a Gaussian sliding 2 % along its ray changes
//! it by several `h`. `far` pairs per Gaussian (`tracks.rigidity_far`) reach across the
//! object: other members of its *part*, the Gaussians of its life joined to it through
//! near pairs no longer than twice the median near distance (so two objects apart in
//! space are two parts), drawn with a fixed seed; their distances grow with the object.

use crate::splats::Splats;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rand::{RngExt, SeedableRng};
use scene::real::Real;
use std::collections::BTreeMap;
use std::num::NonZeroUsize;

/// Pairs of neighbouring tracked Gaussians of one life each.
#[derive(Clone, Debug, Default)]
pub struct Pairs {
    /// Gaussians the lists were built for.
    pub gaussians: usize,
    pub pairs: Vec<[u32; 2]>,
    /// Each pair's life (both Gaussians share it); its middle within the recording is
    /// the pair's reference time `τ_r` ([`middle`]).
    pub life: Vec<[f32; 2]>,
    /// Mean distance `h` of the pairs at their reference times when built (> 0).
    pub scale: f32,
    pub built_at: u32,
}

/// The middle of a life, clamped to the recording `[0, 1]`.
fn middle(life: [f32; 2]) -> f32 {
    let (a, b) = (life[0].max(0.0), life[1].min(1.0));
    0.5 * (a + b)
}

impl Pairs {
    /// The `k` nearest tracked Gaussians of each tracked one within its life group, at
    /// the group's reference time.
    /// With `far` > 0, also that many members of its part per Gaussian (module doc).
    pub fn build(s: &Splats, k: usize, far: usize, at: u32) -> Pairs {
        let n = s.len();
        let mut out = Pairs {
            gaussians: n,
            scale: 1.0,
            built_at: at,
            ..Pairs::default()
        };
        let (Some(k1), false) = (NonZeroUsize::new(k + 1), s.motion.is_empty()) else {
            return out;
        };
        let life = |i: usize| s.life.get(i).copied().unwrap_or(crate::splats::ALWAYS);
        let mut groups: BTreeMap<[u32; 2], Vec<u32>> = BTreeMap::new();
        for i in 0..n {
            if crate::motion::has_trajectory(&s.motion[i]) {
                let l = life(i);
                groups
                    .entry([l[0].to_bits(), l[1].to_bits()])
                    .or_default()
                    .push(i as u32);
            }
        }
        let (mut total, mut count) = (0.0, 0usize);
        for (key, ids) in groups {
            let l = [f32::from_bits(key[0]), f32::from_bits(key[1])];
            let tr = middle(l);
            let pts: Vec<[f32; 3]> = ids.iter().map(|&i| position(s, i as usize, tr)).collect();
            if pts.len() < 2 || pts.iter().flatten().any(|v| !v.is_finite()) {
                continue;
            }
            let tree: ImmutableKdTree<f32, 3> =
                ImmutableKdTree::new_from_slice(&pts).expect("finite points build a tree");
            let mut near: Vec<(u32, u32, f32)> = Vec::new();
            for (a, p) in pts.iter().enumerate() {
                let found = tree
                    .query(p)
                    .nearest_n::<SquaredEuclidean<f32>>(k1)
                    .execute();
                for q in found.into_iter().filter(|q| q.item as usize != a) {
                    near.push((a as u32, q.item, q.distance.sqrt()));
                }
            }
            for &(a, b, d) in &near {
                out.pairs.push([ids[a as usize], ids[b as usize]]);
                out.life.push(l);
                total += f64::from(d);
                count += 1;
            }
            if far > 0 {
                for [a, b] in far_pairs(pts.len(), &near, far, key) {
                    out.pairs.push([ids[a as usize], ids[b as usize]]);
                    out.life.push(l);
                }
            }
        }
        if total > 0.0 {
            out.scale = (total / count as f64) as f32;
        }
        out
    }

    /// `L` at time `t` for the pairs alive at `life_t` (the time the view reads the
    /// lives at), with `∂L/∂μ` and `∂L/∂[v; a]` added to `g_means` and `g_motion` (one
    /// row per Gaussian each).
    #[allow(clippy::too_many_arguments)]
    pub fn loss<T: Real>(
        &self,
        weight: f64,
        means: &[[T; 3]],
        motion: &[[T; 6]],
        t: f32,
        life_t: f32,
        g_means: &mut [[T; 3]],
        g_motion: &mut [[T; 6]],
    ) -> T {
        if self.pairs.is_empty() || weight == 0.0 || means.len() != self.gaussians {
            return T::ZERO;
        }
        let h = T::from_f64(f64::from(self.scale));
        let c = T::from_f64(weight / self.pairs.len() as f64);
        let two = T::from_f64(2.0);
        let tau = T::from_f64(f64::from(t - crate::motion::T0));
        let at = |i: usize, tau: T| -> [T; 3] {
            std::array::from_fn(|a| means[i][a] + motion[i][a] * tau + motion[i][3 + a] * tau * tau)
        };
        let mut loss = T::ZERO;
        for (p, &l) in self.pairs.iter().zip(&self.life) {
            if !crate::motion::alive(l, life_t) {
                continue;
            }
            let (i, j) = (p[0] as usize, p[1] as usize);
            let taur = T::from_f64(f64::from(middle(l) - crate::motion::T0));
            let (xi, xj, ri, rj) = (at(i, tau), at(j, tau), at(i, taur), at(j, taur));
            let d: [T; 3] = std::array::from_fn(|a| xi[a] - xj[a]);
            let r: [T; 3] = std::array::from_fn(|a| ri[a] - rj[a]);
            let norm = |v: &[T; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let (ld, lr) = (norm(&d), norm(&r));
            let e = (ld - lr) / h;
            loss += c * e * e;
            let eps = T::from_f64(1e-12);
            if ld <= eps || lr <= eps {
                continue;
            }
            // ∂(c·e²)/∂x_i(τ) = 2c·e/h · d/‖d‖, ∂/∂x_i(τ_r) = −2c·e/h · r/‖r‖; j opposite.
            let (sd, sr) = (two * c * e / (h * ld), two * c * e / (h * lr));
            for a in 0..3 {
                let (gd, gr) = (sd * d[a], sr * r[a]);
                for (g, sign) in [(i, T::from_f64(1.0)), (j, T::from_f64(-1.0))] {
                    g_means[g][a] += sign * (gd - gr);
                    g_motion[g][a] += sign * (gd * tau - gr * taur);
                    g_motion[g][3 + a] += sign * (gd * tau * tau - gr * taur * taur);
                }
            }
        }
        loss
    }
}

/// `far` pairs per point of `n` (indices within one life group) with other members of
/// its part: the components of the graph of the `near` pairs `(a, b, distance)` no
/// longer than twice their median. Drawn with a generator seeded by the group's `key`.
fn far_pairs(n: usize, near: &[(u32, u32, f32)], far: usize, key: [u32; 2]) -> Vec<[u32; 2]> {
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn root(parent: &mut [u32], mut a: u32) -> u32 {
        while parent[a as usize] != a {
            parent[a as usize] = parent[parent[a as usize] as usize];
            a = parent[a as usize];
        }
        a
    }
    let mut lengths: Vec<f32> = near.iter().map(|e| e.2).collect();
    if lengths.is_empty() {
        return Vec::new();
    }
    let m = lengths.len() / 2;
    let limit = 2.0 * *lengths.select_nth_unstable_by(m, f32::total_cmp).1;
    for &(a, b, _) in near.iter().filter(|e| e.2 <= limit) {
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
    let mut parts: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for a in 0..n as u32 {
        let r = root(&mut parent, a);
        parts.entry(r).or_default().push(a);
    }
    let mut rng =
        rand_chacha::ChaCha8Rng::seed_from_u64(u64::from(key[0]) << 32 | u64::from(key[1]));
    let mut out = Vec::new();
    for members in parts.values().filter(|p| p.len() > 1) {
        for &a in members {
            for _ in 0..far {
                let b = members[rng.random_range(0..members.len())];
                if b != a {
                    out.push([a, b]);
                }
            }
        }
    }
    out
}

/// The trajectory's position of Gaussian `i` at normalised time `t` (no field).
fn position(s: &Splats, i: usize, t: f32) -> [f32; 3] {
    let d = crate::motion::shift(s, i, t);
    std::array::from_fn(|a| s.means[i][a] + d[a])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::splats::Gaussian;

    fn cloud(means: &[[f32; 3]], motion: Vec<[f32; 6]>, life: Vec<[f32; 2]>) -> Splats {
        let mut s = Splats::default();
        for m in means {
            s.push(Gaussian::isotropic(*m, -2.0, 0.0, [0.5; 3]));
        }
        (s.motion, s.life) = (motion, life);
        s
    }

    /// The gradient against f64 central differences of the loss, for every parameter.
    #[test]
    fn gradient_matches_finite_differences() {
        let mut state = 7u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 33) as f64 / (1u64 << 31) as f64) - 0.5
        };
        let (mut ms, mut rows, mut lives) = (vec![], vec![], vec![]);
        for i in 0..12 {
            ms.push([rnd() as f32, rnd() as f32, 2.0 + rnd() as f32]);
            let row: [f32; 6] = std::array::from_fn(|_| (0.3 * rnd()) as f32);
            rows.push(if i == 11 { [0.0; 6] } else { row });
            lives.push(if i < 6 {
                crate::splats::ALWAYS
            } else {
                [0.25, 0.75]
            });
        }
        let s = cloud(&ms, rows, lives);
        let pairs = Pairs::build(&s, 3, 0, 0);
        assert!(!pairs.pairs.is_empty());
        assert!(
            pairs.pairs.iter().flatten().all(|&i| i != 11),
            "a still Gaussian is paired"
        );
        assert!(
            pairs.pairs.iter().all(|p| (p[0] < 6) == (p[1] < 6)),
            "lives mixed"
        );
        let means: Vec<[f64; 3]> = s.means.iter().map(|m| m.map(f64::from)).collect();
        let motion: Vec<[f64; 6]> = s.motion.iter().map(|m| m.map(f64::from)).collect();
        let (t, life_t) = (0.6, 0.6);
        let f = |me: &[[f64; 3]], mo: &[[f64; 6]]| {
            let (mut a, mut b) = (vec![[0.0; 3]; 12], vec![[0.0; 6]; 12]);
            pairs.loss(2.0, me, mo, t, life_t, &mut a, &mut b)
        };
        let (mut gm, mut gv) = (vec![[0.0; 3]; 12], vec![[0.0; 6]; 12]);
        let l0 = pairs.loss(2.0, &means, &motion, t, life_t, &mut gm, &mut gv);
        assert!(l0 > 0.0);
        let h = 1e-6;
        // Each of the 9 parameters of each Gaussian: μ (0..3), then v and a (3..9).
        for i in 0..12 {
            for q in 0..9 {
                let (mut p, mut m) = (
                    (means.clone(), motion.clone()),
                    (means.clone(), motion.clone()),
                );
                match q {
                    0..3 => (p.0[i][q] += h, m.0[i][q] -= h),
                    _ => (p.1[i][q - 3] += h, m.1[i][q - 3] -= h),
                };
                let fd = (f(&p.0, &p.1) - f(&m.0, &m.1)) / (2.0 * h);
                let got = if q < 3 { gm[i][q] } else { gv[i][q - 3] };
                assert!(
                    (fd - got).abs() < 1e-6 * (1.0 + fd.abs()),
                    "{i} {q}: {fd} {got}"
                );
            }
        }
        // Outside the windowed group's life only the whole-recording pairs count.
        let (mut a, mut b) = (vec![[0.0; 3]; 12], vec![[0.0; 6]; 12]);
        pairs.loss(2.0, &means, &motion, 0.9, 0.9, &mut a, &mut b);
        assert!(a[6..].iter().flatten().all(|&g| g == 0.0));
    }

    /// Two grids of one life, far apart: the far pairs join members of one grid only,
    /// every Gaussian of both grids has some, and `h` stays the near pairs' spacing.
    #[test]
    fn far_pairs_stay_within_a_part() {
        let grid = |x0: f32| -> Vec<[f32; 3]> {
            (0..36)
                .map(|i| [x0 + 0.1 * (i % 6) as f32, 0.1 * (i / 6) as f32, 3.0])
                .collect()
        };
        let ms: Vec<[f32; 3]> = grid(0.0).into_iter().chain(grid(5.0)).collect();
        let n = ms.len();
        let s = cloud(&ms, vec![[0.1; 6]; n], vec![[0.0, 1.0]; n]);
        let near = Pairs::build(&s, 4, 0, 0);
        let both = Pairs::build(&s, 4, 3, 0);
        let extra = &both.pairs[near.pairs.len()..];
        assert_eq!(&both.pairs[..near.pairs.len()], &near.pairs[..]);
        assert!(extra.len() > n && extra.len() <= 3 * n, "{}", extra.len());
        assert!(
            extra.iter().all(|p| (p[0] < 36) == (p[1] < 36)),
            "across parts"
        );
        assert!(extra.iter().all(|p| p[0] != p[1]));
        // Some reach beyond the neighbours: farther than three grid steps.
        let dist = |p: &[u32; 2]| {
            let (a, b) = (ms[p[0] as usize], ms[p[1] as usize]);
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
        };
        assert!(extra.iter().any(|p| dist(p) > 0.3));
        for i in 0..n as u32 {
            assert!(extra.iter().any(|p| p[0] == i), "{i} has no far pair");
        }
        assert_eq!(both.scale, near.scale);
        assert!(near.scale > 0.09 && near.scale < 0.15, "{}", near.scale);
    }

    /// A rigid motion costs nothing; the same cloud scaled about a point over time does.
    #[test]
    fn rigid_motion_is_free_and_breathing_is_not() {
        let ms: Vec<[f32; 3]> = (0..10)
            .map(|i| {
                let f = i as f32;
                [0.1 * f, (0.37 * f).sin(), 3.0 + 0.05 * f * f]
            })
            .collect();
        // A translation with a constant acceleration: every distance is kept.
        let s = cloud(
            &ms,
            vec![[0.4, -0.2, 0.1, 0.3, 0.0, -0.5]; 10],
            vec![crate::splats::ALWAYS; 10],
        );
        // Near and far pairs (one part: the points are a connected chain).
        let pairs = Pairs::build(&s, 4, 2, 0);
        assert!(pairs.pairs.len() > 40, "{}", pairs.pairs.len());
        let means: Vec<[f64; 3]> = s.means.iter().map(|m| m.map(f64::from)).collect();
        let motion: Vec<[f64; 6]> = s.motion.iter().map(|m| m.map(f64::from)).collect();
        let (mut a, mut b) = (vec![[0.0; 3]; 10], vec![[0.0; 6]; 10]);
        let rigid = pairs.loss(1.0, &means, &motion, 0.1, 0.1, &mut a, &mut b);
        assert!(rigid.abs() < 1e-12, "{rigid}");
        // x(τ) = (1 + τ)·x: v = x, a = 0 (a copy along the rays from the origin).
        let breathing: Vec<[f64; 6]> = means
            .iter()
            .map(|m| [m[0], m[1], m[2], 0.0, 0.0, 0.0])
            .collect();
        let l = pairs.loss(1.0, &means, &breathing, 0.1, 0.1, &mut a, &mut b);
        // Every distance grows by |τ| = 0.4 of itself: e = 0.4·d/h, so L = mean(0.16·d²)/h².
        let want: f64 = (pairs.pairs.iter())
            .map(|p| {
                let (x, y) = (means[p[0] as usize], means[p[1] as usize]);
                let d2: f64 = (0..3).map(|k| (x[k] - y[k]).powi(2)).sum();
                0.16 * d2 / f64::from(pairs.scale).powi(2)
            })
            .sum::<f64>()
            / pairs.pairs.len() as f64;
        assert!((l - want).abs() < 1e-5 * want, "{l} {want}");
    }
}
