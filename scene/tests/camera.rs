//! Camera model: projection conventions, inverses, distortion, pose interpolation.

use glam::{DMat4, DQuat, DVec2, DVec3};
use scene::camera::{Camera, Distortion, Intrinsics, Pose, Trajectory};

fn k() -> Intrinsics {
    Intrinsics {
        width: 240,
        height: 180,
        fx: 199.0923,
        fy: 198.8288,
        cx: 132.192,
        cy: 110.7126,
        distortion: Some(Distortion {
            k1: -0.368436,
            k2: 0.150947,
            p1: -0.000296,
            p2: -0.000759,
            k3: 0.0,
        }),
    }
}

#[test]
fn project_unproject_are_inverse() {
    let k = k();
    for &(u, v, d) in &[(0.0, 0.0, 0.5), (239.0, 179.0, 3.0), (120.25, 33.75, 17.0)] {
        let px = DVec2::new(u, v);
        let p = k.unproject(px, d);
        assert!((p.z + d).abs() < 1e-12, "depth is −z");
        let back = k.project(p).unwrap();
        assert!((back - px).length() < 1e-9, "{back} vs {px}");
    }
    // Behind the camera: no pixel.
    assert!(k.project(DVec3::new(0.0, 0.0, 1.0)).is_none());
}

