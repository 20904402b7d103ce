use super::{Rng, assert_close, fd_grad};
use crate::camera_path::{
    CameraPath, CameraVelocity, Interp, velocity_between, velocity_between_backward,
};
use crate::lie::{exp_so3, log_so3, perturb_camera_right};
use glam::DQuat;
use scene::Pose;

fn sample_path(interp: Interp) -> CameraPath {
    let mut rng = Rng::new(7);
    let times = [0.0, 0.13, 0.3, 0.42, 0.61];
    let poses: Vec<Pose> = (0..times.len()).map(|_| rng.pose(0.6, 1.0)).collect();
    CameraPath::new(&times, &poses, interp).unwrap()
}

fn pose_dist(a: &Pose, b: &Pose) -> f64 {
    (a.translation - b.translation).length() + log_so3(a.rotation.inverse() * b.rotation).length()
}

#[test]
fn so3_exp_log_round_trip_and_small_angles() {
    let mut rng = Rng::new(1);
    for s in [1e-9, 1e-5, 1e-3, 0.5, 2.0, 3.0] {
        for _ in 0..20 {
            let w = rng.vec3(1.0).normalize() * s;
            let back = log_so3(exp_so3(w));
            assert_close("log(exp(w))", &back.to_array(), &w.to_array(), 1e-10, 1e-15);
            let glam = DQuat::from_scaled_axis(w);
            assert!(exp_so3(w).dot(glam).abs() > 1.0 - 1e-14);
        }
    }
}

#[test]
fn keys_are_interpolated_through_and_held_outside() {
    for interp in [Interp::Linear, Interp::CatmullRom] {
        let p = sample_path(interp);
        for (t, k) in p.times().iter().zip(p.poses()) {
            assert!(
                pose_dist(&p.pose_at(*t), k) < 1e-12,
                "{interp:?} at key {t}"
            );
        }
        assert_eq!(p.pose_at(-5.0), p.poses()[0]);
        assert_eq!(p.pose_at(9.0), *p.poses().last().unwrap());
        assert_eq!(p.velocity_at(-0.1), CameraVelocity::ZERO);
        assert_eq!(p.velocity_at(0.7), CameraVelocity::ZERO);
        assert_eq!(p.pose_at(f64::NAN), p.poses()[0]);
        assert_eq!(p.velocity_at(f64::NAN), CameraVelocity::ZERO);
        assert_eq!(p.normalised_time(-1.0), 0.0);
        assert_eq!(p.normalised_time(0.61), 1.0);
        assert!((p.normalised_time(0.305) - 0.5).abs() < 1e-12);
    }
    // Linear: the mid-segment centre is the mean of the two keys.
    let p = sample_path(Interp::Linear);
    let mid = p.pose_at(0.5 * (0.13 + 0.3)).translation;
    let want = 0.5 * (p.poses()[1].translation + p.poses()[2].translation);
    assert!((mid - want).length() < 1e-12);
    // The rotation matches glam's slerp.
    let q = p.pose_at(0.13 + 0.3 * 0.17).rotation;
    let g = p.poses()[1]
        .rotation
        .slerp(p.poses()[2].rotation, 0.3 * 0.17 / 0.17);
    assert!(q.dot(g).abs() > 1.0 - 1e-12);
}

#[test]
fn analytic_velocity_matches_finite_differences_of_the_pose() {
    for interp in [Interp::Linear, Interp::CatmullRom] {
        let p = sample_path(interp);
        for &t in &[0.001, 0.05, 0.2, 0.299, 0.35, 0.5, 0.6] {
            let h = 1e-6;
            let fd = velocity_between(&p.pose_at(t - h), &p.pose_at(t + h), 2.0 * h);
            let an = p.velocity_at(t);
            assert_close(
                &format!("{interp:?} velocity at {t}"),
                &an.to_array(),
                &fd.to_array(),
                1e-6,
                1e-7,
            );
        }
    }
}

#[test]
fn velocity_is_the_time_derivative_of_pose_as_defined() {
    // Independent of `velocity_between`: ċ = R·v and Ṙ = R·[ω]× from raw differences.
    let p = sample_path(Interp::CatmullRom);
    let (t, h) = (0.37, 1e-6);
    let (a, b) = (p.pose_at(t - h), p.pose_at(t + h));
    let vel = p.velocity_at(t);
    let r = p.pose_at(t).rotation;
    let c_dot = (b.translation - a.translation) / (2.0 * h);
    assert_close("ċ", &(r * vel.v).to_array(), &c_dot.to_array(), 1e-7, 1e-8);
    let rm = glam::DMat3::from_quat(r);
    let rdot =
        (glam::DMat3::from_quat(b.rotation) - glam::DMat3::from_quat(a.rotation)) * (0.5 / h);
    let want = rm * crate::lie::skew(vel.w);
    for c in 0..3 {
        assert_close(
            "Ṙ",
            &rdot.col(c).to_array(),
            &want.col(c).to_array(),
            1e-6,
            1e-8,
        );
    }
}

