//! Rigid parts (`gaussians::parts`): `advance` (members moved by their part's pose at a
//! time) and `backward` (the gradients turned back and summed into the knots), per call
//! and per Gaussian, for models where no Gaussian, a tenth or every Gaussian is in one of
//! 8 parts over 9 knots. Prints a table and writes `target/bench-results/parts.json`.

use gaussians::parts::{NO_PART, Parts};
use gaussians::{Gaussian, SplatGrads, Splats, parts};
mod common;
use common::time;

/// `n` Gaussians, every `every`-th in one of 8 parts (none when `every` is 0).
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
    let knots: Vec<f32> = (0..9).map(|k| k as f32 / 8.0).collect();
    let rows = 8 * knots.len();
    s.parts = Parts {
        origin: vec![[0.0, 0.0, 2.0]; 8],
        rot: (0..rows)
            .map(|r| [1.0, 0.01 * (r % 5) as f32, 0.02, -0.01])
            .collect(),
        shift: (0..rows)
            .map(|r| [0.01 * (r % 3) as f32, 0.0, 0.02])
            .collect(),
        knots,
        fixed: 4,
    };
    s.part = (0..n)
        .map(|i| match every > 0 && i % every == 0 {
            true => (i / every % 8) as u32,
            false => NO_PART,
        })
        .collect();
    s
}

fn main() {
    let reps = 21;
    let mut rows = Vec::new();
    println!(
        "{:>9} {:>8} {:>12} {:>13} {:>12} {:>13}",
        "Gaussians", "in parts", "advance ms", "backward ms", "advance ns/G", "backward ns/G"
    );
    for n in [100_000, 1_000_000] {
        for (every, label) in [(0, "none"), (10, "1/10"), (1, "all")] {
            let s = model(n, every);
            let mut out = s.clone();
            let mut g = SplatGrads::zeros(n);
            // Repeated calls on one copy: the work per call is the same, no copy timed.
            let adv = time(reps, || {
                parts::advance(&s.parts, &s.part, 0.3, &mut out);
                std::hint::black_box(&out);
            });
            let bwd = time(reps, || {
                parts::backward(&s.parts, &s.part, 0.3, &out, &mut g);
                std::hint::black_box(&g);
            });
            let per = |ms: f64| ms * 1e6 / n as f64;
            println!(
                "{n:>9} {label:>8} {adv:>12.3} {bwd:>13.3} {:>12.2} {:>13.2}",
                per(adv),
                per(bwd)
            );
            rows.push(serde_json::json!({
                "gaussians": n, "in_parts": label, "advance_ms": adv, "backward_ms": bwd,
                "reps": reps,
            }));
        }
    }
    common::write_rows("parts", rows);
}
