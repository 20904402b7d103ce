//! The tile rasterizer's forward pass against the f64 reference and analytic cases.

mod raster_common;

use gaussians::raster::TileRasterizer;
use gaussians::raster::reference::{self, Gaussians64};
use gaussians::{Rasterizer, Splats};
use glam::DVec3;
use raster_common::*;

fn compare(s: &Splats, cam: &scene::Camera, sh: u32, bg: [f32; 3]) -> (f64, f64, f64, f32) {
    let (f, _) = TileRasterizer.render(s, cam, sh, bg);
    let r = reference::render(&Gaussians64::from(s), cam, sh, bg.map(f64::from));
    let cover = f.alpha.iter().sum::<f32>() / f.alpha.len() as f32;
    (
        max_abs_diff(&f.rgb, &r.rgb),
        max_abs_diff(&f.depth, &r.depth),
        max_abs_diff(&f.alpha, &r.alpha),
        cover,
    )
}

/// 24 random scenes: dense overlaps, tile-border straddling (sizes 20–100 px on a
/// 16-px tile grid), Gaussians partly off-screen and behind the camera.
#[test]
fn forward_matches_f64_reference_on_random_scenes() {
    let mut rng = Rng(7);
    let mut covered = 0;
    for scene in 0..24 {
        let (w, h) = (40 + (scene * 7) % 50, 30 + (scene * 11) % 45);
        let kind = SceneKind {
            n: 20 + scene * 6,
            spread: if scene % 3 == 0 { 6.0 } else { 1.6 },
            log_scale: (-3.5, -1.0),
            logit: (-3.0, 4.0),
            sh_rest: 0.3,
        };
        let mut s = random_splats(&mut rng, kind);
        // Behind the camera, on the near plane's wrong side, straddling the image edge.
        push_gaussian(&mut s, [0.0, 0.0, 6.0], -1.0, 3.0);
        push_gaussian(&mut s, [0.1, 0.0, 3.995], -2.0, 3.0);
        push_gaussian(&mut s, [1.9, 0.2, 0.0], -1.2, 2.0);
        let eye = DVec3::new(0.3 * (scene as f64).sin(), 0.2, 4.0);
        let cam = camera(w as u32, h as u32, 0.9 * w as f64, eye);
        let sh = (scene % 4) as u32;
        let bg = [0.1 * (scene % 3) as f32, 0.5, 1.0];
        let (drgb, ddepth, dalpha, cover) = compare(&s, &cam, sh, bg);
        eprintln!("scene {scene}: {drgb:.1e} {ddepth:.1e} {dalpha:.1e} cover {cover:.2}");
        assert!(drgb < 1e-4, "scene {scene}: rgb differs by {drgb:e}");
        assert!(ddepth < 1e-4, "scene {scene}: depth differs by {ddepth:e}");
        assert!(dalpha < 1e-4, "scene {scene}: alpha differs by {dalpha:e}");
        if cover > 0.2 {
            covered += 1;
        }
    }
    assert!(
        covered >= 12,
        "too few scenes actually cover the image ({covered})"
    );
}

/// Many large, opaque Gaussians: pixels saturate (T < 1e-4 stop, α = 0.99 clamp).
#[test]
fn forward_matches_reference_when_saturated() {
    let mut rng = Rng(99);
    for scene in 0..4 {
        let kind = SceneKind {
            n: 150,
            spread: 1.0,
            log_scale: (-1.5, -0.5),
            logit: (4.0, 8.0),
            sh_rest: 0.2,
        };
        let s = random_splats(&mut rng, kind);
        let cam = camera(48, 40, 40.0, DVec3::new(0.0, 0.0, 4.0));
        let (drgb, ddepth, dalpha, cover) = compare(&s, &cam, 3, [0.0, 0.0, 0.0]);
        assert!(cover > 0.5, "scene {scene} should be mostly covered");
        assert!(
            drgb < 1e-4 && ddepth < 1e-4 && dalpha < 1e-4,
            "scene {scene}: {drgb:e} {ddepth:e} {dalpha:e}"
        );
    }
}

