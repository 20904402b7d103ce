//! How far the camera of the joint training is from the recorded poses of the held-out
//! frames: the interpolated path alone and with the PoseNet correction, at the test
//! frames' times. On a recording whose camera moves faster than the frame rate can follow,
//! the interpolated camera is off by degrees between frames, and `L_event` (rendered with
//! that camera) would teach the scene to move in its place; this says whether the PoseNet
//! took that error up.
//!
//! Centre distance and angle are not what the frames and events can tell apart: seen on
//! a far, flat scene a small turn and a sideways step move the image alike. So each frame
//! also gets the **image error**: how far (pixels) the surface seen by the recorded camera
//! (the model's depth there) lands in the estimated camera, averaged over the pixels.

use glam::DVec2;
use scene::{Camera, Pose};
use serde::Serialize;

/// Mean and largest error of one camera against the recorded poses, and the error at
/// each frame (which interval the camera is off in).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PoseError {
    /// Distance between camera centres, scene units.
    pub position_mean: f64,
    pub position_max: f64,
    /// Angle of the relative rotation, degrees.
    pub rotation_deg_mean: f64,
    pub rotation_deg_max: f64,
    /// Mean image error, pixels ([`image_error_px`]; frames with no surface left out).
    pub image_px_mean: f64,
    pub image_px_max: f64,
    /// Per frame, in the order of the test frames.
    pub position: Vec<f64>,
    pub rotation_deg: Vec<f64>,
    /// `None` where the model draws no surface in the recorded view.
    pub image_px: Vec<Option<f64>>,
}

/// The check on the test frames (`frames` = 0 when there are none).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CameraCheck {
    pub frames: usize,
    pub interpolated: PoseError,
    /// With the PoseNet correction (equal to `interpolated` without a PoseNet).
    pub corrected: PoseError,
}

/// Centre distance and rotation angle (degrees) between two poses.
pub(crate) fn pose_distance(a: &Pose, b: &Pose) -> (f64, f64) {
    let d = a
        .rotation
        .normalize()
        .dot(b.rotation.normalize())
        .abs()
        .min(1.0);
    (
        (a.translation - b.translation).length(),
        (2.0 * d.acos()).to_degrees(),
    )
}

/// Mean distance (pixels) between where the recorded camera sees its surface and where
/// the `estimated` pose puts the same points: each pixel with a depth (`depth[i] > 0`,
/// distance along −Z, row-major at the camera's size) is lifted with `recorded` and
/// projected with `estimated`; a point behind the estimated camera counts as the image's
/// diagonal. `None` when no pixel has a depth.
pub fn image_error_px(recorded: &Camera, estimated: &Pose, depth: &[f32]) -> Option<f64> {
    let k = recorded.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    assert_eq!(depth.len(), w * h, "depth of {w}×{h} pixels");
    let other = Camera {
        intrinsics: k,
        cam_to_world: *estimated,
    };
    let diagonal = ((w * w + h * h) as f64).sqrt();
    let (mut sum, mut n) = (0.0, 0usize);
    for (i, &z) in depth.iter().enumerate() {
        if z <= 0.0 {
            continue;
        }
        let px = DVec2::new((i % w) as f64, (i / w) as f64);
        let p = recorded.unproject_world(px, f64::from(z));
        sum += other
            .project_world(p)
            .map_or(diagonal, |(q, _)| (q - px).length());
        n += 1;
    }
    (n > 0).then(|| sum / n as f64)
}

