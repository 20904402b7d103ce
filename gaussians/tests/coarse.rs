//! Coarse-to-fine (`coarse_until`): a view at half resolution is the 2 × 2 block mean of
//! the frame, seen by a camera whose pixels look through the blocks' centres. The
//! rasterizer at full resolution is the reference: its render, averaged over the blocks,
//! is matched best by the half camera's own render at the principal point `View::half`
//! gives, not at one moved by a quarter or half pixel.

use gaussians::train::{TrainSettings, Trainer, View, init::random_splats};
use gaussians::{Rasterizer, TileRasterizer};
use glam::DVec3;
use scene::{Camera, Intrinsics, Pose};

fn camera(w: u32, h: u32) -> Camera {
    Camera {
        intrinsics: Intrinsics::from_fov_x(w, h, 0.8),
        cam_to_world: Pose::look_at(DVec3::new(0.2, 0.3, 2.5), DVec3::ZERO, DVec3::Y),
    }
}

#[test]
fn the_half_view_is_the_block_mean() {
    let (w, h) = (7usize, 5usize);
    let rgb: Vec<f32> = (0..3 * w * h)
        .map(|i| ((i * 37) % 101) as f32 / 100.0)
        .collect();
    let v = View {
        camera: camera(w as u32, h as u32),
        time: 0.25,
        rgb: rgb.clone(),
    };
    let half = v.half();
    let k = &half.camera.intrinsics;
    assert_eq!((k.width, k.height, half.time), (3, 2, 0.25));
    for c in 0..3 {
        for y in 0..2 {
            for x in 0..3 {
                let at = |yy: usize, xx: usize| rgb[c * w * h + yy * w + xx];
                let mean = (at(2 * y, 2 * x)
                    + at(2 * y, 2 * x + 1)
                    + at(2 * y + 1, 2 * x)
                    + at(2 * y + 1, 2 * x + 1))
                    / 4.0;
                assert!((half.rgb[c * 6 + y * 3 + x] - mean).abs() < 1e-6);
            }
        }
    }
}

#[test]
fn the_half_camera_looks_through_the_block_centres() {
    let (w, h) = (128u32, 96u32);
    let full = camera(w, h);
    let r = TileRasterizer;
    // Many small Gaussians: a texture fine enough to show a quarter-pixel shift.
    let splats = random_splats(20_000, DVec3::ZERO, 0.7, 3);
    let (img, _) = r.render(&splats, &full, 0, [0.0; 3]);
    let reference = View {
        camera: full,
        time: 0.0,
        rgb: img.rgb.clone(),
    }
    .half();
    let error = |dx: f64, dy: f64| {
        let mut cam = reference.camera;
        cam.intrinsics.cx += dx;
        cam.intrinsics.cy += dy;
        let (im, _) = r.render(&splats, &cam, 0, [0.0; 3]);
        let e: f64 = im
            .rgb
            .iter()
            .zip(&reference.rgb)
            .map(|(a, b)| f64::from(a - b).powi(2))
            .sum();
        e / im.rgb.len() as f64
    };
    let at_zero = error(0.0, 0.0);
    for (dx, dy) in [
        (0.25, 0.0),
        (-0.25, 0.0),
        (0.0, 0.25),
        (0.0, -0.25),
        (0.5, 0.5),
    ] {
        let e = error(dx, dy);
        eprintln!("principal point moved by ({dx}, {dy}): MSE {e:.3e} against {at_zero:.3e}");
        assert!(
            e > 1.2 * at_zero,
            "({dx}, {dy}) fits as well: {e} vs {at_zero}"
        );
    }
    // A trainer told to go coarse trains its first steps on the half view, then on the
    // whole one: its step's loss is the loss of the render of the one or the other.
    let settings = TrainSettings {
        coarse_until: 1,
        coarse_min_pixels: 0,
        iterations: 2,
        deform: false,
        ..Default::default()
    };
    let views = vec![View {
        camera: full,
        time: 0.0,
        rgb: img.rgb.clone(),
    }];
    let start = random_splats(500, DVec3::ZERO, 0.7, 4);
    let loss_on = |tr: &Trainer, v: &View| {
        let rv = tr.render_view(&r, &v.camera, v.time);
        tr.rgb_loss(&rv.image, &v.rgb).0
    };
    let mut tr = Trainer::new(settings, start, 1.0);
    let expected = [loss_on(&tr, &views[0].half()), loss_on(&tr, &views[0])];
    let first = tr.step(&r, &views).loss;
    assert!(
        (first - expected[0]).abs() < 1e-9,
        "{first} vs {expected:?}"
    );
    assert!(
        (first - expected[1]).abs() > 1e-6,
        "coarse step on the whole view"
    );
    let expected_full = loss_on(&tr, &views[0]);
    let second = tr.step(&r, &views).loss;
    assert!(
        (second - expected_full).abs() < 1e-9,
        "{second} vs {expected_full}"
    );
}
