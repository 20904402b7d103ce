//! Deformation field: finite-difference gradient check in f64, shapes, init, delta
//! application and its backward, save/load round trip and hostile files.

use gaussians::field::{
    self, Deformation, Deltas, FieldSettings, Mlp, apply_deltas, apply_deltas_backward,
};

fn small(depth: usize, width: usize) -> FieldSettings {
    FieldSettings {
        depth,
        width,
        pos_freqs: 3,
        time_freqs: 2,
        seed: 7,
        zero_head_init: false,
        color: false,
    }
}

fn coloured(depth: usize, width: usize) -> FieldSettings {
    FieldSettings {
        color: true,
        ..small(depth, width)
    }
}

fn points(n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let f = i as f64;
            [
                (f * 0.37).sin(),
                (f * 0.71).cos() * 0.8,
                (f * 0.13).sin() * 1.2,
            ]
        })
        .collect()
}

/// Loss = Σ w ⊙ out with fixed pseudo-random weights; gradient w.r.t. out is w.
fn weights(n: usize) -> Vec<f64> {
    weights_of(n, field::HEAD_OUT)
}

fn weights_of(n: usize, width: usize) -> Vec<f64> {
    (0..n * width).map(|i| ((i as f64) * 1.618).sin()).collect()
}

fn loss(mlp: &Mlp<f64>, x: &[[f64; 3]], t: &[f64], w: &[f64]) -> f64 {
    let (out, _) = mlp.forward(x, t);
    out.iter().zip(w).map(|(a, b)| a * b).sum()
}

fn fd_check(depth: usize, width: usize) {
    fd_check_settings(small(depth, width));
}

fn fd_check_settings(settings: FieldSettings) {
    let depth = settings.depth;
    let mut mlp = Mlp::<f64>::new(settings, 3);
    let x = points(9);
    let t: Vec<f64> = (0..9).map(|i| i as f64 / 9.0).collect();
    let w = weights_of(9, settings.head_out());
    let (_, cache) = mlp.forward(&x, &t);
    let g = mlp.backward(&cache, &w);
    assert_eq!(g.len(), mlp.params.len());
    let h = 1e-6;
    let mut checked = 0;
    let stride = (mlp.params.len() / 150).max(1);
    for p in (0..mlp.params.len()).step_by(stride) {
        let orig = mlp.params[p];
        mlp.params[p] = orig + h;
        let lp = loss(&mlp, &x, &t, &w);
        mlp.params[p] = orig - h;
        let lm = loss(&mlp, &x, &t, &w);
        mlp.params[p] = orig;
        let fd = (lp - lm) / (2.0 * h);
        let err = (fd - g[p]).abs() / fd.abs().max(g[p].abs()).max(1e-6);
        assert!(err < 1e-3, "D={depth} param {p}: fd {fd} analytic {}", g[p]);
        checked += 1;
    }
    assert!(checked > 100);
}

#[test]
fn gradients_match_finite_differences_with_skip() {
    fd_check(6, 12); // skip after layer 3
}

#[test]
fn gradients_match_finite_differences_shallow() {
    fd_check(2, 10);
}

/// The colour head's three more outputs, every layer's parameters checked.
#[test]
fn gradients_match_finite_differences_with_colour() {
    fd_check_settings(coloured(6, 12));
    let s = coloured(3, 8);
    assert_eq!(s.head_out(), 13);
    let l = *Mlp::<f64>::layout(&s).last().unwrap();
    assert_eq!(l.fan_out, 13);
}

/// The f32 path splits a colour head's rows into δx, δq, δs and δc, and without a colour
/// head the deltas carry none.
#[test]
fn colour_rows_split_into_deltas() {
    let s = coloured(2, 6);
    let m64 = Mlp::<f64>::new(s, 4);
    let m32 = Mlp::<f32>::new(s, 4);
    let x64 = points(4);
    let x32: Vec<[f32; 3]> = x64.iter().map(|p| p.map(|v| v as f32)).collect();
    let (o64, _) = m64.forward(&x64, &[0.7]);
    let (d, _) = Deformation::forward(&m32, &x32, &[0.7]);
    assert!(d.has_color());
    for i in 0..4 {
        for k in 0..3 {
            assert!((d.ds[i][k] as f64 - o64[i * 13 + 7 + k]).abs() < 1e-5);
            assert!((d.dc[i][k] as f64 - o64[i * 13 + 10 + k]).abs() < 1e-5);
        }
    }
    let (plain, _) = Deformation::forward(&Mlp::<f32>::new(small(2, 6), 4), &x32, &[0.7]);
    assert!(!plain.has_color());
}

