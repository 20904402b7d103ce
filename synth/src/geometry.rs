//! Ray–surface geometry of the analytic world in material coordinates: the travelling
//! wave of a plane, ray intersections with planes, boxes, ellipsoids and waving planes,
//! and where a hit evaluates its solid texture.

use crate::config::Shape;
use glam::DVec3;

/// The travelling wave of a plane at one time:
/// `h(x, y) = amplitude·sin(kx·x − phase)·cos(ky·y)`, `∂h/∂t = −rate·amplitude·cos(kx·x − phase)·cos(ky·y)`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Wave {
    pub(crate) amplitude: f64,
    pub(crate) kx: f64,
    pub(crate) ky: f64,
    pub(crate) phase: f64,
    pub(crate) rate: f64,
}

impl Wave {
    pub(crate) fn height(&self, x: f64, y: f64) -> f64 {
        self.amplitude * (self.kx * x - self.phase).sin() * (self.ky * y).cos()
    }

    pub(crate) fn height_rate(&self, x: f64, y: f64) -> f64 {
        -self.rate * self.amplitude * (self.kx * x - self.phase).cos() * (self.ky * y).cos()
    }
}

/// Smallest ray parameter `s ∈ (ε, limit)` where `o + s·d` (material space) meets the
/// shape.
pub(crate) fn intersect(shape: &Shape, o: DVec3, d: DVec3, limit: f64) -> Option<f64> {
    const EPS: f64 = 1e-9;
    let s = match shape {
        Shape::Plane { half_size } => {
            if d.z.abs() < 1e-15 {
                return None;
            }
            let s = -o.z / d.z;
            let p = o + d * s;
            let inside = |c: f64, h: f64| h <= 0.0 || c.abs() <= h;
            if !(inside(p.x, half_size[0]) && inside(p.y, half_size[1])) {
                return None;
            }
            s
        }
        Shape::Cuboid { half_size } => {
            // Slab method.
            let inv = d.recip();
            let t1 = (-*half_size - o) * inv;
            let t2 = (*half_size - o) * inv;
            let near = t1.min(t2).max_element();
            let far = t1.max(t2).min_element();
            if near > far || far <= EPS {
                return None;
            }
            if near > EPS { near } else { far }
        }
        Shape::Ellipsoid { radii } => {
            let (oe, de) = (o / *radii, d / *radii);
            let a = de.length_squared();
            let b = oe.dot(de);
            let c = oe.length_squared() - 1.0;
            let disc = b * b - a * c;
            if disc < 0.0 {
                return None;
            }
            let sq = disc.sqrt();
            let near = (-b - sq) / a;
            if near > EPS { near } else { (-b + sq) / a }
        }
    };
    (s > EPS && s < limit && s.is_finite()).then_some(s)
}

/// First crossing of the ray `o + s·d` (space before `S`, i.e. `S⁻¹Rᵀ` applied) with
/// the waving plane `z = h(x, y)` inside the rectangle; returns the ray parameter and
/// the material point `(x, y, 0)`. The crossing lies in the slab `|z| ≤ amplitude`:
/// march 32 steps through it, then bisect the first sign change to machine precision.
pub(crate) fn intersect_wave(
    half_size: [f64; 2],
    w: &Wave,
    o: DVec3,
    d: DVec3,
    limit: f64,
) -> Option<(f64, DVec3)> {
    const EPS: f64 = 1e-9;
    const STEPS: usize = 32;
    if d.z.abs() < 1e-12 {
        return None;
    }
    let a = w.amplitude.abs();
    let (s1, s2) = ((-a - o.z) / d.z, (a - o.z) / d.z);
    let (lo, hi) = (s1.min(s2).max(EPS), s1.max(s2).min(limit));
    if lo.is_nan() || hi.is_nan() || lo >= hi {
        return None;
    }
    // Whole slab segment outside the rectangle on one side: no hit.
    for (axis, h) in [(0, half_size[0]), (1, half_size[1])] {
        let (c0, c1) = (o[axis] + d[axis] * lo, o[axis] + d[axis] * hi);
        if h > 0.0 && ((c0 > h && c1 > h) || (c0 < -h && c1 < -h)) {
            return None;
        }
    }
    let g = |s: f64| {
        let p = o + d * s;
        p.z - w.height(p.x, p.y)
    };
    let inside = |p: DVec3| {
        (half_size[0] <= 0.0 || p.x.abs() <= half_size[0])
            && (half_size[1] <= 0.0 || p.y.abs() <= half_size[1])
    };
    let (mut s_prev, mut g_prev) = (lo, g(lo));
    for i in 1..=STEPS {
        let s_next = lo + (hi - lo) * i as f64 / STEPS as f64;
        let g_next = g(s_next);
        if g_prev == 0.0 || g_prev.signum() != g_next.signum() {
            let (mut a_s, mut b_s, mut g_a) = (s_prev, s_next, g_prev);
            for _ in 0..64 {
                let m = 0.5 * (a_s + b_s);
                let g_m = g(m);
                if g_m == 0.0 {
                    (a_s, b_s) = (m, m);
                    break;
                }
                if g_m.signum() == g_a.signum() {
                    (a_s, g_a) = (m, g_m);
                } else {
                    b_s = m;
                }
            }
            let s = 0.5 * (a_s + b_s);
            let p = o + d * s;
            if inside(p) {
                return Some((s, DVec3::new(p.x, p.y, 0.0)));
            }
        }
        (s_prev, g_prev) = (s_next, g_next);
    }
    None
}

/// Where the solid texture is evaluated: planes and ellipsoids use the material point;
/// a box face uses its two in-face coordinates plus a per-face offset (so faces differ
/// and the exact face coordinate, which is noisy in the last bits, is not used).
pub(crate) fn texture_coords(shape: &Shape, q: DVec3) -> DVec3 {
    match shape {
        Shape::Cuboid { half_size } => {
            let r = (q / *half_size).abs();
            let axis = if r.x >= r.y && r.x >= r.z {
                0
            } else if r.y >= r.z {
                1
            } else {
                2
            };
            let mut c = q;
            let face = 2.0 * axis as f64 + if q[axis] > 0.0 { 1.0 } else { 0.0 };
            c[axis] = 0.37 * face;
            c
        }
        _ => q,
    }
}