/// One isotropic Gaussian straight ahead: the centre pixel sees α = o and the
/// colour SH_dc·C0 + 0.5; a Gaussian above the axis (+Y) lands on smaller v.
#[test]
fn single_gaussian_matches_closed_form() {
    let cam = camera(33, 33, 30.0, DVec3::new(0.0, 0.0, 4.0));
    let mut cam = cam;
    cam.cam_to_world = scene::Pose::default(); // at the origin looking down −Z
    cam.intrinsics.cx = 16.0;
    cam.intrinsics.cy = 16.0;
    cam.intrinsics.fy = 30.0;
    let mut s = Splats::default();
    push_gaussian(&mut s, [0.0, 0.0, -4.0], (0.2f32).ln(), 0.0);
    let (f, st) = TileRasterizer.render(&s, &cam, 0, [0.0; 3]);
    let np = 33 * 33;
    let centre = 16 * 33 + 16;
    let c0 = gaussians::raster::sh::C0 as f32;
    assert!((f.alpha[centre] - 0.5).abs() < 1e-6);
    assert!((f.rgb[centre] - 0.5 * (0.5 * c0 + 0.5)).abs() < 1e-6);
    assert!((f.depth[centre] - 0.5 * 4.0).abs() < 1e-5);
    // σ² in pixels = (f·s/d)² + 0.3.
    let var = (30.0f32 * 0.2 / 4.0).powi(2) + 0.3;
    let off = centre + 2;
    let want = 0.5 * (-0.5 * 4.0 / var).exp();
    assert!(
        (f.alpha[off] - want).abs() < 1e-6,
        "{} vs {want}",
        f.alpha[off]
    );
    // 3DGS radius: λ_max gets max(0.1, mid² − det) under its square root.
    assert_eq!(st.radius()[0], (3.0 * (var + 0.1f32.sqrt()).sqrt()).ceil());
    assert_eq!(f.rgb.len(), 3 * np);

    // Above the optical axis: brightest row above the centre row.
    let mut s = Splats::default();
    push_gaussian(&mut s, [0.0, 0.5, -4.0], (0.1f32).ln(), 2.0);
    let (f, _) = TileRasterizer.render(&s, &cam, 0, [0.0; 3]);
    let best = (0..np)
        .max_by(|&a, &b| f.alpha[a].total_cmp(&f.alpha[b]))
        .unwrap();
    assert_eq!(best % 33, 16);
    assert!((best / 33) as f64 - (16.0 - 30.0 * 0.5 / 4.0) < 1.0);
    assert!(best / 33 < 16);
}

/// Empty scenes and scenes entirely behind the camera render the background.
#[test]
fn empty_and_behind_render_background() {
    let cam = camera(20, 18, 20.0, DVec3::new(0.0, 0.0, 4.0));
    let (f, st) = TileRasterizer.render(&Splats::default(), &cam, 3, [0.2, 0.3, 0.4]);
    assert!(f.rgb[..360].iter().all(|&v| v == 0.2));
    assert!(f.alpha.iter().all(|&v| v == 0.0));
    assert_eq!(st.pairs(), 0);
    let mut s = Splats::default();
    push_gaussian(&mut s, [0.0, 0.0, 8.0], 0.0, 5.0);
    let (f, st) = TileRasterizer.render(&s, &cam, 3, [0.2, 0.3, 0.4]);
    assert!(f.alpha.iter().all(|&v| v == 0.0));
    assert_eq!(st.radius()[0], 0.0);
    let g = TileRasterizer.backward(&s, &cam, &st, &vec![1.0; 3 * 360]);
    assert!(g.means[0].iter().all(|v| *v == 0.0));
}

/// Degenerate parameters (zero or NaN quaternion, NaN/infinite mean, scale or opacity,
/// NaN SH) are culled or clamped: finite images, finite gradients, never NaN.
#[test]
fn degenerate_gaussians_give_finite_results() {
    let cam = camera(40, 30, 36.0, DVec3::new(0.0, 0.0, 4.0));
    let mut s = Splats::default();
    for k in 0..8 {
        push_gaussian(&mut s, [0.1 * k as f32 - 0.4, 0.05, 0.0], -1.5, 1.0);
    }
    s.rotations[0] = [0.0; 4];
    s.rotations[1] = [f32::NAN, 0.0, 0.0, 1.0];
    s.means[2] = [f32::NAN, 0.0, 0.0];
    s.means[3] = [f32::INFINITY, 0.0, 0.0];
    s.log_scales[4] = [f32::INFINITY, 0.0, 0.0];
    s.log_scales[5] = [f32::NEG_INFINITY; 3];
    s.opacity_logits[6] = f32::NAN;
    s.sh_dc[7] = [f32::NAN, 0.0, 0.0];
    let (f, st) = TileRasterizer.render_full(&s, &cam, 3, [0.1, 0.2, 0.3]);
    assert!(
        f.rgb
            .iter()
            .chain(&f.depth)
            .chain(&f.alpha)
            .all(|v| v.is_finite())
    );
    assert!(
        f.alpha.iter().any(|&a| a > 0.1),
        "the valid Gaussians still render"
    );
    let np = 40 * 30;
    let (g, pose) = TileRasterizer.backward_full(
        &s,
        &cam,
        &st,
        &vec![0.5; 3 * np],
        Some(&vec![0.1; np]),
        Some(&vec![0.2; np]),
    );
    let all = g
        .means
        .as_flattened()
        .iter()
        .chain(g.log_scales.as_flattened())
        .chain(g.rotations.as_flattened())
        .chain(&g.opacity_logits)
        .chain(g.sh_dc.as_flattened())
        .chain(g.sh_rest.as_flattened())
        .chain(&g.screen_grad_norm)
        .chain(&g.radius);
    assert!(all.copied().all(f32::is_finite));
    assert!(pose.iter().all(|v| v.is_finite()));
    for i in [0, 1, 2, 3, 4, 6] {
        assert_eq!(st.radius()[i], 0.0, "Gaussian {i} should be culled");
        assert_eq!(g.means[i], [0.0; 3]);
    }
}
