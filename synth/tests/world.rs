//! Analytic synthetic scenes: flow against finite differences of tracked material
//! points, depth against closed-form plane/sphere depths, presets.

use glam::{DVec2, DVec3};
use stagekit::Settings;
use synth::{
    CameraPath, Motion, ObjectSpec, PRESETS, Render, Shape, SynthConfig, SynthWorld, Texture,
};

fn world(name: &str) -> SynthWorld {
    SynthWorld::new(&SynthConfig::preset(name).unwrap()).unwrap()
}

/// Central finite difference of the projection of the material point hit at `px`.
fn tracked_flow(w: &SynthWorld, t: f64, px: DVec2, dt: f64) -> Option<DVec2> {
    let hit = w.cast(t, px)?;
    let at = |s: f64| {
        let x = w.material_to_world(hit.object, hit.local, s);
        w.camera_at(s).project_world(x).unwrap().0
    };
    Some((at(t + dt) - at(t - dt)) / (2.0 * dt))
}

#[test]
fn analytic_flow_matches_finite_differences_of_tracked_points() {
    for name in ["rigid", "nonrigid", "fast"] {
        let w = world(name);
        let mut checked = 0;
        let mut objects = std::collections::BTreeSet::new();
        for &t in &[0.13, 0.5, 0.87] {
            for j in (3..128).step_by(9) {
                for i in (2..128).step_by(9) {
                    let px = DVec2::new(i as f64 + 0.25, j as f64 - 0.4);
                    let hit = w.cast(t, px).unwrap();
                    objects.insert(hit.object);
                    let fd = tracked_flow(&w, t, px, 1e-5).unwrap();
                    let an = w.flow_at(t, px);
                    let err = (fd - an).length();
                    assert!(
                        err < 1e-4 * an.length().max(1.0),
                        "{name} t={t} px={px}: analytic {an} vs fd {fd}"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 500);
        // Floor, wall and all four props are covered by the grid.
        assert_eq!(objects.len(), 6, "{name}: {objects:?}");
    }
}

#[test]
fn the_point_a_pixel_sees_moves_by_its_flow() {
    // Track: the material point hit at px at t is, at t + dt, hit by the ray through
    // px + flow·dt (same object, same material point up to O(dt²)).
    let w = world("nonrigid");
    let (t, dt) = (0.4, 1e-4);
    let mut n = 0;
    for j in (5..120).step_by(13) {
        for i in (5..120).step_by(13) {
            let px = DVec2::new(i as f64, j as f64);
            let hit = w.cast(t, px).unwrap();
            let moved = px + w.flow_at(t, px) * dt;
            let later = w.cast(t + dt, moved).unwrap();
            if later.object != hit.object {
                continue; // occlusion boundary
            }
            assert!(
                (later.local - hit.local).length() < 1e-5,
                "px {px}: {} vs {}",
                later.local,
                hit.local
            );
            n += 1;
        }
    }
    assert!(n > 50);
}

fn still_camera(eye: DVec3, target: DVec3) -> CameraPath {
    CameraPath {
        eye,
        target,
        sway: DVec3::ZERO,
        sway_hz: 0.0,
        yaw_deg: 0.0,
        pitch_deg: 0.0,
        turn_hz: 0.0,
    }
}

fn custom(objects: Vec<ObjectSpec>, camera: CameraPath, size: u32) -> SynthWorld {
    let cfg = SynthConfig {
        width: size,
        height: size,
        supersample: 1,
        camera,
        objects,
        ..SynthConfig::default()
    };
    SynthWorld::new(&cfg).unwrap()
}

fn plane(name: &str, position: DVec3, rotation_deg: DVec3) -> ObjectSpec {
    ObjectSpec {
        name: name.into(),
        shape: Shape::Plane {
            half_size: [0.0, 0.0],
        },
        texture: Texture::default(),
        motion: Motion {
            position,
            rotation_deg,
            ..Motion::default()
        },
        deform: Default::default(),
    }
}

#[test]
fn depth_of_a_fronto_parallel_wall_is_constant() {
    let w = custom(
        vec![plane("wall", DVec3::new(0.0, 0.0, -1.0), DVec3::ZERO)],
        still_camera(DVec3::new(0.0, 0.0, 2.0), DVec3::ZERO),
        33,
    );
    let r = w.render(0.5);
    assert!(r.depth.iter().all(|&d| (d - 3.0).abs() < 1e-6));
    assert!(r.object_id.iter().all(|&k| k == 1));
    assert!(r.flow_u.iter().chain(&r.flow_v).all(|&f| f == 0.0));
}

#[test]
fn depth_of_a_floor_follows_the_ground_plane_formula() {
    // Camera at height 1 looking along −Z (identity orientation), floor y = −1:
    // the ray of row v (below the centre) meets it at depth 2·f_y/(v − c_y).
    let eye = DVec3::new(0.0, 1.0, 0.0);
    let w = custom(
        vec![plane(
            "floor",
            DVec3::new(0.0, -1.0, 0.0),
            DVec3::new(-90.0, 0.0, 0.0),
        )],
        still_camera(eye, eye - DVec3::Z),
        41,
    );
    let k = w.intrinsics();
    let r = w.render(0.0);
    for v in 0..41usize {
        for u in [0usize, 7, 20, 40] {
            let i = v * 41 + u;
            if (v as f64) > k.cy {
                let expected = 2.0 * k.fy / (v as f64 - k.cy);
                assert!((r.depth[i] as f64 - expected).abs() < 1e-5 * expected);
                assert_eq!(r.object_id[i], 1);
            } else {
                assert_eq!((r.depth[i], r.object_id[i]), (0.0, 0), "row {v}");
            }
        }
    }
}

#[test]
fn depth_of_a_sphere_centre_and_its_silhouette() {
    let radius = 0.5;
    let ball = ObjectSpec {
        name: "ball".into(),
        shape: Shape::Ellipsoid {
            radii: DVec3::splat(radius),
        },
        texture: Texture::default(),
        motion: Motion::default(),
        deform: Default::default(),
    };
    let w = custom(
        vec![ball],
        still_camera(DVec3::new(0.0, 0.0, 3.0), DVec3::ZERO),
        65,
    );
    let r = w.render(0.0);
    let k = w.intrinsics();
    let centre = 32 * 65 + 32;
    assert!((r.depth[centre] - 2.5).abs() < 1e-6);
    // Silhouette radius in pixels: f·r/√(D² − r²).
    let rim = k.fx * radius / (9.0f64 - radius * radius).sqrt();
    for u in 0..65usize {
        let inside = ((u as f64 - k.cx).abs()) < rim;
        let id = r.object_id[32 * 65 + u];
        if ((u as f64 - k.cx).abs() - rim).abs() > 0.01 {
            assert_eq!(id == 1, inside, "column {u}");
        }
        if inside {
            // Depth along the row: ray ‖(x/f, 0, −1)‖ meets the sphere.
            let a = (u as f64 - k.cx) / k.fx;
            let (qa, qb, qc) = (a * a + 1.0, -6.0, 9.0 - radius * radius);
            let s = (-qb - (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa);
            assert!((r.depth[32 * 65 + u] as f64 - s).abs() < 1e-6);
        }
    }
}

#[test]
fn waving_plane_depth_follows_the_wave_exactly() {
    let (amp, length, hz) = (0.1, 0.8, 1.5);
    let mut flag = plane("flag", DVec3::ZERO, DVec3::ZERO);
    flag.deform.wave_amplitude = amp;
    flag.deform.wave_length = length;
    flag.deform.wave_hz = hz;
    let w = custom(
        vec![flag],
        still_camera(DVec3::new(0.0, 0.0, 2.0), DVec3::ZERO),
        31,
    );
    let h = |x: f64, y: f64, t: f64| {
        amp * (std::f64::consts::TAU * (x / length - hz * t)).sin()
            * (std::f64::consts::PI * y / length).cos()
    };
    for t in [0.0, 0.1, 0.37] {
        let r = w.render(t);
        // Centre pixel: the ray is the optical axis, it meets z = h(0, 0, t).
        assert!((r.depth[15 * 31 + 15] as f64 - (2.0 - h(0.0, 0.0, t))).abs() < 1e-6);
        for (i, j) in [(0.0, 0.0), (7.5, 20.25), (30.0, 11.0)] {
            let hit = w.cast(t, DVec2::new(i, j)).unwrap();
            let p = hit.world;
            assert!((p.z - h(p.x, p.y, t)).abs() < 1e-10, "{p}");
            assert!((hit.local - DVec3::new(p.x, p.y, 0.0)).length() < 1e-12);
            assert!((hit.depth - (2.0 - p.z)).abs() < 1e-12);
        }
    }
    // A material point moves along z only, with ∂h/∂t.
    let q = DVec3::new(0.1, -0.2, 0.0);
    let dt = 1e-6;
    let v =
        (w.material_to_world(0, q, 0.2 + dt) - w.material_to_world(0, q, 0.2 - dt)) / (2.0 * dt);
    assert!(v.x.abs() < 1e-9 && v.y.abs() < 1e-9 && v.z.abs() > 0.1);
}

#[test]
fn background_flow_is_the_rotational_flow_of_points_at_infinity() {
    let cfg = SynthConfig {
        width: 32,
        height: 32,
        objects: vec![],
        ..SynthConfig::preset("static").unwrap()
    };
    let w = SynthWorld::new(&cfg).unwrap();
    let t = 0.3;
    let dt = 1e-5;
    for (i, j) in [(0.0, 0.0), (10.0, 25.0), (31.0, 3.0)] {
        let px = DVec2::new(i, j);
        assert!(w.cast(t, px).is_none());
        // Direction seen at px, held fixed in the world, projected at t ± dt.
        let cam = w.camera_at(t);
        let dir = cam.unproject_world(px, 1.0) - cam.cam_to_world.translation;
        let at = |s: f64| {
            let c = w.camera_at(s);
            let local = c.cam_to_world.rotation.inverse() * dir;
            c.intrinsics.project(local).unwrap()
        };
        let fd = (at(t + dt) - at(t - dt)) / (2.0 * dt);
        let an = w.flow_at(t, px);
        assert!(
            (fd - an).length() < 1e-4 * an.length().max(1.0),
            "{fd} {an}"
        );
        assert!(an.length() > 0.1);
    }
}

#[test]
fn render_agrees_with_point_queries() {
    let w = world("fast");
    let r = w.render(0.61);
    assert_eq!(r.rgb.len(), 3 * 128 * 128);
    assert!(r.rgb.iter().all(|&c| (0.0..=1.0).contains(&c)));
    for (i, j) in [(0usize, 0usize), (64, 64), (100, 17), (5, 120), (127, 127)] {
        let idx = j * 128 + i;
        let px = DVec2::new(i as f64, j as f64);
        let hit = w.cast(0.61, px).unwrap();
        assert_eq!(r.object_id[idx] as usize, hit.object + 1);
        assert_eq!(r.depth[idx], hit.depth as f32);
        let f = w.flow_at(0.61, px);
        assert_eq!((r.flow_u[idx], r.flow_v[idx]), (f.x as f32, f.y as f32));
    }
    // Rich content: many distinct colours and large flow somewhere.
    let max_flow = r
        .flow_u
        .iter()
        .zip(&r.flow_v)
        .map(|(u, v)| (u * u + v * v).sqrt())
        .fold(0.0f32, f32::max);
    assert!(max_flow > 50.0, "{max_flow}");
}

#[test]
fn presets_exist_round_trip_and_differ_in_motion() {
    for name in PRESETS {
        let cfg = SynthConfig::preset(name).unwrap();
        cfg.validate().unwrap();
        assert_eq!(cfg.preset, *name);
        let json = serde_json::to_string(&cfg).unwrap();
        let back: SynthConfig = serde_json::from_str(&json).unwrap();
        assert_eq!(back, cfg);
    }
    assert!(SynthConfig::preset("nope").is_none());
    // Defaults fill missing fields.
    let partial: SynthConfig = serde_json::from_str(r#"{"width": 64, "preset": "x"}"#).unwrap();
    assert_eq!(partial.width, 64);
    assert_eq!(partial.height, SynthConfig::default().height);
    assert!(serde_json::from_str::<SynthConfig>(r#"{"widht": 64}"#).is_err());

    // static: every material point stays put; the camera moves.
    let w = world("static");
    for k in 0..6 {
        let q = DVec3::new(0.1, 0.2, 0.05);
        let a = w.material_to_world(k, q, 0.0);
        let b = w.material_to_world(k, q, 0.7);
        assert!((a - b).length() < 1e-12);
    }
    assert_ne!(w.camera_at(0.0), w.camera_at(0.5));

    // rigid keeps distances on the blob; nonrigid changes them.
    let dist = |w: &SynthWorld, t: f64| {
        let a = w.material_to_world(4, DVec3::new(0.3, 0.0, 0.0), t);
        let b = w.material_to_world(4, DVec3::new(0.0, 0.25, 0.0), t);
        (a - b).length()
    };
    let rigid = world("rigid");
    assert!((dist(&rigid, 0.1) - dist(&rigid, 0.6)).abs() < 1e-12);
    let nonrigid = world("nonrigid");
    assert!((dist(&nonrigid, 0.1) - dist(&nonrigid, 0.6)).abs() > 0.01);
    // The flag (object 6) waves only in the non-rigid presets.
    let q = DVec3::new(0.2, 0.1, 0.0);
    let moved = |w: &SynthWorld| {
        (w.material_to_world(5, q, 0.1) - w.material_to_world(5, q, 0.35)).length()
    };
    assert_eq!(moved(&rigid), 0.0);
    assert!(moved(&nonrigid) > 0.01);
}

#[test]
fn invalid_configs_are_rejected() {
    let cfg = SynthConfig {
        width: 0,
        ..SynthConfig::default()
    };
    assert!(SynthWorld::new(&cfg).is_err());
    let mut cfg = SynthConfig::default();
    cfg.objects[2].shape = Shape::Cuboid {
        half_size: DVec3::new(0.1, -1.0, 0.1),
    };
    assert!(SynthWorld::new(&cfg).unwrap_err().contains("box"));
    let mut cfg = SynthConfig::default();
    cfg.objects[3].deform.wave_amplitude = 0.1; // the ball is not a plane
    cfg.objects[3].deform.wave_length = 0.5;
    assert!(SynthWorld::new(&cfg).unwrap_err().contains("planes only"));
    let mut cfg = SynthConfig::default();
    cfg.objects[5].deform.wave_amplitude = 0.1;
    cfg.objects[5].deform.wave_length = 0.0;
    assert!(SynthWorld::new(&cfg).unwrap_err().contains("wave_length"));
    let cfg = SynthConfig {
        train_fps: f64::NAN,
        ..SynthConfig::default()
    };
    assert!(cfg.validate().is_err());
    for n in [0, 9] {
        let cfg = SynthConfig {
            frame_supersample: n,
            ..SynthConfig::default()
        };
        assert!(cfg.validate().unwrap_err().contains("frame_supersample"));
    }
}

/// The RGB frames integrate over the pixel: more samples converge to the area average
/// (a 16×16-sample reference), and `render_frame` uses `frame_supersample` while the
/// event simulator's `render` uses `supersample`.
#[test]
fn frame_supersampling_converges_to_the_pixel_area_average() {
    let cfg = SynthConfig {
        width: 48,
        height: 48,
        supersample: 1,
        frame_supersample: 4,
        ..SynthConfig::preset("static").unwrap()
    };
    let w = SynthWorld::new(&cfg).unwrap();
    let reference = w.render_sampled(0.3, 16).rgb;
    let rms = |rgb: &[f32]| {
        let se: f64 = rgb
            .iter()
            .zip(&reference)
            .map(|(a, b)| ((a - b) as f64).powi(2))
            .sum();
        (se / rgb.len() as f64).sqrt()
    };
    let errors: Vec<f64> = [1, 2, 4, 8]
        .iter()
        .map(|&n| rms(&w.render_sampled(0.3, n).rgb))
        .collect();
    // Point sampling aliases the hard texture edges; each doubling roughly halves the error.
    assert!(errors[0] > 0.02, "point-sampled error {errors:?}");
    for k in 1..4 {
        assert!(errors[k] < 0.75 * errors[k - 1], "errors {errors:?}");
    }
    assert!(errors[3] < 0.3 * errors[0], "errors {errors:?}");
    assert_eq!(w.render_frame(0.3).rgb, w.render_sampled(0.3, 4).rgb);
    assert_eq!(w.render(0.3).rgb, w.render_sampled(0.3, 1).rgb);
    // Depth, flow and ids stay those of the pixel centre.
    assert_eq!(w.render_frame(0.3).depth, w.render(0.3).depth);
}

#[test]
fn frame_times() {
    let cfg = SynthConfig::default();
    let train = cfg.train_times();
    assert_eq!(train.len(), 9);
    assert_eq!(train[8], 1.0);
    let test = cfg.test_times();
    assert_eq!(
        test,
        (0..8)
            .map(|k| 0.0625 + 0.125 * k as f64)
            .collect::<Vec<_>>()
    );
    let internal = cfg.render_times();
    assert_eq!(internal.len(), 1001);
    assert_eq!(*internal.last().unwrap(), 1.0);
    assert!(internal.windows(2).all(|w| w[1] > w[0]));
}

/// Bilinear sample of channel `c` of interleaved RGB at sub-pixel `(x, y)` (pixel
/// centres at integers); the caller keeps the four taps inside the frame.
fn bilinear(rgb: &[f32], w: usize, x: f64, y: f64, c: usize) -> f64 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (i, j) = (x0 as usize, y0 as usize);
    let at = |i: usize, j: usize| rgb[3 * (j * w + i) + c] as f64;
    (1.0 - fy) * ((1.0 - fx) * at(i, j) + fx * at(i + 1, j))
        + fy * ((1.0 - fx) * at(i, j + 1) + fx * at(i + 1, j + 1))
}

/// Whether the pixels `lo..=hi` (inclusive corners) lie inside the frame, all show
/// object `id`, and hold no texture edge: neighbouring pixels differ by at most `tau`
/// in every channel (`tau = ∞` checks the object only).
fn clean_patch(r: &Render, lo: (isize, isize), hi: (isize, isize), id: u16, tau: f32) -> bool {
    let (w, h) = (r.width as isize, r.height as isize);
    if lo.0 < 0 || lo.1 < 0 || hi.0 >= w || hi.1 >= h {
        return false;
    }
    let at = |x: isize, y: isize| (y * w + x) as usize;
    let close =
        |a: usize, b: usize| (0..3).all(|c| (r.rgb[3 * a + c] - r.rgb[3 * b + c]).abs() <= tau);
    (lo.1..=hi.1).all(|y| {
        (lo.0..=hi.0).all(|x| {
            let k = at(x, y);
            r.object_id[k] == id
                && (x == hi.0 || close(k, at(x + 1, y)))
                && (y == hi.1 || close(k, at(x, y + 1)))
        })
    })
}

/// Backward warp of frame `a` (time t) onto frame `b` (t + δ) by the GT flow of `b`:
/// pixel p of `b` is compared with `a` sampled bilinearly at `p − gain·flow_b(p)·δ`
/// (gain 1: the GT flow; 0: no motion; −1: the flow reversed). Backward, so every target
/// pixel gets exactly one value and no splatting is needed; the flow of `b` at p is the
/// velocity of the point seen at p at t + δ, so `p − flow·δ` is where it was at t, up
/// to O(δ²). Only non-occluded pixels count: the 3×3 patch around p in `b` and the
/// 4×4 bilinear support (+1 ring) around the GT source point in `a` show the same
/// object as p and no texture edge (see [`clean_patch`]). The mask uses the GT source
/// for every gain, so all gains are scored on the same pixels.
/// Returns the mean |error| over RGB per object id (sum, count).
fn warp_errors(a: &Render, b: &Render, delta: f64, tau: f32, gain: f64) -> Vec<(f64, usize)> {
    let (w, h) = (a.width as usize, a.height as usize);
    let mut per_id = vec![(0.0, 0); 8]; // the presets' ids are 0–6
    for j in 0..h {
        for i in 0..w {
            let k = j * w + i;
            let id = b.object_id[k];
            let f = DVec2::new(b.flow_u[k] as f64, b.flow_v[k] as f64) * delta;
            let p = DVec2::new(i as f64, j as f64);
            let src = p - f;
            let (sx, sy) = (src.x.floor() as isize, src.y.floor() as isize);
            let (pi, pj) = (i as isize, j as isize);
            if !clean_patch(b, (pi - 1, pj - 1), (pi + 1, pj + 1), id, tau)
                || !clean_patch(a, (sx - 1, sy - 1), (sx + 2, sy + 2), id, tau)
            {
                continue;
            }
            let q = p - f * gain;
            let e: f64 = (0..3)
                .map(|c| (bilinear(&a.rgb, w, q.x, q.y, c) - b.rgb[3 * k + c] as f64).abs())
                .sum();
            per_id[id as usize].0 += e / 3.0;
            per_id[id as usize].1 += 1;
        }
    }
    per_id
}

/// Mean error and pixel count over the objects `ids`.
fn mean_over(per_id: &[(f64, usize)], ids: impl IntoIterator<Item = usize>) -> (f64, usize) {
    let (s, n) = ids
        .into_iter()
        .fold((0.0, 0), |a, i| (a.0 + per_id[i].0, a.1 + per_id[i].1));
    (s / n.max(1) as f64, n)
}

#[test]
fn warping_a_frame_by_the_gt_flow_reproduces_the_frame_at_t_plus_delta() {
    // δ = 5 ms moves points by at most ~0.13 px at 64² ("rigid": up to 26 px/s). That is
    // far below the pixel grid, so at a sharp texture edge the rendered frame changes by
    // whole aliasing steps that no interpolation of frame t can predict: scored on every
    // non-occluded pixel (τ = ∞), the GT warp (mean |error| 0.009–0.023) is even worse
    // than no warp (0.004–0.012). The comparison is therefore made away from texture
    // edges (neighbouring pixels within τ = 0.05), where the frames vary smoothly (the
    // value-noise "detail" of the textures) and bilinear interpolation is accurate.
    //
    // Scene 1: the preset as is; its clean pixels are on the floor and the wall (their
    // flow is camera motion). Scene 2: the same preset with flat colours (colour_b =
    // colour_a) and 4× coarser detail, so that the rigidly moving box and ball (and the
    // flag) take part too.
    //
    // Measured at t = 0.1, 0.3, 0.5, 0.7, 0.9 (mean |error| over RGB in [0, 1]):
    //   scene 1 (435–557 px): GT 0.6–3.8e-5, zero flow 5.3–6.9× worse, reversed ≈ 2× zero;
    //   scene 2 (3030–3136 px): GT 1.1–3.9e-5, zero flow 7.6–10.7× worse, reversed ≈ 2×;
    //   scene 2 per object with ≥ 20 px: GT ≤ 1.9e-4, zero flow 2.0–18× worse
    //   (box 35–83 px, 8.4–11.7×; ball 40–55 px, 2.0–17.6×).
    // Tolerances: GT < 1e-4 overall (< 2.5e-4 per object); zero flow > 4× GT overall
    // (> 1.5× per object); reversed flow > 1.8× zero flow. Scaling the flow by 1.5
    // already fails (GT 4.3e-5 vs zero 8.4e-5 at t = 0.1).
    let delta = 0.005;
    let tau = 0.05;
    for smooth in [false, true] {
        let mut cfg = SynthConfig {
            width: 64,
            height: 64,
            supersample: 1,
            ..SynthConfig::preset("rigid").unwrap()
        };
        if smooth {
            for o in &mut cfg.objects {
                o.texture.colour_b = o.texture.colour_a;
                o.texture.detail = 0.8;
                o.texture.cell *= 4.0;
            }
        }
        let w = SynthWorld::new(&cfg).unwrap();
        let ids = 0..=cfg.objects.len();
        for t in [0.1, 0.3, 0.5, 0.7, 0.9] {
            let (a, b) = (w.render(t), w.render(t + delta));
            let gt = warp_errors(&a, &b, delta, tau, 1.0);
            let zero = warp_errors(&a, &b, delta, tau, 0.0);
            let back = warp_errors(&a, &b, delta, tau, -1.0);
            let (e_gt, n) = mean_over(&gt, ids.clone());
            let (e_zero, _) = mean_over(&zero, ids.clone());
            let (e_back, _) = mean_over(&back, ids.clone());
            let what = format!(
                "smooth {smooth} t {t}: {n} px, GT {e_gt:.2e}, zero {e_zero:.2e}, reversed {e_back:.2e}"
            );
            assert!(n >= if smooth { 2500 } else { 300 }, "{what}");
            assert!(e_gt < 1e-4, "{what}");
            assert!(
                e_zero > 4.0 * e_gt,
                "zero flow is not clearly worse: {what}"
            );
            assert!(e_back > 1.8 * e_zero, "reversed flow: {what}");
            if smooth {
                // Every object with enough clean pixels, the moving ones included.
                let mut seen = vec![];
                for id in ids.clone().filter(|&i| gt[i].1 >= 20) {
                    let (g, z) = (gt[id].0 / gt[id].1 as f64, zero[id].0 / gt[id].1 as f64);
                    assert!(
                        g < 2.5e-4 && z > 1.5 * g,
                        "object {id}: {g:e} vs {z:e}, {what}"
                    );
                    seen.push(id);
                }
                assert!(
                    seen.contains(&3) && seen.contains(&4),
                    "box and ball: {seen:?}"
                );
            }
        }
    }
}
