//! Every gradient of the tile rasterizer (means, quaternions, log-scales, opacity
//! logits, SH DC and rest, camera twist) against central finite differences of the f64
//! reference, for losses on colour, depth and alpha, for the depth distortion
//! (`raster::Distortion`) and for the depths pulled to an anchor (`raster::Anchor`).
//! Relative error per group, norm-wise.
//!
//! Scenes keep the cut-offs out of the way: opacity logits ≥ −0.5 (so α never falls to
//! 1/255 inside the 3σ ellipse), ≤ 1.2 (α < 0.99), few layers (T stays above 1e-4), and
//! the step is 1e-8 so a pixel crossing the ellipse's edge is very unlikely.

mod raster_common;

use gaussians::raster::reference::{self, Gaussians64};
use gaussians::raster::{Anchor, Distortion, Planes, TileRasterizer, apply_twist};
use gaussians::{Rasterizer, SplatGrads, Splats};
use glam::DVec3;
use raster_common::*;
use scene::Camera;

const EPS: f64 = 1e-8;

/// Which image the loss reads.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Target {
    Rgb,
    Depth,
    Alpha,
    Distortion,
    Anchor,
    All,
}

/// The anchor's σ: small enough that some Gaussians lie beyond one unit of Huber.
const SIGMA: f64 = 0.08;

/// The anchor's factor per Gaussian: 0, ½ and 1 in turn.
fn factors(n: usize) -> Vec<f64> {
    (0..n).map(|i| (i % 3) as f64 / 2.0).collect()
}

struct Weights {
    rgb: Vec<f64>,
    depth: Vec<f64>,
    alpha: Vec<f64>,
    /// The distortion's λ per pixel (≥ 0).
    dist: Vec<f64>,
    /// The anchor's λ per pixel (≥ 0) and its depth per pixel (about the scene's).
    anchor: Vec<f64>,
    z_hat: Vec<f64>,
}

fn weights(rng: &mut Rng, np: usize, t: Target) -> Weights {
    let mut w = |on: bool, n: usize| -> Vec<f64> {
        (0..n)
            .map(|_| if on { rng.uni(-1.0, 1.0) } else { 0.0 })
            .collect()
    };
    Weights {
        rgb: w(matches!(t, Target::Rgb | Target::All), 3 * np),
        depth: w(matches!(t, Target::Depth | Target::All), np),
        alpha: w(matches!(t, Target::Alpha | Target::All), np),
        dist: w(matches!(t, Target::Distortion | Target::All), np)
            .iter()
            .map(|v| v.abs())
            .collect(),
        anchor: w(matches!(t, Target::Anchor | Target::All), np)
            .iter()
            .map(|v| v.abs())
            .collect(),
        z_hat: (0..np).map(|_| rng.uni(3.2, 4.8)).collect(),
    }
}

fn loss(g: &Gaussians64, cam: &Camera, sh: u32, bg: [f64; 3], w: &Weights) -> f64 {
    let f = reference::render(g, cam, sh, bg);
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let (dist, _) = reference::distortion(g, cam);
    let anchored = reference::anchored(g, cam, &w.z_hat, SIGMA, &factors(g.means.len()));
    dot(&f.rgb, &w.rgb)
        + dot(&f.depth, &w.depth)
        + dot(&f.alpha, &w.alpha)
        + dot(&dist, &w.dist)
        + dot(&anchored, &w.anchor)
}

const GROUPS: [&str; 6] = [
    "means",
    "rotations",
    "log_scales",
    "opacity",
    "sh_dc",
    "sh_rest",
];

fn param(g: &mut Gaussians64, group: usize, i: usize, k: usize) -> &mut f64 {
    match group {
        0 => &mut g.means[i][k],
        1 => &mut g.rotations[i][k],
        2 => &mut g.log_scales[i][k],
        3 => &mut g.opacity_logits[i],
        4 => &mut g.sh_dc[i][k],
        _ => &mut g.sh_rest[i][k],
    }
}

fn analytic(g: &SplatGrads, group: usize, i: usize, k: usize) -> f64 {
    (match group {
        0 => g.means[i][k],
        1 => g.rotations[i][k],
        2 => g.log_scales[i][k],
        3 => g.opacity_logits[i],
        4 => g.sh_dc[i][k],
        _ => g.sh_rest[i][k],
    }) as f64
}

const WIDTHS: [usize; 6] = [3, 4, 3, 1, 3, 45];

struct Check {
    name: String,
    rel: f64,
    norm: f64,
}

