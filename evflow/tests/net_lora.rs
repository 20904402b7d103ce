//! EV-FlowNet + LoRA: shapes, LoRA at init == base, merged == unmerged, weights and
//! adapters round-trip, corrupt files give clear errors, and the network + LoRA
//! gradient matches central finite differences in f64.

use burn::tensor::{DType, Device, Tensor, TensorData};
use evflow::net::io::{load_adapters, save_adapters, sidecar};
use evflow::net::{FlowNet, NetConfig, tensor4, to_f64};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn voxel(h: usize, w: usize, dev: &Device, dt: DType, seed: u64) -> Tensor<4> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let v: Vec<f32> = (0..5 * h * w)
        .map(|_| rng.random_range(-1.0f32..1.0))
        .collect();
    tensor4(v, [1, 5, h, w], dev, dt)
}

fn cfg(base: usize) -> NetConfig {
    NetConfig {
        base,
        bins: 5,
        max_flow: 8.0,
    }
}

/// Give every adapter a non-zero B so LoRA changes the output.
fn randomise_b(net: &mut FlowNet, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for c in &mut net.convs {
        let l = c.lora.as_mut().unwrap();
        let [o, r] = l.b.dims();
        let v: Vec<f64> = (0..o * r).map(|_| rng.random_range(-0.3..0.3)).collect();
        l.b = Tensor::<2>::from_data(
            TensorData::new(v, [o, r]).convert_dtype(net.dtype),
            (&net.device, net.dtype),
        );
    }
}

#[test]
fn output_has_input_size_and_is_bounded() {
    let dev = Device::flex();
    let net = FlowNet::new(cfg(4), 1, &dev, DType::F32);
    let out = net.forward(voxel(20, 36, &dev, DType::F32, 2));
    assert_eq!(out.dims(), [1, 2, 20, 36]);
    let v = to_f64(out);
    assert!(v.iter().all(|x| x.is_finite() && x.abs() <= 8.0));
    assert!(v.iter().any(|x| x.abs() > 1e-6), "output is not all zero");
    let all = net.forward_all(voxel(32, 32, &dev, DType::F32, 2));
    let dims: Vec<_> = all.iter().map(|t| t.dims()).collect();
    assert_eq!(
        dims,
        vec![[1, 2, 4, 4], [1, 2, 8, 8], [1, 2, 16, 16], [1, 2, 32, 32]]
    );
    // 14.1 M parameters at base 64 (`docs/REFERENCES.md`): the layout matches the original.
    let big = evflow::net::layout(&cfg(64));
    let n: usize = big.iter().map(|(_, o, i, k, _)| o * i * k * k + o).sum();
    assert!(
        (13_500_000..14_500_000).contains(&n),
        "{n} parameters at C=64"
    );
}

#[test]
fn lora_at_init_is_exactly_the_base_network_and_merge_matches() {
    let dev = Device::flex();
    let mut net = FlowNet::new(cfg(4), 3, &dev, DType::F32);
    let x = voxel(32, 32, &dev, DType::F32, 4);
    let base = to_f64(net.forward(x.clone()));
    net.attach_lora(16, 16.0, 5);
    let init = to_f64(net.forward(x.clone()));
    assert_eq!(
        base, init,
        "LoRA with B = 0 must reproduce the base output bit for bit"
    );
    randomise_b(&mut net, 6);
    let unmerged = to_f64(net.forward(x.clone()));
    let diff: f64 = unmerged
        .iter()
        .zip(&base)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(diff > 1e-3, "non-zero adapters change the output ({diff})");
    net.merge_lora();
    assert!(net.convs.iter().all(|c| c.lora.is_none()));
    let merged = to_f64(net.forward(x));
    for (a, b) in merged.iter().zip(&unmerged) {
        assert!((a - b).abs() < 1e-5, "merged {a} vs unmerged {b}");
    }
}

#[test]
fn weights_and_adapters_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let dev = Device::flex();
    let mut net = FlowNet::new(cfg(4), 7, &dev, DType::F32);
    let x = voxel(16, 32, &dev, DType::F32, 8);
    let wpath = dir.path().join("w.safetensors");
    net.save(&wpath, "test").unwrap();
    let loaded = FlowNet::load(&wpath, None, &dev, DType::F32).unwrap();
    assert_eq!(
        to_f64(net.forward(x.clone())),
        to_f64(loaded.forward(x.clone()))
    );
    net.attach_lora(4, 4.0, 9);
    randomise_b(&mut net, 10);
    let apath = dir.path().join("a.safetensors");
    save_adapters(&net, &apath).unwrap();
    let mut again = FlowNet::load(&wpath, None, &dev, DType::F32).unwrap();
    load_adapters(&mut again, &apath).unwrap();
    assert_eq!(to_f64(net.forward(x.clone())), to_f64(again.forward(x)));
}

