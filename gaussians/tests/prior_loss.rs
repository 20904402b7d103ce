//! The depth-prior term `L_depth` (`tracks::prior_loss`): its gradient with respect to
//! the rendered depth and alpha against central finite differences in f64, and through
//! the tile rasterizer to the Gaussians against finite differences of the f64 reference
//! renderer.

mod raster_common;

use gaussians::raster::TileRasterizer;
use gaussians::raster::reference::{self, Gaussians64};
use gaussians::tracks::prior_loss::{MIN_ALPHA, at_view};
use glam::DVec3;
use raster_common::*;

/// `L_depth` in f64, written from its definition (module docs of `prior_loss`).
fn loss64(depth: &[f64], alpha: &[f64], prior: &[f64], w: f64, sigma: f64) -> f64 {
    let on: Vec<usize> = (0..depth.len())
        .filter(|&p| prior[p] > 0.0 && alpha[p] >= MIN_ALPHA as f64)
        .collect();
    let huber = |r: f64| {
        if r.abs() <= 1.0 {
            0.5 * r * r
        } else {
            r.abs() - 0.5
        }
    };
    let sum: f64 = (on.iter())
        .map(|&p| huber((depth[p] / alpha[p] - prior[p]) / (sigma * prior[p])))
        .sum();
    w * sum / on.len() as f64
}

fn param<'a>(g: &'a mut Gaussians64, name: &str, i: usize, k: usize) -> &'a mut f64 {
    match name {
        "means" => &mut g.means[i][k],
        "log_scales" => &mut g.log_scales[i][k],
        _ => &mut g.opacity_logits[i],
    }
}

#[test]
fn depth_and_alpha_gradients_match_finite_differences() {
    let mut rng = Rng(7);
    let n = 200;
    let (w, sigma) = (0.7, 0.05);
    let alpha: Vec<f32> = (0..n).map(|_| rng.uf(0.3, 1.0)).collect();
    let prior: Vec<f32> = (0..n)
        .map(|p| if p % 9 == 0 { 0.0 } else { rng.uf(1.0, 5.0) })
        .collect();
    // Rendered depths up to 15 % off the prior (both Huber branches), times alpha.
    let depth: Vec<f32> = (0..n)
        .map(|p| alpha[p] * prior[p].max(2.0) * (1.0 + rng.uf(-0.15, 0.15)))
        .collect();
    let (mut dd, mut da) = (Vec::new(), Vec::new());
    let (l, count, rel) = at_view(&depth, &alpha, &prior, w, sigma, &mut dd, &mut da);
    let f64v = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<f64>>();
    let (d64, a64, z64) = (f64v(&depth), f64v(&alpha), f64v(&prior));
    let expected = (0..n)
        .filter(|&p| prior[p] > 0.0 && alpha[p] >= MIN_ALPHA)
        .count();
    assert_eq!(count, expected);
    assert!(count > n / 2, "too few pixels compared: {count}");
    assert!((l - loss64(&d64, &a64, &z64, w, sigma)).abs() < 1e-9 * l.max(1.0));
    let rel64: f64 = (0..n)
        .filter(|&p| prior[p] > 0.0 && alpha[p] >= MIN_ALPHA)
        .map(|p| (d64[p] / a64[p] - z64[p]).abs() / z64[p])
        .sum::<f64>()
        / count as f64;
    assert!((rel - rel64).abs() < 1e-9, "{rel} against {rel64}");
    let eps = 1e-6;
    let mut worst = 0.0f64;
    for p in 0..n {
        for (plane, an) in [(0, dd[p]), (1, da[p])] {
            let (mut hi, mut lo) = ([d64.clone(), a64.clone()], [d64.clone(), a64.clone()]);
            hi[plane][p] += eps;
            lo[plane][p] -= eps;
            let fd = (loss64(&hi[0], &hi[1], &z64, w, sigma)
                - loss64(&lo[0], &lo[1], &z64, w, sigma))
                / (2.0 * eps);
            let err = (an as f64 - fd).abs() / fd.abs().max(1e-3);
            worst = worst.max(err);
            assert!(err < 1e-4, "pixel {p} plane {plane}: {an} against {fd}");
        }
    }
    eprintln!("L_depth planes: worst relative error {worst:.2e} over {count} pixels");
}

