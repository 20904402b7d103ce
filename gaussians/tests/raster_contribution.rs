//! Blending weights per Gaussian (`Σ_pixels α·T`, the contribution pruning ranks by)
//! against the f64 reference and against the rendered alpha they must sum to.

mod raster_common;

use gaussians::raster::TileRasterizer;
use gaussians::raster::reference::{self, Gaussians64};
use gaussians::{Rasterizer, Splats};
use glam::DVec3;
use raster_common::*;

fn tile_weights(s: &Splats, cam: &scene::Camera) -> Vec<f64> {
    let mut w = vec![0.0; s.len()];
    assert!(TileRasterizer.add_contributions(s, cam, &mut w));
    w
}

/// Random scenes, sparse and saturated: every Gaussian's weight within 1e-3 px of the
/// reference's (the forward's colours agree to 1e-4 per pixel), and the weights of a
/// render sum to its alpha.
#[test]
fn weights_match_the_reference_and_sum_to_alpha() {
    let mut rng = Rng(11);
    let mut nonzero = 0;
    for scene in 0..12 {
        let (w, h) = (40 + (scene * 7) % 50, 30 + (scene * 11) % 45);
        let saturated = scene % 3 == 2;
        let kind = SceneKind {
            n: 30 + scene * 8,
            spread: if saturated { 1.0 } else { 1.6 },
            log_scale: if saturated {
                (-1.5, -0.5)
            } else {
                (-3.5, -1.0)
            },
            logit: if saturated { (4.0, 8.0) } else { (-3.0, 4.0) },
            sh_rest: 0.3,
        };
        let mut s = random_splats(&mut rng, kind);
        push_gaussian(&mut s, [0.0, 0.0, 6.0], -1.0, 3.0); // behind the camera
        let cam = camera(
            w as u32,
            h as u32,
            0.9 * w as f64,
            DVec3::new(0.2, 0.1, 4.0),
        );
        let got = tile_weights(&s, &cam);
        let want = reference::contributions(&Gaussians64::from(&s), &cam);
        let worst = got
            .iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-3, "scene {scene}: weights differ by {worst:e}");
        assert_eq!(got[s.len() - 1], 0.0, "a culled Gaussian weighs nothing");
        nonzero += got.iter().filter(|&&v| v > 0.0).count();
        let (img, _) = TileRasterizer.render(&s, &cam, 0, [0.0; 3]);
        let alpha: f64 = img.alpha.iter().map(|&a| a as f64).sum();
        let total: f64 = got.iter().sum();
        assert!(
            (total - alpha).abs() < 1e-4 * alpha.max(1.0),
            "scene {scene}: weights sum to {total}, alpha to {alpha}"
        );
    }
    assert!(nonzero > 300, "too few visible Gaussians ({nonzero})");
}

/// Two Gaussians at the same place: the front one weighs `Σ α`, the one behind
/// `Σ α·(1 − α_front)` at each pixel; a third far outside the image weighs nothing.
#[test]
fn an_occluded_gaussian_weighs_what_shows_through() {
    let mut s = Splats::default();
    push_gaussian(&mut s, [0.0, 0.0, 0.0], -1.5, 0.0); // behind, opacity 0.5
    push_gaussian(&mut s, [0.0, 0.0, 0.5], -1.5, 1.0); // in front, opacity 0.73
    push_gaussian(&mut s, [40.0, 0.0, 0.0], -1.5, 1.0); // off-screen
    let cam = camera(48, 40, 40.0, DVec3::new(0.0, 0.0, 4.0));
    let w = tile_weights(&s, &cam);
    let r = reference::contributions(&Gaussians64::from(&s), &cam);
    assert!(w[0] > 1.0 && w[1] > w[0], "{w:?}");
    assert_eq!(w[2], 0.0);
    for k in 0..3 {
        assert!((w[k] - r[k]).abs() < 1e-3, "{k}: {} vs {}", w[k], r[k]);
    }
    // Adding a Gaussian never raises the weights of those in front of it.
    push_gaussian(&mut s, [0.0, 0.0, -0.5], -1.0, 2.0);
    let w2 = tile_weights(&s, &cam);
    assert_eq!((w2[0], w2[1]), (w[0], w[1]));
    assert!(w2[3] > 0.0);
}
