//! The camera at any time between the train frames, and its velocity.
//!
//! [`CameraPath`] interpolates the train frames' camera-to-world poses:
//! - **rotation**: slerp between the two neighbouring frames, written as
//!   `R(t) = R_i·Exp(s·φ_i)` with `φ_i = Log(R_iᵀ·R_{i+1})` (shortest arc) and
//!   `s = (t − t_i)/(t_{i+1} − t_i)`;
//! - **translation** (camera centre): linear ([`Interp::Linear`], the default) or a cubic
//!   Hermite spline with Catmull-Rom tangents ([`Interp::CatmullRom`]: non-uniform
//!   finite-difference tangents `m_i = (c_{i+1} − c_{i−1})/(t_{i+1} − t_{i−1})`,
//!   one-sided at the two ends), which passes through every frame with a continuous
//!   velocity;
//! - outside `[t_first, t_last]` the end pose is held (clamped) and the velocity is zero.
//! - Frames that share a timestamp are merged into one key before anything else (mean
//!   centre, rotation mean by incremental slerp), so no segment has zero length and
//!   nothing divides by zero.
//!
//! **Velocity** ([`CameraVelocity`]): the camera's linear velocity `v = Rᵀ·ċ` and its
//! angular velocity `ω` with `Ṙ = R·[ω]×`, both in the camera frame (OpenGL axes: x right,
//! y up, z backwards), in m/s (scene units/s) and rad/s. [`CameraPath::velocity_at`] is
//! **analytic** from the interpolation (`ω = φ_i/(t_{i+1} − t_i)`, constant per segment;
//! `ċ` the derivative of the lerp or the Hermite cubic); at a key it is the velocity of
//! the segment that starts there (of the last segment at the last key).
//!
//! For a path that has no closed-form derivative (the PoseNet-corrected one),
//! [`velocity_between`] is the **symmetric difference** of two poses `h` apart: `ω =
//! Log(R_aᵀR_b)/h` and `v = R_midᵀ·(c_b − c_a)/h` with `R_mid = R_a·Exp(½·Log(R_aᵀR_b))`;
//! exact for a screw motion at constant speed (such as one slerp + lerp segment),
//! second-order in `h` otherwise. [`velocity_between_backward`] gives its gradient with
//! respect to the two poses (camera-right twists, see [`crate::lie`]).
//!
//! A static world point `X` has camera coordinates `P = Rᵀ(X − c)` moving at
//! `Ṗ = −v − ω × P`, the relation Eq. 9 rests on.

use crate::lie::{
    exp_so3, join, left_jacobian_inv, log_so3, right_jacobian, right_jacobian_inv, skew, split,
};
use glam::DVec3;
use scene::{Pose, Trajectory};
use serde::{Deserialize, Serialize};

/// How the camera centre is interpolated between frames (rotation is always slerp).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Interp {
    /// Piecewise linear (the paper's "interpolated poses").
    #[default]
    Linear,
    /// Cubic Hermite with Catmull-Rom tangents.
    CatmullRom,
}

/// Camera velocity in the camera frame (OpenGL axes): `v = Rᵀ·ċ`, `Ṙ = R·[ω]×`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraVelocity {
    /// Linear velocity, scene units per second.
    pub v: DVec3,
    /// Angular velocity, radians per second.
    pub w: DVec3,
}

impl CameraVelocity {
    pub const ZERO: CameraVelocity = CameraVelocity {
        v: DVec3::ZERO,
        w: DVec3::ZERO,
    };

    /// As a twist `[v_x, v_y, v_z, ω_x, ω_y, ω_z]`.
    pub fn to_array(&self) -> [f64; 6] {
        join(self.v, self.w)
    }

    pub fn from_array(a: [f64; 6]) -> Self {
        let (v, w) = split(a);
        CameraVelocity { v, w }
    }
}

/// Camera poses of the train frames, interpolated in time.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraPath {
    times: Vec<f64>,
    poses: Vec<Pose>,
    interp: Interp,
    /// Per segment `i`: `Log(R_iᵀ·R_{i+1})`.
    phi: Vec<DVec3>,
    /// Per key: centre tangent `dc/dt` (cubic only; empty for linear).
    tangents: Vec<DVec3>,
}

