//! The field's output per Gaussian ([`Deltas`]), the [`Deformation`] trait the MLP
//! implements, and how deltas deform a Gaussian (DEGS Eq. 3, after activation as
//! Deform-GS) with its backward.

use super::mlp::{HEAD_OUT, Mlp, MlpCache};

/// Per-Gaussian deltas, struct of arrays. `dc` (added to the SH DC coefficients) is
/// empty unless the field has a colour head ([`super::FieldSettings::color`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Deltas {
    pub dx: Vec<[f32; 3]>,
    pub dq: Vec<[f32; 4]>,
    pub ds: Vec<[f32; 3]>,
    pub dc: Vec<[f32; 3]>,
}

impl Deltas {
    pub fn zeros(n: usize) -> Self {
        Deltas {
            dx: vec![[0.0; 3]; n],
            dq: vec![[0.0; 4]; n],
            ds: vec![[0.0; 3]; n],
            dc: Vec::new(),
        }
    }
    /// Whether these deltas change colour (the field has a colour head).
    pub fn has_color(&self) -> bool {
        !self.dc.is_empty()
    }
    pub fn len(&self) -> usize {
        self.dx.len()
    }
    pub fn is_empty(&self) -> bool {
        self.dx.is_empty()
    }
    /// `n` zero deltas in place, with a zero colour column when `color` (allocations
    /// kept).
    pub(crate) fn set_zeros_with(&mut self, n: usize, color: bool) {
        for v in [
            &mut self.dx as &mut dyn ZeroFill,
            &mut self.dq,
            &mut self.ds,
        ] {
            v.zero_fill(n);
        }
        self.dc.zero_fill(if color { n } else { 0 });
    }
    /// `n` zero deltas in place, no colour (allocations kept).
    pub(crate) fn set_zeros(&mut self, n: usize) {
        self.set_zeros_with(n, false);
    }
    fn from_rows(rows: &[f32], width: usize) -> Self {
        let mut d = Deltas::default();
        d.set_rows(rows, width);
        d
    }
    /// Overwrite with the head's output rows (`n × width`; `width` is `HEAD_OUT`, or
    /// `HEAD_OUT + 3` with a colour head).
    pub(crate) fn set_rows(&mut self, rows: &[f32], width: usize) {
        let n = rows.len() / width;
        self.set_zeros_with(n, width > HEAD_OUT);
        for (i, r) in rows.chunks(width).enumerate() {
            self.set_row(i, r);
        }
    }
    /// Gaussian i's deltas from one head row.
    pub(crate) fn set_row(&mut self, i: usize, r: &[f32]) {
        self.dx[i] = [r[0], r[1], r[2]];
        self.dq[i] = [r[3], r[4], r[5], r[6]];
        self.ds[i] = [r[7], r[8], r[9]];
        if r.len() > HEAD_OUT {
            self.dc[i] = [r[10], r[11], r[12]];
        }
    }
    /// Gaussian `src`'s deltas of `from` as Gaussian `dst`'s here (colour when both have it).
    pub(crate) fn copy_one(&mut self, dst: usize, from: &Deltas, src: usize) {
        self.dx[dst] = from.dx[src];
        self.dq[dst] = from.dq[src];
        self.ds[dst] = from.ds[src];
        if self.has_color() && from.has_color() {
            self.dc[dst] = from.dc[src];
        }
    }
    /// Gaussian i's deltas appended (the colour too when both have it).
    pub fn push_one(&mut self, from: &Deltas, i: usize) {
        self.dx.push(from.dx[i]);
        self.dq.push(from.dq[i]);
        self.ds.push(from.ds[i]);
        if from.has_color() {
            self.dc.push(from.dc[i]);
        }
    }
    fn to_rows(&self, width: usize) -> Vec<f32> {
        let mut rows = Vec::new();
        self.rows_into(&mut rows, width);
        rows
    }
    /// The deltas as head rows (`n × width`) into `rows` (cleared first); a colour
    /// column these deltas lack is written as zeros.
    pub(crate) fn rows_into(&self, rows: &mut Vec<f32>, width: usize) {
        rows.clear();
        for i in 0..self.len() {
            rows.extend_from_slice(&self.dx[i]);
            rows.extend_from_slice(&self.dq[i]);
            rows.extend_from_slice(&self.ds[i]);
            if width > HEAD_OUT {
                rows.extend_from_slice(self.dc.get(i).unwrap_or(&[0.0; 3]));
            }
        }
    }
}

