//! Random test scenes shared by the rasterizer tests.
#![allow(dead_code)]

use gaussians::{Gaussian, Splats};
use glam::DVec3;
use scene::{Camera, Intrinsics, Pose};

/// SplitMix64: a tiny deterministic generator (tests only).
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [lo, hi).
    pub fn uni(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn uf(&mut self, lo: f64, hi: f64) -> f32 {
        self.uni(lo, hi) as f32
    }
}

/// A camera at `eye` looking at the origin, `w×h`, focal `f`, slightly off-centre
/// principal point.
pub fn camera(w: u32, h: u32, f: f64, eye: DVec3) -> Camera {
    Camera {
        intrinsics: Intrinsics {
            width: w,
            height: h,
            fx: f,
            fy: f * 1.05,
            cx: w as f64 * 0.5 - 0.3,
            cy: h as f64 * 0.5 + 0.2,
            distortion: None,
        },
        cam_to_world: Pose::look_at(eye, DVec3::new(0.1, -0.05, 0.0), DVec3::Y),
    }
}

/// What a random scene should exercise.
#[derive(Clone, Copy, Debug)]
pub struct SceneKind {
    pub n: usize,
    /// Half-size of the box the means are drawn from.
    pub spread: f64,
    /// Range of log-scales.
    pub log_scale: (f64, f64),
    /// Range of opacity logits.
    pub logit: (f64, f64),
    /// Scale of the higher SH coefficients.
    pub sh_rest: f64,
}

/// Eight Gaussians a few pixels to ten wide in front of [`smooth_camera`], SH degree 0:
/// a rendered loss is smooth in every parameter (the gradient checks of a trainer).
#[allow(dead_code)]
pub const SMOOTH: SceneKind = SceneKind {
    n: 8,
    spread: 1.2,
    log_scale: (-2.6, -1.4),
    logit: (-0.5, 1.2),
    sh_rest: 0.0,
};

/// The 37 × 29 camera the gradient checks render [`SMOOTH`] scenes with.
#[allow(dead_code)]
pub fn smooth_camera() -> Camera {
    camera(37, 29, 34.0, DVec3::new(0.1, 0.3, 4.0))
}

/// Random Gaussians around the origin (camera at distance ≈ 4 on +Z).
pub fn random_splats(rng: &mut Rng, k: SceneKind) -> Splats {
    (0..k.n)
        .map(|_| Gaussian {
            mean: std::array::from_fn(|_| rng.uf(-k.spread, k.spread)),
            log_scale: std::array::from_fn(|_| rng.uf(k.log_scale.0, k.log_scale.1)),
            rotation: std::array::from_fn(|_| rng.uf(-1.0, 1.0)),
            opacity_logit: rng.uf(k.logit.0, k.logit.1),
            sh_dc: std::array::from_fn(|_| rng.uf(-1.2, 1.2)),
            sh_rest: std::array::from_fn(|_| rng.uf(-k.sh_rest, k.sh_rest)),
            dynamic: false,
        })
        .collect()
}

/// Append one Gaussian with the given mean (isotropic scale, fixed colour).
pub fn push_gaussian(s: &mut Splats, mean: [f32; 3], log_scale: f32, logit: f32) {
    s.push(Gaussian::isotropic(
        mean,
        log_scale,
        logit,
        [0.5, -0.2, 0.1],
    ));
}

pub fn max_abs_diff(a: &[f32], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(&x, &y)| (x as f64 - y).abs())
        .fold(0.0, f64::max)
}
