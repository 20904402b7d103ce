//! Procedural solid textures: evaluated at a material point, so they stick to the
//! surface through rigid motion and deformation. Edges between the two colours are
//! sharp (events and flow are rich there); an optional smooth value-noise factor adds
//! low-contrast detail inside the regions.

use crate::config::{Pattern, Texture};
use glam::DVec3;

/// Direction of the stripes (oblique, so both image axes see motion).
const STRIPE_DIR: DVec3 = DVec3::new(0.8, 0.5, 0.33);

/// Integer lattice hash → [0, 1).
fn hash3(x: i64, y: i64, z: i64, seed: u32) -> f64 {
    let mut h = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (z as u64).wrapping_mul(0x1656_67B1_9E37_79F9)
        ^ (seed as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93);
    // splitmix64 finaliser
    h ^= h >> 30;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 27;
    h = h.wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^= h >> 31;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Smooth 3-D value noise in [0, 1] (trilinear with a quintic fade).
pub(crate) fn value_noise(p: DVec3, seed: u32) -> f64 {
    let f = p.floor();
    let (ix, iy, iz) = (f.x as i64, f.y as i64, f.z as i64);
    let r = p - f;
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (u, v, w) = (fade(r.x), fade(r.y), fade(r.z));
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let c = |dx: i64, dy: i64, dz: i64| hash3(ix + dx, iy + dy, iz + dz, seed);
    let x00 = lerp(c(0, 0, 0), c(1, 0, 0), u);
    let x10 = lerp(c(0, 1, 0), c(1, 1, 0), u);
    let x01 = lerp(c(0, 0, 1), c(1, 0, 1), u);
    let x11 = lerp(c(0, 1, 1), c(1, 1, 1), u);
    lerp(lerp(x00, x10, v), lerp(x01, x11, v), w)
}

/// Linear RGB of `tex` at material point `q`.
pub(crate) fn shade(tex: &Texture, q: DVec3) -> [f64; 3] {
    let s = q / tex.cell;
    let first = match tex.pattern {
        Pattern::Checker => {
            let f = (s + DVec3::splat(0.5)).floor();
            (f.x as i64 + f.y as i64 + f.z as i64).rem_euclid(2) == 0
        }
        Pattern::Stripes => (s.dot(STRIPE_DIR.normalize()).floor() as i64).rem_euclid(2) == 0,
        Pattern::Blobs => value_noise(s, tex.seed) > 0.5,
    };
    let base = if first { tex.colour_a } else { tex.colour_b };
    let k = if tex.detail > 0.0 {
        1.0 - tex.detail * value_noise(s * 0.37 + DVec3::splat(17.3), tex.seed ^ 0x5bd1)
    } else {
        1.0
    };
    [
        (base[0] * k).clamp(0.0, 1.0),
        (base[1] * k).clamp(0.0, 1.0),
        (base[2] * k).clamp(0.0, 1.0),
    ]
}
