//! Lost links carried by their neighbours (`tracks.fill`, `tracks::fill`): the affine
//! motion of neighbouring links against a known affine map with outliers among them,
//! and a textured image moved by a known affine map whose flat disc Lucas–Kanade cannot
//! follow, against the map.

use gaussians::tracks::fill::{apply, carried, fit_affine};
use gaussians::tracks::lk::{Grey, Pyramid};
use gaussians::tracks::{Frame, TrackSettings, raw_tracks_at};
use glam::{DQuat, DVec3, Vec2};
use scene::{Camera, Intrinsics, Pose};

/// A turn of 1.5° about (40, 52), a stretch of 1 % in x and a shift of (2.6, −1.4) px.
const MAP: [f64; 6] = {
    let (c, s) = (0.9996573249755573, 0.026176948307873153);
    let (a, b, d, e) = (1.01 * c, -s, 1.01 * s, c);
    [
        a,
        b,
        40.0 - a * 40.0 - b * 52.0 + 2.6,
        d,
        e,
        52.0 - d * 40.0 - e * 52.0 - 1.4,
    ]
};

#[test]
fn neighbours_carry_a_point_by_the_affine_map_most_of_them_agree_on() {
    let truth = |p: Vec2| apply(&MAP, p);
    let p = Vec2::new(40.0, 52.0);
    // 24 neighbours on a ring of radius 2–5 px, every fourth moved 3 px off the map.
    let links: Vec<(Vec2, Vec2)> = (0..24)
        .map(|i| {
            let a = i as f32 * 0.7;
            let r = 2.0 + (i % 4) as f32;
            let u = p + r * Vec2::new(a.cos(), a.sin());
            let off = if i % 4 == 1 {
                Vec2::new(3.0, -1.0)
            } else {
                Vec2::ZERO
            };
            (u, truth(u) + off)
        })
        .collect();
    let fit = fit_affine(&links[..3]).expect("three points in general position");
    for (u, v) in &links[..3] {
        assert!(apply(&fit, *u).distance(*v) < 1e-3);
    }
    let q = carried(&links, p, 6.0, 7).expect("18 of 24 agree");
    assert!(q.distance(truth(p)) < 0.01, "{q} vs {}", truth(p));
    // The least squares over all of them (no RANSAC) is pulled off by the outliers.
    let all = fit_affine(&links).unwrap();
    assert!(apply(&all, p).distance(truth(p)) > 0.1);
    // Too few neighbours within reach: nothing carries it.
    assert_eq!(carried(&links[..5], p, 6.0, 7), None);
    assert_eq!(carried(&links, p + Vec2::new(20.0, 0.0), 6.0, 7), None);
}

/// A texture (sinusoids, periods of 6–90 px) at source point `s`, flat (0.5) within 8 px of (40, 52).
fn surface(s: Vec2) -> f32 {
    if s.distance(Vec2::new(40.0, 52.0)) < 8.0 {
        return 0.5;
    }
    let (x, y) = (s.x, s.y);
    0.5 + 0.15 * (0.31 * x + 0.11 * y).sin()
        + 0.12 * (0.07 * x - 0.23 * y).cos()
        + 0.1 * (0.133 * x + 0.29 * y).sin()
        + 0.08 * ((0.9 * x + 0.4 * y).sin() + (0.5 * x - 0.8 * y).cos())
}

#[test]
fn a_flat_patch_lucas_kanade_loses_is_carried_by_the_texture_around_it() {
    let (w, h) = (96usize, 96usize);
    // Frame 1 shows the surface moved by MAP: the pixel at x holds the source point
    // MAP⁻¹(x).
    let [a, b, c, d, e, f] = MAP;
    let det = a * e - b * d;
    let back = |x: Vec2| {
        let (u, v) = (x.x as f64 - c, x.y as f64 - f);
        Vec2::new(
            ((e * u - b * v) / det) as f32,
            ((a * v - d * u) / det) as f32,
        )
    };
    // Frame k shows the surface moved k times.
    let image = |k: usize| Grey {
        width: w,
        height: h,
        data: (0..w * h)
            .map(|i| {
                let x = Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                surface((0..k).fold(x, |x, _| back(x)))
            })
            .collect(),
    };
    let camera = Camera {
        intrinsics: Intrinsics::from_fov_x(w as u32, h as u32, 1.0),
        cam_to_world: Pose::new(DQuat::IDENTITY, DVec3::ZERO),
    };
    let frames: Vec<Frame> = (0..3)
        .map(|k| Frame {
            camera: &camera,
            time: k as f64,
            pyramid: Pyramid::new(image(k), 3),
            between: Vec::new(),
        })
        .collect();
    let st = TrackSettings::default();
    let plain = raw_tracks_at(&frames, 1, &[0], &st);
    let carried = raw_tracks_at(&frames, 1, &[0], &TrackSettings { fill: 2, ..st });
    let once = raw_tracks_at(&frames, 1, &[0], &TrackSettings { fill: 1, ..st });
    let track = |tracks: &[gaussians::tracks::RawTrack], p: Vec2| {
        (tracks.iter().find(|t| t.pixel == p))
            .map(|t| t.track.clone())
            .unwrap()
    };
    let at = |tracks: &[gaussians::tracks::RawTrack], p: Vec2| track(tracks, p)[1];
    // The disc's middle: no texture in any window there. Its neighbours' links, whose
    // windows are half flat, are each off by up to half a pixel, and the map is
    // extrapolated from one side of some of these points: within 0.75 px (a pixel less
    // than the ~3 px the map moves them).
    for p in [
        Vec2::new(40.5, 52.5),
        Vec2::new(38.5, 50.5),
        Vec2::new(42.5, 54.5),
    ] {
        assert_eq!(
            at(&plain, p),
            None,
            "{p} is flat: Lucas–Kanade has nothing to follow"
        );
        let q = at(&carried, p).expect("carried by the texture around the disc");
        assert!(
            q.distance(apply(&MAP, p)) < 0.75,
            "{p}: {q} vs {}",
            apply(&MAP, p)
        );
        // The next link is flat too: carried again where two may be, ended where one.
        let twice = apply(&MAP, apply(&MAP, p));
        let q = track(&carried, p)[2].expect("carried a second time");
        assert!(q.distance(twice) < 1.0, "{p}: {q} vs {twice}");
        assert_eq!(track(&once, p)[1], at(&carried, p));
        assert_eq!(track(&once, p)[2], None, "`fill = 1` carries one link");
    }
    // Where Lucas–Kanade follows, filling changes nothing.
    for p in [Vec2::new(20.5, 20.5), Vec2::new(70.5, 30.5)] {
        let q = at(&plain, p).expect("textured");
        assert_eq!(at(&carried, p), Some(q));
        assert!(
            q.distance(apply(&MAP, p)) < 0.3,
            "{p}: {q} vs {}",
            apply(&MAP, p)
        );
    }
}
