//! Deformation-field forward+backward: the hand-written gemm MLP against the same
//! network in burn 0.22.1 (flex backend + autodiff), for several D × W and batch sizes.
//! Prints a table and writes `target/bench-results/field.json`.

use burn::tensor::{Device, Distribution, Tensor, activation::relu};
use gaussians::field::{FieldSettings, Mlp, MlpCache, MlpScratch};
use std::time::Instant;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn hand(mlp: &Mlp<f32>, x: &[[f32; 3]], reps: usize) -> (f64, f64) {
    let g = vec![1e-3f32; x.len() * 10];
    let (mut f, mut fb) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        let t0 = Instant::now();
        let (out, cache) = mlp.forward(x, &[0.5]);
        let t1 = Instant::now();
        let grads = mlp.backward(&cache, &g);
        let t2 = Instant::now();
        std::hint::black_box((out, grads));
        f.push((t1 - t0).as_secs_f64() * 1e3);
        fb.push((t2 - t0).as_secs_f64() * 1e3);
    }
    (median(f), median(fb))
}

/// The same MLP in burn: input encoding precomputed (it is not part of the network).
/// Forward + backward into buffers reused from call to call, as the training loop does
/// (`forward_into` / `backward_into`): ms per call, median.
fn hand_reused(mlp: &Mlp<f32>, x: &[[f32; 3]], reps: usize) -> f64 {
    let g = vec![1e-3f32; x.len() * 10];
    let (mut cache, mut scratch) = (MlpCache::default(), MlpScratch::default());
    let (mut out, mut grads) = (Vec::new(), Vec::new());
    let mut fb = Vec::new();
    for _ in 0..reps + 1 {
        let t0 = Instant::now();
        mlp.forward_into(x, &[0.5], &mut cache, &mut scratch, &mut out);
        mlp.backward_into(&cache, &g, &mut scratch, &mut grads);
        fb.push(t0.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box((&out, &grads));
    }
    fb.remove(0); // the first call allocates
    median(fb)
}

fn burn_fb(s: &FieldSettings, enc: &[f32], n: usize, reps: usize) -> f64 {
    let dev = Device::flex().autodiff();
    let layers = Mlp::<f32>::layout(s);
    let skip = Mlp::<f32>::skip_after(s);
    let in_dim = Mlp::<f32>::input_dim(s);
    let params: Vec<(Tensor<2>, Tensor<2>)> = layers
        .iter()
        .map(|l| {
            let b = 1.0 / (l.fan_in as f64).sqrt();
            (
                Tensor::<2>::random([l.fan_in, l.fan_out], Distribution::Uniform(-b, b), &dev)
                    .require_grad(),
                Tensor::<2>::random([1, l.fan_out], Distribution::Uniform(-b, b), &dev)
                    .require_grad(),
            )
        })
        .collect();
    let input = Tensor::<1>::from_floats(enc, &dev).reshape([n, in_dim]);
    let mut times = Vec::new();
    for _ in 0..reps {
        let t0 = Instant::now();
        let mut h = input.clone();
        for (i, (w, b)) in params[..s.depth].iter().enumerate() {
            h = relu(h.matmul(w.clone()) + b.clone());
            if Some(i) == skip {
                h = Tensor::cat(vec![input.clone(), h], 1);
            }
        }
        let (w, b) = &params[s.depth];
        let out = h.matmul(w.clone()) + b.clone();
        let loss = (out * 1e-3).sum();
        let grads = loss.backward();
        let g0 = params[0].0.grad(&grads).expect("grad");
        std::hint::black_box(g0.into_data());
        times.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    median(times)
}

fn main() {
    // FIELD_BENCH_ONLY=DxW (e.g. 4x64) runs one network; FIELD_BENCH_NO_BURN=1 skips burn.
    let only = std::env::var("FIELD_BENCH_ONLY").ok();
    let no_burn = std::env::var_os("FIELD_BENCH_NO_BURN").is_some();
    let configs: Vec<(usize, usize)> = [(8usize, 256usize), (4, 128), (4, 64), (2, 64)]
        .into_iter()
        .filter(|(d, w)| only.as_ref().is_none_or(|o| *o == format!("{d}x{w}")))
        .collect();
    let sizes = [10_000usize, 50_000];
    let mut rows = Vec::new();
    println!(
        "{:>6} {:>7} {:>9} {:>10} {:>10} {:>12} {:>10} {:>9} {:>10} {:>12}",
        "D×W",
        "n",
        "encode ms",
        "fwd ms",
        "fwd+bwd ms",
        "GFLOP/s",
        "reused ms",
        "GFLOP/s",
        "burn ms",
        "burn/hand"
    );
    for &(d, w) in &configs {
        let s = FieldSettings {
            depth: d,
            width: w,
            ..FieldSettings::default()
        };
        let mlp = Mlp::<f32>::new(s, 0);
        let macs: usize = Mlp::<f32>::layout(&s)
            .iter()
            .map(|l| l.fan_in * l.fan_out)
            .sum();
        for &n in &sizes {
            let x: Vec<[f32; 3]> = (0..n)
                .map(|i| {
                    let f = i as f32;
                    [(f * 0.37).sin(), (f * 0.71).cos(), (f * 0.13).sin()]
                })
                .collect();
            let reps = if macs * n > 10_000_000_000 { 3 } else { 7 };
            let (f, fb) = hand(&mlp, &x, reps);
            // forward 2·MACs, backward ≈ 4·MACs (dW and dA) per row
            let gflops = 6.0 * (macs * n) as f64 / (fb * 1e-3) / 1e9;
            let t_enc = Instant::now();
            let enc = mlp.encode(&x, &[0.5]);
            let enc_ms = t_enc.elapsed().as_secs_f64() * 1e3;
            let re = hand_reused(&mlp, &x, reps);
            let re_gflops = 6.0 * (macs * n) as f64 / (re * 1e-3) / 1e9;
            let b = if no_burn {
                f64::NAN
            } else {
                burn_fb(&s, &enc, n, reps)
            };
            println!(
                "{:>6} {:>7} {:>9.1} {:>10.1} {:>10.1} {:>12.0} {:>10.1} {:>9.0} {:>10.1} {:>12.2}",
                format!("{d}×{w}"),
                n,
                enc_ms,
                f,
                fb,
                gflops,
                re,
                re_gflops,
                b,
                b / fb
            );
            rows.push(serde_json::json!({
                "depth": d, "width": w, "n": n, "params": Mlp::<f32>::param_count(&s),
                "hand_forward_ms": f, "encode_ms": enc_ms, "hand_forward_backward_ms": fb, "hand_gflops": gflops,
                "hand_reused_forward_backward_ms": re,
                "burn_forward_backward_ms": b,
            }));
        }
    }
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/bench-results");
    std::fs::create_dir_all(&dir).expect("bench-results dir");
    let json =
        serde_json::to_vec_pretty(&serde_json::json!({ "bench": "field", "rows": rows })).unwrap();
    scene::atomic::write_bytes_atomic(&dir.join("field.json"), &json).expect("write json");
}