/// Mean and max of the distances between `estimated[k]` and `recorded[k]`; `image_px`, one
/// per frame, from [`image_error_px`] (empty: no image errors).
pub(crate) fn pose_error(
    estimated: &[Pose],
    recorded: &[Pose],
    image_px: &[Option<f64>],
) -> PoseError {
    let n = estimated.len().min(recorded.len());
    let mut e = PoseError::default();
    for (a, b) in estimated.iter().zip(recorded) {
        let (p, r) = pose_distance(a, b);
        e.position_mean += p / n as f64;
        e.rotation_deg_mean += r / n as f64;
        e.position_max = e.position_max.max(p);
        e.rotation_deg_max = e.rotation_deg_max.max(r);
        e.position.push(p);
        e.rotation_deg.push(r);
    }
    let seen: Vec<f64> = image_px.iter().flatten().copied().collect();
    if !seen.is_empty() {
        e.image_px_mean = seen.iter().sum::<f64>() / seen.len() as f64;
        e.image_px_max = seen.iter().copied().fold(0.0, f64::max);
    }
    e.image_px = image_px.to_vec();
    e
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, DVec3};

    #[test]
    fn distances_of_known_offsets() {
        let a = Pose::default();
        let b = Pose {
            rotation: DQuat::from_rotation_y(3f64.to_radians()),
            translation: DVec3::new(0.3, 0.4, 0.0),
        };
        let (p, r) = pose_distance(&a, &b);
        assert!((p - 0.5).abs() < 1e-12 && (r - 3.0).abs() < 1e-9, "{p} {r}");
        // q and −q are the same rotation.
        let c = Pose {
            rotation: -b.rotation,
            ..b
        };
        assert!(pose_distance(&b, &c).1 < 1e-6);
        let e = pose_error(&[a, b], &[a, a], &[]);
        assert!((e.position_mean - 0.25).abs() < 1e-12 && (e.rotation_deg_max - 3.0).abs() < 1e-9);
        assert_eq!(e.position[0], 0.0);
        assert!((e.position[1] - 0.5).abs() < 1e-12 && (e.rotation_deg[1] - 3.0).abs() < 1e-9);
    }

    /// A fronto-parallel plane at depth `z`: a sideways step `b` shifts it by `f·b/z`
    /// pixels everywhere; a turn by `θ` about the camera's x axis by `f·tan θ` at the
    /// principal point and more off it (pinhole: `f·(tan(θ+φ) − tan φ)`).
    #[test]
    fn image_error_of_a_plane_in_closed_form() {
        use glam::{DQuat, DVec3};
        use scene::Intrinsics;
        let k = Intrinsics::from_fov_x(32, 24, 60f64.to_radians());
        let rec = Camera {
            intrinsics: k,
            cam_to_world: Pose::default(),
        };
        let z = 3.0f32;
        let depth = vec![z; 32 * 24];
        let step = Pose {
            translation: DVec3::new(0.0, 0.2, 0.0),
            ..Pose::default()
        };
        let e = image_error_px(&rec, &step, &depth).unwrap();
        assert!((e - k.fy * 0.2 / 3.0).abs() < 1e-9, "{e}");
        let theta = 0.05f64;
        let turn = Pose {
            rotation: DQuat::from_rotation_x(theta),
            ..Pose::default()
        };
        let mut want = 0.0;
        for y in 0..24 {
            for x in 0..32 {
                // Pixel row y sees the ray at angle φ below the axis; the turn adds θ.
                let phi = ((y as f64 - k.cy) / k.fy).atan();
                let ray = (x as f64 - k.cx) / k.fx;
                let (ny, nx) = (
                    k.fy * (phi + theta).tan(),
                    k.fx * ray * phi.cos() / (phi + theta).cos(),
                );
                let (oy, ox) = (y as f64 - k.cy, x as f64 - k.cx);
                // A turn about +x (OpenGL: up is +y, looking down −z) moves the image down.
                want += ((ny - oy).powi(2) + (nx - ox).powi(2)).sqrt();
            }
        }
        want /= (32 * 24) as f64;
        let e = image_error_px(&rec, &turn, &depth).unwrap();
        assert!((e - want).abs() < 1e-6, "{e} vs {want}");
        assert!(image_error_px(&rec, &turn, &[0.0; 32 * 24]).is_none());
    }
}