/// Zero-filled resize of the delta columns.
trait ZeroFill {
    fn zero_fill(&mut self, n: usize);
}

impl<const K: usize> ZeroFill for Vec<[f32; K]> {
    fn zero_fill(&mut self, n: usize) {
        self.clear();
        self.resize(n, [0.0; K]);
    }
}

/// A learnable deformation field.
pub trait Deformation: Send + Sync {
    type Cache;
    /// Deltas for positions `x` at times `t` (length 1 = same time for all, or `x.len()`).
    fn forward(&self, x: &[[f32; 3]], t: &[f32]) -> (Deltas, Self::Cache);
    /// Parameter gradients from the deltas' gradients (no gradient into x: detached).
    fn backward(&self, cache: &Self::Cache, grads: &Deltas) -> Vec<f32>;
    fn params(&self) -> &[f32];
    fn params_mut(&mut self) -> &mut [f32];
}

/// The Deform-GS MLP in f32.
pub type DeformMlp = Mlp<f32>;

impl Deformation for Mlp<f32> {
    type Cache = MlpCache<f32>;
    fn forward(&self, x: &[[f32; 3]], t: &[f32]) -> (Deltas, Self::Cache) {
        let (rows, cache) = Mlp::forward(self, x, t);
        (Deltas::from_rows(&rows, self.settings.head_out()), cache)
    }
    fn backward(&self, cache: &Self::Cache, grads: &Deltas) -> Vec<f32> {
        Mlp::backward(self, cache, &grads.to_rows(self.settings.head_out()))
    }
    fn params(&self) -> &[f32] {
        &self.params
    }
    fn params_mut(&mut self) -> &mut [f32] {
        &mut self.params
    }
}

/// Smallest activated scale after adding δs (keeps the log finite).
pub const MIN_SCALE: f32 = 1e-6;

/// Deformed Gaussian parameters in the rasterizer's raw form (log-scale, raw quaternion
/// w-first), for the Gaussians listed.
#[derive(Clone, Debug, Default)]
pub struct Deformed {
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    pub rotations: Vec<[f32; 4]>,
}

/// Apply deltas: `μ' = μ + δx`, `log s' = ln(max(exp(log s) + δs, 1e-6))`,
/// `q' = q/‖q‖ + δq`.
// Eq. 3: the canonical Gaussian deformed by the field's output at time t.
pub fn apply_deltas(
    means: &[[f32; 3]],
    log_scales: &[[f32; 3]],
    rotations: &[[f32; 4]],
    d: &Deltas,
) -> Deformed {
    let mut out = Deformed {
        means: means.to_vec(),
        log_scales: log_scales.to_vec(),
        rotations: rotations.to_vec(),
    };
    apply_deltas_in_place(&mut out.means, &mut out.log_scales, &mut out.rotations, d);
    out
}

/// [`apply_deltas`] on parameters that hold the canonical values on entry and the
/// deformed ones on return (rayon over Gaussians; the same values bit for bit).
pub fn apply_deltas_in_place(
    means: &mut [[f32; 3]],
    log_scales: &mut [[f32; 3]],
    rotations: &mut [[f32; 4]],
    d: &Deltas,
) {
    use rayon::prelude::*;
    (means, log_scales, rotations)
        .into_par_iter()
        .enumerate()
        .with_min_len(1024)
        .for_each(|(i, (m, ls, q))| {
            *m = [m[0] + d.dx[i][0], m[1] + d.dx[i][1], m[2] + d.dx[i][2]];
            *ls = std::array::from_fn(|k| (ls[k].exp() + d.ds[i][k]).max(MIN_SCALE).ln());
            let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
            *q = std::array::from_fn(|k| q[k] / norm + d.dq[i][k]);
        });
}

