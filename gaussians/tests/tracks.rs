//! Tracks init (issue #30): Lucas–Kanade against known sub-pixel shifts of an analytic
//! texture, the lift against exact projections of known trajectories, and the whole
//! init against the ground truth of a synthetic scene.

use gaussians::tracks::lift::{self, Lifted, Observation};
use gaussians::tracks::lk::{self, Grey, Pyramid, track};
use gaussians::tracks::{Frame, TrackSettings, lift_frames, lift_track, track_from, track_within};
use glam::{DQuat, DVec3, Vec2};
use scene::{Camera, Intrinsics, Pose};

mod synth_frames;

/// A smooth texture: a sum of sinusoids, sampled at pixel centres shifted by `d`.
fn texture(w: usize, h: usize, d: Vec2) -> Grey {
    textured(w, h, d, 0.0)
}

/// The smooth texture plus `fine` × waves of about 4.5 px period, which a window
/// started more than a couple of pixels off locks onto the wrong crest of.
fn textured(w: usize, h: usize, d: Vec2, fine: f32) -> Grey {
    let f = |x: f32, y: f32| {
        0.5 + 0.15 * (0.31 * x + 0.11 * y).sin()
            + 0.12 * (0.07 * x - 0.23 * y).cos()
            + 0.1 * (0.19 * x * 0.7 + 0.29 * y).sin()
            + fine * ((1.3 * x + 0.5 * y).sin() + (0.6 * x - 1.2 * y).cos())
    };
    let data = (0..w * h)
        .map(|i| f((i % w) as f32 + 0.5 - d.x, (i / w) as f32 + 0.5 - d.y))
        .collect();
    Grey {
        width: w,
        height: h,
        data,
    }
}

#[test]
fn lucas_kanade_started_at_a_guess_follows_a_shift_beyond_its_reach() {
    // A 24 px shift of the fine-wave texture: three levels reach about 12 px, so from no
    // guess the window locks onto a wrong crest; started within a pixel it lands on the
    // truth (the start is the finest level's displacement, handed down the pyramid).
    let (w, h) = (128, 128);
    let d = Vec2::new(21.3, -11.6);
    let a = Pyramid::new(textured(w, h, Vec2::ZERO, 0.08), 3);
    let b = Pyramid::new(textured(w, h, d, 0.08), 3);
    for p in [Vec2::new(40.5, 70.5), Vec2::new(50.25, 60.75)] {
        let blind = track(&a, &b, p, 3, 1e-6);
        assert!(blind.is_none_or(|q| q.distance(p + d) > 1.0), "{blind:?}");
        let guess = d + Vec2::new(0.8, -0.6);
        let q = lk::track_from(&a, &b, p, guess, 3, 1e-6).expect("textured window");
        assert!(q.distance(p + d) < 0.15, "from {guess}: {q} vs {}", p + d);
        let same = lk::track_from(&a, &b, p, Vec2::ZERO, 3, 1e-6);
        assert_eq!(same, blind, "no guess is `track`");
    }
}

