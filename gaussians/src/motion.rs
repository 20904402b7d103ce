//! Per-Gaussian trajectories ([`Splats::motion`], issue #30): each centre follows its
//! own quadratic path in normalised time,
//!
//! ```text
//! μ(t) = μ + v·τ + a·τ²,   τ = t − T0,   motion[i] = [v; a]
//! ```
//!
//! on top of whatever the deformation field adds (`μ' = μ(t) + δx`). Why: the rendering
//! loss does not move a textured object (its Gaussians' photometric gradients align them
//! with the texture under them, not with the object's motion), so the motion has to come
//! from correspondences, and a few numbers per Gaussian hold it where an MLP would have
//! to learn it (BENCHMARKS.md, "What moves them"). `T0` is the middle of the recording, so
//! `v` and `a` are uncorrelated over it and μ is the centre there.
//!
//! Empty [`Splats::motion`] = no trajectories (every centre still, the field alone moves
//! it). The gradient: `∂μ(t)/∂v = τ·I`, `∂μ(t)/∂a = τ²·I`, for the Gaussians that have a
//! trajectory ([`has_trajectory`]) only: a row of zeros is a still Gaussian and gets no
//! gradient, so it stays still. Were it trained, every still Gaussian could follow its
//! own path to fit each train view apart (as the field could): the still background
//! bends along the recorded path and misregisters from elsewhere (BENCHMARKS.md, "Still
//! Gaussians stay still").

use crate::field::{self, Mlp};
use crate::splats::Splats;
use rayon::prelude::*;
use std::borrow::Cow;

/// Normalised time at which a Gaussian's centre is `μ` (the middle of the recording).
pub const T0: f32 = 0.5;

/// Values per Gaussian: velocity then acceleration, world units per normalised time.
pub(crate) const WIDTH: usize = 6;

/// `(τ, τ²)` of normalised time `t`.
fn powers(t: f32) -> (f32, f32) {
    let tau = t - T0;
    (tau, tau * tau)
}

/// The trajectory's shift `v·τ + a·τ²` of Gaussian `i` at time `t` (0 without motion).
pub fn shift(s: &Splats, i: usize, t: f32) -> [f32; 3] {
    let Some(m) = s.motion.get(i) else {
        return [0.0; 3];
    };
    let (p1, p2) = powers(t);
    std::array::from_fn(|k| m[k] * p1 + m[3 + k] * p2)
}

/// Whether a trajectory row `[v; a]` is one: all zeros is a still Gaussian (the init
/// gives trajectories to the moving tracks' Gaussians only; densification copies rows).
pub fn has_trajectory(m: &[f32; WIDTH]) -> bool {
    m.iter().any(|&c| c != 0.0)
}

/// Move the Gaussians of `out` (those of `s` as rendered, one per Gaussian) along the
/// trajectories of `s` to time `t`, and hide those whose life ([`Splats::life`]) does
/// not hold `t`; nothing when `s` has neither.
pub fn advance(s: &Splats, t: f32, out: &mut Splats) {
    advance_living(s, t, t, out);
}

/// [`advance`] with the lives read at `life_t` instead of `t` (the centres at `t`): a
/// train view drawn with the copies of a neighbouring window ([`life_clock_shared`]).
pub fn advance_living(s: &Splats, t: f32, life_t: f32, out: &mut Splats) {
    if !s.motion.is_empty() {
        assert_eq!(s.motion.len(), out.len(), "motion: one row per Gaussian");
        let (p1, p2) = powers(t);
        (out.means.as_mut_slice(), &s.motion)
            .into_par_iter()
            .with_min_len(4096)
            .for_each(|(x, m)| (0..3).for_each(|k| x[k] += m[k] * p1 + m[3 + k] * p2));
    }
    if !s.life.is_empty() {
        assert_eq!(s.life.len(), out.len(), "life: one row per Gaussian");
        for (o, l) in out.opacity_logits.iter_mut().zip(&s.life) {
            if !alive(*l, life_t) {
                *o += HIDDEN_LOGIT;
            }
        }
    }
}

