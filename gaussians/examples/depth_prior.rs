//! A depth prior for a synthetic scene (`degs synth`), issue #30: the ground-truth depth
//! of the train frames (`gt/train/depth_NNNN.exr`) written as `depth/<stem>.exr`
//! (`scene::depth_prior`), as it is or spoilt the way a monocular depth network's output
//! is, so that what the tracks init does with a prior can be measured at a known quality
//! before a user brings their own (this machine cannot fetch a network's weights).
//!
//! ```text
//! cargo run --release -p degs-gaussians --example depth_prior -- SCENE KIND [ERROR] [BLUR] [SEED]
//! ```
//!
//! `KIND`: `z` (the depth itself: ERROR and BLUR still apply) or `inverse_affine` (each
//! frame's inverse depth times a random factor in [0.5, 2] plus a random offset of up to
//! a tenth of its mean, as relative-depth networks give). `ERROR` (default 0): the
//! relative amplitude of a smooth multiplicative error over each frame (three random
//! waves of one to three periods across the image). `BLUR` (default 0): the radius in
//! pixels of a box blur of the inverse depth, which mixes an object's depth with its
//! background's at its edges as networks do. Refuses a scene that already has a
//! `depth/` folder.

use glam::DVec2;
use rand::{RngExt, SeedableRng};
use scene::depth_prior::{DepthKind, DepthPriors};
use std::path::Path;

fn blur(inv: &[f64], w: usize, h: usize, r: usize) -> Vec<f64> {
    if r == 0 {
        return inv.to_vec();
    }
    let pass = |src: &[f64], horizontal: bool| -> Vec<f64> {
        let mut out = vec![0.0; src.len()];
        for y in 0..h {
            for x in 0..w {
                let (mut sum, mut n) = (0.0, 0.0);
                for d in -(r as isize)..=(r as isize) {
                    let (xx, yy) = if horizontal {
                        (x as isize + d, y as isize)
                    } else {
                        (x as isize, y as isize + d)
                    };
                    if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
                        let v = src[yy as usize * w + xx as usize];
                        if v > 0.0 {
                            sum += v;
                            n += 1.0;
                        }
                    }
                }
                out[y * w + x] = if n > 0.0 { sum / n } else { 0.0 };
            }
        }
        out
    };
    pass(&pass(inv, true), false)
}

fn main() -> scene::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: depth_prior SCENE z|inverse_affine [ERROR] [BLUR] [SEED]");
        std::process::exit(2);
    }
    let root = Path::new(&args[0]);
    let kind = match args[1].as_str() {
        "z" => DepthKind::Z,
        "inverse_affine" => DepthKind::InverseAffine,
        k => {
            eprintln!("unknown kind {k}: z or inverse_affine");
            std::process::exit(2);
        }
    };
    let num = |i: usize, d: f64| args.get(i).map_or(Ok(d), |s| s.parse::<f64>());
    let (Ok(error), Ok(radius), Ok(seed)) = (num(2, 0.0), num(3, 0.0), num(4, 0.0)) else {
        eprintln!("ERROR, BLUR and SEED are numbers");
        std::process::exit(2);
    };
    let sc = scene::Scene::open(root)?;
    let (w, h) = (
        sc.train.camera.width as usize,
        sc.train.camera.height as usize,
    );
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed as u64);
    let mut maps = Vec::new();
    for k in 0..sc.train.frames.len() {
        let path = root.join(format!("gt/train/depth_{k:04}.exr"));
        let (_, _, z) = scene::image_io::read_exr_depth(&path)?;
        let inv: Vec<f64> = (z.iter())
            .map(|&z| if z > 0.0 { 1.0 / z as f64 } else { 0.0 })
            .collect();
        let mut inv = blur(&inv, w, h, radius as usize);
        let waves: Vec<(DVec2, f64, f64)> = (0..3)
            .map(|_| {
                let angle = rng.random_range(0.0..std::f64::consts::TAU);
                let periods = rng.random_range(1.0..3.0);
                let k = DVec2::new(angle.cos(), angle.sin()) * periods * std::f64::consts::TAU;
                (
                    k,
                    rng.random_range(0.0..std::f64::consts::TAU),
                    error / 3f64.sqrt(),
                )
            })
            .collect();
        for (i, v) in inv.iter_mut().enumerate() {
            let p = DVec2::new((i % w) as f64 / w as f64, (i / w) as f64 / h as f64);
            let e: f64 = waves
                .iter()
                .map(|(k, ph, a)| a * (k.dot(p) + ph).sin())
                .sum();
            // A depth error of e is an inverse-depth error of about −e.
            *v *= 1.0 - e;
        }
        let map: Vec<f32> = match kind {
            DepthKind::Z | DepthKind::Affine => (inv.iter())
                .map(|&v| if v > 0.0 { (1.0 / v) as f32 } else { 0.0 })
                .collect(),
            DepthKind::InverseAffine => {
                let valid: Vec<f64> = inv.iter().copied().filter(|&v| v > 0.0).collect();
                let mean = valid.iter().sum::<f64>() / valid.len().max(1) as f64;
                let a = 2f64.powf(rng.random_range(-1.0..1.0));
                let b = rng.random_range(-0.1..0.1) * mean;
                (inv.iter())
                    .map(|&v| if v > 0.0 { (a * v + b) as f32 } else { 0.0 })
                    .collect()
            }
        };
        maps.push(Some(map));
    }
    scene::depth_prior::write(root, &sc.train, &DepthPriors { kind, maps })?;
    eprintln!(
        "{}: {} depth maps ({:?}, error {error}, blur {radius} px)",
        root.join(scene::depth_prior::DIR).display(),
        sc.train.frames.len(),
        kind
    );
    Ok(())
}
