//! Initial Gaussians: random points inside the region the cameras look at (Deform-GS
//! synthetic init: random points, random colours, opacity 0.1, identity rotation), and
//! the scene extent (1.1 × the largest camera-centre distance from their mean).

use super::Splats;
use glam::DVec3;
use rand::{RngExt, SeedableRng};
use scene::Camera;

/// 0th-order SH constant: colour = 0.5 + C0 · dc.
pub const SH_C0: f32 = 0.282_094_8;

/// 3DGS camera extent: 1.1 × max distance of a camera centre from their mean.
pub fn camera_extent(cams: &[Camera]) -> f32 {
    let n = cams.len().max(1) as f64;
    let mean = cams.iter().map(|c| c.cam_to_world.centre()).sum::<DVec3>() / n;
    let r = cams
        .iter()
        .map(|c| (c.cam_to_world.centre() - mean).length())
        .fold(0.0, f64::max);
    (1.1 * r).max(1e-3) as f32
}

/// Box the cameras look at: centre = least-squares meeting point of the optical axes,
/// half-size = the smallest camera distance to it × tan(half the horizontal FOV), so
/// every camera sees the whole box. Returns (centre, half-size).
pub fn camera_bounds(cams: &[Camera]) -> (DVec3, f64) {
    let mut a = glam::DMat3::ZERO;
    let mut b = DVec3::ZERO;
    for c in cams {
        let o = c.cam_to_world.centre();
        let d = (c.cam_to_world.rotation * DVec3::NEG_Z).normalize();
        // Σ (I − d dᵀ) x = Σ (I − d dᵀ) o
        let p = glam::DMat3::IDENTITY - glam::DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += p;
        b += p * o;
    }
    let centre = if a.determinant().abs() > 1e-9 {
        a.inverse() * b
    } else {
        // parallel axes: a point in front of the mean camera
        let c = &cams[0];
        c.cam_to_world.centre() + c.cam_to_world.rotation * DVec3::NEG_Z
    };
    let half = cams
        .iter()
        .map(|c| (c.cam_to_world.centre() - centre).length() * (c.intrinsics.fov_x() * 0.5).tan())
        .fold(f64::INFINITY, f64::min);
    (
        centre,
        if half.is_finite() && half > 0.0 {
            half
        } else {
            1.0
        },
    )
}

/// `n` random Gaussians uniform in the cube `centre ± half`. The scale is the expected
/// nearest-neighbour distance of `n` uniform points (≈ 0.55·(V/n)^{1/3}), standing in
/// for 3DGS's mean distance to 3 nearest neighbours.
pub fn random_splats(n: usize, centre: DVec3, half: f64, seed: u64) -> Splats {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let spacing = 0.55 * ((2.0 * half).powi(3) / n.max(1) as f64).cbrt();
    let ls = (spacing as f32).ln();
    let opacity = (0.1f32 / 0.9).ln();
    let mut s = Splats::default();
    for _ in 0..n {
        let p: [f32; 3] =
            std::array::from_fn(|k| (centre[k] + half * rng.random_range(-1.0..1.0)) as f32);
        s.means.push(p);
        s.log_scales.push([ls; 3]);
        s.rotations.push([1.0, 0.0, 0.0, 0.0]);
        s.opacity_logits.push(opacity);
        s.sh_dc.push(std::array::from_fn(|_| {
            (rng.random_range(0.0f32..1.0) - 0.5) / SH_C0
        }));
        s.sh_rest.push([0.0; 45]);
        s.dynamic.push(true);
    }
    s
}

/// `n` random Gaussians inside the train cameras' viewing frusta: a random camera, a
/// random pixel ray, a depth uniform in `[near, far]` (`near`/`far` = `near_frac`/
/// `far_frac` × the camera's distance to the [`camera_bounds`] centre). Covers what the
/// cameras see (walls and floors beyond the box included) with no geometry known.
/// Scale: expected nearest-neighbour spacing of `n` points in one frustum.
pub fn frustum_splats(
    cams: &[Camera],
    n: usize,
    near_frac: f64,
    far_frac: f64,
    seed: u64,
) -> Splats {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (centre, _) = camera_bounds(cams);
    let opacity = (0.1f32 / 0.9).ln();
    let mut s = Splats::default();
    if cams.is_empty() {
        return s;
    }
    let c0 = &cams[0];
    let d0 = (c0.cam_to_world.centre() - centre).length().max(1e-3);
    let (near0, far0) = (near_frac * d0, far_frac * d0);
    let i0 = &c0.intrinsics;
    let (tx, ty) = (
        i0.width as f64 / (2.0 * i0.fx),
        i0.height as f64 / (2.0 * i0.fy),
    );
    let volume = 4.0 * tx * ty * (far0.powi(3) - near0.powi(3)) / 3.0;
    let ls = ((0.55 * (volume / n.max(1) as f64).cbrt()) as f32).ln();
    for _ in 0..n {
        let cam = &cams[rng.random_range(0..cams.len())];
        let d = (cam.cam_to_world.centre() - centre).length().max(1e-3);
        let i = &cam.intrinsics;
        let px = glam::DVec2::new(
            rng.random_range(0.0..i.width as f64),
            rng.random_range(0.0..i.height as f64),
        );
        let depth = rng.random_range(near_frac * d..far_frac * d);
        let p = cam.unproject_world(px, depth);
        s.means.push([p.x as f32, p.y as f32, p.z as f32]);
        s.log_scales.push([ls; 3]);
        s.rotations.push([1.0, 0.0, 0.0, 0.0]);
        s.opacity_logits.push(opacity);
        s.sh_dc.push(std::array::from_fn(|_| {
            (rng.random_range(0.0f32..1.0) - 0.5) / SH_C0
        }));
        s.sh_rest.push([0.0; 45]);
        s.dynamic.push(true);
    }
    s
}
