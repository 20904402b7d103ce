//! Diagnostic for synthetic scenes (`degs synth`), issue #30: initial Gaussians at the
//! ground-truth depth of some train frames, one per pixel, for `gaussians train
//! --init-ply`. It measures what a right initial depth alone is worth (BENCHMARKS.md,
//! "Why moving objects smear"), against the stereo init, which assumes a still scene and
//! puts the moving objects at the wrong depth.
//!
//! ```text
//! cargo run --release -p degs-gaussians --example gt_init -- SCENE OUT.ply [FRAMES] [MOVING_IDS] [MOTION] [SCALE]
//! ```
//!
//! `FRAMES`: comma-separated train frame indices (default `0`). `MOVING_IDS`: object ids
//! (`gt/train/object_NNNN.png`: k + 1 for `objects[k]`) whose pixels are taken from the
//! first listed frame only, so that each moving object starts as one copy (default: none,
//! every pixel of every listed frame). Pixels without a surface (infinite depth) are
//! skipped. Colours are the frame's pixel values, opacity 0.5, isotropic footprint of one
//! pixel at the point's depth. `MOTION` (a path): also the true trajectories, for
//! `--init-motion`: the moving objects' Gaussians get the quadratic (about the
//! recording's middle, `gaussians::motion`) fitted by least squares to their surface
//! point's analytic positions at the train times, and sit where that fit puts them at the
//! middle; every other Gaussian is still. `SCALE` (default 1): the moving objects'
//! points as a camera whose images are the same would see them at another distance:
//! at every train time `c + SCALE·(x − c)` with `c` the camera's centre then (the
//! one-parameter family one moving camera cannot tell apart, BENCHMARKS.md).

use gaussians::splats::{Gaussian, Splats};
use glam::{DMat3, DVec2, DVec3};
use std::path::Path;

/// Least squares `x(t) ≈ μ + v·τ + a·τ²` (τ = t − T0) over `(t, x)` samples: `(μ, v, a)`.
fn fit_quadratic(samples: &[(f64, DVec3)]) -> (DVec3, DVec3, DVec3) {
    let t0 = gaussians::motion::T0 as f64;
    let mut ata = DMat3::ZERO;
    let mut atb = [DVec3::ZERO; 3];
    for &(t, x) in samples {
        let b = [1.0, t - t0, (t - t0) * (t - t0)];
        for r in 0..3 {
            for c in 0..3 {
                ata.col_mut(c)[r] += b[r] * b[c];
            }
            atb[r] += b[r] * x;
        }
    }
    let inv = ata.inverse();
    let coef = |r: usize| (0..3).fold(DVec3::ZERO, |acc, c| acc + inv.col(c)[r] * atb[c]);
    (coef(0), coef(1), coef(2))
}

fn list<T: std::str::FromStr>(arg: Option<&String>, default: Vec<T>) -> Vec<T> {
    match arg {
        None => default,
        Some(s) => s
            .split(',')
            .map(|v| {
                v.trim()
                    .parse()
                    .ok()
                    .expect("a comma-separated list of numbers")
            })
            .collect(),
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: gt_init SCENE OUT.ply [FRAMES] [MOVING_IDS]");
        std::process::exit(2);
    }
    let scene = scene::manifest::Scene::open(&args[1])?;
    let frames: Vec<usize> = list(args.get(3), vec![0]);
    let moving: Vec<u16> = list(args.get(4), Vec::new());
    let motion_out = args.get(5);
    let along_ray: f64 = args.get(6).map_or(Ok(1.0), |s| s.parse())?;
    let world = match motion_out {
        None => None,
        Some(_) => {
            let text = std::fs::read_to_string(scene.root.join("synth.json"))?;
            let cfg: synth::SynthConfig = serde_json::from_str(&text)?;
            Some(synth::SynthWorld::new(&cfg)?)
        }
    };
    let mut motion = Vec::new();
    const SH_C0: f32 = 0.282_094_8;
    let mut splats = Splats::default();
    for (n, &k) in frames.iter().enumerate() {
        let frame = scene
            .train
            .frames
            .get(k)
            .ok_or_else(|| format!("{}: no train frame {k}", args[1]))?;
        let cam = scene.camera(frame);
        let gt = scene.root.join("gt").join("train");
        let (w, h, depth) = scene::image_io::read_exr_depth(gt.join(format!("depth_{k:04}.exr")))?;
        let (_, _, ids) = synth::gt::read_object_png(gt.join(format!("object_{k:04}.png")))?;
        let rgb = scene::image_io::read_image(scene.image_path(frame))?;
        for y in 0..h as usize {
            for x in 0..w as usize {
                let i = y * w as usize + x;
                let d = depth[i] as f64;
                if !(d.is_finite() && d > 0.0 && d < 1e4) || (n > 0 && moving.contains(&ids[i])) {
                    continue;
                }
                let px = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                let mut p = cam.unproject_world(px, d);
                let mut m = [0.0f32; 6];
                if let Some(world) = &world
                    && moving.contains(&ids[i])
                    && let Some(hit) = world.cast(frame.timestamp, px)
                {
                    let path: Vec<(f64, DVec3)> = (scene.train.frames.iter())
                        .map(|f| {
                            let c = scene.camera(f).cam_to_world.centre();
                            let x = world.material_to_world(hit.object, hit.local, f.timestamp);
                            (f.time, c + along_ray * (x - c))
                        })
                        .collect();
                    let (mu, v, a) = fit_quadratic(&path);
                    p = mu;
                    m = [v.x, v.y, v.z, a.x, a.y, a.z].map(|c| c as f32);
                }
                let c = &rgb.data[3 * i..3 * i + 3];
                let sh = [c[0], c[1], c[2]].map(|v| (v - 0.5) / SH_C0);
                let d = if moving.contains(&ids[i]) {
                    d * along_ray
                } else {
                    d
                };
                let scale = (0.5 * d / cam.intrinsics.fx) as f32;
                let mean = [p.x as f32, p.y as f32, p.z as f32];
                splats.push(Gaussian::isotropic(mean, scale.ln(), 0.0, sh));
                motion.push(m);
            }
        }
    }
    gaussians::ply::write(Path::new(&args[2]), &splats, 0)?;
    if let Some(path) = motion_out {
        gaussians::model::motion_file::write(Path::new(path), &motion, &[])?;
    }
    eprintln!("{}: {} Gaussians", args[2], splats.len());
    Ok(())
}
