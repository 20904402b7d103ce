//! The still test of the tracks' lift with a depth prior (issue #30): over a short
//! baseline the rays' meeting point is loose in depth, so a still point whose rays meet
//! far off the prior is still a still point when one at the prior's depth fits them as
//! well; a moving point that mimics parallax over a wide baseline is not.

use gaussians::tracks::depth::Aligned;
use gaussians::tracks::lift::{self, Lifted, Observation};
use gaussians::tracks::lk::{Grey, Pyramid};
use gaussians::tracks::{Frame, TrackSettings, camera_pixel, lift_track};
use glam::{DQuat, DVec2, DVec3, Vec2};
use scene::{Camera, Intrinsics, Pose};

mod synth_frames;

const W: usize = 32;

/// Five cameras looking down −Z from `z = 4`, their centres at `x = ±spread` and between.
fn cameras(spread: f64) -> Vec<Camera> {
    let k = Intrinsics::from_fov_x(W as u32, W as u32, 60f64.to_radians());
    (0..5)
        .map(|i| Camera {
            intrinsics: k,
            cam_to_world: Pose::new(
                DQuat::IDENTITY,
                DVec3::new(spread * (i as f64 - 2.0) / 2.0, 0.0, 4.0),
            ),
        })
        .collect()
}

fn frames(cams: &[Camera]) -> Vec<Frame<'_>> {
    let flat = || Grey {
        width: W,
        height: W,
        data: vec![0.5; W * W],
    };
    (cams.iter().enumerate())
        .map(|(i, camera)| Frame {
            camera,
            time: i as f64 / 4.0,
            pyramid: Pyramid::new(flat(), 1),
            between: Vec::new(),
        })
        .collect()
}

/// Every frame's prior: the plane `z = 0`, 4 units in front of every camera (exact).
fn plane_priors() -> Vec<Option<Aligned>> {
    (0..5)
        .map(|_| {
            Some(Aligned {
                width: W,
                height: W,
                z: vec![4.0; W * W],
                median_rel_error: 0.0,
                points: 0,
            })
        })
        .collect()
}

/// Lucas–Kanade positions (pixel centres at `x + ½`) of `path(k)` in camera `k`, `x`
/// moved by `noise(k)` pixels.
fn track(
    cams: &[Camera],
    path: impl Fn(usize) -> DVec3,
    noise: impl Fn(usize) -> f64,
) -> Vec<Option<Vec2>> {
    (cams.iter().enumerate())
        .map(|(k, c)| {
            let (p, _) = c.project_world(path(k)).expect("in front");
            Some((p + DVec2::new(noise(k), 0.0) + 0.5).as_vec2())
        })
        .collect()
}

fn observations<'a>(
    cams: &'a [Camera],
    tr: &[Option<Vec2>],
    depth: Option<f64>,
) -> Vec<Observation<'a>> {
    (cams.iter().zip(tr))
        .map(|(camera, p)| Observation {
            camera,
            pixel: camera_pixel(p.unwrap()),
            tau: 0.0,
            depth,
        })
        .collect()
}

#[test]
fn a_still_point_over_a_short_baseline_stays_still_at_the_priors_depth() {
    // 4 cm of baseline at 4 units: 0.28 px of parallax end to end; the track drifts
    // 0.6 px the same way (Lucas–Kanade's error), so its rays meet at a third of the way.
    let cams = cameras(0.02);
    let x = DVec3::new(0.3, -0.2, 0.0);
    let tr = track(&cams, |_| x, |k| -0.3 * (k as f64 - 2.0) / 2.0);
    let st = TrackSettings::default();
    let rays = lift::still(&observations(&cams, &tr, None)).unwrap();
    let ray_depth = 4.0 - rays.z;
    assert!(
        (ray_depth - 4.0).abs() > 0.5 * 4.0,
        "premise: the rays meet at depth {ray_depth}, not far off 4"
    );
    // The point at the prior's depth fits the rays within a pixel: still, on the plane.
    let obs = observations(&cams, &tr, Some(4.0));
    let y = lift::still_with_depth(&obs, x, st.depth_sigma).unwrap();
    let rms = lift::rms_pixels(&Lifted::Still(y), &obs);
    assert!(rms < 0.3, "{rms} px");
    assert!((y.z).abs() < 0.05 * 4.0, "{y}");
    let f = frames(&cams);
    match lift_track(&f, &tr, &st, &plane_priors()) {
        Some(Lifted::Still(p)) => assert!(p.distance(x) < 0.2, "{p} vs {x}"),
        other => panic!("not still: {other:?}"),
    }
    // Without priors the same track is still at the rays' depth (they meet within a pixel).
    match lift_track(&f, &tr, &st, &[]) {
        Some(Lifted::Still(p)) => assert!(p.distance(rays) < 1e-9),
        other => panic!("not still: {other:?}"),
    }
}