#[test]
fn lucas_kanade_finds_known_sub_pixel_and_large_shifts() {
    let (w, h) = (96, 96);
    let a = Pyramid::new(texture(w, h, Vec2::ZERO), 3);
    for d in [
        Vec2::new(0.37, -0.81),
        Vec2::new(2.3, -1.7),
        Vec2::new(6.4, 3.1),
        Vec2::new(10.3, -7.6),
    ] {
        let b = Pyramid::new(texture(w, h, d), 3);
        for p in [
            Vec2::new(30.5, 40.5),
            Vec2::new(50.25, 33.75),
            Vec2::new(60.5, 60.5),
        ] {
            let q = track(&a, &b, p, 3, 1e-6).expect("textured window");
            assert!(
                q.distance(p + d) < 0.1,
                "shift {d}: tracked {p} to {q}, truth {}",
                p + d
            );
        }
    }
    // Fine waves: each level must hand the next twice its estimate (coarse to fine), or
    // the finest level starts pixels off and locks onto a wrong crest.
    let a = Pyramid::new(textured(w, h, Vec2::ZERO, 0.08), 3);
    for d in [Vec2::new(6.4, 3.1), Vec2::new(10.3, -7.6)] {
        let b = Pyramid::new(textured(w, h, d, 0.08), 3);
        for p in [Vec2::new(30.5, 40.5), Vec2::new(60.5, 60.5)] {
            let q = track(&a, &b, p, 3, 1e-6).expect("textured window");
            assert!(
                q.distance(p + d) < 0.15,
                "fine waves, shift {d}: {q} vs {}",
                p + d
            );
        }
    }
    // One level cannot follow a shift larger than its window's reach; three can (above).
    let one = Pyramid::new(texture(w, h, Vec2::ZERO), 1);
    let far = Pyramid::new(texture(w, h, Vec2::new(6.4, 3.1)), 1);
    let q = track(&one, &far, Vec2::new(50.5, 50.5), 3, 1e-6);
    assert!(q.is_none_or(|q| q.distance(Vec2::new(56.9, 53.6)) > 0.5));
    // A flat window has no displacement.
    let flat = Grey {
        width: w,
        height: h,
        data: vec![0.5; w * h],
    };
    let fp = Pyramid::new(flat, 3);
    assert!(track(&fp, &fp, Vec2::new(40.5, 40.5), 3, 1e-6).is_none());
}

/// Cameras on a circle arc about the origin, looking at it, at times `t_k` (normalised).
fn arc_cameras(n: usize) -> (Vec<Camera>, Vec<f64>) {
    let k = Intrinsics::from_fov_x(96, 96, 60f64.to_radians());
    let times: Vec<f64> = (0..n).map(|i| i as f64 / (n - 1) as f64).collect();
    let cams = times
        .iter()
        .map(|&t| {
            // 90° of arc with a cubic wobble: far from any quadratic in t.
            let ang = (t - 0.5) * std::f64::consts::FRAC_PI_2 + 0.3 * (t - 0.5).powi(3);
            let eye = DVec3::new(
                4.0 * ang.sin(),
                0.5 + 0.4 * (t - 0.5).powi(3),
                4.0 * ang.cos(),
            );
            Camera {
                intrinsics: k,
                cam_to_world: Pose::look_at(eye, DVec3::ZERO, DVec3::Y),
            }
        })
        .collect();
    (cams, times)
}

fn observe<'a>(
    cams: &'a [Camera],
    times: &[f64],
    path: impl Fn(f64) -> DVec3,
) -> Vec<Observation<'a>> {
    cams.iter()
        .zip(times)
        .map(|(c, &t)| Observation {
            camera: c,
            pixel: c.project_world(path(t - 0.5)).expect("in front").0,
            tau: t - 0.5,
            depth: None,
        })
        .collect()
}

#[test]
fn the_lift_recovers_still_points_and_quadratic_trajectories_exactly() {
    let (cams, times) = arc_cameras(9);
    let x = DVec3::new(0.3, -0.2, 0.4);
    let obs = observe(&cams, &times, |_| x);
    let s = lift::still(&obs).unwrap();
    assert!(s.distance(x) < 1e-9, "{s} vs {x}");
    assert!(lift::rms_pixels(&Lifted::Still(s), &obs) < 1e-6);

    let (mu, v, a) = (
        DVec3::new(-0.2, 0.1, 0.3),
        DVec3::new(0.6, -0.2, 0.4),
        DVec3::new(-0.5, 0.8, 0.3),
    );
    let obs = observe(&cams, &times, |t| mu + v * t + a * t * t);
    let moving = lift::moving(&obs, lift::still(&obs).unwrap(), 0.0, 0.0).unwrap();
    let Lifted::Moving {
        mu: m,
        v: vv,
        a: aa,
    } = moving
    else {
        panic!("moving")
    };
    assert!(
        m.distance(mu) < 1e-6 && vv.distance(v) < 1e-6 && aa.distance(a) < 1e-6,
        "{moving:?}"
    );
    // The still fit leaves the moving point's rays apart: it is not called still.
    let still_rms = lift::rms_pixels(&Lifted::Still(lift::still(&obs).unwrap()), &obs);
    assert!(still_rms > 3.0, "{still_rms}");
}

