//! The motion loss `L_motion` (Eq. 12): the flow of a Gaussian's bound events against
//! the image motion the model predicts for it.
//!
//! For each Gaussian `i` bound to events `k ∈ B(i)` (CSR table: `offsets`, event
//! indices, weights `w_k`, as `assoc` writes them) over a span `Δt = t1 − t0`:
//!
//! `r_i = Δt·Σ_k w̄_k·f_k − (Δt·F_ego(i) + F_gs^i)`,  `L_motion = (1/N)·Σ_i ρ(r_i)`
//!
//! with `f_k` the per-event flow (px/s, from the flow network), `w̄_k = w_k/Σw` (a no-op
//! when the weights sum to 1, as `assoc` writes them), `F_ego(i)` the ego-motion flow at
//! the Gaussian's pixel (px/s, Eq. 9), `F_gs^i` its scene flow over the span (px,
//! Eq. 10), `ρ` a robust norm ([`Norm`]) and `N` the number of Gaussians that
//! contribute: bound to at least one usable event, positive weight sum, valid `F_gs`
//! (and `F_ego` when given), everything finite. With the exact form of `F_gs` (which
//! already contains the camera's motion) pass no `F_ego`.
//!
//! **Implausible flows are dropped, event by event** (and counted in [`MotionLoss`]);
//! the sums above run over the events left, their weights renormalised:
//! - an event with no flow entry (`missing_events`) or a non-finite flow
//!   (`dropped_non_finite`: `deform` marks events no `.evflow` window covers, and flows
//!   beyond the flow network's range, with NaN);
//! - an **outlier** among the events of one Gaussian (`dropped_outliers`): with at least
//!   three usable events, `m` the component-wise median of their flows and
//!   `d_k = |f_k − m|`, event `k` is dropped when
//!   `d_k > max(outlier_px/|Δt|, 3·1.4826·median_j d_j)`: it moves more than
//!   [`MotionSettings::outlier_px`] pixels over the span away from the others *and* lies
//!   beyond three robust standard deviations of the group. Two events cannot outvote each
//!   other and are kept.
//!
//! Gradients are w.r.t. `F_ego` (per Gaussian, px/s) and `F_gs` (px), ready for
//! `flow::ego_flow_backward` and `flow::gaussian_flow_backward`. The flow network is
//! frozen in this stage, so no gradient goes to `f_k`.

use rayon::prelude::*;
use scene::real::Real;
use serde::{Deserialize, Serialize};

const CHUNK: usize = 2048;

/// The robust norm `ρ` of the 2-D residual `r` (px).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Norm {
    /// Smooth L1 per component: `Σ_c (√(r_c² + ε²) − ε)`.
    L1,
    /// Charbonnier on the vector: `√(|r|² + ε²) − ε`.
    #[default]
    Charbonnier,
    /// Huber on the vector: `|r|²/(2δ)` for `|r| ≤ δ`, else `|r| − δ/2`.
    Huber,
    /// Squared L2: `|r|²`.
    L2,
}

/// Settings of the motion loss (serde, every field optional in files).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionSettings {
    pub norm: Norm,
    /// `ε` of the smooth L1 and Charbonnier norms, px.
    pub epsilon: f64,
    /// `δ` of the Huber norm, px.
    pub huber_delta: f64,
    /// A bound event whose flow, over the span, lands more than this many pixels from
    /// the median of its Gaussian's events (and beyond three robust deviations) is an
    /// outlier and dropped (module docs); 0 keeps every event.
    pub outlier_px: f64,
    /// The flow network's range: the largest displacement (px, per component) a
    /// per-event flow can carry over its `.evflow` window. `evflow`'s tanh heads bound
    /// it by the network's `max_flow` (32 px per window for the shipped weights); a
    /// flow beyond it (0.1 % tolerance) is corrupt and its event gets no flow (read by
    /// `deform`'s inputs). 0: no check.
    pub flow_range_px: f64,
}

impl Default for MotionSettings {
    fn default() -> Self {
        MotionSettings {
            norm: Norm::Charbonnier,
            epsilon: 1e-3,
            huber_delta: 1.0,
            outlier_px: 2.0,
            flow_range_px: 32.0,
        }
    }
}