impl CameraPath {
    /// From frame times (seconds, any order) and camera-to-world poses. `Err` when the
    /// lengths differ, the list is empty, or a time or pose is not finite. Frames at the
    /// same time are merged into one key (see the module docs).
    pub fn new(times: &[f64], poses: &[Pose], interp: Interp) -> Result<Self, String> {
        if times.len() != poses.len() {
            return Err(format!("{} times but {} poses", times.len(), poses.len()));
        }
        if times.is_empty() {
            return Err("a camera path needs at least one frame".into());
        }
        for (i, (t, p)) in times.iter().zip(poses).enumerate() {
            if !t.is_finite() || !p.translation.is_finite() || !p.rotation.is_finite() {
                return Err(format!("frame {i}: time or pose is not finite"));
            }
            if p.rotation.length_squared() < 1e-12 {
                return Err(format!("frame {i}: rotation quaternion is zero"));
            }
        }
        let mut order: Vec<usize> = (0..times.len()).collect();
        order.sort_by(|&a, &b| times[a].total_cmp(&times[b]));
        let mut kt: Vec<f64> = Vec::with_capacity(times.len());
        let mut kp: Vec<Pose> = Vec::with_capacity(times.len());
        let mut group = 0usize; // frames merged into the last key so far
        for &i in &order {
            let p = Pose::new(poses[i].rotation, poses[i].translation);
            if kt.last() == Some(&times[i]) {
                group += 1;
                let k = kp.last_mut().expect("key exists");
                let f = 1.0 / group as f64;
                k.translation += (p.translation - k.translation) * f;
                let d = log_so3(k.rotation.inverse() * p.rotation);
                k.rotation = (k.rotation * exp_so3(d * f)).normalize();
            } else {
                kt.push(times[i]);
                kp.push(p);
                group = 1;
            }
        }
        let phi = kp
            .windows(2)
            .map(|w| log_so3(w[0].rotation.inverse() * w[1].rotation))
            .collect();
        let tangents = match interp {
            Interp::Linear => Vec::new(),
            Interp::CatmullRom => {
                let n = kt.len();
                (0..n)
                    .map(|i| {
                        if n == 1 {
                            return DVec3::ZERO;
                        }
                        let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
                        (kp[b].translation - kp[a].translation) / (kt[b] - kt[a])
                    })
                    .collect()
            }
        };
        Ok(CameraPath {
            times: kt,
            poses: kp,
            interp,
            phi,
            tangents,
        })
    }

    /// From a `scene::Trajectory` (whose times are strictly increasing).
    pub(crate) fn from_trajectory(tr: &Trajectory, interp: Interp) -> Result<Self, String> {
        Self::new(&tr.times, &tr.poses, interp)
    }

    /// Key times after merging equal ones (increasing).
    pub fn times(&self) -> &[f64] {
        &self.times
    }

    /// Key poses (normalised rotations), one per [`Self::times`].
    pub fn poses(&self) -> &[Pose] {
        &self.poses
    }

    pub fn interp(&self) -> Interp {
        self.interp
    }

    /// `(t_first, t_last)`.
    pub(crate) fn time_range(&self) -> (f64, f64) {
        (self.times[0], self.times[self.times.len() - 1])
    }