/// Nine cameras at times 0, ⅛, …, 1 whose centres move along a parabola (sideways
/// linearly, upwards quadratically), looking down −Z.
fn parabola_cameras() -> (Vec<Camera>, Vec<f64>) {
    let k = Intrinsics::from_fov_x(96, 96, 60f64.to_radians());
    let times: Vec<f64> = (0..9).map(|i| i as f64 / 8.0).collect();
    let cams = times
        .iter()
        .map(|&t| {
            let tau = t - 0.5;
            let eye = DVec3::new(1.5 * tau, 0.3 + 2.0 * tau * tau, 4.0);
            Camera {
                intrinsics: k,
                cam_to_world: Pose::new(DQuat::IDENTITY, eye),
            }
        })
        .collect();
    (cams, times)
}

#[test]
fn the_ridge_picks_the_still_acceleration_when_the_camera_path_is_quadratic() {
    // A camera moving along a parabola and a point moving at constant velocity: the
    // family C(τ) + s (X(τ) − C(τ)) fits every observation for any s, with
    // acceleration (1 − s)·C''. The penalty selects s = 1, the true (unaccelerated) path.
    let (cams, times) = parabola_cameras();
    let (mu, v) = (DVec3::new(0.2, 0.1, 0.0), DVec3::new(-0.6, 0.3, 0.5));
    let obs = observe(&cams, &times, |t| mu + v * t);
    let guess = lift::still(&obs).unwrap();
    let Lifted::Moving { mu: m, v: vv, a } = lift::moving(&obs, guess, 10.0, 0.0).unwrap() else {
        panic!("moving")
    };
    assert!(
        a.length() < 1e-3 && m.distance(mu) < 1e-3 && vv.distance(v) < 1e-3,
        "{m} {vv} {a}"
    );
}

/// The camera on a parabola and the point accelerating: every member of the family
/// `C(τ) + s (X(τ) − C(τ))` is a quadratic, so the rays alone cannot tell `s` and the
/// ridge picks a wrong one; the true depths (what an aligned prior gives) pin it.
#[test]
fn depth_rows_fix_the_distance_the_rays_leave_free() {
    let (cams, times) = parabola_cameras();
    let (mu, v, a) = (
        DVec3::new(0.2, 0.1, 0.0),
        DVec3::new(-0.6, 0.3, 0.5),
        DVec3::new(0.4, -0.3, 0.2),
    );
    let path = |t: f64| mu + v * t + a * t * t;
    let mut obs = observe(&cams, &times, path);
    let guess = lift::still(&obs).unwrap();
    let err = |l: Lifted| {
        (0..9)
            .map(|i| {
                l.at(i as f64 / 8.0 - 0.5)
                    .distance(path(i as f64 / 8.0 - 0.5))
            })
            .fold(0.0, f64::max)
    };
    let rays_only = lift::moving(&obs, guess, 10.0, 0.05).unwrap();
    assert!(err(rays_only) > 0.05, "rays alone: {}", err(rays_only));
    for o in &mut obs {
        o.depth = Some(o.camera.project_world(path(o.tau)).unwrap().1);
    }
    let with_depth = lift::moving(&obs, guess, 0.0, 0.05).unwrap();
    assert!(err(with_depth) < 1e-6, "with depths: {}", err(with_depth));
    // The small ridge kept with depths (`depth_ridge`) barely pulls; the rays-only
    // ridge would (0.22 here).
    let both = lift::moving(&obs, guess, 1e-3, 0.05).unwrap();
    assert!(
        err(both) < 0.02 * err(rays_only),
        "{} vs {}",
        err(both),
        err(rays_only)
    );
}