/// `ρ(r)` and `∂ρ/∂r`.
#[inline]
pub fn robust<R: Real>(s: &MotionSettings, r: [R; 2]) -> (R, [R; 2]) {
    let eps = R::from_f64(s.epsilon);
    match s.norm {
        Norm::L1 => {
            let a = (r[0] * r[0] + eps * eps).sqrt();
            let b = (r[1] * r[1] + eps * eps).sqrt();
            (a + b - eps - eps, [r[0] / a, r[1] / b])
        }
        Norm::Charbonnier => {
            let n = (r[0] * r[0] + r[1] * r[1] + eps * eps).sqrt();
            (n - eps, [r[0] / n, r[1] / n])
        }
        Norm::Huber => {
            let d = R::from_f64(s.huber_delta);
            let n2 = r[0] * r[0] + r[1] * r[1];
            if n2 <= d * d {
                (n2 / (d + d), [r[0] / d, r[1] / d])
            } else {
                let n = n2.sqrt();
                (n - d * R::from_f64(0.5), [r[0] / n, r[1] / n])
            }
        }
        Norm::L2 => {
            let two = R::from_f64(2.0);
            (r[0] * r[0] + r[1] * r[1], [two * r[0], two * r[1]])
        }
    }
}

/// The Gaussian ↔ event bindings in CSR form: Gaussian `g` binds to
/// `events[offsets[g]..offsets[g+1]]` with the matching `weights`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CsrBindings<'a> {
    pub offsets: &'a [u32],
    pub events: &'a [u64],
    pub weights: &'a [f32],
}

/// A per-Gaussian 2-D quantity with an optional validity flag.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PerGaussian<'a, R> {
    pub u: &'a [R],
    pub v: &'a [R],
    pub valid: Option<&'a [bool]>,
}

/// Everything Eq. 12 needs.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MotionInputs<'a, R> {
    /// The span `Δt = t1 − t0` in seconds (signed).
    pub dt: R,
    pub bindings: CsrBindings<'a>,
    /// Per-event flow `(u, v)` in px/s; event index `e` reads entry `e − flow_base`
    /// (events outside the arrays are skipped and counted as missing).
    pub flow_u: &'a [R],
    pub flow_v: &'a [R],
    pub flow_base: u64,
    /// `F_ego` per Gaussian (px/s), or `None` (exact-form `F_gs`).
    pub ego: Option<PerGaussian<'a, R>>,
    /// `F_gs` per Gaussian (px over the span).
    pub gs: PerGaussian<'a, R>,
}

/// The value of `L_motion` and its counts.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct MotionLoss<R> {
    pub loss: R,
    /// Gaussians that contributed (`N`).
    pub bound: usize,
    /// Bound event indices with no flow entry.
    pub missing_events: usize,
    /// Bound events left out because their flow is not finite.
    pub dropped_non_finite: usize,
    /// Bound events left out as outliers among their Gaussian's events.
    pub dropped_outliers: usize,
    /// Mean `|r_i|` over the contributing Gaussians (px), for reports.
    pub mean_residual: R,
}

/// `∂L_motion/∂F_ego` (px/s) and `∂L_motion/∂F_gs` (px), per Gaussian; zero where a
/// Gaussian does not contribute.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct MotionGrad<R> {
    pub ego_u: Vec<R>,
    pub ego_v: Vec<R>,
    pub gs_u: Vec<R>,
    pub gs_v: Vec<R>,
}

/// Bound events of one Gaussian left out of its residual, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Dropped {
    missing: usize,
    non_finite: usize,
    outliers: usize,
}

impl Dropped {
    fn add(&mut self, o: Dropped) {
        self.missing += o.missing;
        self.non_finite += o.non_finite;
        self.outliers += o.outliers;
    }
}

/// Groups up to this size are sorted on the stack.
const STACK_GROUP: usize = 64;

