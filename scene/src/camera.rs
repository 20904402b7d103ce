//! Pinhole camera with optional OpenCV radial-tangential distortion, rigid poses and
//! pose interpolation.
//!
//! Conventions (DESIGN §3), fixed for the whole project:
//! - **Camera axes: OpenGL/Blender.** The camera looks down −Z, +Y is up, +X is right.
//!   A point in front of the camera has camera-space `z < 0`; its *depth* is `−z`.
//! - **Poses are camera-to-world** (`transform_matrix` of the scene manifest).
//! - **Pixel coordinates: OpenCV.** `u` grows to the right, `v` grows downwards, and the
//!   centre of pixel `(i, j)` is at `(u, v) = (i, j)`. So an ideal centred camera has
//!   `cx = (w − 1) / 2`. Events at integer `(x, y)` sit exactly on pixel centres.
//! - Projection: `u = cx + fx · X / d`, `v = cy − fy · Y / d` with `d = −Z`.

use glam::{DMat3, DMat4, DQuat, DVec2, DVec3};
use serde::{Deserialize, Serialize};

/// OpenCV radial-tangential distortion `k1 k2 p1 p2 k3`, applied to normalised image
/// coordinates `(x, y) = ((u − cx)/fx, (v − cy)/fy)` (y downwards).
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct Distortion {
    pub k1: f64,
    pub k2: f64,
    pub p1: f64,
    pub p2: f64,
    pub k3: f64,
}

impl Distortion {
    pub fn is_zero(&self) -> bool {
        [self.k1, self.k2, self.p1, self.p2, self.k3]
            .iter()
            .all(|&c| c == 0.0)
    }

    /// Undistorted normalised coordinates → distorted normalised coordinates.
    pub(crate) fn distort(&self, n: DVec2) -> DVec2 {
        let (x, y) = (n.x, n.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        DVec2::new(
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// Inverse of [`Distortion::distort`] by Newton's method (converges to ~1e-12 for
    /// the distortions of real lenses inside the image).
    pub(crate) fn undistort(&self, d: DVec2) -> DVec2 {
        let mut n = d;
        for _ in 0..30 {
            let (x, y) = (n.x, n.y);
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
            // d radial / d r2
            let dradial = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3);
            let f = self.distort(n) - d;
            // Jacobian of distort at n.
            let j00 = radial + 2.0 * x * x * dradial + 2.0 * self.p1 * y + 6.0 * self.p2 * x;
            let j01 = 2.0 * x * y * dradial + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
            let j10 = 2.0 * x * y * dradial + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
            let j11 = radial + 2.0 * y * y * dradial + 6.0 * self.p1 * y + 2.0 * self.p2 * x;
            let det = j00 * j11 - j01 * j10;
            if det.abs() < 1e-12 {
                break;
            }
            let step = DVec2::new(j11 * f.x - j01 * f.y, -j10 * f.x + j00 * f.y) / det;
            n -= step;
            if step.length_squared() < 1e-28 {
                break;
            }
        }
        n
    }
}

/// Pinhole intrinsics of a `width × height` sensor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<Distortion>,
}

impl Intrinsics {
    /// A centred camera with the given horizontal field of view (radians).
    pub fn from_fov_x(width: u32, height: u32, fov_x: f64) -> Self {
        let fx = 0.5 * width as f64 / (0.5 * fov_x).tan();
        Intrinsics {
            width,
            height,
            fx,
            fy: fx,
            cx: (width as f64 - 1.0) * 0.5,
            cy: (height as f64 - 1.0) * 0.5,
            distortion: None,
        }
    }

    /// Camera-space point → pixel (ideal pinhole; no distortion). `None` behind the camera.
    pub fn project(&self, p_cam: DVec3) -> Option<DVec2> {
        let d = -p_cam.z;
        if d <= 0.0 {
            return None;
        }
        Some(DVec2::new(
            self.cx + self.fx * p_cam.x / d,
            self.cy - self.fy * p_cam.y / d,
        ))
    }

    /// Pixel + depth (distance along −Z) → camera-space point. Inverse of [`Self::project`].
    pub fn unproject(&self, px: DVec2, depth: f64) -> DVec3 {
        DVec3::new(
            (px.x - self.cx) / self.fx * depth,
            -(px.y - self.cy) / self.fy * depth,
            -depth,
        )
    }

    /// Distorted sensor pixel → ideal (undistorted) pixel of the same K. Identity when the
    /// camera has no distortion.
    pub fn undistort_pixel(&self, px: DVec2) -> DVec2 {
        match self.distortion {
            Some(d) if !d.is_zero() => {
                let n = DVec2::new((px.x - self.cx) / self.fx, (px.y - self.cy) / self.fy);
                let u = d.undistort(n);
                DVec2::new(self.cx + self.fx * u.x, self.cy + self.fy * u.y)
            }
            _ => px,
        }
    }

    /// Ideal pixel → distorted sensor pixel.
    pub fn distort_pixel(&self, px: DVec2) -> DVec2 {
        match self.distortion {
            Some(d) if !d.is_zero() => {
                let n = DVec2::new((px.x - self.cx) / self.fx, (px.y - self.cy) / self.fy);
                let u = d.distort(n);
                DVec2::new(self.cx + self.fx * u.x, self.cy + self.fy * u.y)
            }
            _ => px,
        }
    }

    /// Horizontal field of view in radians.
    pub fn fov_x(&self) -> f64 {
        2.0 * (0.5 * self.width as f64 / self.fx).atan()
    }

    pub fn contains(&self, px: DVec2) -> bool {
        px.x >= -0.5
            && px.y >= -0.5
            && px.x < self.width as f64 - 0.5
            && px.y < self.height as f64 - 0.5
    }
}

/// A rigid camera-to-world transform.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub rotation: DQuat,
    pub translation: DVec3,
}