/// Past 4 096 rows the products run by blocks of 2 048 rows (and the weight gradients
/// as sums of per-block partial products): the forward and backward of 5 000 rows equal
/// those of their two halves (one block each) — outputs row for row, parameter gradients
/// summed (f64, rounding only).
#[test]
fn row_blocks_compute_what_the_halves_compute() {
    let mlp = Mlp::<f64>::new(small(4, 16), 5);
    let n = 5000;
    let x = points(n);
    let t: Vec<f64> = (0..n).map(|i| (i % 97) as f64 / 97.0).collect();
    let w = weights(n);
    let (out, cache) = mlp.forward(&x, &t);
    let g = mlp.backward(&cache, &w);
    let h = 2500;
    let o = field::HEAD_OUT;
    let (out_a, cache_a) = mlp.forward(&x[..h], &t[..h]);
    let (out_b, cache_b) = mlp.forward(&x[h..], &t[h..]);
    let ga = mlp.backward(&cache_a, &w[..h * o]);
    let gb = mlp.backward(&cache_b, &w[h * o..]);
    assert_eq!(out[..h * o], out_a[..]);
    assert_eq!(out[h * o..], out_b[..]);
    let scale = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 1.0, "gradients too small to compare: {scale}");
    for (p, (&whole, (&a, &b))) in g.iter().zip(ga.iter().zip(&gb)).enumerate() {
        assert!(
            (whole - (a + b)).abs() <= 1e-9 * scale,
            "param {p}: {whole} against {a} + {b}"
        );
    }
}

#[test]
fn layout_matches_deform_gs_sizes() {
    let s = FieldSettings {
        depth: 8,
        width: 256,
        pos_freqs: 10,
        time_freqs: 6,
        seed: 0,
        zero_head_init: true,
        color: false,
    };
    assert_eq!(Mlp::<f32>::input_dim(&s), 63 + 13);
    let layers = Mlp::<f32>::layout(&s);
    assert_eq!(layers.len(), 9);
    assert_eq!(layers[0].fan_in, 76);
    assert_eq!(layers[5].fan_in, 256 + 76); // input re-concatenated after layer 4
    assert_eq!(layers[8].fan_out, 10);
    let expected = 76 * 256 + 256 + 6 * (256 * 256 + 256) + (332 * 256 + 256) + 256 * 10 + 10;
    assert_eq!(Mlp::<f32>::param_count(&s), expected);
    // PyTorch default init bounds
    let m = Mlp::<f32>::new(s, 1);
    let l = layers[1];
    let bound = 1.0 / 256f32.sqrt();
    let w = &m.params[l.weight..l.bias];
    assert!(w.iter().all(|v| v.abs() <= bound));
    let mean_abs = w.iter().map(|v| v.abs()).sum::<f32>() / w.len() as f32;
    assert!((mean_abs - bound / 2.0).abs() < 0.01 * bound);
}

#[test]
fn encoding_keeps_raw_input_and_nerf_order() {
    let m = Mlp::<f64>::new(small(2, 4), 0);
    let e = m.encode(&[[0.5, -0.25, 1.0]], &[0.3]);
    assert_eq!(e.len(), 3 * 7 + 5);
    assert_eq!(&e[..3], &[0.5, -0.25, 1.0]);
    assert!((e[3] - 0.5f64.sin()).abs() < 1e-15); // sin(2⁰x)
    assert!((e[6] - 0.5f64.cos()).abs() < 1e-15); // cos(2⁰x)
    assert!((e[9] - 1.0f64.sin()).abs() < 1e-15); // sin(2¹x)
    assert_eq!(e[21], 0.3);
    assert!((e[25] - 0.6f64.cos()).abs() < 1e-15);
}

