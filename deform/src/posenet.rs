//! PoseNet (after DE-NeRF; DEGS §3.4 and its appendix): a small MLP of time that
//! corrects the interpolated camera pose.
//!
//! - Input: normalised time `t ∈ [0, 1]` (see `CameraPath::normalised_time`), encoded
//!   as `γ(t) = (t, sin(2⁰πt), cos(2⁰πt), …, sin(2^{L−1}πt), cos(2^{L−1}πt))`: the raw `t`
//!   is kept, `L` = [`PoseNetSettings::frequencies`] (default 6, so 13 inputs).
//! - Two layers: `h = ReLU(W₁γ + b₁)` (width [`PoseNetSettings::hidden`], default 64),
//!   `ξ = W₂h + b₂ ∈ R⁶`, the twist `ξ = (v, ω)`.
//! - `W₁, b₁` start uniform in `±1/√fan_in` from [`PoseNetSettings::seed`]; `W₂, b₂` start
//!   at **zero**, so the corrected pose equals the interpolated one at initialisation.
//! - **Applying ξ** ([`apply_correction`]): right-multiplied in the camera frame,
//!   `T' = T·[Exp(ω) | v]`, i.e. `R' = R·Exp(ω)` (Rodrigues' formula, not the coupled
//!   SE(3) exponential) and `c' = c + R·v`: the camera turns about its own centre by `ω`
//!   and moves by `v`, both in its own (OpenGL) axes.
//!
//! Parameters are one flat vector (`W₁` row-major `hidden × in`, `b₁`, `W₂` row-major
//! `6 × hidden`, `b₂`), so an Adam over flat slices updates them. The backward chain is
//! `∂L/∂ε` (camera-right twist of the corrected pose, [`crate::lie`]) →
//! [`correction_backward`] → `∂L/∂ξ` → [`PoseNet::backward`] → `∂L/∂params`. A gradient
//! from the `gaussians` rasterizer is in that twist already; one from a
//! symmetric-difference velocity comes from `camera_path::velocity_between_backward`.

use crate::lie::{exp_so3, join, right_jacobian, split};
use glam::DVec3;
use scene::Pose;
use scene::real::Real;
use serde::{Deserialize, Serialize};

/// Settings of the PoseNet (serde, every field optional in files).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PoseNetSettings {
    /// Number of sinusoidal frequencies `L` of the time encoding.
    pub frequencies: usize,
    /// Width of the hidden layer.
    pub hidden: usize,
    /// Seed of the first layer's initial weights.
    pub seed: u64,
}

impl Default for PoseNetSettings {
    fn default() -> Self {
        PoseNetSettings {
            frequencies: 6,
            hidden: 64,
            seed: 0,
        }
    }
}

impl PoseNetSettings {
    /// Size of the time encoding, `1 + 2L`.
    pub fn input_dim(&self) -> usize {
        1 + 2 * self.frequencies
    }

    /// Number of parameters, `hidden·(in + 1) + 6·(hidden + 1)`.
    pub fn num_params(&self) -> usize {
        self.hidden * (self.input_dim() + 1) + 6 * (self.hidden + 1)
    }
}

/// The PoseNet: settings and flat parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseNet<R> {
    settings: PoseNetSettings,
    params: Vec<R>,
}

/// SplitMix64 → uniform in `[-1, 1)` (deterministic initialisation without a `rand`
/// dependency).
fn splitmix(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    2.0 * ((z >> 11) as f64 / (1u64 << 53) as f64) - 1.0
}

impl<R: Real> PoseNet<R> {
    /// A fresh network: first layer random (seeded), output layer zero.
    pub fn new(settings: PoseNetSettings) -> Self {
        let (d, h) = (settings.input_dim(), settings.hidden);
        let bound = 1.0 / (d as f64).sqrt();
        let mut state = settings.seed;
        let mut params = vec![R::ZERO; settings.num_params()];
        for p in &mut params[..h * (d + 1)] {
            *p = R::from_f64(bound * splitmix(&mut state));
        }
        PoseNet { settings, params }
    }

    /// From saved parameters; `Err` if their number does not fit the settings or one is
    /// not finite.
    pub fn from_params(settings: PoseNetSettings, params: Vec<R>) -> Result<Self, String> {
        if params.len() != settings.num_params() {
            return Err(format!(
                "PoseNet: {} parameters, the settings need {}",
                params.len(),
                settings.num_params()
            ));
        }
        if let Some(i) = params.iter().position(|p| !p.is_finite()) {
            return Err(format!("PoseNet: parameter {i} is not finite"));
        }
        Ok(PoseNet { settings, params })
    }

    pub fn settings(&self) -> &PoseNetSettings {
        &self.settings
    }

    pub fn params(&self) -> &[R] {
        &self.params
    }

    /// Mutable parameters (for the optimiser).
    pub fn params_mut(&mut self) -> &mut [R] {
        &mut self.params
    }

    /// `γ(t)` into `out` (length [`PoseNetSettings::input_dim`]).
    pub fn encode(&self, t: R, out: &mut [R]) {
        out[0] = t;
        let mut f = std::f64::consts::PI;
        for k in 0..self.settings.frequencies {
            let a = t * R::from_f64(f);
            out[1 + 2 * k] = a.sin();
            out[2 + 2 * k] = a.cos();
            f *= 2.0;
        }
    }

