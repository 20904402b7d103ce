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

/// The reference's depth spread (`Σᵢ Σⱼ wᵢ wⱼ |zᵢ − zⱼ| / ((Σ w)² D̄)`, summed over the
/// depth-sorted Gaussians with running sums) against the double sum by brute force,
/// each Gaussian's alpha read from a render of it alone and its weight `αᵢ Πⱼ (1 − αⱼ)`
/// over the nearer ones; one Gaussian alone spreads nothing.
#[test]
fn depth_spread_is_the_double_sum() {
    let mut s = Splats::default();
    let layers = [([0.0, 0.0, 1.0], -1.2, 0.3), ([0.1, 0.0, 0.0], -1.0, 1.0)];
    let more = [
        ([-0.1, 0.1, -0.7], -0.9, -0.5),
        ([0.0, -0.1, 0.4], -1.4, 0.0),
    ];
    for (m, ls, logit) in layers.iter().chain(&more) {
        push_gaussian(&mut s, *m, *ls, *logit);
    }
    let cam = camera(40, 32, 36.0, DVec3::new(0.0, 0.0, 4.0));
    let g = Gaussians64::from(&s);
    let got = reference::depth_spread(&g, &cam);
    let alone: Vec<Vec<f64>> = (0..s.len())
        .map(|i| {
            let mut one = Splats::default();
            push_gaussian(
                &mut one,
                s.means[i],
                s.log_scales[i][0],
                s.opacity_logits[i],
            );
            reference::render(&Gaussians64::from(&one), &cam, 0, [0.0; 3]).alpha
        })
        .collect();
    let z: Vec<f64> = (s.means.iter())
        .map(|m| {
            cam.project_world(glam::Vec3::from(*m).as_dvec3())
                .unwrap()
                .1
        })
        .collect();
    let mut order: Vec<usize> = (0..s.len()).collect();
    order.sort_by(|&a, &b| z[a].total_cmp(&z[b]));
    let mut checked = 0;
    for p in 0..got.len() {
        let mut t = 1.0;
        let mut w = vec![0.0; s.len()];
        for &i in &order {
            w[i] = alone[i][p] * t;
            t *= 1.0 - alone[i][p];
        }
        let total: f64 = w.iter().sum();
        if total < 0.05 {
            continue;
        }
        let mean = w.iter().zip(&z).map(|(w, z)| w * z).sum::<f64>() / total;
        let mut pairs = 0.0;
        for i in 0..s.len() {
            for j in 0..s.len() {
                pairs += w[i] * w[j] * (z[i] - z[j]).abs();
            }
        }
        let want = pairs / (total * total * mean);
        assert!(
            (got[p] - want).abs() < 1e-9,
            "pixel {p}: {} against {want}",
            got[p]
        );
        checked += (want > 0.01) as usize;
    }
    assert!(checked > 50, "too few pixels with two layers ({checked})");
    let mut one = Splats::default();
    push_gaussian(&mut one, [0.0, 0.0, 0.0], -1.0, 1.0);
    let single = reference::depth_spread(&Gaussians64::from(&one), &cam);
    assert!(single.iter().all(|&v| v.abs() < 1e-12));
}
