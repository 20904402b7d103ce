//! Camera axis conventions and their conversion to the manifest's (DESIGN §3).
//!
//! The manifest's `transform_matrix` is camera-to-world in **OpenGL camera axes**
//! (x right, y up, camera looks down −z). Most datasets with real cameras (ECD, COLMAP,
//! nerfies, OpenCV calibrations) give camera-to-world poses in **OpenCV camera axes**
//! (x right, y down, camera looks down +z).
//!
//! Derivation. The same physical camera frame in the two conventions differs by the
//! axis flip `F = diag(1, −1, −1)` (a rotation by π about x, so `F = F⁻¹ = Fᵀ`): a point
//! with OpenCV camera coordinates `p_cv` has OpenGL camera coordinates `p_gl = F p_cv`.
//! With `p_w = R_cv p_cv + t` (the dataset's pose), `p_w = R_cv F p_gl + t`, so
//!
//! `R_gl = R_cv F`, `t_gl = t_cv`
//!
//! (the camera centre does not move; the rotation's 2nd and 3rd columns change sign).
//! The map is its own inverse. As a quaternion, `F` is `(x, y, z, w) = (1, 0, 0, 0)`.

use glam::DQuat;
use scene::Pose;

/// The axis flip `F` (a half turn about x) as a quaternion.
const FLIP: DQuat = DQuat::from_xyzw(1.0, 0.0, 0.0, 0.0);

/// A camera-to-world pose in OpenCV camera axes → the manifest's OpenGL axes.
pub(crate) fn opencv_to_opengl(cam_to_world_cv: Pose) -> Pose {
    Pose::new(cam_to_world_cv.rotation * FLIP, cam_to_world_cv.translation)
}

/// The inverse of [`opencv_to_opengl`] (the same map: `F` is its own inverse).
pub(crate) fn opengl_to_opencv(cam_to_world_gl: Pose) -> Pose {
    Pose::new(cam_to_world_gl.rotation * FLIP, cam_to_world_gl.translation)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn opencv_forward_becomes_opengl_minus_z() {
        // An OpenCV camera at (1, 2, 3) rotated 0.6 rad about world y.
        let cv = Pose::new(DQuat::from_rotation_y(0.6), DVec3::new(1.0, 2.0, 3.0));
        let gl = opencv_to_opengl(cv);
        assert_eq!(gl.translation, cv.translation);
        // The viewing direction: +z of OpenCV = −z of OpenGL; image-down = −(GL up).
        let fwd_cv = cv.rotation * DVec3::Z;
        let fwd_gl = gl.rotation * -DVec3::Z;
        assert!((fwd_cv - fwd_gl).length() < 1e-12, "{fwd_cv} vs {fwd_gl}");
        let down_cv = cv.rotation * DVec3::Y;
        let up_gl = gl.rotation * DVec3::Y;
        assert!((down_cv + up_gl).length() < 1e-12);
        assert!((cv.rotation * DVec3::X - gl.rotation * DVec3::X).length() < 1e-12);
        // A world point seen by both lands on the same pixel row/column signs.
        let p = DVec3::new(1.2, 2.5, 9.0);
        let (pc, pg) = (cv.to_camera(p), gl.to_camera(p));
        assert!((pc.x - pg.x).abs() < 1e-12 && (pc.y + pg.y).abs() < 1e-12);
        assert!((pc.z + pg.z).abs() < 1e-12);
        // Round trip.
        let back = opengl_to_opencv(gl);
        assert!(back.rotation.dot(cv.rotation).abs() > 1.0 - 1e-15);
    }
}