    /// Offsets of `(W₁, b₁, W₂, b₂)` in the flat parameters.
    fn layout(&self) -> (usize, usize, usize, usize) {
        let (d, h) = (self.settings.input_dim(), self.settings.hidden);
        (0, h * d, h * d + h, h * d + h + 6 * h)
    }

    /// Encoding and first-layer pre-activations at `t`.
    fn hidden(&self, t: R) -> (Vec<R>, Vec<R>) {
        let (d, h) = (self.settings.input_dim(), self.settings.hidden);
        let (w1, b1, _, _) = self.layout();
        let mut x = vec![R::ZERO; d];
        self.encode(t, &mut x);
        let a = (0..h)
            .map(|j| {
                let row = &self.params[w1 + j * d..w1 + (j + 1) * d];
                row.iter().zip(&x).map(|(&w, &xi)| w * xi).sum::<R>() + self.params[b1 + j]
            })
            .collect();
        (x, a)
    }

    /// The correction twist `ξ = (v, ω)` at normalised time `t`.
    pub fn forward(&self, t: R) -> [R; 6] {
        let h = self.settings.hidden;
        let (_, _, w2, b2) = self.layout();
        let (_, a) = self.hidden(t);
        std::array::from_fn(|o| {
            let row = &self.params[w2 + o * h..w2 + (o + 1) * h];
            row.iter()
                .zip(&a)
                .map(|(&w, &aj)| w * aj.max(R::ZERO))
                .sum::<R>()
                + self.params[b2 + o]
        })
    }

    /// Accumulate `∂L/∂params` into `grad` (same layout as [`Self::params`]) for an
    /// upstream `g = ∂L/∂ξ` at time `t`.
    pub fn backward(&self, t: R, g: [R; 6], grad: &mut [R]) {
        assert_eq!(
            grad.len(),
            self.params.len(),
            "PoseNet::backward: gradient size"
        );
        let (d, h) = (self.settings.input_dim(), self.settings.hidden);
        let (w1, b1, w2, b2) = self.layout();
        let (x, a) = self.hidden(t);
        for o in 0..6 {
            grad[b2 + o] += g[o];
            for j in 0..h {
                grad[w2 + o * h + j] += g[o] * a[j].max(R::ZERO);
            }
        }
        for j in 0..h {
            if a[j] <= R::ZERO {
                continue;
            }
            let gh: R = (0..6).map(|o| self.params[w2 + o * h + j] * g[o]).sum();
            grad[b1 + j] += gh;
            for (gw, &xi) in grad[w1 + j * d..w1 + (j + 1) * d].iter_mut().zip(&x) {
                *gw += gh * xi;
            }
        }
    }
}

impl<R: Real> PoseNet<R> {
    /// Weights `(w_t, w_a, w_b)` of `ξ(t) − (1 − s)·ξ(ta) − s·ξ(tb)`.
    fn anchor_weights(t: R, ta: R, tb: R) -> [(R, R); 3] {
        let s = if tb > ta {
            ((t - ta) / (tb - ta)).max(R::ZERO).min(R::ONE)
        } else {
            R::ZERO
        };
        [(t, R::ONE), (ta, s - R::ONE), (tb, -s)]
    }

    /// The correction at `t` anchored to zero at the neighbouring key times `ta ≤ t ≤ tb`
    /// (where the poses are known): `ξ(t) − (1 − s)·ξ(ta) − s·ξ(tb)`,
    /// `s = (t − ta)/(tb − ta)`. All times normalised.
    pub(crate) fn forward_anchored(&self, t: R, ta: R, tb: R) -> [R; 6] {
        let mut out = [R::ZERO; 6];
        for (tk, w) in Self::anchor_weights(t, ta, tb) {
            let x = self.forward(tk);
            out.iter_mut().zip(x).for_each(|(o, v)| *o += w * v);
        }
        out
    }

    /// [`Self::backward`] of [`Self::forward_anchored`].
    pub(crate) fn backward_anchored(&self, t: R, ta: R, tb: R, g: [R; 6], grad: &mut [R]) {
        for (tk, w) in Self::anchor_weights(t, ta, tb) {
            self.backward(tk, g.map(|x| w * x), grad);
        }
    }
}

/// The corrected pose `T·[Exp(ω) | v]`: `R' = R·Exp(ω)`, `c' = c + R·v`.
pub(crate) fn apply_correction(pose: &Pose, xi: [f64; 6]) -> Pose {
    let (v, w) = split(xi);
    Pose {
        rotation: (pose.rotation * exp_so3(w)).normalize(),
        translation: pose.translation + pose.rotation * v,
    }
}

/// From `∂L/∂ε` (camera-right twist of the *corrected* pose) to `∂L/∂ξ`:
/// `ε_v = Exp(ω)ᵀ·dv`, `ε_ω = J_r(ω)·dω`, so `∂L/∂v = Exp(ω)·g_εv`,
/// `∂L/∂ω = J_r(ω)ᵀ·g_εω` (the identity at `ξ = 0`).
pub(crate) fn correction_backward(xi: [f64; 6], g_eps: [f64; 6]) -> [f64; 6] {
    let (_, w) = split(xi);
    let (gv, gw) = split(g_eps);
    let gv: DVec3 = exp_so3(w) * gv;
    join(gv, right_jacobian(w).transpose() * gw)
}