impl Default for Pose {
    fn default() -> Self {
        Pose {
            rotation: DQuat::IDENTITY,
            translation: DVec3::ZERO,
        }
    }
}

/// Tolerance on `RᵀR = I` and `det R = 1` when a pose is read from a matrix.
pub(crate) const RIGID_TOLERANCE: f64 = 1e-4;

impl Pose {
    pub fn new(rotation: DQuat, translation: DVec3) -> Self {
        Pose {
            rotation: rotation.normalize(),
            translation,
        }
    }

    /// From a 4×4 camera-to-world matrix; `Err` names what is not rigid.
    pub fn from_matrix(m: DMat4) -> Result<Self, String> {
        if !m.is_finite() {
            return Err("matrix has non-finite entries".into());
        }
        let bottom = m.row(3);
        if (bottom - glam::DVec4::new(0.0, 0.0, 0.0, 1.0))
            .abs()
            .max_element()
            > RIGID_TOLERANCE
        {
            return Err(format!("bottom row is {bottom:?}, expected [0 0 0 1]"));
        }
        let r = DMat3::from_mat4(m);
        let rtr = r.transpose() * r;
        let off = (0..3)
            .flat_map(|i| (0..3).map(move |j| (i, j)))
            .map(|(i, j)| (rtr.col(j)[i] - if i == j { 1.0 } else { 0.0 }).abs())
            .fold(0.0, f64::max);
        if off > RIGID_TOLERANCE {
            return Err(format!(
                "rotation part is not orthonormal (max |RᵀR − I| = {off:.2e})"
            ));
        }
        if r.determinant() < 0.0 {
            return Err("rotation part is a reflection (det < 0)".into());
        }
        Ok(Pose {
            rotation: DQuat::from_mat3(&r).normalize(),
            translation: m.col(3).truncate(),
        })
    }

    pub fn matrix(&self) -> DMat4 {
        DMat4::from_rotation_translation(self.rotation, self.translation)
    }

    /// Camera centre in world coordinates.
    pub fn centre(&self) -> DVec3 {
        self.translation
    }

    pub fn to_world(&self, p_cam: DVec3) -> DVec3 {
        self.rotation * p_cam + self.translation
    }

    pub fn to_camera(&self, p_world: DVec3) -> DVec3 {
        self.rotation.inverse() * (p_world - self.translation)
    }

    /// The inverse transform (world-to-camera).
    pub fn inverse(&self) -> Pose {
        let r = self.rotation.inverse();
        Pose {
            rotation: r,
            translation: -(r * self.translation),
        }
    }

    /// Translation lerp + rotation slerp; `s = 0` gives `a`, `s = 1` gives `b` exactly.
    pub fn interpolate(a: &Pose, b: &Pose, s: f64) -> Pose {
        if s <= 0.0 {
            return *a;
        }
        if s >= 1.0 {
            return *b;
        }
        Pose {
            rotation: a.rotation.slerp(b.rotation, s).normalize(),
            translation: a.translation.lerp(b.translation, s),
        }
    }

    /// A camera at `eye` looking at `target` with `up` roughly up (OpenGL axes).
    pub fn look_at(eye: DVec3, target: DVec3, up: DVec3) -> Pose {
        let back = (eye - target).normalize(); // camera +Z points away from the target
        let right = up.cross(back).normalize();
        let true_up = back.cross(right);
        let r = DMat3::from_cols(right, true_up, back);
        Pose {
            rotation: DQuat::from_mat3(&r).normalize(),
            translation: eye,
        }
    }
}

/// A pinhole camera at a pose.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub intrinsics: Intrinsics,
    pub cam_to_world: Pose,
}

impl Camera {
    /// World point → (pixel, depth). `None` behind the camera.
    pub fn project_world(&self, p_world: DVec3) -> Option<(DVec2, f64)> {
        let pc = self.cam_to_world.to_camera(p_world);
        self.intrinsics.project(pc).map(|px| (px, -pc.z))
    }

    /// Pixel + depth → world point.
    pub fn unproject_world(&self, px: DVec2, depth: f64) -> DVec3 {
        self.cam_to_world
            .to_world(self.intrinsics.unproject(px, depth))
    }
}

/// Key poses at increasing times; [`Trajectory::pose_at`] interpolates between them and
/// holds the end poses outside the covered interval.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    pub times: Vec<f64>,
    pub poses: Vec<Pose>,
}

impl Trajectory {
    /// `Err` if the lengths differ, the list is empty or the times are not increasing.
    pub fn new(times: Vec<f64>, poses: Vec<Pose>) -> Result<Self, String> {
        if times.len() != poses.len() {
            return Err(format!("{} times but {} poses", times.len(), poses.len()));
        }
        if times.is_empty() {
            return Err("a trajectory needs at least one pose".into());
        }
        if let Some(i) = times
            .windows(2)
            .position(|w| w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater))
        {
            return Err(format!(
                "times are not increasing at index {}: {} then {}",
                i + 1,
                times[i],
                times[i + 1]
            ));
        }
        Ok(Trajectory { times, poses })
    }

    pub fn pose_at(&self, t: f64) -> Pose {
        let n = self.times.len();
        if t <= self.times[0] {
            return self.poses[0];
        }
        if t >= self.times[n - 1] {
            return self.poses[n - 1];
        }
        // First key strictly after t; t lies in [times[i-1], times[i]).
        let i = self.times.partition_point(|&k| k <= t);
        let (t0, t1) = (self.times[i - 1], self.times[i]);
        Pose::interpolate(&self.poses[i - 1], &self.poses[i], (t - t0) / (t1 - t0))
    }
}