#[test]
fn corrupt_weights_give_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let dev = Device::flex();
    let net = FlowNet::new(cfg(2), 7, &dev, DType::F32);
    let wpath = dir.path().join("w.safetensors");
    net.save(&wpath, "test").unwrap();
    let bytes = std::fs::read(&wpath).unwrap();
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("empty", vec![]),
        ("truncated", bytes[..bytes.len() / 2].to_vec()),
        ("garbage", vec![0xff; 64]),
        ("huge header", {
            let mut b = (u64::MAX / 2).to_le_bytes().to_vec();
            b.extend_from_slice(&bytes[8..]);
            b
        }),
    ];
    for (what, b) in cases {
        let p = dir
            .path()
            .join(format!("{}.safetensors", what.replace(' ', "_")));
        std::fs::write(&p, b).unwrap();
        std::fs::copy(sidecar(&wpath), sidecar(&p)).unwrap();
        let e = FlowNet::load(&p, None, &dev, DType::F32)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(p.file_name().unwrap().to_str().unwrap()),
            "{what}: {e}"
        );
    }
    // NaN in a kernel
    let mut t = evflow::net::io::read_safetensors(&wpath).unwrap();
    let mut named: Vec<_> = t.drain().map(|(n, (s, v))| (n, s, v)).collect();
    named.sort_by(|a, b| a.0.cmp(&b.0));
    named[0].2[0] = f32::NAN;
    let p = dir.path().join("nan.safetensors");
    evflow::net::io::write_safetensors(&p, &named).unwrap();
    std::fs::copy(sidecar(&wpath), sidecar(&p)).unwrap();
    let e = FlowNet::load(&p, None, &dev, DType::F32)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("non-finite") && e.contains("nan.safetensors"),
        "{e}"
    );
    // wrong network width in the sidecar
    let p2 = dir.path().join("wide.safetensors");
    std::fs::copy(&wpath, &p2).unwrap();
    let side = std::fs::read_to_string(sidecar(&wpath)).unwrap();
    let mut meta: serde_json::Value = serde_json::from_str(&side).unwrap();
    meta["net"]["base"] = serde_json::json!(3);
    std::fs::write(sidecar(&p2), meta.to_string()).unwrap();
    let e = FlowNet::load(&p2, None, &dev, DType::F32)
        .unwrap_err()
        .to_string();
    assert!(e.contains("shape") && e.contains("wide.safetensors"), "{e}");
}

/// L = Σ flow · g for a fixed g (the form the CM surrogate takes).
fn loss(net: &FlowNet, x: &Tensor<4>, g: &Tensor<4>) -> (f64, Tensor<1>) {
    let l = (net.forward(x.clone()) * g.clone()).sum();
    (to_f64(l.clone())[0], l)
}

#[test]
fn network_and_lora_gradient_matches_finite_differences_f64() {
    let dev = Device::flex().autodiff();
    let dt = DType::F64;
    let mut net = FlowNet::new(cfg(2), 11, &dev, dt);
    net.attach_lora(3, 3.0, 12);
    randomise_b(&mut net, 13);
    net.set_trainable(true, true);
    let x = voxel(16, 16, &dev, dt, 14);
    let mut rng = ChaCha8Rng::seed_from_u64(15);
    let gv: Vec<f64> = (0..2 * 256).map(|_| rng.random_range(-1.0..1.0)).collect();
    let g = Tensor::<4>::from_data(TensorData::new(gv, [1, 2, 16, 16]), (&dev, dt));
    let (_, l) = loss(&net, &x, &g);
    let grads = l.backward();
    // directional derivatives along random directions, per parameter tensor
    let mut checked = 0;
    for ci in [0usize, 4, 8, 9, 14, 15] {
        for which in 0..3 {
            let c = &net.convs[ci];
            let (param_grad, values, shape): (Vec<f64>, Vec<f64>, Vec<usize>) = match which {
                0 => (
                    to_f64(c.weight.grad(&grads).unwrap()),
                    to_f64(c.weight.clone()),
                    c.weight.dims().to_vec(),
                ),
                1 => {
                    let a = &c.lora.as_ref().unwrap().a;
                    (
                        to_f64(a.grad(&grads).unwrap()),
                        to_f64(a.clone()),
                        a.dims().to_vec(),
                    )
                }
                _ => {
                    let b = &c.lora.as_ref().unwrap().b;
                    (
                        to_f64(b.grad(&grads).unwrap()),
                        to_f64(b.clone()),
                        b.dims().to_vec(),
                    )
                }
            };
            let d: Vec<f64> = (0..values.len())
                .map(|_| rng.random_range(-1.0..1.0))
                .collect();
            let analytic: f64 = param_grad.iter().zip(&d).map(|(a, b)| a * b).sum();
            let eps = 1e-6;
            let eval = |s: f64| {
                let mut n2 = net.clone();
                let v: Vec<f64> = values.iter().zip(&d).map(|(x, dd)| x + s * dd).collect();
                let c2 = &mut n2.convs[ci];
                match which {
                    0 => {
                        c2.weight =
                            Tensor::<4>::from_data(TensorData::new(v, shape.clone()), (&dev, dt))
                    }
                    1 => {
                        c2.lora.as_mut().unwrap().a =
                            Tensor::<2>::from_data(TensorData::new(v, shape.clone()), (&dev, dt))
                    }
                    _ => {
                        c2.lora.as_mut().unwrap().b =
                            Tensor::<2>::from_data(TensorData::new(v, shape.clone()), (&dev, dt))
                    }
                }
                loss(&n2, &x, &g).0
            };
            let numeric = (eval(eps) - eval(-eps)) / (2.0 * eps);
            let rel = (analytic - numeric).abs() / analytic.abs().max(numeric.abs()).max(1e-8);
            assert!(
                rel < 1e-3,
                "conv {} param {which}: analytic {analytic} numeric {numeric} rel {rel}",
                c.name
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 18);
}
