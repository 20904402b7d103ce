//! Without depth priors a moving track needs 5 observations (9 unknowns, 2 rows a ray):
//! a window of 3 frames has too few. Its positions in the event images between the
//! frames count as observations too (`tracks::between_positions`, used by `lift_track`).
//! Checked against the analytic image motion of a textured plane sliding at constant
//! speed in front of a camera that rises with acceleration (so that the true path is the
//! least accelerated of those the rays allow, and the lift's penalty picks it): the
//! in-between positions where the plane truly is, the 3-frame track lifted only with
//! them, and the lifted trajectory at times no observation saw where the plane is in
//! the image.

use gaussians::tracks::lift::Lifted;
use gaussians::tracks::lk::{Grey, Pyramid};
use gaussians::tracks::{Frame, TrackSettings, between_positions, lift_track, track_within};
use glam::{DQuat, DVec2, DVec3, Vec2};
use scene::{Camera, Intrinsics, Pose};

const W: usize = 64;
const DEPTH: f64 = 4.0;

/// A smooth texture (sums of sinusoids) sampled at pixel centres shifted by `d`.
fn texture(d: DVec2) -> Grey {
    let f = |x: f64, y: f64| {
        0.5 + 0.15 * (0.31 * x + 0.11 * y).sin()
            + 0.12 * (0.07 * x - 0.23 * y).cos()
            + 0.1 * (0.133 * x + 0.29 * y).sin()
    };
    let data = (0..W * W)
        .map(|i| f((i % W) as f64 + 0.5 - d.x, (i / W) as f64 + 0.5 - d.y) as f32)
        .collect();
    Grey {
        width: W,
        height: W,
        data,
    }
}

fn intrinsics() -> Intrinsics {
    Intrinsics::from_fov_x(W as u32, W as u32, 60f64.to_radians())
}

/// The camera rises along +Y, accelerating (interpolated linearly between frames a
/// sixth of the recording apart, it is off by at most 0.006, 0.08 px).
fn camera_centre(t: f64) -> DVec3 {
    DVec3::new(0.0, 0.6 * t + 0.8 * t * t, 0.0)
}

/// The plane (at z = −DEPTH, facing the camera) slides along +X at constant speed.
fn plane_shift(t: f64) -> DVec3 {
    DVec3::new(1.0 * t, 0.0, 0.0)
}

/// The image of the plane at `t` moves by this many pixels (a camera looking down −Z).
fn image_shift(t: f64) -> DVec2 {
    let k = intrinsics();
    let rel = plane_shift(t) - camera_centre(t);
    DVec2::new(k.fx * rel.x / DEPTH, -k.fy * rel.y / DEPTH)
}

fn camera(t: f64) -> Camera {
    Camera {
        intrinsics: intrinsics(),
        cam_to_world: Pose::new(DQuat::IDENTITY, camera_centre(t)),
    }
}

#[test]
fn event_image_positions_lift_a_window_the_frames_alone_cannot() {
    let n = 7;
    let times: Vec<f64> = (0..n).map(|i| i as f64 / (n - 1) as f64).collect();
    let cams: Vec<Camera> = times.iter().map(|&t| camera(t)).collect();
    let steps = 2;
    let frames_with = |between: bool| -> Vec<Frame> {
        (0..n)
            .map(|k| Frame {
                camera: &cams[k],
                time: times[k],
                pyramid: Pyramid::new(texture(image_shift(times[k])), 3),
                between: if between && k + 1 < n {
                    (1..=steps)
                        .map(|j| {
                            let s = j as f64 / (steps + 1) as f64;
                            let t = times[k] + s * (times[k + 1] - times[k]);
                            Pyramid::new(texture(image_shift(t)), 3)
                        })
                        .collect()
                } else {
                    Vec::new()
                },
            })
            .collect()
    };
    let st = TrackSettings::default();
    let (r, p) = (3, Vec2::new(30.5, 30.5));
    // Where the texture point under `p` in frame `r` is at time `t` (LK pixels).
    let truth = |t: f64| {
        let d = image_shift(t) - image_shift(times[r]);
        DVec2::new(p.x as f64 + d.x, p.y as f64 + d.y)
    };

    // Frames alone: seen in 3 frames only, so no trajectory (nor a still point: the
    // camera moves along Y, the image along X).
    let alone = frames_with(false);
    let track = track_within(&alone, r, p, &st, 2..5);
    assert_eq!(track.iter().flatten().count(), 3);
    for (k, q) in track.iter().enumerate() {
        if let Some(q) = q {
            let e = DVec2::new(q.x as f64, q.y as f64).distance(truth(times[k]));
            assert!(e < 0.2, "frame {k}: {e} px off");
        }
    }
    assert_eq!(lift_track(&alone, &track, &st, &[]), None);

    // With the event images: 4 positions between frames 2, 3 and 4, each where the
    // plane is at its time, by the camera of that time.
    let with = frames_with(true);
    let track = track_within(&with, r, p, &st, 2..5);
    let between = between_positions(&with, &track, &st);
    assert_eq!(between.len(), 2 * steps);
    for (cam, t, px) in &between {
        let want = truth(*t) - DVec2::splat(0.5); // camera pixels: centre of pixel x at x
        assert!(px.distance(want) < 0.2, "t = {t}: {px} vs {want}");
        assert!(cam.cam_to_world.translation.distance(camera_centre(*t)) < 0.01);
    }
    let lifted = lift_track(&with, &track, &st, &[]).expect("lifts with the event images");
    assert!(matches!(lifted, Lifted::Moving { .. }), "{lifted:?}");
    // Reprojected at times no observation saw (a sixth, a half and five sixths of each
    // of the two intervals), the trajectory is where the plane is in the image. (Not its
    // distance: over a window of a third of the recording the camera's path departs from
    // a line by 0.3 px, so the distance is barely observed: what depth priors are for.)
    let t0 = gaussians::motion::T0 as f64;
    for k in 2..4 {
        for s in [1.0 / 6.0, 0.5, 5.0 / 6.0] {
            let t = times[k] + s * (times[k + 1] - times[k]);
            let (px, _) = camera(t)
                .project_world(lifted.at(t - t0))
                .expect("in front");
            let want = truth(t) - DVec2::splat(0.5);
            assert!(px.distance(want) < 0.5, "t = {t}: {px} vs {want}");
        }
    }
}
