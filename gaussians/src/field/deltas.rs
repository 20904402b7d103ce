//! The field's output per Gaussian ([`Deltas`]), the [`Deformation`] trait the MLP
//! implements, and how deltas deform a Gaussian (DEGS Eq. 3, after activation as
//! Deform-GS) with its backward.

use super::mlp::{HEAD_OUT, Mlp, MlpCache};

/// Per-Gaussian deltas, struct of arrays.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Deltas {
    pub dx: Vec<[f32; 3]>,
    pub dq: Vec<[f32; 4]>,
    pub ds: Vec<[f32; 3]>,
}

impl Deltas {
    pub fn zeros(n: usize) -> Self {
        Deltas {
            dx: vec![[0.0; 3]; n],
            dq: vec![[0.0; 4]; n],
            ds: vec![[0.0; 3]; n],
        }
    }
    pub fn len(&self) -> usize {
        self.dx.len()
    }
    pub fn is_empty(&self) -> bool {
        self.dx.is_empty()
    }
    fn from_rows(rows: &[f32]) -> Self {
        let n = rows.len() / HEAD_OUT;
        let mut d = Deltas::zeros(n);
        for (i, r) in rows.chunks(HEAD_OUT).enumerate() {
            d.dx[i] = [r[0], r[1], r[2]];
            d.dq[i] = [r[3], r[4], r[5], r[6]];
            d.ds[i] = [r[7], r[8], r[9]];
        }
        d
    }
    fn to_rows(&self) -> Vec<f32> {
        let mut rows = Vec::with_capacity(self.len() * HEAD_OUT);
        for i in 0..self.len() {
            rows.extend_from_slice(&self.dx[i]);
            rows.extend_from_slice(&self.dq[i]);
            rows.extend_from_slice(&self.ds[i]);
        }
        rows
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
        (Deltas::from_rows(&rows), cache)
    }
    fn backward(&self, cache: &Self::Cache, grads: &Deltas) -> Vec<f32> {
        Mlp::backward(self, cache, &grads.to_rows())
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
    let n = means.len();
    let mut out = Deformed {
        means: Vec::with_capacity(n),
        log_scales: Vec::with_capacity(n),
        rotations: Vec::with_capacity(n),
    };
    for i in 0..n {
        let m = means[i];
        out.means
            .push([m[0] + d.dx[i][0], m[1] + d.dx[i][1], m[2] + d.dx[i][2]]);
        let ls = log_scales[i];
        out.log_scales.push(std::array::from_fn(|k| {
            (ls[k].exp() + d.ds[i][k]).max(MIN_SCALE).ln()
        }));
        let q = rotations[i];
        let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
        out.rotations
            .push(std::array::from_fn(|k| q[k] / norm + d.dq[i][k]));
    }
    out
}

/// Gradients of the canonical parameters and of the deltas, from the gradients of the
/// deformed ones (`g_*`, as returned by the rasterizer's backward).
pub struct DeltaGrads {
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    pub rotations: Vec<[f32; 4]>,
    pub deltas: Deltas,
}

/// Backward of [`apply_deltas`].
pub fn apply_deltas_backward(
    log_scales: &[[f32; 3]],
    rotations: &[[f32; 4]],
    d: &Deltas,
    g_means: &[[f32; 3]],
    g_log_scales: &[[f32; 3]],
    g_rotations: &[[f32; 4]],
) -> DeltaGrads {
    let n = log_scales.len();
    let mut out = DeltaGrads {
        means: g_means.to_vec(),
        log_scales: vec![[0.0; 3]; n],
        rotations: vec![[0.0; 4]; n],
        deltas: Deltas::zeros(n),
    };
    for i in 0..n {
        out.deltas.dx[i] = g_means[i];
        for k in 0..3 {
            let e = log_scales[i][k].exp();
            let s = e + d.ds[i][k];
            if s > MIN_SCALE {
                // d ln(s)/dδs = 1/s ; d ln(s)/d log s = exp(log s)/s
                out.deltas.ds[i][k] = g_log_scales[i][k] / s;
                out.log_scales[i][k] = g_log_scales[i][k] * e / s;
            }
        }
        out.deltas.dq[i] = g_rotations[i];
        // d(q/‖q‖)/dq = (I − n nᵀ)/‖q‖
        let q = rotations[i];
        let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
        let nq: [f32; 4] = std::array::from_fn(|k| q[k] / norm);
        let g = g_rotations[i];
        let dot: f32 = (0..4).map(|k| g[k] * nq[k]).sum();
        out.rotations[i] = std::array::from_fn(|k| (g[k] - dot * nq[k]) / norm);
    }
    out
}