/// Median of finite values (sorts `v`; mean of the middle two for an even count).
fn median<R: Real>(v: &mut [R]) -> R {
    v.sort_unstable_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) * R::from_f64(0.5)
    }
}

/// Threshold (px/s) on `|f_k − m|` above which an event of a group of usable flows
/// `(u, v)` is an outlier, and the median `m`; `None` when nothing is rejected (fewer
/// than three events, rejection off, or a zero span).
fn outlier_test<R: Real>(u: &[R], v: &[R], s: &MotionSettings, dt: R) -> Option<(R, [R; 2])> {
    let n = u.len();
    if n < 3 || s.outlier_px <= 0.0 || dt == R::ZERO || !dt.is_finite() {
        return None;
    }
    let mut stack = [R::ZERO; STACK_GROUP];
    let mut heap = Vec::new();
    let buf: &mut [R] = if n <= STACK_GROUP {
        &mut stack[..n]
    } else {
        heap.resize(n, R::ZERO);
        &mut heap
    };
    buf.copy_from_slice(u);
    let mu = median(buf);
    buf.copy_from_slice(v);
    let mv = median(buf);
    for k in 0..n {
        let (a, b) = (u[k] - mu, v[k] - mv);
        buf[k] = (a * a + b * b).sqrt();
    }
    let mad = median(buf);
    let floor = R::from_f64(s.outlier_px) / dt.abs();
    Some((floor.max(R::from_f64(3.0 * 1.4826) * mad), [mu, mv]))
}

/// Residual `r_i` of Gaussian `i`, or `None` if it does not contribute; also its bound
/// events left out (module docs).
#[inline]
fn residual<R: Real>(
    s: &MotionSettings,
    inp: &MotionInputs<'_, R>,
    i: usize,
) -> (Option<[R; 2]>, Dropped) {
    let b = &inp.bindings;
    let (lo, hi) = (b.offsets[i] as usize, b.offsets[i + 1] as usize);
    let mut dropped = Dropped::default();
    if hi <= lo {
        return (None, dropped);
    }
    let ok = |p: &PerGaussian<'_, R>| p.valid.is_none_or(|v| v[i]);
    if !ok(&inp.gs) || !inp.ego.as_ref().is_none_or(ok) {
        return (None, dropped);
    }
    // The usable events: a flow entry, finite.
    let flow = |k: usize| -> Result<(R, R), bool> {
        let j = b.events[k]
            .checked_sub(inp.flow_base)
            .map(|j| j as usize)
            .filter(|&j| j < inp.flow_u.len())
            .ok_or(false)?;
        let (u, v) = (inp.flow_u[j], inp.flow_v[j]);
        if u.is_finite() && v.is_finite() {
            Ok((u, v))
        } else {
            Err(true)
        }
    };
    let (mut us, mut vs) = ([R::ZERO; STACK_GROUP], [R::ZERO; STACK_GROUP]);
    let mut n = 0;
    for k in lo..hi {
        match flow(k) {
            Ok((u, v)) if n < STACK_GROUP => {
                (us[n], vs[n]) = (u, v);
                n += 1;
            }
            Ok(_) => n += 1,
            Err(false) => dropped.missing += 1,
            Err(true) => dropped.non_finite += 1,
        }
    }
    let test = if n <= STACK_GROUP {
        outlier_test(&us[..n], &vs[..n], s, inp.dt)
    } else {
        let (u, v): (Vec<R>, Vec<R>) = (lo..hi).filter_map(|k| flow(k).ok()).unzip();
        outlier_test(&u, &v, s, inp.dt)
    };
    let (mut su, mut sv, mut sw) = (R::ZERO, R::ZERO, R::ZERO);
    for k in lo..hi {
        let Ok((u, v)) = flow(k) else { continue };
        if let Some((thr, m)) = test {
            let (a, c) = (u - m[0], v - m[1]);
            if (a * a + c * c).sqrt() > thr {
                dropped.outliers += 1;
                continue;
            }
        }
        let w = R::from_f64(b.weights[k] as f64);
        su += w * u;
        sv += w * v;
        sw += w;
    }
    let positive = sw > R::ZERO; // false for NaN
    if !positive {
        return (None, dropped);
    }
    let (mut pu, mut pv) = (inp.gs.u[i], inp.gs.v[i]);
    if let Some(e) = &inp.ego {
        pu += inp.dt * e.u[i];
        pv += inp.dt * e.v[i];
    }
    let r = [inp.dt * su / sw - pu, inp.dt * sv / sw - pv];
    if r[0].is_finite() && r[1].is_finite() {
        (Some(r), dropped)
    } else {
        (None, dropped)
    }
}