#[test]
fn chained_tracks_follow_a_moving_texture_and_classify_it() {
    // Frames of a texture sliding by a known amount per frame, seen by cameras that are
    // all the same: the image motion is the texture's, so the lift must call it moving
    // (rays from one centre never meet elsewhere) and keep the links exact.
    let (w, h) = (64, 64);
    let k = Intrinsics::from_fov_x(w as u32, h as u32, 60f64.to_radians());
    let cam = Camera {
        intrinsics: k,
        cam_to_world: Pose::new(DQuat::IDENTITY, DVec3::ZERO),
    };
    let step = Vec2::new(0.8, -0.5);
    let frames: Vec<Frame> = (0..7)
        .map(|i| Frame {
            camera: &cam,
            time: i as f64 / 6.0,
            pyramid: Pyramid::new(texture(w, h, step * i as f32), 3),
            between: Vec::new(),
        })
        .collect();
    let st = TrackSettings::default();
    let p = Vec2::new(30.5, 30.5);
    let tr = track_from(&frames, 3, p, &st);
    for (i, q) in tr.iter().enumerate() {
        let q = q.expect("tracked through every frame");
        let truth = p + step * (i as f32 - 3.0);
        assert!(q.distance(truth) < 0.2, "frame {i}: {q} vs {truth}");
    }
    // Followed over frames 2..5 only: the same positions there, none outside.
    let within = track_within(&frames, 3, p, &st, 2..5);
    for (i, (a, b)) in within.iter().zip(&tr).enumerate() {
        let want = if (2..5).contains(&i) { *b } else { None };
        assert_eq!(*a, want, "frame {i}");
    }
    // One camera centre: every ray passes through it, so no still point fits and no
    // depth is defined; the lift must not invent one.
    let lifted = lift_track(&frames, &tr, &st, &[]);
    assert!(
        lifted.is_none_or(|l| !matches!(l, Lifted::Still(_))),
        "{lifted:?}"
    );
}

#[test]
fn on_a_synthetic_scene_still_tracks_are_on_still_surfaces_and_moving_ones_move() {
    let mut cfg = synth::SynthConfig::preset("rigid").unwrap();
    cfg.width = 80;
    cfg.height = 80;
    let world = synth::SynthWorld::new(&cfg).unwrap();
    let times = cfg.train_times();
    let cams: Vec<Camera> = times.iter().map(|&t| world.camera_at(t)).collect();
    let renders: Vec<_> = times.iter().map(|&t| world.render(t)).collect();
    let (t_first, t_last) = (times[0], *times.last().unwrap());
    let frames = synth_frames::frames(&cams, &times, &renders, (t_first, t_last));
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let lifted = lift_frames(&frames, 1, 5, &TrackSettings::default());
    let (mut still_ok, mut still_n, mut moving_ok, mut moving_n) = (0, 0, 0, 0);
    let (mut still_err, mut moving_err, mut still_px) = (vec![], vec![], vec![]);
    for l in &lifted {
        let f = &frames[l.frame];
        // Lucas–Kanade's pixel (x + ½, y + ½) is the camera's pixel (x, y): the ray the
        // renderer cast for it.
        let px = glam::DVec2::new(l.pixel.x.floor() as f64, l.pixel.y.floor() as f64);
        let Some(hit) = world.cast(times[l.frame], px) else {
            continue;
        };
        if let Lifted::Still(x) = l.point {
            let (a, b) = (f.camera.project_world(x), f.camera.project_world(hit.world));
            still_px.push((a.unwrap().0 - b.unwrap().0).length());
        }
        let truth = renders[l.frame].depth[l.pixel.y as usize * 80 + l.pixel.x as usize] as f64;
        let (_, depth) = f.camera.project_world(l.point.at(f.time - 0.5)).unwrap();
        let err = ((depth - truth) / truth).abs();
        let moves = cfg.objects[hit.object].moves();
        match l.point {
            Lifted::Still(_) => {
                still_n += 1;
                still_ok += usize::from(!moves);
                still_err.push(err);
            }
            Lifted::Moving { .. } => {
                moving_n += 1;
                moving_ok += usize::from(moves);
                moving_err.push(err);
            }
        }
    }
    assert!(
        still_n > 2000 && moving_n > 100,
        "{still_n} still, {moving_n} moving"
    );
    assert!(
        still_ok as f64 > 0.95 * still_n as f64,
        "{still_ok} of {still_n} still on still objects"
    );
    // Lucas–Kanade drifts at occlusion edges, so some still pixels look moving; most
    // moving tracks are on the moving objects all the same.
    assert!(
        moving_ok as f64 > 0.5 * moving_n as f64,
        "{moving_ok} of {moving_n} moving on moving objects"
    );
    let (ms, mm) = (median(&mut still_err), median(&mut moving_err));
    // Still points triangulate; moving ones are bounded by the depth ambiguity (the
    // stereo init, which assumes a still scene, is 45 % off on them: BENCHMARKS.md).
    assert!(ms < 0.03, "still depth error median {ms}");
    assert!(mm < 0.3, "moving depth error median {mm}");
    // Where a still track's point lands in its own frame against where the surface seen
    // through that pixel's centre does (half a pixel each way, 0.71 px, before the
    // tracks' pixels were taken in the cameras' convention).
    let sp = median(&mut still_px);
    assert!(
        sp < 0.3,
        "still points {sp} px from their pixels' surface points (median)"
    );
}

