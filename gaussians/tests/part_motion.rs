//! A part's rigid motion from brightness (`tracks::part_motion`, issue #30): a textured
//! plane drawn by ray casting through two cameras, moved between them by a known rigid
//! motion, must be found to that motion; and a group of movers fitted at one frame only,
//! on a textured square that turns and drifts, must be followed as one part whose poses
//! put every member where the known motion does (`tracks.part_steps`).

use gaussians::tracks::lk::{Grey, Pyramid};
use gaussians::tracks::part_motion::{self, LEVELS, Motion};
use glam::{DQuat, DVec2, DVec3};
use scene::{Camera, Intrinsics, Pose};

const SIZE: u32 = 64;
const PLANE_Z: f64 = -5.0;

/// Smooth texture with structure in every direction, material coordinates.
fn texture(x: f64, y: f64) -> f64 {
    0.5 + 0.2 * (3.0 * x + 1.0).sin() * (2.3 * y).sin() + 0.15 * (4.1 * x - 2.7 * y).cos()
}

fn camera(eye: DVec3, yaw_deg: f64) -> Camera {
    Camera {
        intrinsics: Intrinsics::from_fov_x(SIZE, SIZE, 60f64.to_radians()),
        cam_to_world: Pose::new(DQuat::from_rotation_y(yaw_deg.to_radians()), eye),
    }
}

/// The image of the plane `z = PLANE_Z` (material frame) moved by `m`, seen by `cam`:
/// textured within `half` of its centre's axis lines (everywhere: `f64::INFINITY`), flat
/// grey outside.
fn draw(cam: &Camera, m: &Motion, half: f64) -> Grey {
    let n = SIZE as usize;
    let inverse = |p: DVec3| m.rot.inverse() * (p - m.centre - m.shift) + m.centre;
    let data = (0..n * n)
        .map(|i| {
            let px = DVec2::new((i % n) as f64, (i / n) as f64);
            // The ray in the plane's material frame.
            let o = inverse(cam.cam_to_world.centre());
            let d = inverse(cam.unproject_world(px, 1.0)) - o;
            let x = o + (PLANE_Z - o.z) / d.z * d;
            match x.x.abs() <= half && x.y.abs() <= half {
                true => texture(x.x, x.y) as f32,
                false => 0.3,
            }
        })
        .collect();
    Grey {
        width: n,
        height: n,
        data,
    }
}

#[test]
fn a_moved_plane_is_followed_to_the_known_motion() {
    let centre = DVec3::new(0.0, 0.0, PLANE_Z);
    let rest = Motion::identity(centre);
    let truth = Motion {
        rot: DQuat::from_axis_angle(DVec3::new(0.3, 1.0, 0.2).normalize(), 6f64.to_radians()),
        shift: DVec3::new(0.25, -0.15, 0.2),
        centre,
    };
    let (ca, cb) = (
        camera(DVec3::ZERO, 0.0),
        camera(DVec3::new(0.1, 0.0, 0.0), 1.5),
    );
    let (a, b) = (
        Pyramid::new(draw(&ca, &rest, f64::INFINITY), LEVELS),
        Pyramid::new(draw(&cb, &truth, f64::INFINITY), LEVELS),
    );
    // The plane's points under the central pixels of the first image.
    let xs: Vec<DVec3> = (16..48)
        .flat_map(|y| (16..48).map(move |x| DVec2::new(x as f64, y as f64)))
        .map(|px| ca.unproject_world(px, -PLANE_Z))
        .collect();
    let found = part_motion::step(&a, &b, &ca, &cb, &xs, rest).expect("followed");
    let mut worst = 0.0f64;
    let mut start = 0.0f64;
    for &x in &xs {
        let want = cb.project_world(truth.apply(x)).expect("in front").0;
        let got = cb.project_world(found.apply(x)).expect("in front").0;
        worst = worst.max(got.distance(want));
        start = start.max(cb.project_world(x).expect("in front").0.distance(want));
    }
    assert!(start > 3.0, "the motion moves the points ({start:.2} px)");
    assert!(
        worst < 0.05,
        "worst point {worst:.3} px from the known motion"
    );
    let angle = (found.rot * truth.rot.inverse())
        .to_axis_angle()
        .1
        .to_degrees();
    assert!(angle < 0.2, "rotation off by {angle:.3}°");
}

#[test]
fn too_few_points_inside_the_images_are_not_followed() {
    let cam = camera(DVec3::ZERO, 0.0);
    let img = Pyramid::new(
        draw(&cam, &Motion::identity(DVec3::ZERO), f64::INFINITY),
        LEVELS,
    );
    // Behind the camera: no point projects.
    let xs = vec![DVec3::new(0.0, 0.0, 5.0); 100];
    assert!(
        part_motion::step(&img, &img, &cam, &cam, &xs, Motion::identity(DVec3::ZERO)).is_none()
    );
}

