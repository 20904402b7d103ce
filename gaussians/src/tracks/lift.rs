//! A 2D track to 3D: triangulated as a still point when its rays meet, else fitted with
//! the quadratic trajectory of [`crate::motion`] (trajectory triangulation, Avidan &
//! Shashua 2000), with a penalty on the acceleration.
//!
//! Each observation `(c_k, d_k)` (camera centre, unit ray) at time `τ_k` asks for
//! `P_k (X(τ_k) − c_k) = 0`, `P_k = I − d_k d_kᵀ`; rows are divided by the point's
//! depth so that they are angles. A still point: `X(τ) = X`, 3 unknowns. A moving one:
//! `X(τ) = μ + v·τ + a·τ²`, 9 unknowns, plus `ridge · |a|² / depth²`.
//!
//! Why the penalty: with one camera a moving point's distance is known only where the
//! camera's own path leaves the trajectory's span. A camera path that is itself close
//! to a quadratic over the recording (a smooth sway) lets a family `C(τ) + s (X(τ) −
//! C(τ))` fit every observation; the penalty picks the member with the smallest
//! acceleration (Park et al., ECCV 2010, on when trajectories are reconstructible).

use glam::{DMat3, DVec2, DVec3};
use scene::Camera;

/// What a track lifts to, positions at `τ = 0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lifted {
    Still(DVec3),
    Moving { mu: DVec3, v: DVec3, a: DVec3 },
}

impl Lifted {
    pub fn at(&self, tau: f64) -> DVec3 {
        match *self {
            Lifted::Still(x) => x,
            Lifted::Moving { mu, v, a } => mu + v * tau + a * tau * tau,
        }
    }
}

/// One observation: the camera, the pixel, and `τ = t − T0` of the frame; with a
/// depth prior, the point's camera-space depth there (`tracks::depth`).
pub struct Observation<'a> {
    pub camera: &'a Camera,
    pub pixel: DVec2,
    pub tau: f64,
    pub depth: Option<f64>,
}

/// Root-mean-square reprojection error (pixels) of a lifted point over the
/// observations; infinite when it falls behind a camera.
pub fn rms_pixels(l: &Lifted, obs: &[Observation]) -> f64 {
    let mut e = 0.0;
    for o in obs {
        match o.camera.project_world(l.at(o.tau)) {
            Some((q, d)) if d > 0.0 => e += (q - o.pixel).length_squared(),
            _ => return f64::INFINITY,
        }
    }
    (e / obs.len().max(1) as f64).sqrt()
}

fn ray(o: &Observation) -> (DVec3, DMat3) {
    let c = o.camera.cam_to_world.centre();
    let d = (o.camera.unproject_world(o.pixel, 1.0) - c).normalize();
    (
        c,
        DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z),
    )
}

/// The point nearest all rays (least squares); `None` for parallel rays.
pub fn still(obs: &[Observation]) -> Option<DVec3> {
    let (mut m, mut b) = (DMat3::ZERO, DVec3::ZERO);
    for o in obs {
        let (c, p) = ray(o);
        m += p;
        b += p * c;
    }
    (m.determinant().abs() > 1e-12)
        .then(|| m.inverse() * b)
        .filter(|x| x.is_finite())
}

/// The quadratic trajectory through the rays, rows weighted by `1 / depth²` of `guess`
/// (a still triangulation); `None` when the system is singular.
///
/// With `depth_sigma > 0`, each observation with a depth `z` adds the row `fᵀ(X(τ) − c)
/// = z` (`f` the camera's forward axis), weighted so that a relative depth error of
/// `depth_sigma` costs as much as one pixel of reprojection error: `1 / (f_x σ z)²`
/// against the rays' `1 / depth²` (their residual, divided by the depth, is an angle,
/// a pixel being `1 / f_x` of it). These rows fix the distance the rays leave free.
pub fn moving(obs: &[Observation], guess: DVec3, ridge: f64, depth_sigma: f64) -> Option<Lifted> {
    let x = fit::<9>(obs, guess, ridge, depth_sigma)?;
    Some(Lifted::Moving {
        mu: DVec3::new(x[0], x[1], x[2]),
        v: DVec3::new(x[3], x[4], x[5]),
        a: DVec3::new(x[6], x[7], x[8]),
    })
}

/// The still point nearest the rays and the observations' depths, weighted as in
/// [`moving`]: where the cameras are close together the rays alone leave the distance
/// loose (their meeting point may lie far off the prior though a point at the prior's
/// depth fits them as well); the depth rows fix it. `None` when the system is singular.
pub fn still_with_depth(obs: &[Observation], guess: DVec3, depth_sigma: f64) -> Option<DVec3> {
    let x = fit::<3>(obs, guess, 0.0, depth_sigma)?;
    Some(DVec3::new(x[0], x[1], x[2]))
}

/// Least squares for `X(τ) = Σ_j x_j τ^j`, `N / 3` coefficients (3: a still point, 9: a
/// quadratic), the ridge on the last three (the acceleration of a quadratic).
fn fit<const N: usize>(
    obs: &[Observation],
    guess: DVec3,
    ridge: f64,
    depth_sigma: f64,
) -> Option<[f64; N]> {
    let mut m = [[0.0f64; N]; N];
    let mut b = [0.0f64; N];
    let mut depth2 = 0.0;
    let mut add = |w: f64, r: DVec3, rhs: f64, t: f64| {
        let co: [f64; N] = std::array::from_fn(|u| r[u % 3] * t.powi((u / 3) as i32));
        for u in 0..N {
            b[u] += w * co[u] * rhs;
            for (q, cq) in co.iter().enumerate() {
                m[u][q] += w * co[u] * cq;
            }
        }
    };
    for o in obs {
        let (c, p) = ray(o);
        let w = 1.0 / (guess - c).length_squared().max(1e-12);
        depth2 += (guess - c).length_squared() / obs.len() as f64;
        let t = o.tau;
        if let Some(z) = o.depth.filter(|z| depth_sigma > 0.0 && *z > 0.0) {
            let f = o.camera.cam_to_world.rotation * DVec3::NEG_Z;
            let fx = o.camera.intrinsics.fx;
            add(1.0 / (fx * depth_sigma * z).powi(2), f, z + f.dot(c), t);
        }
        for i in 0..3 {
            let r = p.row(i);
            add(w, r, r.dot(c), t);
        }
    }
    if N > 3 {
        for (u, row) in m.iter_mut().enumerate().skip(N - 3) {
            row[u] += ridge / depth2.max(1e-12);
        }
    }
    solve(m, b)
}

/// Gaussian elimination with partial pivoting.
fn solve<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    let scale = (0..N)
        .map(|i| a[i][i].abs())
        .fold(0.0, f64::max)
        .max(1e-300);
    for c in 0..N {
        let p = (c..N).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-14 * scale {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in 0..N {
            if r != c {
                let f = a[r][c] / a[c][c];
                let pivot_row = a[c];
                for (x, y) in a[r].iter_mut().zip(pivot_row) {
                    *x -= f * y;
                }
                b[r] -= f * b[c];
            }
        }
    }
    let x: [f64; N] = std::array::from_fn(|i| b[i] / a[i][i]);
    x.iter().all(|v| v.is_finite()).then_some(x)
}