#[test]
fn exact_rays_and_depths_give_the_point_back() {
    let cams = cameras(0.8);
    let x = DVec3::new(-0.4, 0.25, 0.0);
    let tr = track(&cams, |_| x, |_| 0.0);
    let y = lift::still_with_depth(&observations(&cams, &tr, Some(4.0)), x + 0.3, 0.05).unwrap();
    assert!(y.distance(x) < 1e-6, "{y} vs {x}");
}

#[test]
fn a_moving_point_that_mimics_parallax_is_not_still() {
    // 80 cm of baseline. On the plane (depth 4, the prior's) the point slides with the
    // camera so that its rays meet exactly at depth 2: P(t) = 2 Q − c(t) in x.
    let cams = cameras(0.8);
    let q = DVec3::new(0.1, 0.2, 2.0);
    let path = |k: usize| {
        let cx = cams[k].cam_to_world.centre().x;
        DVec3::new(2.0 * q.x - cx, 2.0 * q.y, 0.0)
    };
    let tr = track(&cams, path, |_| 0.0);
    let rays = lift::still(&observations(&cams, &tr, None)).unwrap();
    assert!(
        rays.distance(q) < 1e-6,
        "premise: the rays meet at {rays}, not {q}"
    );
    let st = TrackSettings::default();
    let obs = observations(&cams, &tr, Some(4.0));
    let y = lift::still_with_depth(&obs, path(2), st.depth_sigma).unwrap();
    assert!(lift::rms_pixels(&Lifted::Still(y), &obs) > st.still_pixels);
    let f = frames(&cams);
    let Some(Lifted::Moving { mu, v, a }) = lift_track(&f, &tr, &st, &plane_priors()) else {
        panic!("not moving")
    };
    // The trajectory at the prior's depth: on the plane at every frame, sliding in x.
    for (k, c) in cams.iter().enumerate() {
        let tau = f[k].time - 0.5;
        let p = mu + v * tau + a * tau * tau;
        assert!(p.distance(path(k)) < 0.05, "frame {k}: {p} vs {}", path(k));
        assert!(c.project_world(p).is_some());
    }
}

/// The tracks of a window's middle frame (`rigid` at 8 fps, 80²: three frames and one
/// either side, as `tracks.window` has them), lifted with priors that are the true depth
/// spoilt by a smooth 4 % wave: about half the tracks lifted to trajectories start on the
/// moving objects (by the synthetic world's own ray cast; 232 of 451), the rest on still
/// surfaces whose tracks drift by more than a pixel. Before the still test tried the
/// prior's depth, 390 of 1 274: the still floor and wall whose rays meet
/// off the prior over the window's short baseline were trajectories.
#[test]
fn a_windows_trajectories_start_on_the_moving_objects() {
    use gaussians::tracks::{lift_raw, raw_tracks_at};
    let mut cfg = synth::SynthConfig::preset("rigid").unwrap();
    cfg.width = 80;
    cfg.height = 80;
    cfg.train_fps = 8.0;
    let world = synth::SynthWorld::new(&cfg).unwrap();
    let all = cfg.train_times();
    let (t_first, t_last) = (all[0], *all.last().unwrap());
    let times = &all[2..7];
    let cams: Vec<Camera> = times.iter().map(|&t| world.camera_at(t)).collect();
    let renders: Vec<_> = times.iter().map(|&t| world.render(t)).collect();
    let frames = synth_frames::frames(&cams, times, &renders, (t_first, t_last));
    let priors: Vec<Option<Aligned>> = (renders.iter().enumerate())
        .map(|(k, r)| {
            let z = (r.depth.iter().enumerate())
                .map(|(p, &z)| {
                    let (x, y) = ((p % 80) as f32 / 80.0, (p / 80) as f32 / 80.0);
                    z * (1.0 + 0.04 * (6.0 * x + 4.0 * y + k as f32).sin())
                })
                .collect();
            Some(Aligned {
                width: 80,
                height: 80,
                z,
                median_rel_error: 0.0,
                points: 0,
            })
        })
        .collect();
    let st = TrackSettings::default();
    let raws = raw_tracks_at(&frames, 1, &[2], &st);
    let lifted = lift_raw(&frames, &raws, &st, &priors);
    let (mut on_moving, mut moving) = (0, 0);
    for l in &lifted {
        if !matches!(l.point, Lifted::Moving { .. }) {
            continue;
        }
        let px = DVec2::new(l.pixel.x.floor() as f64, l.pixel.y.floor() as f64);
        let Some(hit) = world.cast(times[l.frame], px) else {
            continue;
        };
        moving += 1;
        on_moving += usize::from(cfg.objects[hit.object].moves());
    }
    assert!(on_moving > 150, "{on_moving} of {moving} on moving objects");
    assert!(
        on_moving as f64 > 0.45 * moving as f64,
        "{on_moving} of {moving} trajectories start on moving objects"
    );
}