#[test]
fn f32_trait_path_agrees_with_f64() {
    let s = small(5, 16);
    let m64 = Mlp::<f64>::new(s, 1);
    let m32 = Mlp::<f32>::new(s, 1);
    let x64 = points(5);
    let x32: Vec<[f32; 3]> = x64.iter().map(|p| p.map(|v| v as f32)).collect();
    let (o64, _) = m64.forward(&x64, &[0.4]);
    let (d, _) = Deformation::forward(&m32, &x32, &[0.4]);
    for i in 0..5 {
        assert!((d.dx[i][1] as f64 - o64[i * 10 + 1]).abs() < 1e-5);
        assert!((d.dq[i][3] as f64 - o64[i * 10 + 6]).abs() < 1e-5);
        assert!((d.ds[i][2] as f64 - o64[i * 10 + 9]).abs() < 1e-5);
    }
}

#[test]
fn delta_application_and_backward_match_finite_differences() {
    let means = vec![[0.1f32, 0.2, 0.3]];
    let ls = vec![[-2.0f32, -1.5, -3.0]];
    let rot = vec![[0.9f32, 0.1, -0.2, 0.3]];
    let mut d = Deltas::zeros(1);
    d.dx[0] = [0.01, -0.02, 0.03];
    d.ds[0] = [0.02, -0.3, 0.01];
    d.dq[0] = [0.05, 0.0, 0.1, -0.1];
    let out = apply_deltas(&means, &ls, &rot, &d);
    assert!((out.means[0][2] - 0.33).abs() < 1e-6);
    assert!((out.log_scales[0][0] - ((-2.0f32).exp() + 0.02).ln()).abs() < 1e-6);
    // δs driving the scale negative clamps to 1e-6
    assert!((out.log_scales[0][1] - 1e-6f32.ln()).abs() < 1e-4);
    let n = (0.81f32 + 0.01 + 0.04 + 0.09).sqrt();
    assert!((out.rotations[0][0] - (0.9 / n + 0.05)).abs() < 1e-6);

    // scalar loss L = Σ a·log s' + Σ b·q' ; check dL/d log s and dL/dq and dL/dδs
    let a = [0.3f32, 0.7, -0.4];
    let b = [0.2f32, -0.5, 0.9, 0.1];
    let g = apply_deltas_backward(&ls, &rot, &d, &[[1.0; 3]], &[a], &[b], &[[0.5; 3]]);
    let lossf = |ls: &[[f32; 3]], rot: &[[f32; 4]], d: &Deltas| -> f64 {
        let o = apply_deltas(&means, ls, rot, d);
        (0..3)
            .map(|k| (a[k] * o.log_scales[0][k]) as f64)
            .sum::<f64>()
            + (0..4)
                .map(|k| (b[k] * o.rotations[0][k]) as f64)
                .sum::<f64>()
    };
    let h = 1e-3f32;
    for k in [0usize, 2] {
        let mut p = ls.clone();
        p[0][k] += h;
        let mut m = ls.clone();
        m[0][k] -= h;
        let fd = (lossf(&p, &rot, &d) - lossf(&m, &rot, &d)) / (2.0 * h as f64);
        assert!((fd - g.log_scales[0][k] as f64).abs() < 2e-3 * fd.abs().max(0.1));
        let mut dp = d.clone();
        dp.ds[0][k] += h;
        let mut dm = d.clone();
        dm.ds[0][k] -= h;
        let fd = (lossf(&ls, &rot, &dp) - lossf(&ls, &rot, &dm)) / (2.0 * h as f64);
        assert!((fd - g.deltas.ds[0][k] as f64).abs() < 2e-3 * fd.abs().max(0.1));
    }
    assert_eq!(g.log_scales[0][1], 0.0); // clamped: no gradient
    for k in 0..4 {
        let mut p = rot.clone();
        p[0][k] += h;
        let mut m = rot.clone();
        m[0][k] -= h;
        let fd = (lossf(&ls, &p, &d) - lossf(&ls, &m, &d)) / (2.0 * h as f64);
        assert!(
            (fd - g.rotations[0][k] as f64).abs() < 2e-3,
            "q{k}: {fd} vs {}",
            g.rotations[0][k]
        );
    }
    assert_eq!(g.deltas.dq[0], b);
    assert_eq!(g.deltas.dx[0], [1.0; 3]);
    // No colour head: no colour gradient.
    assert!(!g.deltas.has_color());
    // With one, δc's gradient is the deformed DC coefficients' (c' = c + δc).
    let mut dc = d.clone();
    dc.dc = vec![[0.1, -0.2, 0.3]];
    let gc = apply_deltas_backward(
        &ls,
        &rot,
        &dc,
        &[[1.0; 3]],
        &[a],
        &[b],
        &[[0.5, 0.25, -1.0]],
    );
    assert_eq!(gc.deltas.dc, vec![[0.5, 0.25, -1.0]]);
    let mut sh = vec![[1.0f32, 2.0, 3.0]];
    field::apply_color_deltas(&mut sh, &dc);
    assert_eq!(sh, vec![[1.1, 1.8, 3.3]]);
}

