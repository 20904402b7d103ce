//! Reusing buffers changes nothing: a render into the image and state of an earlier,
//! different render, a backward into dirty gradients, the field's forward and backward
//! into dirty activations, and the trainer's recycled views and gradients all give the
//! values of fresh buffers, bit for bit.

mod raster_common;

use gaussians::Planes;
use gaussians::field::{FieldSettings, Mlp, MlpCache, MlpScratch};
use gaussians::raster::{Rasterizer, TileRasterizer};
use gaussians::train::{TrainSettings, Trainer};
use gaussians::{SplatGrads, Splats};
use glam::DVec3;
use raster_common::*;

fn flat(g: &SplatGrads) -> Vec<f32> {
    let mut v = Vec::new();
    v.extend(g.means.as_flattened());
    v.extend(g.log_scales.as_flattened());
    v.extend(g.rotations.as_flattened());
    v.extend(&g.opacity_logits);
    v.extend(g.sh_dc.as_flattened());
    v.extend(g.sh_rest.as_flattened());
    v.extend(&g.screen_grad_norm);
    v.extend(&g.radius);
    v
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn scene(seed: u64, n: usize) -> Splats {
    let kind = SceneKind {
        n,
        spread: 1.0,
        log_scale: (-3.0, -1.5),
        logit: (-1.0, 3.0),
        sh_rest: 0.3,
    };
    random_splats(&mut Rng(seed), kind)
}

#[test]
fn render_and_backward_into_reused_buffers_match_fresh_ones() {
    let r = TileRasterizer;
    // Sizes and counts change from call to call (densification, another camera), and
    // each call reuses the last one's buffers; the first is fresh.
    let calls = [(300, 64, 48), (120, 40, 40), (500, 72, 56), (80, 64, 48)];
    let mut reuse = None;
    let mut grads = SplatGrads::default();
    for (k, &(n, w, h)) in calls.iter().enumerate() {
        let s = scene(k as u64 + 1, n);
        let cam = camera(w, h, 60.0, DVec3::new(0.2, 0.1, 4.0));
        let (fresh, st) = r.render_full(&s, &cam, 3, [0.1, 0.2, 0.3]);
        let (image, state) = r.render_reusing(&s, &cam, 3, [0.1, 0.2, 0.3], reuse.take());
        assert_eq!(bits(&image.rgb), bits(&fresh.rgb), "call {k}: rgb");
        assert_eq!(bits(&image.depth), bits(&fresh.depth), "call {k}: depth");
        assert_eq!(bits(&image.alpha), bits(&fresh.alpha), "call {k}: alpha");
        let np = (w * h) as usize;
        let d_rgb: Vec<f32> = (0..3 * np)
            .map(|i| ((i % 11) as f32 - 5.0) * 1e-2)
            .collect();
        let d_depth: Vec<f32> = (0..np).map(|i| ((i % 5) as f32 - 2.0) * 1e-3).collect();
        let (g0, tw0) = r.backward_full(&s, &cam, &st, &d_rgb, Some(&d_depth), None);
        let tw = r.backward_view_into(
            &s,
            &cam,
            &state,
            &d_rgb,
            Planes {
                depth: Some(&d_depth),
                alpha: None,
                distortion: None,
                anchor: None,
            },
            &mut grads,
        );
        assert_eq!(bits(&flat(&grads)), bits(&flat(&g0)), "call {k}: gradients");
        assert_eq!(tw, tw0, "call {k}: camera gradient");
        assert!(
            g0.radius.iter().any(|&v| v > 0.0),
            "call {k}: nothing rendered"
        );
        reuse = Some((image, state));
    }
}

#[test]
fn field_into_reused_buffers_matches_fresh_ones() {
    // Depth 6 has the skip connection (after layer 3).
    let settings = FieldSettings {
        depth: 6,
        width: 24,
        ..Default::default()
    };
    let mlp = Mlp::<f32>::new(settings, 7);
    let mut rng = Rng(3);
    let (mut cache, mut scratch) = (MlpCache::default(), MlpScratch::default());
    let (mut out, mut grads) = (Vec::new(), Vec::new());
    for (k, n) in [5000usize, 700, 4100].into_iter().enumerate() {
        let x: Vec<[f32; 3]> = (0..n)
            .map(|_| std::array::from_fn(|_| rng.uf(-1.0, 1.0)))
            .collect();
        let t = [0.1 + 0.3 * k as f32];
        let (o0, c0) = mlp.forward(&x, &t);
        mlp.forward_into(&x, &t, &mut cache, &mut scratch, &mut out);
        assert_eq!(bits(&out), bits(&o0), "n = {n}: outputs");
        let g_out: Vec<f32> = (0..o0.len())
            .map(|i| ((i % 13) as f32 - 6.0) * 1e-2)
            .collect();
        let g0 = mlp.backward(&c0, &g_out);
        mlp.backward_into(&cache, &g_out, &mut scratch, &mut grads);
        assert_eq!(bits(&grads), bits(&g0), "n = {n}: parameter gradients");
    }
}

#[test]
fn recycled_views_and_gradients_change_nothing() {
    let r = TileRasterizer;
    let settings = TrainSettings {
        static_iterations: 0,
        field: FieldSettings {
            depth: 2,
            width: 16,
            zero_head_init: false,
            ..Default::default()
        },
        ..Default::default()
    };
    let init = scene(9, 400);
    let warm = Trainer::new(settings.clone(), init.clone(), 1.0);
    let fresh = Trainer::new(settings, init, 1.0);
    let cam = |x: f64, w: u32| camera(w, 48, 60.0, DVec3::new(x, 0.1, 4.0));
    // Warm the trainer's spare buffers on other views, sizes and times.
    for (k, w) in [80u32, 40, 64].into_iter().enumerate() {
        let v = warm.render_view(&r, &cam(-0.3 + 0.2 * k as f64, w), 0.2 * k as f32);
        let d: Vec<f32> = vec![1e-2; v.image.rgb.len()];
        let g = warm.view_backward(&r, &v, &d, Planes::NONE, None);
        warm.recycle_view(v);
        warm.recycle_grads(g);
    }
    let (c, t) = (cam(0.25, 56), 0.7);
    let (a, b) = (warm.render_view(&r, &c, t), fresh.render_view(&r, &c, t));
    assert_eq!(bits(&a.image.rgb), bits(&b.image.rgb));
    assert_eq!(a.deformed, b.deformed);
    let d: Vec<f32> = (0..a.image.rgb.len())
        .map(|i| ((i % 7) as f32 - 3.0) * 1e-2)
        .collect();
    let dm = vec![[1e-3f32, -2e-3, 5e-4]; a.deformed.len()];
    let ga = warm.view_backward(&r, &a, &d, Planes::NONE, Some(&dm));
    let gb = fresh.view_backward(&r, &b, &d, Planes::NONE, Some(&dm));
    assert_eq!(bits(&flat(&ga.splats)), bits(&flat(&gb.splats)));
    assert_eq!(bits(&ga.field), bits(&gb.field));
    assert!(
        ga.field.iter().any(|&v| v != 0.0),
        "the field got no gradient"
    );
    assert_eq!(ga.camera, gb.camera);
}
