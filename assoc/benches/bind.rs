//! Association benchmark (issue #5): k-d tree build + k-nearest query for 1 M lifted
//! events × 200 k Gaussians, on 1 thread and on all threads. Prints a table and writes
//! `target/bench-results/assoc.json`.
//!
//! Run: `cargo bench -p assoc --bench bind` (optionally `-- EVENTS GAUSSIANS`).

use std::time::Instant;

use assoc::bind_nearest;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Points on a few slanted surfaces (like lifted events), centres near them.
fn surface_points(n: usize, rng: &mut ChaCha8Rng) -> Vec<[f32; 3]> {
    (0..n)
        .map(|_| {
            let x: f32 = rng.random::<f32>() * 2.0 - 1.0;
            let y: f32 = rng.random::<f32>() * 2.0 - 1.0;
            let layer = (rng.random::<f32>() * 3.0).floor();
            [x, y, -3.0 - layer * 0.5 + 0.2 * x]
        })
        .collect()
}

fn time_bind(
    points: &[[f32; 3]],
    ids: &[u64],
    centres: &[[f32; 3]],
    radii: &[f32],
) -> (f64, usize) {
    let mut best = f64::INFINITY;
    let mut bound = 0;
    for _ in 0..3 {
        let t = Instant::now();
        let (b, _) = bind_nearest(points, ids, centres, radii, 3);
        best = best.min(t.elapsed().as_secs_f64());
        bound = b.bound();
    }
    (best, bound)
}

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let n_events = args.first().copied().unwrap_or(1_000_000);
    let n_gauss = args.get(1).copied().unwrap_or(200_000);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let points = surface_points(n_events, &mut rng);
    let ids: Vec<u64> = (0..n_events as u64).collect();
    let centres = surface_points(n_gauss, &mut rng);
    // 2 px at depth ~3.5 with fx ~ 128: about 0.05 world units.
    let radii = vec![0.05f32; n_gauss];

    let threads = rayon::current_num_threads();
    let mut rows = Vec::new();
    for t in [1, threads] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap();
        let (secs, bound) = pool.install(|| time_bind(&points, &ids, &centres, &radii));
        rows.push((t, secs, bound));
        if threads == 1 {
            break;
        }
    }
    println!("assoc bind: {n_events} events x {n_gauss} Gaussians, k = 3 (best of 3)");
    println!("{:>8} | {:>10} | {:>8}", "threads", "build+query", "bound");
    for (t, s, b) in &rows {
        println!("{t:>8} | {:>8.1} ms | {b:>8}", s * 1e3);
    }
    let json = serde_json::json!({
        "bench": "assoc_bind",
        "events": n_events,
        "gaussians": n_gauss,
        "k": 3,
        "rows": rows.iter().map(|(t, s, b)| serde_json::json!({"threads": t, "seconds": s, "bound": b})).collect::<Vec<_>>(),
    });
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/bench-results");
    std::fs::create_dir_all(&dir).ok();
    std::fs::write(
        dir.join("assoc.json"),
        serde_json::to_string_pretty(&json).unwrap(),
    )
    .ok();
}
