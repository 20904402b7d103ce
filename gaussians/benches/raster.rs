//! Tile rasterizer: forward and forward+backward, ms per call, at 128², 256², 512² with
//! 10k, 50k, 200k Gaussians (SH degree 3). Prints a table and writes
//! `target/bench-results/raster.json`. `RASTER_BENCH_ONLY=256x50000` runs one configuration;
//! `RASTER_BENCH_REUSE=1` reuses the buffers from call to call (the training path).
//!
//! Scene: Gaussians uniform in a cube of side 2 at distance 4, random rotations,
//! scales around 0.5 × the mean spacing (so they tile the volume like a trained
//! model), opacity ≈ 0.3–0.9.

use gaussians::raster::{Planes, Rasterizer, TileRasterizer};
use gaussians::{Gaussian, SplatGrads, Splats};
use glam::DVec3;
use scene::{Camera, Intrinsics, Pose};
use std::time::Instant;

struct Rng(u64);
impl Rng {
    fn f(&mut self, lo: f32, hi: f32) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        lo + (hi - lo) * ((z >> 40) as f32 / (1u64 << 24) as f32)
    }
}

fn scene(n: usize) -> Splats {
    let mut r = Rng(n as u64);
    let spacing = 2.0 / (n as f32).cbrt();
    let ls = (0.5 * spacing).ln();
    (0..n)
        .map(|_| Gaussian {
            mean: std::array::from_fn(|_| r.f(-1.0, 1.0)),
            log_scale: std::array::from_fn(|_| ls + r.f(-0.5, 0.5)),
            rotation: std::array::from_fn(|_| r.f(-1.0, 1.0)),
            opacity_logit: r.f(-1.0, 2.0),
            sh_dc: std::array::from_fn(|_| r.f(-1.0, 1.0)),
            sh_rest: std::array::from_fn(|_| r.f(-0.2, 0.2)),
            dynamic: true,
        })
        .collect()
}

fn camera(size: u32) -> Camera {
    Camera {
        intrinsics: Intrinsics::from_fov_x(size, size, 0.6),
        cam_to_world: Pose::look_at(DVec3::new(0.0, 0.0, 4.0), DVec3::ZERO, DVec3::Y),
    }
}