    /// `t` mapped to `[0, 1]` over the key times, clamped (0 for a single key): the
    /// input of the PoseNet.
    pub(crate) fn normalised_time(&self, t: f64) -> f64 {
        let (a, b) = self.time_range();
        if b > a && t.is_finite() {
            ((t - a) / (b - a)).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// The key times `(ta, tb)` of the segment holding `t` (`None` outside the covered
    /// time, for a single key or a NaN time).
    pub(crate) fn bracket(&self, t: f64) -> Option<(f64, f64)> {
        self.segment(t)
            .map(|(i, _)| (self.times[i], self.times[i + 1]))
    }

    /// Segment `i` and fraction `s ∈ [0, 1]` of `t`, or `None` outside the covered time
    /// (or for a single key, or a NaN time).
    fn segment(&self, t: f64) -> Option<(usize, f64)> {
        let n = self.times.len();
        if n < 2 || !(t >= self.times[0] && t <= self.times[n - 1]) {
            return None;
        }
        let i = (self.times.partition_point(|&k| k <= t) - 1).min(n - 2);
        let dt = self.times[i + 1] - self.times[i];
        Some((i, ((t - self.times[i]) / dt).clamp(0.0, 1.0)))
    }

    /// The camera-to-world pose at `t` (held at the end poses outside the frames' time).
    pub fn pose_at(&self, t: f64) -> Pose {
        let n = self.times.len();
        let Some((i, s)) = self.segment(t) else {
            return if n > 1 && t > self.times[n - 1] {
                self.poses[n - 1]
            } else {
                self.poses[0]
            };
        };
        if s == 0.0 {
            return self.poses[i];
        }
        let (a, b) = (&self.poses[i], &self.poses[i + 1]);
        let rotation = (a.rotation * exp_so3(self.phi[i] * s)).normalize();
        let translation = match self.interp {
            Interp::Linear => a.translation.lerp(b.translation, s),
            Interp::CatmullRom => {
                let dt = self.times[i + 1] - self.times[i];
                let (s2, s3) = (s * s, s * s * s);
                a.translation * (2.0 * s3 - 3.0 * s2 + 1.0)
                    + self.tangents[i] * (dt * (s3 - 2.0 * s2 + s))
                    + b.translation * (-2.0 * s3 + 3.0 * s2)
                    + self.tangents[i + 1] * (dt * (s3 - s2))
            }
        };
        Pose {
            rotation,
            translation,
        }
    }

    /// Analytic camera velocity at `t` in the camera frame (zero outside the frames'
    /// time, where the pose is held).
    pub fn velocity_at(&self, t: f64) -> CameraVelocity {
        let Some((i, s)) = self.segment(t) else {
            return CameraVelocity::ZERO;
        };
        let dt = self.times[i + 1] - self.times[i];
        let (a, b) = (&self.poses[i], &self.poses[i + 1]);
        let c_dot = match self.interp {
            Interp::Linear => (b.translation - a.translation) / dt,
            Interp::CatmullRom => {
                let s2 = s * s;
                (a.translation * (6.0 * s2 - 6.0 * s) + b.translation * (-6.0 * s2 + 6.0 * s)) / dt
                    + self.tangents[i] * (3.0 * s2 - 4.0 * s + 1.0)
                    + self.tangents[i + 1] * (3.0 * s2 - 2.0 * s)
            }
        };
        let r = self.pose_at(t).rotation;
        CameraVelocity {
            v: r.inverse() * c_dot,
            w: self.phi[i] / dt,
        }
    }
}

/// Symmetric-difference camera velocity between pose `a` (time `t − h/2`) and pose `b`
/// (time `t + h/2`), in the frame of the mid rotation (module docs). Zero when `h` is
/// zero or not finite.
pub(crate) fn velocity_between(a: &Pose, b: &Pose, h: f64) -> CameraVelocity {
    if h == 0.0 || !h.is_finite() {
        return CameraVelocity::ZERO;
    }
    let phi = log_so3(a.rotation.inverse() * b.rotation);
    let u = a.rotation.inverse() * (b.translation - a.translation);
    CameraVelocity {
        v: exp_so3(-0.5 * phi) * u / h,
        w: phi / h,
    }
}

/// Gradient of a loss through [`velocity_between`]: from `g = ∂L/∂(v, ω)` to `∂L/∂ε_a`
/// and `∂L/∂ε_b`, the camera-right twists of the two poses ([`crate::lie`]).
///
/// With `φ = Log(R_aᵀR_b)`, `u = R_aᵀ(c_b − c_a)`, `Q = Exp(−φ/2)`:
/// `dφ = −J_l⁻¹(φ)·α + J_r⁻¹(φ)·β`, `du = [u]×·α − a + Exp(φ)·b`,
/// `d(Q·u) = Q·du + Q·[u]×·J_r(−φ/2)·dφ/2` (α, β the rotation and a, b the translation
/// parts of ε_a, ε_b).
pub(crate) fn velocity_between_backward(
    a: &Pose,
    b: &Pose,
    h: f64,
    g: &CameraVelocity,
) -> ([f64; 6], [f64; 6]) {
    if h == 0.0 || !h.is_finite() {
        return ([0.0; 6], [0.0; 6]);
    }
    let phi = log_so3(a.rotation.inverse() * b.rotation);
    let u = a.rotation.inverse() * (b.translation - a.translation);
    let q = exp_so3(-0.5 * phi);
    let qt_gv = q.inverse() * g.v / h; // ∂L/∂(Q·u)·Qᵀ … i.e. Qᵀ·g_v/h
    let g_u = qt_gv;
    let g_phi = (skew(u) * right_jacobian(-0.5 * phi)).transpose() * qt_gv * 0.5 + g.w / h;
    let g_alpha = skew(u).transpose() * g_u - left_jacobian_inv(phi).transpose() * g_phi;
    let g_a = -g_u;
    let g_beta = right_jacobian_inv(phi).transpose() * g_phi;
    let g_b = exp_so3(phi).inverse() * g_u;
    (join(g_a, g_alpha), join(g_b, g_beta))
}
