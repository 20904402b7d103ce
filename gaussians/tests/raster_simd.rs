//! The portable 4-lane kernels (SSE2) against the f64 reference and, where the CPU has
//! AVX-512F, against the 16-lane kernels (the same images and gradients to rounding). On a
//! CPU without AVX-512 only the first comparison can run; the test says which ran.
//! One test in its own binary, because it flips the process-wide kernel switch.

mod raster_common;

use gaussians::SplatGrads;
use gaussians::raster::reference::{self, Gaussians64};
use gaussians::raster::{TileRasterizer, simd};
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
    v
}

#[test]
fn narrow_and_wide_kernels_agree() {
    let r = TileRasterizer;
    let kernels: &[bool] = if simd::wide_available() {
        eprintln!(
            "comparing the 4-lane (SSE2) kernels with the f64 reference and with the \
             16-lane (AVX-512) kernels"
        );
        &[false, true]
    } else {
        eprintln!(
            "this CPU has no AVX-512F: comparing the 4-lane (SSE2) kernels with the f64 \
             reference only; 4-lane vs 16-lane is NOT compared"
        );
        &[false]
    };
    let mut rng = Rng(4242);
    for scene in 0..6 {
        let kind = SceneKind {
            n: 60 + 20 * scene,
            spread: 1.5,
            log_scale: (-3.5, -1.0),
            logit: (-3.0, 4.0),
            sh_rest: 0.3,
        };
        let s = random_splats(&mut rng, kind);
        let cam = camera(53, 41, 45.0, DVec3::new(0.2, 0.1, 4.0));
        let np = 53 * 41;
        let d_rgb: Vec<f32> = (0..3 * np)
            .map(|i| ((i * 37 % 11) as f32 - 5.0) * 0.01)
            .collect();
        let d_depth: Vec<f32> = (0..np)
            .map(|i| ((i * 13 % 7) as f32 - 3.0) * 0.01)
            .collect();
        let d_alpha: Vec<f32> = (0..np).map(|i| ((i * 5 % 9) as f32 - 4.0) * 0.01).collect();
        let mut out = Vec::new();
        for &wide in kernels {
            simd::set_wide(wide);
            assert_eq!(simd::use_wide(), wide, "kernel switch");
            let (f, st) = r.render_full(&s, &cam, 3, [0.2, 0.1, 0.0]);
            let (g, pose) = r.backward_full(&s, &cam, &st, &d_rgb, Some(&d_depth), Some(&d_alpha));
            out.push((f, flat(&g), pose));
        }
        let rf = reference::render(&Gaussians64::from(&s), &cam, 3, [0.2, 0.1, 0.0]);
        // Each kernel against the reference; the 16-lane one uses fused multiply-adds
        // and a reciprocal estimate, so the two agree to rounding, not bit for bit.
        for (kernel, o) in ["narrow", "wide"].iter().zip(&out) {
            for (name, a, b) in [
                ("rgb", &o.0.rgb, &rf.rgb),
                ("depth", &o.0.depth, &rf.depth),
                ("alpha", &o.0.alpha, &rf.alpha),
            ] {
                let d = max_abs_diff(a, b);
                assert!(
                    d < 1e-4,
                    "scene {scene}: {kernel} vs reference, {name} by {d:e}"
                );
            }
        }
        let narrow = &out[0];
        let Some(wide) = out.get(1) else {
            continue;
        };
        for (a, b) in [
            (&narrow.0.rgb, &wide.0.rgb),
            (&narrow.0.depth, &wide.0.depth),
            (&narrow.0.alpha, &wide.0.alpha),
        ] {
            let d = a
                .iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f32::max);
            assert!(
                d < 1e-5,
                "scene {scene}: the kernels' images differ by {d:e}"
            );
        }
        let norm = narrow
            .1
            .iter()
            .map(|v| (*v as f64).powi(2))
            .sum::<f64>()
            .sqrt();
        let diff = narrow
            .1
            .iter()
            .zip(&wide.1)
            .map(|(a, b)| ((a - b) as f64).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(
            norm > 0.0 && diff <= 1e-5 * norm,
            "scene {scene}: gradients differ by {diff:e} of {norm:e}"
        );
        for k in 0..6 {
            assert!(
                (narrow.2[k] - wide.2[k]).abs() <= 1e-5 * (1.0 + wide.2[k].abs()),
                "pose {k}"
            );
        }
    }
    simd::set_wide(true);
    eprintln!("compared on {} kernel(s)", kernels.len());
}
