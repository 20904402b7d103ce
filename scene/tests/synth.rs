//! Analytic synthetic scenes: flow against finite differences of tracked material
//! points, depth against closed-form plane/sphere depths, presets.

use glam::{DVec2, DVec3};
use scene::synth::{
    CameraPath, Motion, ObjectSpec, PRESETS, Shape, SynthConfig, SynthWorld, Texture,
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
