//! The opacity `α` of one Gaussian at a pixel and the cut-offs around it, shared by the
//! forward and backward passes and the f64 reference (see the module docs of
//! [`crate::raster`]).

use super::simd::{self, Lanes, Mask};

/// Gaussians with camera depth at or below this are culled.
pub const NEAR: f32 = 0.01;
/// Added to the diagonal of every 2-D covariance (pixels²).
pub const LOW_PASS: f32 = 0.3;
/// Gaussians are evaluated inside `dᵀΣ⁻¹d ≤ SIGMA_CUTOFF²`.
pub const SIGMA_CUTOFF: f32 = 3.0;
/// Largest alpha of one Gaussian at one pixel.
pub const ALPHA_MAX: f32 = 0.99;
/// Contributions below this alpha are skipped.
pub const ALPHA_MIN: f32 = 1.0 / 255.0;
/// Gaussians less opaque than this cannot reach `ALPHA_MIN` and are culled.
pub const CULL_OPACITY: f32 = 1.0 / 255.0;
/// A pixel stops compositing before its transmittance would drop below this.
pub const T_MIN: f32 = 1e-4;

/// `(α, raw)` of a Gaussian with `conic` and opacity `op` at a few pixels with offsets
/// `(dx, dy)` = pixel − mean; `α = 0` outside the 3σ ellipse or where `α < ALPHA_MIN`;
/// `raw = o·G` before the clamp at `ALPHA_MAX` (the clamp stops the gradient). Forward
/// and backward call this same function, so their decisions agree bit for bit.
#[inline(always)]
pub(crate) fn eval_alpha<V: Lanes>(conic: [f32; 3], op: f32, dx: V, dy: V) -> (V, V) {
    let s = V::splat;
    let maha = s(conic[0])
        .mul_add(dx, s(2.0 * conic[1]) * dy)
        .mul_add(dx, s(conic[2]) * dy * dy);
    let raw = s(op) * simd::fast_exp(s(-0.5) * maha);
    let alpha = raw.min(s(ALPHA_MAX));
    let ok = maha
        .le(s(SIGMA_CUTOFF * SIGMA_CUTOFF))
        .and(s(ALPHA_MIN).le(alpha));
    (alpha.and(ok), raw)
}