/// Added to the opacity logit of a Gaussian outside its life: its opacity falls below
/// 10⁻¹⁷, under what the rasterizer draws. A constant, so the opacity's gradient passes
/// through unchanged (and is zero for a hidden Gaussian).
const HIDDEN_LOGIT: f32 = -40.0;

/// The time at which a train view at `t` reads the lives when the windows hand over at
/// shared frames (`tracks.handover = "frame"`): midway to the previous frame
/// `prev` when `unit < ½` (the earlier window's copies, whose life ends at `t`), else
/// `t`. At a frame inside a window both times lie in the same lives.
pub fn life_clock_shared(t: f32, prev: Option<f32>, unit: f32) -> f32 {
    match prev {
        Some(p) if unit < 0.5 => 0.5 * (p + t),
        _ => t,
    }
}

/// Whether a Gaussian of life `[from, to)` exists at time `t`.
pub fn alive(life: [f32; 2], t: f32) -> bool {
    t >= life[0] && t < life[1]
}

/// Gradient of the trajectory parameters from the rendered centres' gradient `g_means`
/// at time `t`, into `out` (resized; emptied when `s` has no motion; zero rows for the
/// still Gaussians, [`has_trajectory`]).
pub fn backward(s: &Splats, t: f32, g_means: &[[f32; 3]], out: &mut Vec<[f32; WIDTH]>) {
    if s.motion.is_empty() {
        out.clear();
        return;
    }
    let (p1, p2) = powers(t);
    // Every row written (no clear, no filter): a filter makes the iterator unindexed and
    // halved its speed (`cargo bench -p degs-gaussians --bench motion`).
    out.resize(g_means.len(), [0.0; WIDTH]);
    (out.as_mut_slice(), g_means, &s.motion)
        .into_par_iter()
        .with_min_len(4096)
        .for_each(|(o, g, m)| {
            *o = match has_trajectory(m) {
                true => std::array::from_fn(|k| g[k % 3] * if k < 3 { p1 } else { p2 }),
                false => [0.0; WIDTH],
            }
        });
}

/// `s` deformed to time `t` by `field` and its trajectories (`s` itself without
/// either).
pub(crate) fn at_time<'s>(
    s: &'s Splats,
    field: Option<&Mlp<f32>>,
    dynamic_only: bool,
    t: f32,
) -> Cow<'s, Splats> {
    let deformed = match field {
        None => Cow::Borrowed(s),
        Some(f) => {
            let (d, _) = field::splat_deltas(f, s, t, dynamic_only);
            Cow::Owned(field::deform_splats(s, &d))
        }
    };
    with_trajectories(s, t, deformed)
}

/// `deformed` (the Gaussians of `s` deformed by a field) moved along their trajectories
/// and by their parts ([`crate::parts`]), and hidden outside their lives.
pub(crate) fn with_trajectories<'s>(
    s: &Splats,
    t: f32,
    deformed: Cow<'s, Splats>,
) -> Cow<'s, Splats> {
    if s.motion.is_empty() && s.life.is_empty() && s.part.is_empty() {
        return deformed;
    }
    let mut out = deformed.into_owned();
    advance(s, t, &mut out);
    crate::parts::advance(&s.parts, &s.part, t, &mut out);
    Cow::Owned(out)
}

/// Add a gradient `d` on the rendered centres at time `t` to the canonical centres' and
/// the trajectories' gradients in `g` only (not through the field; a still Gaussian's
/// trajectory gets none, [`has_trajectory`]).
pub fn add_centre_gradient(s: &Splats, t: f32, d: &[[f32; 3]], g: &mut crate::splats::SplatGrads) {
    let (p1, p2) = powers(t);
    for (i, d) in d.iter().enumerate() {
        (0..3).for_each(|k| g.means[i][k] += d[k]);
        let moves = s.motion.get(i).is_some_and(has_trajectory);
        if let Some(m) = g.motion.get_mut(i).filter(|_| moves) {
            (0..3).for_each(|k| {
                m[k] += d[k] * p1;
                m[3 + k] += d[k] * p2;
            });
        }
    }
}