/// `L_track`'s value against the camera's own projection and its gradient against f64
/// central differences, inside and beyond the Huber threshold, with Gaussians that have
/// no track, a track lost in this view and one behind the camera.
#[test]
fn the_track_term_matches_projections_and_central_differences() {
    use gaussians::tracks::loss::{NONE, at_view};
    use glam::DVec2;
    let cam = Camera {
        intrinsics: Intrinsics::from_fov_x(96, 64, 50f64.to_radians()),
        cam_to_world: Pose::look_at(
            DVec3::new(0.4, 0.3, 3.0),
            DVec3::new(0.1, -0.2, 0.0),
            DVec3::Y,
        ),
    };
    let means: Vec<[f32; 3]> = vec![
        [0.1, 0.2, 0.3],
        [-0.4, 0.1, -0.2],
        [0.3, -0.5, 0.1],
        [0.0, 0.0, 0.0],
        [0.5, 0.4, -0.3],
        [0.4, 0.3, 3.5], // behind the camera
    ];
    let ids = vec![0, 1, NONE, 2, 3, 4];
    let seen = |i: usize, off: DVec2| {
        let x = DVec3::from(means[i].map(f64::from));
        Some(cam.project_world(x).unwrap().0 + off)
    };
    // Gaussian 0 within the 1.5 px threshold, 1 and 4 beyond it; track 2 lost here.
    let table = vec![
        vec![None, seen(0, DVec2::new(0.6, -0.9))],
        vec![None, seen(1, DVec2::new(-4.0, 2.5))],
        vec![None, None],
        vec![None, seen(4, DVec2::new(3.0, 3.0))],
        vec![None, Some(DVec2::new(10.0, 10.0))],
    ];
    let (w, huber) = (0.7, 1.5);
    let mut g = Vec::new();
    let (loss, n) = at_view(&means, &ids, &table, 1, &cam, w, huber, &mut g);
    assert_eq!(n, 3);
    let h = |r: f64| {
        if r <= huber {
            0.5 * r * r
        } else {
            huber * (r - 0.5 * huber)
        }
    };
    let expected = w / 3.0
        * [(0, 0), (1, 1), (4, 3)]
            .iter()
            .map(|&(i, k)| {
                let x = DVec3::from(means[i].map(f64::from));
                h((cam.project_world(x).unwrap().0 - table[k][1].unwrap()).length())
            })
            .sum::<f64>();
    assert!(
        (loss - expected).abs() < 1e-9 * expected,
        "{loss} vs {expected}"
    );
    for i in 0..means.len() {
        for c in 0..3 {
            let step = 1e-3f32;
            let at = |d: f32| {
                let mut m = means.clone();
                m[i][c] += d;
                let mut scratch = Vec::new();
                at_view(&m, &ids, &table, 1, &cam, w, huber, &mut scratch).0
            };
            let fd = (at(step) - at(-step)) / (2.0 * step as f64);
            let an = g[i][c] as f64;
            assert!(
                (an - fd).abs() <= 1e-3 * fd.abs().max(1e-2),
                "Gaussian {i} axis {c}: {an} vs {fd}"
            );
        }
    }
    assert!(g[2] == [0.0; 3] && g[3] == [0.0; 3] && g[5] == [0.0; 3]);
}

