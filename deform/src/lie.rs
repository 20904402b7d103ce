//! Rotations and rigid motions in `f64`: SO(3) exponential and logarithm, their
//! Jacobians, and the pose perturbation every pose gradient of degs is expressed in.
//!
//! A pose is `scene::Pose` (camera-to-world: rotation `R`, camera centre `c`, OpenGL
//! camera axes). A *pose gradient* is a `[f64; 6]` ordered `[v_x, v_y, v_z, ω_x, ω_y,
//! ω_z]`: the derivative of a loss with respect to a small twist `ε = (v, ω)` at zero
//! of the **camera-right** perturbation `R' = R·Exp(ω)`, `c' = c + R·v`, i.e.
//! `T' = T·[Exp(ω) | v]`: the camera rotates about its own centre and moves by `v`,
//! both expressed in its own (OpenGL) axes ([`perturb_camera_right`]; the `gaussians`
//! rasterizer's `raster::apply_twist` is the same perturbation, so its camera gradient
//! enters the PoseNet as it is).

use glam::{DMat3, DQuat, DVec3};
use scene::Pose;

/// `[v]×`, the matrix with `[v]× x = v × x`.
pub fn skew(v: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, v.z, -v.y),
        DVec3::new(-v.z, 0.0, v.x),
        DVec3::new(v.y, -v.x, 0.0),
    )
}

/// SO(3) exponential (Rodrigues' formula, as a unit quaternion); accurate for tiny angles.
pub(crate) fn exp_so3(w: DVec3) -> DQuat {
    let th2 = w.length_squared();
    let th = th2.sqrt();
    // sin(θ/2)/θ and cos(θ/2), with their series below 1e-4 rad.
    let (s, c) = if th < 1e-4 {
        (0.5 - th2 / 48.0, 1.0 - th2 / 8.0)
    } else {
        ((0.5 * th).sin() / th, (0.5 * th).cos())
    };
    DQuat::from_xyzw(w.x * s, w.y * s, w.z * s, c).normalize()
}

/// SO(3) logarithm: the rotation vector of `q` with angle in `[0, π]`.
pub(crate) fn log_so3(q: DQuat) -> DVec3 {
    let q = q.normalize();
    let q = if q.w < 0.0 { -q } else { q };
    let xyz = DVec3::new(q.x, q.y, q.z);
    let n2 = xyz.length_squared();
    let n = n2.sqrt();
    let scale = if n < 1e-6 {
        // θ/n = 2·atan(n/w)/n ≈ 2/w − 2n²/(3w³)
        2.0 / q.w - 2.0 * n2 / (3.0 * q.w * q.w * q.w)
    } else {
        2.0 * n.atan2(q.w) / n
    };
    xyz * scale
}

/// Right Jacobian of SO(3): `Exp(φ + δ) ≈ Exp(φ)·Exp(J_r(φ)·δ)`.
pub(crate) fn right_jacobian(phi: DVec3) -> DMat3 {
    let th2 = phi.length_squared();
    let th = th2.sqrt();
    let (a, b) = if th < 1e-4 {
        (0.5 - th2 / 24.0, 1.0 / 6.0 - th2 / 120.0)
    } else {
        ((1.0 - th.cos()) / th2, (th - th.sin()) / (th2 * th))
    };
    let k = skew(phi);
    DMat3::IDENTITY - k * a + k * k * b
}

/// Left Jacobian of SO(3): `Exp(φ + δ) ≈ Exp(J_l(φ)·δ)·Exp(φ)`; `J_l(φ) = J_r(−φ)`.
pub fn left_jacobian(phi: DVec3) -> DMat3 {
    right_jacobian(-phi)
}

/// Inverse of [`right_jacobian`]: `Exp(φ)·Exp(δ) ≈ Exp(φ + J_r⁻¹(φ)·δ)`. Singular at
/// `|φ| = 2π`; fine for the angles between nearby poses.
pub(crate) fn right_jacobian_inv(phi: DVec3) -> DMat3 {
    let th2 = phi.length_squared();
    let th = th2.sqrt();
    let c = if th < 1e-4 {
        1.0 / 12.0 + th2 / 720.0
    } else {
        1.0 / th2 - (1.0 + th.cos()) / (2.0 * th * th.sin())
    };
    let k = skew(phi);
    DMat3::IDENTITY + k * 0.5 + k * k * c
}

/// Inverse of [`left_jacobian`]: `Exp(δ)·Exp(φ) ≈ Exp(φ + J_l⁻¹(φ)·δ)`.
pub(crate) fn left_jacobian_inv(phi: DVec3) -> DMat3 {
    right_jacobian_inv(-phi)
}

/// Split a twist `[v, ω]` into its two halves.
pub fn split(t: [f64; 6]) -> (DVec3, DVec3) {
    (DVec3::new(t[0], t[1], t[2]), DVec3::new(t[3], t[4], t[5]))
}

/// Join two halves into a twist `[v, ω]`.
pub fn join(v: DVec3, w: DVec3) -> [f64; 6] {
    [v.x, v.y, v.z, w.x, w.y, w.z]
}

/// `T·[Exp(ω) | v]`: `R' = R·Exp(ω)`, `c' = c + R·v` (camera-frame twist).
pub fn perturb_camera_right(pose: &Pose, eps: [f64; 6]) -> Pose {
    let (v, w) = split(eps);
    Pose {
        rotation: (pose.rotation * exp_so3(w)).normalize(),
        translation: pose.translation + pose.rotation * v,
    }
}
