//! The isometry term (`train/rigidity.rs`): its neighbour lists against a brute-force
//! search, its value against a direct sum, its gradient against central finite
//! differences in f64, and its zero on any rigid motion.

mod raster_common;

use gaussians::Planes;
use gaussians::train::rigidity::Neighbours;
use rand::{RngExt, SeedableRng};

fn cloud(n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0f32..1.0)))
        .collect()
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

fn to64(v: &[[f32; 3]]) -> Vec<[f64; 3]> {
    v.iter().map(|p| p.map(f64::from)).collect()
}

#[test]
fn neighbour_lists_are_the_brute_force_k_nearest() {
    let pts = cloud(300, 1);
    let eligible: Vec<bool> = (0..pts.len()).map(|i| i % 3 != 0).collect();
    let nb = Neighbours::build(&pts, Some(&eligible), 5, 0);
    let p64 = to64(&pts);
    for i in 0..pts.len() {
        let mine: Vec<u32> = nb
            .pairs
            .iter()
            .filter(|p| p[0] == i as u32)
            .map(|p| p[1])
            .collect();
        if !eligible[i] {
            assert!(mine.is_empty(), "Gaussian {i} is not moved by the field");
            continue;
        }
        let mut all: Vec<(f64, u32)> = (0..pts.len())
            .filter(|&j| j != i)
            .map(|j| (dist(p64[i], p64[j]), j as u32))
            .collect();
        all.sort_by(|a, b| a.0.total_cmp(&b.0));
        let want: Vec<u32> = all[..5].iter().map(|a| a.1).collect();
        assert_eq!(mine, want, "Gaussian {i}");
    }
    let mean: f64 = nb.rest.iter().map(|&r| r as f64).sum::<f64>() / nb.rest.len() as f64;
    assert!((nb.scale as f64 - mean).abs() < 1e-6);
    for (p, &r) in nb.pairs.iter().zip(&nb.rest) {
        let d = dist(p64[p[0] as usize], p64[p[1] as usize]);
        assert!((d - r as f64).abs() < 1e-6);
    }
}

#[test]
fn isometry_value_and_gradient_match_finite_differences() {
    let pts = cloud(60, 2);
    let nb = Neighbours::build(&pts, None, 4, 0);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let moved: Vec<[f64; 3]> = to64(&pts)
        .iter()
        .map(|p| p.map(|v| v + rng.random_range(-0.2..0.2)))
        .collect();
    let w = 0.7;
    let loss = |m: &[[f64; 3]]| {
        let mut g = vec![[0.0f64; 3]; m.len()];
        nb.isometry(w, m, &mut g)
    };
    // Direct sum from the definition.
    let h = nb.scale as f64;
    let direct: f64 = nb
        .pairs
        .iter()
        .zip(&nb.rest)
        .map(|(p, &r)| {
            let e = (dist(moved[p[0] as usize], moved[p[1] as usize]) - r as f64) / h;
            e * e
        })
        .sum::<f64>()
        * w
        / nb.pairs.len() as f64;
    let l = loss(&moved);
    assert!(
        l > 1e-4 && (l - direct).abs() < 1e-12 * direct.max(1.0),
        "{l} vs {direct}"
    );
    let mut grad = vec![[0.0f64; 3]; moved.len()];
    nb.isometry(w, &moved, &mut grad);
    let eps = 1e-6;
    let mut worst = 0.0f64;
    for i in 0..moved.len() {
        for a in 0..3 {
            let mut p = moved.clone();
            p[i][a] += eps;
            let up = loss(&p);
            p[i][a] -= 2.0 * eps;
            let down = loss(&p);
            let fd = (up - down) / (2.0 * eps);
            worst = worst.max((fd - grad[i][a]).abs() / (fd.abs() + 1e-6));
        }
    }
    assert!(worst < 1e-5, "worst relative error {worst}");
}

