//! EV-FlowNet cost per window: forward (inference device) and forward + backward
//! (autodiff device, gradient of every weight) at 128² and 256² for C = 16, 32, 64,
//! one window (batch 1, B = 5). Prints a table and writes
//! `target/bench-results/evflow_net.json` (or `$CARGO_TARGET_DIR/bench-results/`).
//! `NET_BENCH_REPS` sets the timed repetitions (median; default 3, after one warm-up).
//! `NET_BENCH_WIDTHS` (e.g. `16,32`) and `NET_BENCH_SIZES` (e.g. `128`) restrict the grid.

use burn::tensor::{DType, Device};
use evflow::net::{FlowNet, NetConfig, tensor4, to_f32};
use std::time::Instant;

#[derive(serde::Serialize)]
struct Row {
    base: usize,
    size: usize,
    params: usize,
    forward_ms: f64,
    forward_backward_ms: f64,
}

fn list(var: &str, default: &[usize]) -> Vec<usize> {
    std::env::var(var)
        .ok()
        .map(|s| s.split(',').filter_map(|x| x.trim().parse().ok()).collect())
        .unwrap_or_else(|| default.to_vec())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn time<F: FnMut()>(reps: usize, mut f: F) -> f64 {
    f();
    median(
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

fn main() {
    let reps = list("NET_BENCH_REPS", &[3])[0].max(1);
    let widths = list("NET_BENCH_WIDTHS", &[16, 32, 64]);
    let sizes = list("NET_BENCH_SIZES", &[128, 256]);
    let mut rows = Vec::new();
    println!("| C | size | params | forward ms | forward+backward ms |");
    println!("|---:|---:|---:|---:|---:|");
    for &base in &widths {
        for &size in &sizes {
            let cfg = NetConfig {
                base,
                ..NetConfig::default()
            };
            let voxel: Vec<f32> = (0..5 * size * size)
                .map(|i| ((i * 7919 % 1000) as f32 / 500.0 - 1.0) * f32::from(i % 3 == 0))
                .collect();
            let dev = Device::flex();
            let net = FlowNet::new(cfg, 1, &dev, DType::F32);
            let params = net.param_count();
            let forward_ms = time(reps, || {
                let x = tensor4(voxel.clone(), [1, 5, size, size], &dev, DType::F32);
                std::hint::black_box(to_f32(net.forward(x)));
            });
            let adev = Device::flex().autodiff();
            let mut anet = FlowNet::new(cfg, 1, &adev, DType::F32);
            anet.set_trainable(true, false);
            let forward_backward_ms = time(reps, || {
                let x = tensor4(voxel.clone(), [1, 5, size, size], &adev, DType::F32);
                let loss = anet.forward(x).powf_scalar(2.0).mean();
                let grads = loss.backward();
                for c in &anet.convs {
                    std::hint::black_box(c.weight.grad(&grads).map(to_f32));
                }
            });
            println!(
                "| {base} | {size}² | {params} | {forward_ms:.1} | {forward_backward_ms:.1} |"
            );
            rows.push(Row {
                base,
                size,
                params,
                forward_ms,
                forward_backward_ms,
            });
        }
    }
    let dir = std::path::PathBuf::from(
        std::env::var("CARGO_TARGET_DIR")
            .unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/../target").to_string()),
    )
    .join("bench-results");
    std::fs::create_dir_all(&dir).expect("create bench-results");
    let path = dir.join("evflow_net.json");
    std::fs::write(&path, serde_json::to_string_pretty(&rows).expect("json")).expect("write json");
    println!("wrote {}", path.display());
}
