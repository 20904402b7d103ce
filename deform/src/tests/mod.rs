//! Tests of the kernels: values on hand-made cases and every backward against central
//! finite differences in `f64`.

mod camera_path;
mod contrast;
mod events;
mod fallbacks;
mod flow;
mod motion;
mod posenet;
mod rate_outliers;

use glam::{DQuat, DVec3};
use scene::Pose;

/// A deterministic generator for test inputs (SplitMix64).
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[a, b)`.
    pub fn uniform(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub(crate) fn vec3(&mut self, s: f64) -> DVec3 {
        DVec3::new(
            self.uniform(-s, s),
            self.uniform(-s, s),
            self.uniform(-s, s),
        )
    }
    pub fn pose(&mut self, rot: f64, trans: f64) -> Pose {
        Pose::new(DQuat::from_scaled_axis(self.vec3(rot)), self.vec3(trans))
    }
}

/// Central finite difference of `f` along coordinate `i` of `x` with step `h`.
pub fn fd(x: &[f64], i: usize, h: f64, mut f: impl FnMut(&[f64]) -> f64) -> f64 {
    let mut xp = x.to_vec();
    xp[i] += h;
    let fp = f(&xp);
    xp[i] = x[i] - h;
    let fm = f(&xp);
    (fp - fm) / (2.0 * h)
}

/// Central finite-difference gradient of `f` at `x`.
pub(crate) fn fd_grad(x: &[f64], h: f64, mut f: impl FnMut(&[f64]) -> f64) -> Vec<f64> {
    (0..x.len()).map(|i| fd(x, i, h, &mut f)).collect()
}

/// Assert `|a − b| ≤ rel·max(|a|, |b|) + abs` element-wise, naming `what` and the index.
#[track_caller]
pub(crate) fn assert_close(what: &str, a: &[f64], b: &[f64], rel: f64, abs: f64) {
    assert_eq!(a.len(), b.len(), "{what}: lengths differ");
    for (i, (&x, &y)) in a.iter().zip(b).enumerate() {
        let tol = rel * x.abs().max(y.abs()) + abs;
        assert!(
            (x - y).abs() <= tol && x.is_finite() && y.is_finite(),
            "{what}[{i}]: {x} vs {y} (|diff| {:.3e} > tol {tol:.3e})",
            (x - y).abs()
        );
    }
}