/// A colour field's deltas added to the SH DC coefficients (nothing without a colour
/// head): `c' = c + δc`, so the colour changes by `C0·δc` in every direction.
pub fn apply_color_deltas(sh_dc: &mut [[f32; 3]], d: &Deltas) {
    if !d.has_color() {
        return;
    }
    for (c, dc) in sh_dc.iter_mut().zip(&d.dc) {
        *c = [c[0] + dc[0], c[1] + dc[1], c[2] + dc[2]];
    }
}

/// Gradients of the canonical parameters and of the deltas, from the gradients of the
/// deformed ones (`g_*`, as returned by the rasterizer's backward).
#[derive(Clone, Debug, Default)]
pub struct DeltaGrads {
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    pub rotations: Vec<[f32; 4]>,
    pub deltas: Deltas,
}

/// Backward of [`apply_deltas`] and [`apply_color_deltas`] (`g_sh_dc`: the deformed
/// DC coefficients' gradient, which is δc's and passes to the canonical ones unchanged).
pub fn apply_deltas_backward(
    log_scales: &[[f32; 3]],
    rotations: &[[f32; 4]],
    d: &Deltas,
    g_means: &[[f32; 3]],
    g_log_scales: &[[f32; 3]],
    g_rotations: &[[f32; 4]],
    g_sh_dc: &[[f32; 3]],
) -> DeltaGrads {
    let mut g = DeltaGrads {
        means: g_means.to_vec(),
        log_scales: g_log_scales.to_vec(),
        rotations: g_rotations.to_vec(),
        deltas: Deltas::default(),
    };
    apply_deltas_backward_in_place(
        log_scales,
        rotations,
        d,
        g_means,
        g_sh_dc,
        &mut g.log_scales,
        &mut g.rotations,
        &mut g.deltas,
    );
    g
}

/// Backward of [`apply_deltas`] in place: `g_log_scales` and `g_rotations` hold the
/// deformed parameters' gradients on entry and the canonical ones' on return (the
/// means' gradient `g_means` passes unchanged: it is δx's, and so does `g_sh_dc`, δc's
/// when `d` has colour); `deltas` receives the deltas' gradients (resized).
/// Rayon over Gaussians; the same values as [`apply_deltas_backward`].
#[allow(clippy::too_many_arguments)]
pub fn apply_deltas_backward_in_place(
    log_scales: &[[f32; 3]],
    rotations: &[[f32; 4]],
    d: &Deltas,
    g_means: &[[f32; 3]],
    g_sh_dc: &[[f32; 3]],
    g_log_scales: &mut [[f32; 3]],
    g_rotations: &mut [[f32; 4]],
    deltas: &mut Deltas,
) {
    use rayon::prelude::*;
    let n = log_scales.len();
    deltas.set_zeros_with(n, d.has_color());
    deltas.dx.copy_from_slice(g_means);
    if d.has_color() {
        deltas.dc.copy_from_slice(g_sh_dc);
    }
    let Deltas { dq, ds, .. } = deltas;
    (g_log_scales, g_rotations, ds, dq)
        .into_par_iter()
        .enumerate()
        .with_min_len(1024)
        .for_each(|(i, (gls, grot, dds, ddq))| {
            let mut canon = [0.0f32; 3];
            for k in 0..3 {
                let e = log_scales[i][k].exp();
                let s = e + d.ds[i][k];
                if s > MIN_SCALE {
                    // d ln(s)/dδs = 1/s ; d ln(s)/d log s = exp(log s)/s
                    dds[k] = gls[k] / s;
                    canon[k] = gls[k] * e / s;
                }
            }
            *gls = canon;
            *ddq = *grot;
            // d(q/‖q‖)/dq = (I − n nᵀ)/‖q‖
            let q = rotations[i];
            let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
            let nq: [f32; 4] = std::array::from_fn(|k| q[k] / norm);
            let g = *grot;
            let dot: f32 = (0..4).map(|k| g[k] * nq[k]).sum();
            *grot = std::array::from_fn(|k| (g[k] - dot * nq[k]) / norm);
        });
}
