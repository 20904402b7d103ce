//! How far the camera of the joint training is from the recorded poses of the held-out
//! frames: the interpolated path alone and with the PoseNet correction, at the test
//! frames' times. On a recording whose camera moves faster than the frame rate can follow,
//! the interpolated camera is off by degrees between frames, and `L_event` (rendered with
//! that camera) would teach the scene to move in its place; this says whether the PoseNet
//! took that error up.

use scene::Pose;
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
    /// Per frame, in the order of the test frames.
    pub position: Vec<f64>,
    pub rotation_deg: Vec<f64>,
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

/// Mean and max of the distances between `estimated[k]` and `recorded[k]`.
pub(crate) fn pose_error(estimated: &[Pose], recorded: &[Pose]) -> PoseError {
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
        let e = pose_error(&[a, b], &[a, a]);
        assert!((e.position_mean - 0.25).abs() < 1e-12 && (e.rotation_deg_max - 3.0).abs() < 1e-9);
        assert_eq!(e.position[0], 0.0);
        assert!((e.position[1] - 0.5).abs() < 1e-12 && (e.rotation_deg[1] - 3.0).abs() < 1e-9);
    }
}
