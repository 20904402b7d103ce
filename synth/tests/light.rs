//! The directional light of synthetic scenes (`SynthConfig::light`).

use glam::{DVec2, DVec3};
use synth::{Motion, ObjectSpec, Shape, SynthConfig, SynthWorld, Texture};

/// A directional light: every pixel of a lit render is the unlit render's colour times
/// `ambient + (1 − ambient)·max(0, n·l)`, with `n` from the geometry alone — a sphere's
/// `(p − c)/r`, a turned box's face normal found from which coordinate of `p − c` in
/// its own axes reaches the half size — and a wall facing +z.
#[test]
fn a_light_shades_each_surface_by_its_normal() {
    let (centre_ball, r) = (DVec3::new(0.5, 0.0, -0.5), 0.45);
    let (centre_box, half) = (DVec3::new(-0.6, -0.1, 0.0), DVec3::new(0.3, 0.25, 0.35));
    let object = |name: &str, shape: Shape, position: DVec3| ObjectSpec {
        name: name.into(),
        shape,
        texture: Texture::default(),
        motion: Motion {
            position,
            ..Motion::default()
        },
        deform: Default::default(),
    };
    let mut cfg = SynthConfig {
        width: 64,
        height: 64,
        supersample: 1,
        objects: vec![
            object(
                "wall",
                Shape::Plane {
                    half_size: [0.0, 0.0],
                },
                DVec3::new(0.0, 0.0, -2.5),
            ),
            object(
                "ball",
                Shape::Ellipsoid {
                    radii: DVec3::splat(r),
                },
                centre_ball,
            ),
            ObjectSpec {
                motion: Motion {
                    position: centre_box,
                    rotation_deg: DVec3::new(20.0, 35.0, 10.0),
                    ..Motion::default()
                },
                ..object("box", Shape::Cuboid { half_size: half }, centre_box)
            },
        ],
        ..SynthConfig::preset("static").unwrap()
    };
    let unlit = SynthWorld::new(&cfg).unwrap().render(0.3);
    let light = synth::Light {
        direction: DVec3::new(-0.5, 0.8, 0.6),
        ambient: 0.3,
    };
    cfg.light = Some(light);
    let w = SynthWorld::new(&cfg).unwrap();
    let lit = w.render(0.3);
    let l = light.direction.normalize();
    let mut seen = [0usize; 3];
    for y in 0..64 {
        for x in 0..64 {
            let i = y * 64 + x;
            let Some(hit) = w.cast(0.3, DVec2::new(x as f64, y as f64)) else {
                continue;
            };
            let p = hit.world;
            let n = match hit.object {
                0 => DVec3::Z,
                1 => (p - centre_ball) / r,
                _ => {
                    // The box's axes in the world, from where its material axes go.
                    let o = w.material_to_world(2, DVec3::ZERO, 0.3);
                    let axis = |k: usize| {
                        let mut e = DVec3::ZERO;
                        e[k] = 1.0;
                        (w.material_to_world(2, e, 0.3) - o).normalize()
                    };
                    let v = p - o;
                    let d = DVec3::new(v.dot(axis(0)), v.dot(axis(1)), v.dot(axis(2))) / half;
                    let a = d.abs();
                    let k = if a.x >= a.y && a.x >= a.z {
                        0
                    } else if a.y >= a.z {
                        1
                    } else {
                        2
                    };
                    d[k].signum() * axis(k)
                }
            };
            let want = light.ambient + (1.0 - light.ambient) * n.dot(l).max(0.0);
            for c in 0..3 {
                let (a, b) = (unlit.rgb[3 * i + c] as f64, lit.rgb[3 * i + c] as f64);
                assert!(
                    (b - a * want).abs() < 1e-5,
                    "object {} px ({x}, {y}): {b} vs {a}·{want}",
                    hit.object
                );
            }
            seen[hit.object] += 1;
        }
    }
    assert!(seen.iter().all(|&n| n > 50), "{seen:?}");
    // Serialised settings without a light say nothing of it (old scenes keep their keys).
    cfg.light = None;
    assert!(!serde_json::to_string(&cfg).unwrap().contains("light"));
}
