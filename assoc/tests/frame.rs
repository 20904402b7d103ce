//! `associate_frame`: mismatched inputs give errors, not panics; its figures add up.

use assoc::{AssocSettings, FrameError, associate_frame};
use glam::{DVec2, DVec3};
use scene::{Camera, EventStream, Intrinsics, Pose};

/// A camera looking at the plane z = 0 from (0, 0, 4), its exact depth map, and events
/// on a 4-px grid of pixels.
fn plane() -> (Camera, Vec<f32>, EventStream) {
    let cam = Camera {
        intrinsics: Intrinsics::from_fov_x(40, 30, 1.0),
        cam_to_world: Pose::look_at(DVec3::new(0.0, 0.0, 4.0), DVec3::ZERO, DVec3::Y),
    };
    let mut depth = vec![0f32; 40 * 30];
    for v in 0..30 {
        for u in 0..40 {
            let dir = cam.unproject_world(DVec2::new(u as f64, v as f64), 1.0)
                - cam.cam_to_world.centre();
            depth[v * 40 + u] = (-cam.cam_to_world.centre().z / dir.z) as f32;
        }
    }
    let mut ev = EventStream::new(40, 30);
    for (i, (u, v)) in (0..40u16)
        .step_by(4)
        .flat_map(|u| (0..30u16).step_by(4).map(move |v| (u, v)))
        .enumerate()
    {
        ev.push(1.0 + i as f64 * 1e-5, u, v, 1);
    }
    (cam, depth, ev)
}

#[test]
fn gaussians_on_event_points_bind_at_zero_distance() {
    let (cam, depth, ev) = plane();
    let alpha = vec![1.0; depth.len()];
    // One Gaussian exactly at the lifted point of event 5, one far behind the camera.
    let p = cam.unproject_world(
        DVec2::new(ev.x[5] as f64, ev.y[5] as f64),
        depth[ev.y[5] as usize * 40 + ev.x[5] as usize] as f64,
    );
    let centres = vec![[p.x as f32, p.y as f32, p.z as f32], [0.0, 0.0, 10.0]];
    let s = AssocSettings::default();
    let (b, stats) =
        associate_frame(&cam, &depth, &alpha, &ev.as_slice(), &centres, 1.0, &s).unwrap();
    assert_eq!(stats.events_in_window, ev.len());
    assert_eq!(stats.events_used, ev.len());
    assert_eq!(stats.gaussians, 2);
    assert_eq!(stats.gaussians_bound, 1);
    // Grid events are 4 px apart, the radius is 2 px: only event 5 is in reach.
    let (events, weights) = b.of(0);
    assert_eq!(events, &[5]);
    assert_eq!(weights, &[1.0]);
    assert!(stats.distance_px_max < 1e-3, "{stats:?}");
    assert!(b.of(1).0.is_empty());
}

#[test]
fn mismatched_inputs_are_errors() {
    let (cam, depth, ev) = plane();
    let alpha = vec![1.0; depth.len()];
    let c = vec![[0.0f32; 3]];
    let s = AssocSettings::default();
    let e = associate_frame(&cam, &depth[1..], &alpha, &ev.as_slice(), &c, 0.0, &s).unwrap_err();
    assert_eq!(
        e,
        FrameError::DepthSize {
            got: 1199,
            w: 40,
            h: 30
        }
    );
    assert!(e.to_string().contains("40x30"));
    let e = associate_frame(&cam, &depth, &alpha[..10], &ev.as_slice(), &c, 0.0, &s).unwrap_err();
    assert!(matches!(e, FrameError::AlphaSize { got: 10, .. }));
    let e = associate_frame(&cam, &depth, &alpha, &ev.as_slice(), &[], 0.0, &s).unwrap_err();
    assert_eq!(e, FrameError::NoGaussians);
    // An event outside the camera's sensor (a stream of another size).
    let mut big = EventStream::new(64, 64);
    big.push(0.0, 3, 3, 1);
    big.push(0.1, 50, 3, -1);
    let e = associate_frame(&cam, &depth, &alpha, &big.as_slice(), &c, 0.0, &s).unwrap_err();
    assert!(
        matches!(
            e,
            FrameError::EventOutside {
                index: 1,
                x: 50,
                ..
            }
        ),
        "{e}"
    );
    let bad = AssocSettings {
        k: 0,
        ..AssocSettings::default()
    };
    let e = associate_frame(&cam, &depth, &alpha, &ev.as_slice(), &c, 0.0, &bad).unwrap_err();
    assert!(e.to_string().contains("k = 0"), "{e}");
}

#[test]
fn default_radius_is_the_pixel_footprint_at_the_gaussians_depth() {
    use assoc::{bind_nearest, footprint_radii};
    use glam::DQuat;
    use scene::Pose;
    // Identity rotation: camera-space depth is exactly translation.z − world z.
    let cam = Camera {
        intrinsics: Intrinsics::from_fov_x(40, 30, 1.0),
        cam_to_world: Pose {
            rotation: DQuat::IDENTITY,
            translation: DVec3::new(0.5, -0.25, 1.0),
        },
    };
    let fx = cam.intrinsics.fx;
    let radius_px = 2.0;
    let centres = [
        [0.5f32, -0.25, -1.0], // on the axis, depth 2
        [0.5, -0.25, -4.0],    // on the axis, depth 5
        [2.0, 0.5, -4.0],      // off the axis, depth 5 (range is larger)
        [0.5, -0.25, 4.0],     // behind the camera, depth −3
        [0.5, -0.25, 1.0],     // in the camera's plane, depth 0
    ];
    let r = footprint_radii(&cam, &centres, radius_px);
    assert_eq!(r.len(), 5);
    assert_eq!(r[0], (radius_px * 2.0 / fx) as f32);
    assert_eq!(r[1], (radius_px * 5.0 / fx) as f32);
    // fx = 20 / tan(0.5) ≈ 36.61: 2 px at depth 2 is ≈ 0.10926 world units.
    assert!((r[0] - 0.109_26).abs() < 2e-6, "{}", r[0]);
    // r ∝ depth (not range): 5/2, and the off-axis Gaussian at depth 5 gets r[1].
    assert!((r[1] / r[0] - 2.5).abs() < 1e-6, "{} / {}", r[1], r[0]);
    assert_eq!(r[2], r[1]);
    // Scaling radius_px scales r linearly.
    let r4 = footprint_radii(&cam, &centres, 2.0 * radius_px);
    assert!((r4[1] / r[1] - 2.0).abs() < 1e-6);
    assert_eq!((r[3], r[4], r4[3], r4[4]), (0.0, 0.0, 0.0, 0.0));

    // Radius 0 binds nothing, even to a point exactly at the centre; the others bind.
    let (b, d) = bind_nearest(&centres, &[10, 11, 12, 13, 14], &centres, &r, 3);
    assert_eq!(b.offsets, vec![0, 1, 2, 3, 3, 3]);
    assert_eq!(b.events, vec![10, 11, 12]);
    assert_eq!(d, vec![0.0; 3]);
}
