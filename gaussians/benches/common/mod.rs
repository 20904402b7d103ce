//! Timing helpers shared by the benches of `gaussians` (`mod common;`).

use std::time::Instant;

/// The median of `v` (the upper one of an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The median wall time of `reps` calls of `f` in milliseconds, after one warm-up call.
pub fn time(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    median(
        (0..reps)
            .map(|_| {
                let t0 = Instant::now();
                f();
                t0.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

/// Write `target/bench-results/NAME.json`: the bench's name, the threads and its rows.
pub fn write_rows(name: &str, rows: Vec<serde_json::Value>) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/bench-results");
    std::fs::create_dir_all(&dir).expect("bench-results dir");
    let json = serde_json::to_vec_pretty(&serde_json::json!({
        "bench": name, "threads": rayon::current_num_threads(), "rows": rows
    }))
    .expect("JSON");
    let path = dir.join(format!("{name}.json"));
    scene::atomic::write_bytes_atomic(&path, &json).expect("write json");
}