/// Eq. 12: `L_motion` (module docs); with `grad`, also its gradient (resized and
/// overwritten). Deterministic: partial sums per fixed chunk, added in order.
pub(crate) fn motion_loss<R: Real>(
    s: &MotionSettings,
    inp: &MotionInputs<'_, R>,
    grad: Option<&mut MotionGrad<R>>,
) -> MotionLoss<R> {
    let n = inp.bindings.offsets.len().saturating_sub(1);
    let b = &inp.bindings;
    assert_eq!(b.events.len(), b.weights.len(), "motion_loss: CSR lengths");
    assert!(
        b.offsets
            .last()
            .is_none_or(|&o| o as usize <= b.events.len()),
        "motion_loss: offsets past the events"
    );
    assert_eq!(
        inp.flow_u.len(),
        inp.flow_v.len(),
        "motion_loss: flow lengths"
    );
    let lens_ok = |p: &PerGaussian<'_, R>| {
        p.u.len() == n && p.v.len() == n && p.valid.is_none_or(|v| v.len() == n)
    };
    assert!(
        lens_ok(&inp.gs) && inp.ego.as_ref().is_none_or(lens_ok),
        "motion_loss: per-Gaussian lengths"
    );

    // Pass 1: ρ, |r| and counts per chunk.
    let parts: Vec<(R, R, usize, Dropped)> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut acc = (R::ZERO, R::ZERO, 0, Dropped::default());
            for i in c * CHUNK..((c + 1) * CHUNK).min(n) {
                let (r, dropped) = residual(s, inp, i);
                acc.3.add(dropped);
                if let Some(r) = r {
                    acc.0 += robust(s, r).0;
                    acc.1 += (r[0] * r[0] + r[1] * r[1]).sqrt();
                    acc.2 += 1;
                }
            }
            acc
        })
        .collect();
    let (mut sum, mut sum_r, mut bound, mut dropped) = (R::ZERO, R::ZERO, 0, Dropped::default());
    for p in parts {
        sum += p.0;
        sum_r += p.1;
        bound += p.2;
        dropped.add(p.3);
    }
    let inv = if bound > 0 {
        R::ONE / R::from_f64(bound as f64)
    } else {
        R::ZERO
    };
    if let Some(g) = grad {
        for v in [&mut g.ego_u, &mut g.ego_v, &mut g.gs_u, &mut g.gs_v] {
            v.clear();
            v.resize(n, R::ZERO);
        }
        g.ego_u
            .par_chunks_mut(CHUNK)
            .zip(g.ego_v.par_chunks_mut(CHUNK))
            .zip(
                g.gs_u
                    .par_chunks_mut(CHUNK)
                    .zip(g.gs_v.par_chunks_mut(CHUNK)),
            )
            .enumerate()
            .for_each(|(c, ((eu, ev), (gu, gv)))| {
                for j in 0..eu.len() {
                    if let (Some(r), _) = residual(s, inp, c * CHUNK + j) {
                        let d = robust(s, r).1;
                        // r = … − F_gs − Δt·F_ego
                        gu[j] = -d[0] * inv;
                        gv[j] = -d[1] * inv;
                        if inp.ego.is_some() {
                            eu[j] = gu[j] * inp.dt;
                            ev[j] = gv[j] * inp.dt;
                        }
                    }
                }
            });
    }
    MotionLoss {
        loss: sum * inv,
        bound,
        missing_events: dropped.missing,
        dropped_non_finite: dropped.non_finite,
        dropped_outliers: dropped.outliers,
        mean_residual: sum_r * inv,
    }
}