#[test]
fn save_load_round_trip_is_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    let m = Mlp::<f32>::new(small(5, 8), 11);
    field::io::save(&m, dir.path()).unwrap();
    let back = field::io::load(dir.path()).unwrap();
    assert_eq!(back.settings, m.settings);
    assert_eq!(
        back.params.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        m.params.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
}

#[test]
fn load_rejects_bad_files_with_the_file_name() {
    let dir = tempfile::tempdir().unwrap();
    let err = field::io::load(dir.path()).unwrap_err().to_string();
    assert!(err.contains("field.json"), "{err}");
    let m = Mlp::<f32>::new(small(2, 4), 1);
    field::io::save(&m, dir.path()).unwrap();
    let wpath = dir.path().join("field.safetensors");
    let bytes = std::fs::read(&wpath).unwrap();
    // truncated
    std::fs::write(&wpath, &bytes[..bytes.len() / 2]).unwrap();
    let err = field::io::load(dir.path()).unwrap_err().to_string();
    assert!(err.contains("field.safetensors"), "{err}");
    // empty
    std::fs::write(&wpath, b"").unwrap();
    assert!(field::io::load(dir.path()).is_err());
    // wrong shape: settings say a wider net than the weights
    std::fs::write(&wpath, &bytes).unwrap();
    let mut s = m.settings;
    s.width = 5;
    std::fs::write(
        dir.path().join("field.json"),
        serde_json::to_string(&s).unwrap(),
    )
    .unwrap();
    let err = field::io::load(dir.path()).unwrap_err().to_string();
    assert!(err.contains("expected f32"), "{err}");
    // hostile settings
    std::fs::write(
        dir.path().join("field.json"),
        br#"{"depth":100000,"width":1,"pos_freqs":1,"time_freqs":1,"seed":0}"#,
    )
    .unwrap();
    assert!(field::io::load(dir.path()).is_err());
    std::fs::write(dir.path().join("field.json"), b"{garbage").unwrap();
    assert!(field::io::load(dir.path()).is_err());
}

/// A zero head makes the field the identity (all deltas exactly 0), while the head's
/// weight gradient is non-zero, so training can leave the identity.
#[test]
fn zero_head_outputs_zero_deltas_and_still_learns() {
    let mut m = Mlp::<f64>::new(small(3, 8), 2);
    m.zero_head();
    let x = points(16);
    let (out, cache) = m.forward(&x, &[0.4]);
    assert!(out.iter().all(|&v| v == 0.0));
    let g = m.backward(&cache, &vec![1.0; out.len()]);
    let head = *m.layers.last().unwrap();
    let head_grad: f64 = g[head.weight..head.bias + head.fan_out]
        .iter()
        .map(|v| v.abs())
        .sum();
    assert!(head_grad > 1e-3, "head gradient {head_grad}");
}

/// A colour head added to a trained field deforms exactly as before (bit for bit) with
/// zero colour, and its colour columns receive gradients.
#[test]
fn a_colour_head_added_keeps_the_deformation() {
    let m = Mlp::<f64>::new(small(5, 8), 2);
    let c = m.with_color();
    assert!(c.settings.color && !m.settings.color);
    assert_eq!(c.params.len(), m.params.len() + 3 * (8 + 1));
    let x = points(6);
    let (a, _) = m.forward(&x, &[0.3]);
    let (b, cache) = c.forward(&x, &[0.3]);
    for i in 0..6 {
        assert_eq!(a[i * 10..i * 10 + 10], b[i * 13..i * 13 + 10]);
        assert_eq!(b[i * 13 + 10..i * 13 + 13], [0.0; 3]);
    }
    let g = c.backward(&cache, &weights_of(6, 13));
    let head = *c.layers.last().unwrap();
    assert!(
        g[head.bias + 10..head.bias + 13]
            .iter()
            .all(|v| v.abs() > 1e-6)
    );
    assert_eq!(c.with_color().params, c.params);
}