#[test]
fn projection_follows_the_documented_axes() {
    let k = Intrinsics::from_fov_x(101, 51, std::f64::consts::FRAC_PI_2);
    // 90° field of view: fx = w/2.
    assert!((k.fx - 50.5).abs() < 1e-12);
    assert_eq!((k.cx, k.cy), (50.0, 25.0));
    // On the optical axis → the centre pixel.
    assert_eq!(
        k.project(DVec3::new(0.0, 0.0, -2.0)).unwrap(),
        DVec2::new(50.0, 25.0)
    );
    // +X right → larger u; +Y up → smaller v.
    let p = k.project(DVec3::new(1.0, 1.0, -2.0)).unwrap();
    assert!((p.x - (50.0 + 50.5 * 0.5)).abs() < 1e-12);
    assert!((p.y - (25.0 - 50.5 * 0.5)).abs() < 1e-12);
    assert!((k.fov_x() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
}

#[test]
fn distortion_round_trips_inside_the_image() {
    let k = k();
    for j in (0..180).step_by(29) {
        for i in (0..240).step_by(31) {
            let px = DVec2::new(i as f64, j as f64);
            let ideal = k.undistort_pixel(px);
            let back = k.distort_pixel(ideal);
            assert!((back - px).length() < 1e-8, "{px}: {back}");
        }
    }
    // Barrel distortion (k1 < 0): a corner pixel undistorts further from the centre.
    let corner = DVec2::new(0.0, 0.0);
    let c = DVec2::new(k.cx, k.cy);
    assert!((k.undistort_pixel(corner) - c).length() > (corner - c).length());
}

#[test]
fn pose_matrix_round_trip_and_inverse() {
    let pose = Pose::new(
        DQuat::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 0.8),
        DVec3::new(0.3, -1.0, 2.5),
    );
    let back = Pose::from_matrix(pose.matrix()).unwrap();
    assert!(
        (back.matrix() - pose.matrix())
            .abs()
            .to_cols_array()
            .iter()
            .all(|&d| d < 1e-14)
    );
    let p = DVec3::new(0.1, 0.2, -3.0);
    assert!((pose.to_camera(pose.to_world(p)) - p).length() < 1e-12);
    assert!((pose.inverse().to_world(pose.to_world(p)) - p).length() < 1e-12);
    // A scaled matrix is not a pose.
    let err = Pose::from_matrix(DMat4::from_scale(DVec3::splat(1.01))).unwrap_err();
    assert!(err.contains("orthonormal"), "{err}");
    let mut m = pose.matrix();
    m.x_axis.w = 0.5;
    assert!(Pose::from_matrix(m).unwrap_err().contains("bottom row"));
    m = pose.matrix();
    m.w_axis.x = f64::NAN;
    assert!(Pose::from_matrix(m).unwrap_err().contains("non-finite"));
}

#[test]
fn camera_world_round_trip_and_look_at() {
    let eye = DVec3::new(1.0, 2.0, 3.0);
    let cam = Camera {
        intrinsics: Intrinsics::from_fov_x(64, 48, 1.0),
        cam_to_world: Pose::look_at(eye, DVec3::ZERO, DVec3::Y),
    };
    // The target is seen at the image centre, at its distance.
    let (px, d) = cam.project_world(DVec3::ZERO).unwrap();
    assert!((px - DVec2::new(31.5, 23.5)).length() < 1e-9);
    assert!((d - eye.length()).abs() < 1e-12);
    let q = DVec2::new(10.25, 40.0);
    let w = cam.unproject_world(q, 2.5);
    let (back, depth) = cam.project_world(w).unwrap();
    assert!((back - q).length() < 1e-9 && (depth - 2.5).abs() < 1e-12);
    // World up projects upwards in the image (smaller v).
    let (up, _) = cam.project_world(DVec3::new(0.0, 0.1, 0.0)).unwrap();
    assert!(up.y < px.y);
}

#[test]
fn interpolation_and_trajectory() {
    let a = Pose::new(DQuat::IDENTITY, DVec3::ZERO);
    let b = Pose::new(DQuat::from_rotation_y(1.0), DVec3::new(2.0, 0.0, -4.0));
    let m = Pose::interpolate(&a, &b, 0.25);
    assert!((m.translation - DVec3::new(0.5, 0.0, -1.0)).length() < 1e-12);
    assert!((m.rotation.angle_between(DQuat::from_rotation_y(0.25))).abs() < 1e-12);
    assert_eq!(Pose::interpolate(&a, &b, 0.0), a);
    assert_eq!(Pose::interpolate(&a, &b, 1.0), b);

    let traj = Trajectory::new(vec![1.0, 3.0], vec![a, b]).unwrap();
    assert_eq!(traj.pose_at(0.0), a);
    assert_eq!(traj.pose_at(9.0), b);
    let mid = traj.pose_at(2.0);
    assert!((mid.translation - DVec3::new(1.0, 0.0, -2.0)).length() < 1e-12);
    assert!((mid.rotation.angle_between(DQuat::from_rotation_y(0.5))).abs() < 1e-12);
    assert!(
        Trajectory::new(vec![1.0, 1.0], vec![a, b])
            .unwrap_err()
            .contains("not increasing")
    );
    assert!(Trajectory::new(vec![], vec![]).is_err());
    assert!(Trajectory::new(vec![1.0], vec![a, b]).is_err());
}

/// Max |RᵀR − I| and det R of a pose's rotation matrix.
fn rigidity(p: &Pose) -> (f64, f64) {
    let r = glam::DMat3::from_quat(p.rotation);
    let rtr = r.transpose() * r;
    let off = (rtr - glam::DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    (off, r.determinant())
}

#[test]
fn trajectory_with_many_keys_stays_rigid_and_hits_every_key() {
    // Five keys, unevenly spaced, with large rotations about changing axes (quaternions
    // of neighbouring keys in opposite hemispheres, so slerp must flip one to take the
    // short way) and one key built from a matrix, as the manifest reader does.
    let axis = |x: f64, y: f64, z: f64| DVec3::new(x, y, z).normalize();
    let from_matrix = Pose::from_matrix(DMat4::from_rotation_translation(
        DQuat::from_axis_angle(axis(0.0, 1.0, 1.0), -2.5),
        DVec3::new(-1.0, 0.5, 0.25),
    ))
    .unwrap();
    let keys = vec![
        Pose::new(DQuat::IDENTITY, DVec3::new(0.0, 0.0, 3.0)),
        Pose::new(
            DQuat::from_axis_angle(axis(1.0, 2.0, -0.5), 1.1),
            DVec3::new(0.4, -0.2, 2.5),
        ),
        Pose::new(
            -DQuat::from_axis_angle(axis(-0.3, 0.2, 1.0), 2.9), // −q: the same rotation
            DVec3::new(1.5, 0.3, 1.0),
        ),
        from_matrix,
        Pose::look_at(DVec3::new(2.0, 1.0, -1.0), DVec3::ZERO, DVec3::Y),
    ];
    // Some neighbouring key quaternions lie in opposite hemispheres (q·q' < 0).
    assert!(
        keys.windows(2)
            .any(|k| k[0].rotation.dot(k[1].rotation) < 0.0)
    );
    let times = vec![0.0, 0.1, 0.35, 0.4, 1.0];
    let traj = Trajectory::new(times.clone(), keys.clone()).unwrap();

    // Every key, interior ones included, is hit exactly (bit for bit).
    for (t, key) in times.iter().zip(&keys) {
        assert_eq!(traj.pose_at(*t), *key, "key at t = {t}");
    }
    // Just after a key the pose is close to it (continuity), not to the next key.
    for i in 0..times.len() - 1 {
        let p = traj.pose_at(times[i] + 1e-9);
        assert!((p.translation - keys[i].translation).length() < 1e-6);
        assert!(p.rotation.angle_between(keys[i].rotation) < 1e-6);
        let q = traj.pose_at(times[i + 1] - 1e-9);
        assert!((q.translation - keys[i + 1].translation).length() < 1e-6);
        assert!(q.rotation.angle_between(keys[i + 1].rotation) < 1e-6);
    }

    // Rigid everywhere: RᵀR = I to 1e-12 and det R = +1, on a dense grid, at the keys and
    // outside the covered interval.
    let mut worst = (0.0f64, 0.0f64);
    for k in -20..=1020 {
        let t = k as f64 * 1e-3;
        let p = traj.pose_at(t);
        let (off, det) = rigidity(&p);
        assert!(off < 1e-12, "t = {t}: max |RᵀR − I| = {off:e}");
        assert!((det - 1.0).abs() < 1e-12, "t = {t}: det R = {det}");
        assert!(p.translation.is_finite());
        worst = (worst.0.max(off), worst.1.max((det - 1.0).abs()));
        // The matrix form passes the manifest's rigidity check and round-trips.
        let back = Pose::from_matrix(p.matrix()).unwrap().matrix();
        let diff = (back - p.matrix()).to_cols_array();
        assert!(diff.iter().all(|d| d.abs() < 1e-12), "t = {t}: {diff:?}");
    }
    // Measured: max |RᵀR − I| = 2.2e-15 and max |det R − 1| = 2.2e-15 over the grid.
    assert!(worst.0 < 1e-14 && worst.1 < 1e-14, "{worst:?}");

    // Interpolation inside a segment: translation is the lerp, rotation the slerp on the
    // shortest arc (its angle to each key splits the arc in proportion).
    let (a, b) = (keys[1], keys[2]);
    let s = 0.3;
    let p = traj.pose_at(0.1 + s * 0.25);
    assert!((p.translation - a.translation.lerp(b.translation, s)).length() < 1e-12);
    let arc = a.rotation.angle_between(b.rotation);
    assert!((p.rotation.angle_between(a.rotation) - s * arc).abs() < 1e-9);
    assert!((p.rotation.angle_between(b.rotation) - (1.0 - s) * arc).abs() < 1e-9);
}