/// Compare every group for one scene and loss; returns (group, relative error, ‖fd‖).
fn check_scene(s: &Splats, cam: &Camera, sh: u32, bg: [f32; 3], w: &Weights) -> Vec<Check> {
    let r = TileRasterizer;
    let (image, st) = r.render_full(s, cam, sh, bg);
    let f32v = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let lam = f32v(&w.dist);
    let (lam_a, z_hat) = (f32v(&w.anchor), f32v(&w.z_hat));
    let m = f32v(&factors(s.len()));
    let planes = Planes {
        depth: Some(&f32v(&w.depth)),
        alpha: Some(&f32v(&w.alpha)),
        distortion: Some(Distortion {
            weight: &lam,
            depth: &image.depth,
        }),
        anchor: Some(Anchor {
            weight: &lam_a,
            depth: &z_hat,
            sigma: SIGMA as f32,
            gaussians: &m,
        }),
    };
    let (g, pose) = r.backward_view(s, cam, &st, &f32v(&w.rgb), planes);
    let bg64 = bg.map(f64::from);
    let g64 = Gaussians64::from(s);
    let mut out = Vec::new();
    for group in 0..6 {
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for i in 0..s.len() {
            for k in 0..WIDTHS[group] {
                let mut p = g64.clone();
                let x0 = *param(&mut p, group, i, k);
                *param(&mut p, group, i, k) = x0 + EPS;
                let lp = loss(&p, cam, sh, bg64, w);
                *param(&mut p, group, i, k) = x0 - EPS;
                let lm = loss(&p, cam, sh, bg64, w);
                let fd = (lp - lm) / (2.0 * EPS);
                let an = analytic(&g, group, i, k);
                num += (an - fd).powi(2);
                den += fd * fd;
            }
        }
        out.push(Check {
            name: GROUPS[group].into(),
            rel: num.sqrt() / den.sqrt().max(1e-300),
            norm: den.sqrt(),
        });
    }
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for k in 0..6 {
        let mut d = [0.0; 6];
        let mut c = *cam;
        d[k] = EPS;
        c.cam_to_world = apply_twist(&cam.cam_to_world, d);
        let lp = loss(&g64, &c, sh, bg64, w);
        d[k] = -EPS;
        c.cam_to_world = apply_twist(&cam.cam_to_world, d);
        let lm = loss(&g64, &c, sh, bg64, w);
        let fd = (lp - lm) / (2.0 * EPS);
        num += (pose[k] - fd).powi(2);
        den += fd * fd;
    }
    out.push(Check {
        name: "pose twist".into(),
        rel: num.sqrt() / den.sqrt().max(1e-300),
        norm: den.sqrt(),
    });
    out
}

/// A scene of `n` Gaussians in front of the camera (a few px to ~10 px), plus one
/// straddling the image's right edge and one behind the camera.
fn grad_scene(rng: &mut Rng, n: usize) -> Splats {
    let kind = SceneKind {
        n,
        spread: 1.2,
        log_scale: (-2.6, -1.4),
        logit: (-0.5, 1.2),
        sh_rest: 0.25,
    };
    let mut s = random_splats(rng, kind);
    push_gaussian(&mut s, [1.45, 0.3, 0.2], -1.6, 0.5);
    push_gaussian(&mut s, [0.0, 0.0, 6.0], -1.0, 1.0);
    // Far to the side: its Jacobian is evaluated at the clamped x/d (3DGS's 1.3 × fov).
    push_gaussian(&mut s, [3.3, -0.2, 0.3], -0.8, 0.6);
    s
}

fn run(target: Target, seeds: std::ops::Range<u64>, sh: u32) {
    let mut worst = 0.0f64;
    for seed in seeds {
        let mut rng = Rng(1000 + seed);
        let s = grad_scene(&mut rng, 8);
        let eye = DVec3::new(0.2 * seed as f64 - 0.3, 0.3, 4.0);
        let cam = camera(37, 29, 34.0, eye);
        let w = weights(&mut rng, 37 * 29, target);
        let bg = [0.3, 0.6, 0.1];
        for c in check_scene(&s, &cam, sh, bg, &w) {
            let zero = matches!(
                target,
                Target::Depth | Target::Alpha | Target::Distortion | Target::Anchor
            ) && c.name.starts_with("sh");
            eprintln!(
                "{target:?} seed {seed} {}: rel {:.2e} (|fd| {:.3e})",
                c.name, c.rel, c.norm
            );
            worst = worst.max(c.rel);
            if zero {
                assert!(c.norm == 0.0, "{} must not depend on {target:?}", c.name);
                continue;
            }
            assert!(
                c.norm > 1e-6,
                "{target:?} seed {seed}: {} gradient is trivially 0",
                c.name
            );
            assert!(
                c.rel < 1e-3,
                "{target:?} seed {seed}: {} relative error {:.3e} (|fd| {:.3e})",
                c.name,
                c.rel,
                c.norm
            );
        }
    }
    eprintln!("{target:?}: worst relative error {worst:.2e}");
}

#[test]
fn gradients_of_colour_loss_match_finite_differences() {
    run(Target::Rgb, 0..8, 3);
}

#[test]
fn gradients_of_depth_loss_match_finite_differences() {
    run(Target::Depth, 8..13, 3);
}

#[test]
fn gradients_of_alpha_loss_match_finite_differences() {
    run(Target::Alpha, 13..18, 3);
}

/// The depth distortion's gradient: the double sum's (`reference::distortion`) against
/// the backward's walk with running sums.
#[test]
fn gradients_of_the_depth_distortion_match_finite_differences() {
    run(Target::Distortion, 24..29, 3);
}

/// The anchor's gradient: every blended depth's Huber against the per-pixel sum of the
/// reference.
#[test]
fn gradients_of_the_depth_anchor_match_finite_differences() {
    run(Target::Anchor, 29..34, 3);
}

#[test]
fn gradients_of_joint_loss_match_at_low_sh_degree() {
    run(Target::All, 18..21, 1);
    run(Target::All, 21..24, 2);
}
