//! Per-Gaussian trajectories (`gaussians::motion`): `advance` (centres moved to a time,
//! lives applied) and `backward` (the trajectories' gradient), per call and per Gaussian,
//! for models where none, a tenth or every Gaussian has a trajectory. Beside `backward`,
//! the same gradient written for every row (what it did before still rows were skipped,
//! BENCHMARKS.md "Still Gaussians stay still"), so the cost of the check is seen.
//! Prints a table and writes `target/bench-results/motion.json`.

use gaussians::{Gaussian, Splats, motion};
mod common;
use common::time;

/// `n` Gaussians, every `every`-th with a trajectory (none when `every` is 0), each with
/// a life.
fn model(n: usize, every: usize) -> Splats {
    let mut s = Splats::with_capacity(n);
    for i in 0..n {
        let x = i as f32 * 1e-4;
        s.push(Gaussian::isotropic(
            [x, -x, 2.0 + x],
            -3.0,
            0.5,
            [0.1, 0.2, 0.3],
        ));
    }
    s.motion = (0..n)
        .map(|i| match every > 0 && i % every == 0 {
            true => [0.1, -0.2, 0.05, 0.01, 0.02, -0.03],
            false => [0.0; 6],
        })
        .collect();
    s.life = (0..n)
        .map(|i| [if i % 2 == 0 { 0.0 } else { f32::MIN }, f32::MAX])
        .collect();
    s
}

/// The trajectories' gradient for every row, the check left out.
fn backward_all_rows(s: &Splats, t: f32, g: &[[f32; 3]], out: &mut Vec<[f32; 6]>) {
    use rayon::prelude::*;
    let tau = t - motion::T0;
    out.resize(g.len(), [0.0; 6]);
    (out.as_mut_slice(), g, &s.motion)
        .into_par_iter()
        .with_min_len(4096)
        .for_each(|(o, g, _)| {
            *o = std::array::from_fn(|k| g[k % 3] * if k < 3 { tau } else { tau * tau })
        });
}

fn main() {
    let reps = 21;
    let mut rows = Vec::new();
    println!(
        "{:>9} {:>8} {:>12} {:>13} {:>18} {:>12} {:>13}",
        "Gaussians",
        "moving",
        "advance ms",
        "backward ms",
        "all rows (old) ms",
        "advance ns/G",
        "backward ns/G"
    );
    for n in [100_000, 1_000_000] {
        for (every, label) in [(0, "none"), (10, "1/10"), (1, "all")] {
            let s = model(n, every);
            let mut out = s.clone();
            let g: Vec<[f32; 3]> = (0..n).map(|i| [1e-3, -2e-3, i as f32 * 1e-9]).collect();
            let mut grad = Vec::new();
            // Repeated calls on one copy: the centres drift and hidden logits add up, but
            // the work per call is the same and no copy is timed.
            let adv = time(reps, || {
                motion::advance(&s, 0.8, &mut out);
                std::hint::black_box(&out);
            });
            let bwd = time(reps, || {
                motion::backward(&s, 0.8, &g, &mut grad);
                std::hint::black_box(&grad);
            });
            let old = time(reps, || {
                backward_all_rows(&s, 0.8, &g, &mut grad);
                std::hint::black_box(&grad);
            });
            let per = |ms: f64| ms * 1e6 / n as f64;
            println!(
                "{n:>9} {label:>8} {adv:>12.3} {bwd:>13.3} {old:>18.3} {:>12.2} {:>13.2}",
                per(adv),
                per(bwd)
            );
            rows.push(serde_json::json!({
                "gaussians": n, "moving": label, "advance_ms": adv, "backward_ms": bwd,
                "backward_all_rows_ms": old, "reps": reps,
            }));
        }
    }
    common::write_rows("motion", rows);
}