/// Through the rasterizer: `∂L_depth/∂(means, log-scales, opacity)` of the tile
/// rasterizer's backward, fed the planes from `at_view`, against finite differences of
/// `L_depth` on the f64 reference render.
#[test]
fn depth_term_gradients_reach_the_gaussians() {
    let r = TileRasterizer;
    let mut worst = 0.0f64;
    for seed in 0..4u64 {
        let mut rng = Rng(300 + seed);
        let kind = SceneKind {
            n: 10,
            spread: 1.0,
            log_scale: (-2.0, -1.2),
            logit: (0.0, 1.2),
            sh_rest: 0.0,
        };
        let s = random_splats(&mut rng, kind);
        let cam = camera(31, 23, 30.0, DVec3::new(0.1 * seed as f64, 0.2, 4.0));
        let g64 = Gaussians64::from(&s);
        let f = reference::render(&g64, &cam, 0, [0.0; 3]);
        // A prior up to 12 % off what the render shows, with holes.
        let prior: Vec<f64> = (0..f.depth.len())
            .map(|p| {
                let shown = f.depth[p] / f.alpha[p].max(1e-9);
                let z = shown * (1.0 + rng.uni(-0.12, 0.12));
                if p % 11 == 0 || f.alpha[p] < 0.2 {
                    0.0
                } else {
                    z
                }
            })
            .collect();
        let (w, sigma) = (1.0, 0.05);
        let l = |g: &Gaussians64| {
            let f = reference::render(g, &cam, 0, [0.0; 3]);
            loss64(&f.depth, &f.alpha, &prior, w, sigma)
        };
        let (img, st) = r.render_full(&s, &cam, 0, [0.0; 3]);
        let prior32: Vec<f32> = prior.iter().map(|&z| z as f32).collect();
        let (mut dd, mut da) = (Vec::new(), Vec::new());
        let (_, count, _) = at_view(&img.depth, &img.alpha, &prior32, w, sigma, &mut dd, &mut da);
        assert!(count > 50, "seed {seed}: {count} pixels compared");
        let zero = vec![0.0f32; 3 * img.depth.len()];
        let (g, _) = r.backward_full(&s, &cam, &st, &zero, Some(&dd), Some(&da));
        let eps = 1e-7;
        let groups: [(&str, usize); 3] = [("means", 3), ("log_scales", 3), ("opacity", 1)];
        for (name, width) in groups {
            let (mut num, mut den) = (0.0f64, 0.0f64);
            for i in 0..s.len() {
                for k in 0..width {
                    let (mut hi, mut lo) = (g64.clone(), g64.clone());
                    *param(&mut hi, name, i, k) += eps;
                    *param(&mut lo, name, i, k) -= eps;
                    let fd = (l(&hi) - l(&lo)) / (2.0 * eps);
                    let an = match name {
                        "means" => g.means[i][k],
                        "log_scales" => g.log_scales[i][k],
                        _ => g.opacity_logits[i],
                    } as f64;
                    num += (an - fd).powi(2);
                    den += fd * fd;
                }
            }
            let rel = num.sqrt() / den.sqrt().max(1e-300);
            eprintln!(
                "seed {seed} {name}: relative error {rel:.2e} (|fd| {:.3e})",
                den.sqrt()
            );
            assert!(
                den.sqrt() > 1e-4,
                "seed {seed}: {name} gradient trivially 0"
            );
            assert!(rel < 2e-3, "seed {seed}: {name} relative error {rel:.3e}");
            worst = worst.max(rel);
        }
    }
    eprintln!("L_depth through the rasterizer: worst relative error {worst:.2e}");
}

/// The aligned priors read back as written (a view without a map as none), and a file
/// for another number of views or size is refused with its name in the error.
#[test]
fn the_priors_file_reads_back_and_refuses_what_does_not_fit() {
    use gaussians::tracks::depth::Aligned;
    use gaussians::tracks::file::{PRIORS_FILE, read_priors, write_priors};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(PRIORS_FILE);
    let (w, h) = (5, 3);
    let map = |k: f32| Aligned {
        width: w,
        height: h,
        z: (0..w * h).map(|i| k + 0.25 * i as f32).collect(),
        median_rel_error: 0.01,
        points: 9,
    };
    let maps = vec![Some(map(1.0)), None, Some(map(3.5))];
    write_priors(&path, &maps, w, h).unwrap();
    let back = read_priors(&path, 3, w, h).unwrap();
    assert_eq!(back.len(), 3);
    assert!(back[1].is_none());
    for k in [0, 2] {
        assert_eq!(back[k].as_ref().unwrap().z, maps[k].as_ref().unwrap().z);
    }
    for (views, ww, hh) in [(2, w, h), (3, h, w)] {
        let e = read_priors(&path, views, ww, hh).unwrap_err().to_string();
        assert!(e.contains(PRIORS_FILE) && e.contains("tensor z"), "{e}");
    }
}