/// CPU time of this process in ms (sum over its threads, from
/// `/proc/self/task/*/schedstat`), so figures on a shared machine are not inflated by
/// waiting for a core. 0 where unavailable.
fn cpu_ms() -> f64 {
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else {
        return 0.0;
    };
    dir.filter_map(|e| std::fs::read_to_string(e.ok()?.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .sum::<f64>()
        / 1e6
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Gaussian–pixel evaluations a forward pass performs at most (box ∩ tile areas).
fn evaluations(st: &gaussians::raster::RenderState, size: usize) -> u64 {
    let p = st.projected();
    p.bbox
        .iter()
        .map(|b| {
            let w = (b[1] - b[0] + 1) as u64;
            let h = (b[3] - b[2] + 1) as u64;
            debug_assert!(b[1] < size as u32);
            w * h
        })
        .sum()
}

fn main() {
    // RASTER_BENCH_ONLY=SIZExCOUNT (e.g. 256x50000) runs one configuration.
    let only = std::env::var("RASTER_BENCH_ONLY").ok().and_then(|v| {
        let (a, b) = v.split_once('x')?;
        Some((a.parse::<u32>().ok()?, b.parse::<usize>().ok()?))
    });
    let (sizes, counts): (Vec<u32>, Vec<usize>) = match only {
        Some((a, b)) => (vec![a], vec![b]),
        None => (vec![128, 256, 512], vec![10_000, 50_000, 200_000]),
    };
    // RASTER_BENCH_REUSE=1: render and back-propagate into the last call's buffers
    // (`render_reusing`, `backward_view_into`), as the training loops do.
    let reuse = std::env::var_os("RASTER_BENCH_REUSE").is_some();
    let r = TileRasterizer;
    let mut rows = Vec::new();
    println!(
        "{:>6} {:>8} {:>9} {:>11} {:>9} {:>12} {:>14} {:>10} {:>10} {:>9}",
        "size",
        "gauss",
        "fwd ms",
        "fwd+bwd ms",
        "bwd ms",
        "fwd cpu ms",
        "fwd+bwd cpu ms",
        "pairs",
        "evals (M)",
        "Geval/s"
    );
    for &n in &counts {
        let s = scene(n);
        for &size in &sizes {
            let cam = camera(size);
            let np = (size * size) as usize;
            let d_rgb: Vec<f32> = (0..3 * np).map(|i| ((i % 7) as f32 - 3.0) * 1e-3).collect();
            let d_depth = vec![1e-4f32; np];
            let reps = if n * np > 50_000 * 65_536 { 5 } else { 11 };
            let (mut f, mut fb, mut cf, mut cfb) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
            let mut info = (0, 0);
            let (mut spare, mut g) = (None, SplatGrads::default());
            // One untimed call first when reusing: it allocates the buffers.
            for rep in 0..reps + usize::from(reuse) {
                let (c0, t0) = (cpu_ms(), Instant::now());
                let (frame, st) = if reuse {
                    r.render_reusing(&s, &cam, 3, [0.0; 3], spare.take())
                } else {
                    r.render_full(&s, &cam, 3, [0.0; 3])
                };
                let (c1, t1) = (cpu_ms(), Instant::now());
                if reuse {
                    r.backward_view_into(
                        &s,
                        &cam,
                        &st,
                        &d_rgb,
                        Planes {
                            depth: Some(&d_depth),
                            alpha: None,
                            distortion: None,
                            anchor: None,
                        },
                        &mut g,
                    );
                } else {
                    g = r
                        .backward_full(&s, &cam, &st, &d_rgb, Some(&d_depth), None)
                        .0;
                }
                let (c2, t2) = (cpu_ms(), Instant::now());
                info = (st.pairs(), evaluations(&st, size as usize));
                std::hint::black_box(&g);
                spare = Some((frame, st));
                if reuse && rep == 0 {
                    continue;
                }
                cf.push(c1 - c0);
                cfb.push(c2 - c0);
                f.push((t1 - t0).as_secs_f64() * 1e3);
                fb.push((t2 - t0).as_secs_f64() * 1e3);
            }
            let (fm, fbm) = (median(f), median(fb));
            let (cfm, cfbm) = (median(cf), median(cfb));
            let gev = info.1 as f64 / (fm * 1e-3) / 1e9;
            println!(
                "{:>6} {:>8} {:>9.2} {:>11.2} {:>9.2} {:>12.1} {:>14.1} {:>10} {:>10.2} {:>9.3}",
                format!("{size}²"),
                n,
                fm,
                fbm,
                fbm - fm,
                cfm,
                cfbm,
                info.0,
                info.1 as f64 / 1e6,
                gev
            );
            rows.push(serde_json::json!({
                "size": size, "gaussians": n, "forward_ms": fm, "forward_backward_ms": fbm,
                "backward_ms": fbm - fm, "forward_cpu_ms": cfm, "forward_backward_cpu_ms": cfbm,
                "pairs": info.0, "box_evaluations": info.1,
                "forward_box_evals_per_s": info.1 as f64 / (fm * 1e-3), "reps": reps,
                "reused_buffers": reuse,
            }));
        }
    }
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/bench-results");
    std::fs::create_dir_all(&dir).expect("bench-results dir");
    let json = serde_json::to_vec_pretty(&serde_json::json!({
        "bench": "raster", "threads": rayon::current_num_threads(), "rows": rows
    }))
    .unwrap();
    scene::atomic::write_bytes_atomic(&dir.join("raster.json"), &json).expect("write json");
}