/// With a colour head the field runs on every Gaussian even when `dynamic_only`: the
/// static-flagged ones keep their geometry and take the field's colour. The deltas
/// against the f64 network's rows with the static ones' geometric columns zeroed, and
/// both backward paths against central differences of that masked loss in f64.
#[test]
fn a_colour_field_recolours_static_gaussians_without_moving_them() {
    use gaussians::Gaussian;
    use gaussians::field::{FieldWork, MlpCache, splat_deltas_backward_into, splat_deltas_into};
    let n = 9;
    let x = points(n);
    let splats: gaussians::Splats = x
        .iter()
        .enumerate()
        .map(|(i, m)| Gaussian {
            dynamic: i.is_multiple_of(3),
            ..Gaussian::isotropic(m.map(|v| v as f32), -2.0, 0.0, [0.1; 3])
        })
        .collect();
    let settings = coloured(3, 8);
    let mlp = Mlp::<f32>::new(settings, 5);
    let mut net = Mlp::<f64>::new(settings, 5);
    net.params = mlp.params.iter().map(|&p| p as f64).collect();
    let t = 0.4;
    let w = weights_of(n, 13);
    // The masked weights: a static Gaussian's geometric outputs do not reach the loss.
    let mask = |i: usize, k: usize| i.is_multiple_of(3) || k >= field::HEAD_OUT;
    let wm: Vec<f64> = (0..n * 13)
        .map(|j| if mask(j / 13, j % 13) { w[j] } else { 0.0 })
        .collect();

    let (d, cache) = field::splat_deltas(&mlp, &splats, t as f32, true);
    let mut work = FieldWork::default();
    let (mut d2, mut cache2) = (Deltas::default(), MlpCache::default());
    splat_deltas_into(
        &mlp,
        &splats,
        t as f32,
        true,
        &mut work,
        &mut d2,
        &mut cache2,
    );
    assert_eq!(d, d2);
    let (rows, _) = net.forward(&x, &[t]);
    for i in 0..n {
        let got = [&d.dx[i][..], &d.dq[i][..], &d.ds[i][..], &d.dc[i][..]].concat();
        for k in 0..13 {
            let want = if mask(i, k) { rows[i * 13 + k] } else { 0.0 };
            assert!(
                (got[k] as f64 - want).abs() < 1e-5,
                "Gaussian {i} output {k}: {} against {want}",
                got[k]
            );
        }
        if !i.is_multiple_of(3) {
            assert!(
                d.dc[i].iter().any(|v| v.abs() > 1e-4),
                "static {i} recoloured"
            );
        }
    }

    // The gradient of Σ w ⊙ deltas: the full weights go in, the static geometry's drop.
    let mut g = Deltas::default();
    for i in 0..n {
        let r = &w[i * 13..i * 13 + 13];
        g.dx.push([r[0], r[1], r[2]].map(|v| v as f32));
        g.dq.push([r[3], r[4], r[5], r[6]].map(|v| v as f32));
        g.ds.push([r[7], r[8], r[9]].map(|v| v as f32));
        g.dc.push([r[10], r[11], r[12]].map(|v| v as f32));
    }
    let grad = field::splat_deltas_backward(&mlp, &splats, true, &cache, &g);
    let mut grad2 = Vec::new();
    splat_deltas_backward_into(&mlp, &splats, true, &cache2, &g, &mut work, &mut grad2);
    assert_eq!(grad, grad2);
    let p0 = net.params.clone();
    let (mut num, mut den) = (0.0f64, 0.0f64);
    const EPS: f64 = 1e-6;
    for p in 0..p0.len() {
        net.params[p] = p0[p] + EPS;
        let lp = loss(&net, &x, &[t], &wm);
        net.params[p] = p0[p] - EPS;
        let lm = loss(&net, &x, &[t], &wm);
        net.params[p] = p0[p];
        let fd = (lp - lm) / (2.0 * EPS);
        num += (grad[p] as f64 - fd).powi(2);
        den += fd * fd;
    }
    let rel = num.sqrt() / den.sqrt();
    assert!(den.sqrt() > 1e-2 && rel < 1e-4, "relative error {rel:.2e}");
}