/// `tracks.safetensors` read back as written (lost positions included), and a file for
/// another model or another set of views refused with the file's name.
#[test]
fn the_tracks_file_reads_back_and_refuses_what_does_not_fit() {
    use gaussians::tracks::file::{TRACKS_FILE, read, write};
    use gaussians::tracks::loss::NONE;
    use glam::DVec2;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(TRACKS_FILE);
    let table = vec![
        vec![
            Some(DVec2::new(1.5, 2.25)),
            None,
            Some(DVec2::new(-0.5, 7.0)),
        ],
        vec![None, Some(DVec2::new(10.0, 0.125)), None],
    ];
    let ids = vec![NONE, 1, 0, NONE];
    write(&path, &ids, &table).unwrap();
    let (ids2, table2) = read(&path, 4, 3).unwrap();
    assert_eq!((ids2, table2), (ids, table));
    for (n, views) in [(5, 3), (4, 2)] {
        let e = read(&path, n, views).unwrap_err().to_string();
        assert!(e.contains(TRACKS_FILE), "{e}");
    }
}

/// Three cameras over a still plane 4 units away, the priors its true depth except where
/// frame 0 sees something 2.5 units away in front of one point: a Gaussian on the plane
/// stays (also the one hidden in one frame of three), one floating 1.5 units in front of
/// it (where a stereo init puts a moving object) goes.
#[test]
fn the_prior_drops_initial_gaussians_off_its_surface() {
    use gaussians::splats::{Gaussian, Splats};
    use gaussians::tracks::{depth::Aligned, drop_where_prior_disagrees};
    let (w, h) = (32usize, 32usize);
    let k = Intrinsics::from_fov_x(w as u32, h as u32, 60f64.to_radians());
    let cams: Vec<Camera> = [-0.4, 0.0, 0.4]
        .iter()
        .map(|&x| Camera {
            intrinsics: k,
            cam_to_world: Pose::new(DQuat::IDENTITY, DVec3::new(x, 0.0, 4.0)),
        })
        .collect();
    let frames: Vec<Frame> = (cams.iter().enumerate())
        .map(|(i, c)| Frame {
            camera: c,
            time: i as f64 / 2.0,
            pyramid: Pyramid::new(texture(w, h, Vec2::ZERO), 1),
            between: Vec::new(),
        })
        .collect();
    let hidden = DVec3::new(0.5, 0.3, 0.0);
    let depths: Vec<Option<Aligned>> = cams
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let mut z = vec![4.0f32; w * h];
            if i == 0 {
                let (p, _) = c.project_world(hidden).unwrap();
                for dy in -2..=2 {
                    for dx in -2..=2 {
                        let (x, y) = (p.x.round() as i64 + dx, p.y.round() as i64 + dy);
                        z[y as usize * w + x as usize] = 2.5;
                    }
                }
            }
            Some(Aligned {
                width: w,
                height: h,
                z,
                median_rel_error: 0.0,
                points: 0,
            })
        })
        .collect();
    let mut s = Splats::default();
    for p in [
        [0.0, 0.0, 0.0],
        [0.5, 0.3, 0.0],
        [-0.2, 0.1, 1.5],
        [0.1, -0.3, 0.0],
    ] {
        s.push(Gaussian::isotropic(p, -3.0, 0.0, [0.0; 3]));
    }
    assert_eq!(
        drop_where_prior_disagrees(&mut s, &frames, &depths, 0.15),
        1
    );
    assert_eq!(s.len(), 3);
    let kept: Vec<[f32; 3]> = (0..3).map(|i| s.get(i).mean).collect();
    assert_eq!(
        kept,
        vec![[0.0, 0.0, 0.0], [0.5, 0.3, 0.0], [0.1, -0.3, 0.0]]
    );
}