/// The body's motion from the reference frame (2 of 0..=4): turning 5° per frame about a
/// tilted axis through its centre and drifting 0.1–0.15 units per frame.
fn body_motion(k: usize) -> Motion {
    let d = k as f64 - 2.0;
    Motion {
        rot: DQuat::from_axis_angle(
            DVec3::new(0.2, 0.3, 1.0).normalize(),
            (5.0 * d).to_radians(),
        ),
        shift: DVec3::new(0.12, -0.06, 0.1) * d,
        centre: DVec3::new(0.0, 0.0, PLANE_Z),
    }
}

/// A group whose members were fitted at the middle frame only (so the seen-share gate
/// turns it away) is followed through the frames as one part when the images are given:
/// its poses put every member where the known motion does at every frame.
#[test]
fn a_group_seen_at_one_frame_is_followed_through_the_images() {
    use gaussians::splats::{Gaussian, Splats};
    let times = [0.0, 0.25, 0.5, 0.75, 1.0];
    let cam = camera(DVec3::ZERO, 0.0);
    let cams = [&cam; 5];
    let grey: Vec<Grey> = (0..5).map(|k| draw(&cam, &body_motion(k), 1.2)).collect();
    let seq = part_motion::Sequence::new(grey, Vec::new(), &cams);
    // Movers on the square at the middle frame, every second pixel inside its inner part,
    // each with a trajectory fitted there alone.
    let mut s = Splats::default();
    s.push(Gaussian::isotropic([0.0, 0.0, -20.0], -2.0, 0.0, [0.0; 3]));
    s.motion.push([0.0; 6]);
    s.life.push([f32::MIN, f32::MAX]);
    for y in (0..SIZE).step_by(2) {
        for x in (0..SIZE).step_by(2) {
            let px = DVec2::new(x as f64, y as f64);
            let on = cam.unproject_world(px, -PLANE_Z);
            if on.x.abs() > 0.9 || on.y.abs() > 0.9 {
                continue;
            }
            // Off the plane by up to 0.1 % (a lifted depth's error), so that no two
            // members share a coordinate.
            let p = cam.unproject_world(
                px,
                -PLANE_Z * (1.0 + 1e-3 * ((x * 7 + y * 3) % 5) as f64 / 4.0),
            );
            s.push(Gaussian::isotropic(
                p.as_vec3().to_array(),
                -3.0,
                0.0,
                [0.0; 3],
            ));
            *s.motion.last_mut().expect("pushed") = [0.48, -0.24, 0.4, 0.0, 0.0, 0.0];
            *s.life.last_mut().expect("pushed") = [0.5, 0.5];
        }
    }
    let members = s.len() - 1;
    let before = s.clone();
    let sum = gaussians::tracks::parts::into_parts(&mut s, &times, &cams, 2.0, None, None);
    assert_eq!(
        (sum.parts, sum.unseen),
        (0, 1),
        "without images: turned away ({sum:?})"
    );
    let mut s = before.clone();
    let sum = gaussians::tracks::parts::into_parts(&mut s, &times, &cams, 2.0, None, Some(&seq));
    assert_eq!(
        (sum.parts, sum.followed, sum.members),
        (1, 1, members),
        "{sum:?}"
    );
    let o = s.parts.origin[0].map(|v| v as f64);
    let (mut worst, mut moved) = (0.0f64, 0.0f64);
    for (k, &t) in times.iter().enumerate() {
        let (q, sh) = s.parts.pose(0, t as f32);
        let (q, sh) = (q.map(|v| v as f64), sh.map(|v| v as f64));
        for i in 1..=members {
            let a = DVec3::from_array(before.means[i].map(|v| v as f64));
            let r = gaussians::parts::rotate(q, (a - DVec3::from_array(o)).to_array());
            let got = DVec3::from_array(r) + DVec3::from_array(o) + DVec3::from_array(sh);
            let want = body_motion(k).apply(a);
            let e = cam
                .project_world(got)
                .unwrap()
                .0
                .distance(cam.project_world(want).unwrap().0);
            worst = worst.max(e);
            moved = moved.max(
                cam.project_world(a)
                    .unwrap()
                    .0
                    .distance(cam.project_world(want).unwrap().0),
            );
        }
    }
    assert!(moved > 5.0, "the body moves ({moved:.1} px)");
    assert!(worst < 0.2, "a member {worst:.3} px from the known motion");
}