#[test]
fn a_rigid_motion_costs_nothing_and_a_slide_along_rays_does() {
    let pts = cloud(200, 4);
    let nb = Neighbours::build(&pts, None, 8, 0);
    let p64 = to64(&pts);
    // Rotation about an arbitrary axis plus a translation.
    let (ax, ang) = ([0.48f64, -0.6, 0.64], 0.9f64);
    let (s, c) = ang.sin_cos();
    let rot = |v: [f64; 3]| {
        let d = ax[0] * v[0] + ax[1] * v[1] + ax[2] * v[2];
        let x = [
            ax[1] * v[2] - ax[2] * v[1],
            ax[2] * v[0] - ax[0] * v[2],
            ax[0] * v[1] - ax[1] * v[0],
        ];
        std::array::from_fn(|k| v[k] * c + x[k] * s + ax[k] * d * (1.0 - c) + [0.3, -1.0, 2.0][k])
    };
    let rigid: Vec<[f64; 3]> = p64.iter().map(|&p| rot(p)).collect();
    let mut g = vec![[0.0; 3]; rigid.len()];
    let l = nb.isometry(1.0, &rigid, &mut g);
    // Zero up to the f32 rest distances (relative 1e-7).
    assert!(l < 1e-10, "rigid motion: {l}");
    assert!(g.iter().flatten().all(|v| v.abs() < 1e-5));
    // Each Gaussian slid along its own ray from a camera at (0, 0, 5) by its own amount:
    // the same image from that camera, a smear from any other.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let slid: Vec<[f64; 3]> = p64
        .iter()
        .map(|&p| {
            let ray = [p[0], p[1], p[2] - 5.0];
            let k = 1.0 + rng.random_range(-0.1..0.1);
            [ray[0] * k, ray[1] * k, ray[2] * k + 5.0]
        })
        .collect();
    let l = nb.isometry(1.0, &slid, &mut vec![[0.0; 3]; slid.len()]);
    assert!(l > 0.05, "a slide along the rays must cost: {l}");
}

/// Through the trainer: with no image gradient, `view_backward`'s field gradient is the
/// isometry term's, taken back through `δx` and the MLP; its derivative along a random
/// direction of the field's parameters matches central differences of `L_iso`
/// evaluated from the field's forward (f32 field, so a loose tolerance).
#[test]
fn the_trainer_takes_the_isometry_term_into_the_field() {
    use gaussians::field::{self, FieldSettings};
    use gaussians::raster::TileRasterizer;
    use gaussians::train::init::random_splats;
    use gaussians::train::{TrainSettings, Trainer};
    let splats = random_splats(120, glam::DVec3::ZERO, 0.5, 9);
    let mut s = TrainSettings {
        static_iterations: 0,
        field: FieldSettings {
            depth: 2,
            width: 16,
            zero_head_init: false,
            ..FieldSettings::default()
        },
        ..TrainSettings::default()
    };
    s.rigidity.weight = 3.0;
    s.rigidity.neighbours = 5;
    let mut tr = Trainer::new(s, splats, 1.0);
    assert!(tr.field_on());
    let nb = Neighbours::build(&tr.splats.means, None, 5, 0);
    tr.neighbours = Some(nb.clone());
    let cam = raster_common::camera(32, 32, 30.0, glam::DVec3::new(0.0, 0.0, 3.0));
    let t = 0.37f32;
    let r = TileRasterizer;
    let v = tr.render_view(&r, &cam, t);
    let g = tr.view_backward(&r, &v, &vec![0.0; 3 * 32 * 32], Planes::NONE, None);
    assert_eq!(g.field.len(), tr.field.params.len());
    let loss = |tr: &Trainer| -> f64 {
        let (d, _) = field::splat_deltas(&tr.field, &tr.splats, t, false);
        let moved: Vec<[f64; 3]> = (0..tr.splats.len())
            .map(|i| std::array::from_fn(|a| (tr.splats.means[i][a] + d.dx[i][a]) as f64))
            .collect();
        nb.isometry(3.0, &moved, &mut vec![[0.0; 3]; moved.len()])
    };
    let l0 = loss(&tr);
    assert!(l0 > 1e-6, "a random head moves the Gaussians apart: {l0}");
    assert!((tr.rigidity_loss() - l0).abs() < 1e-3 * l0);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(10);
    let dir: Vec<f32> = (0..g.field.len())
        .map(|_| rng.random_range(-1.0f32..1.0))
        .collect();
    let analytic: f64 = g.field.iter().zip(&dir).map(|(a, b)| (a * b) as f64).sum();
    let eps = 1e-3f32;
    let base = tr.field.params.clone();
    let at = |tr: &mut Trainer, k: f32| {
        for ((p, b), d) in tr.field.params.iter_mut().zip(&base).zip(&dir) {
            *p = b + k * d;
        }
        loss(tr)
    };
    let fd = (at(&mut tr, eps) - at(&mut tr, -eps)) / (2.0 * eps as f64);
    assert!(
        (fd - analytic).abs() < 0.02 * fd.abs().max(1e-9),
        "finite differences {fd} vs the trainer's {analytic}"
    );
}