#[test]
fn symmetric_difference_is_exact_on_one_linear_segment() {
    let p = sample_path(Interp::Linear);
    for &(t, h) in &[(0.2, 0.05), (0.2, 0.1), (0.5, 0.15)] {
        let v = velocity_between(&p.pose_at(t - 0.5 * h), &p.pose_at(t + 0.5 * h), h);
        assert_close(
            "symmetric difference",
            &v.to_array(),
            &p.velocity_at(t).to_array(),
            1e-10,
            1e-12,
        );
    }
    assert_eq!(
        velocity_between(&p.poses()[0], &p.poses()[1], 0.0),
        CameraVelocity::ZERO
    );
}

#[test]
fn velocity_between_backward_matches_finite_differences() {
    let mut rng = Rng::new(3);
    for case in 0..6 {
        let a = rng.pose(1.5, 2.0);
        // Relative rotations from tiny to large.
        let rel = [1e-7, 1e-3, 0.1, 0.5, 1.0, 2.0][case];
        let b = Pose::new(
            a.rotation * exp_so3(rng.vec3(1.0).normalize() * rel),
            a.translation + rng.vec3(0.5),
        );
        let h = rng.uniform(0.01, 0.1);
        let g = CameraVelocity::from_array(std::array::from_fn(|_| rng.uniform(-1.0, 1.0)));
        let loss = |x: &[f64]| {
            let pa = perturb_camera_right(&a, x[0..6].try_into().unwrap());
            let pb = perturb_camera_right(&b, x[6..12].try_into().unwrap());
            let v = velocity_between(&pa, &pb, h);
            v.v.dot(g.v) + v.w.dot(g.w)
        };
        let num = fd_grad(&[0.0; 12], 1e-6, loss);
        let (ga, gb) = velocity_between_backward(&a, &b, h, &g);
        let an: Vec<f64> = ga.iter().chain(&gb).copied().collect();
        let scale = num.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert_close(&format!("case {case}"), &an, &num, 1e-6, 1e-8 * scale);
    }
}

/// One pose-gradient convention: the rasterizer's twist (`gaussians::raster::
/// apply_twist`) is this crate's camera-right perturbation, and the rasterizer's camera
/// gradient is the derivative along it (f64 central differences through the f64
/// reference renderer are in `gaussians/tests/raster_grad.rs`).
#[test]
fn the_rasterizer_twist_is_the_camera_right_perturbation() {
    let mut rng = Rng::new(11);
    for _ in 0..8 {
        let pose = rng.pose(1.0, 3.0);
        let eps: [f64; 6] = std::array::from_fn(|_| rng.vec3(0.3).x);
        let a = perturb_camera_right(&pose, eps);
        let b = gaussians::raster::apply_twist(&pose, eps);
        assert!(
            a.rotation.dot(b.rotation).abs() > 1.0 - 1e-12,
            "{a:?} {b:?}"
        );
        assert!(
            (a.translation - b.translation).length() < 1e-12,
            "{a:?} {b:?}"
        );
    }
}

#[test]
fn equal_times_are_merged_and_single_frames_work() {
    let mut rng = Rng::new(5);
    let (a, b, c) = (rng.pose(0.5, 1.0), rng.pose(0.5, 1.0), rng.pose(0.5, 1.0));
    // Unsorted input with a duplicate time.
    let p = CameraPath::new(&[1.0, 0.0, 1.0], &[b, a, c], Interp::CatmullRom).unwrap();
    assert_eq!(p.times(), &[0.0, 1.0]);
    let m = p.poses()[1];
    assert!((m.translation - 0.5 * (b.translation + c.translation)).length() < 1e-12);
    let mid = b.rotation.slerp(c.rotation, 0.5);
    assert!(m.rotation.dot(mid).abs() > 1.0 - 1e-12);
    for t in [0.0, 0.5, 1.0, 2.0] {
        let v = p.velocity_at(t);
        let q = p.pose_at(t);
        assert!(v.v.is_finite() && v.w.is_finite() && q.translation.is_finite());
    }
    // A single frame: constant pose, zero velocity.
    let one = CameraPath::new(&[3.0], &[a], Interp::Linear).unwrap();
    assert_eq!(one.pose_at(3.0), one.poses()[0]);
    assert_eq!(one.pose_at(-1.0), one.poses()[0]);
    assert_eq!(one.velocity_at(3.0), CameraVelocity::ZERO);
    assert_eq!(one.normalised_time(3.0), 0.0);
    // Bad input.
    assert!(CameraPath::new(&[], &[], Interp::Linear).is_err());
    assert!(CameraPath::new(&[0.0], &[a, b], Interp::Linear).is_err());
    assert!(CameraPath::new(&[f64::NAN], &[a], Interp::Linear).is_err());
}
