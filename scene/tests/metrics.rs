//! PSNR / SSIM values and invariants; D-SSIM and L1 gradients against finite differences.

use scene::metrics::{dssim_loss, l1_loss, psnr_u8, ssim_and_grad, ssim_map_u8, ssim_u8};

fn pattern(n: usize, seed: f64) -> Vec<f64> {
    (0..n)
        .map(|i| {
            0.5 + 0.4 * ((i as f64 * 0.73 + seed).sin() * (i as f64 * 0.11 + seed * 2.0).cos())
        })
        .collect()
}

#[test]
fn psnr_of_one_level_offset_is_48_13_db() {
    let a = vec![100.0 / 255.0; 64];
    let b = vec![101.0 / 255.0; 64];
    let p = psnr_u8(&a, &b);
    assert!((p - 20.0 * 255f64.log10()).abs() < 1e-12, "{p}");
    assert!(psnr_u8(&a, &a).is_infinite());
    // differences below half a level vanish after quantisation
    let c = vec![100.2 / 255.0; 64];
    assert!(psnr_u8(&a, &c).is_infinite());
}

#[test]
fn ssim_single_pixel_matches_hand_computation() {
    // 1×1 image: every blur keeps only the centre tap w = k₅², k₅ = 1/Σ exp(−(i−5)²/4.5).
    let k5 = 1.0
        / (0..11)
            .map(|i| (-((i as f64 - 5.0).powi(2)) / 4.5).exp())
            .sum::<f64>();
    let w = k5 * k5;
    let (x, y) = (0.8f64, 0.3f64);
    let (c1, c2) = (1e-4, 9e-4);
    let (m1, m2) = (w * x, w * y);
    let s11 = w * x * x - m1 * m1;
    let s22 = w * y * y - m2 * m2;
    let s12 = w * x * y - m1 * m2;
    let want =
        (2.0 * m1 * m2 + c1) * (2.0 * s12 + c2) / ((m1 * m1 + m2 * m2 + c1) * (s11 + s22 + c2));
    let (got, _) = ssim_and_grad(&[x], &[y], 1, 1, false);
    assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    assert!(want < 0.9);
}

#[test]
fn ssim_invariants() {
    let (w, h) = (24, 20);
    let a: Vec<f32> = pattern(3 * w * h, 0.3).iter().map(|&v| v as f32).collect();
    assert!((ssim_u8(&a, &a, w, h) - 1.0).abs() < 1e-12);
    let mut prev = 1.0;
    for (k, amp) in [0.02f32, 0.05, 0.1, 0.2].iter().enumerate() {
        let noisy: Vec<f32> = a
            .iter()
            .enumerate()
            .map(|(i, &v)| v + amp * ((i as f32 * 12.9898).sin() * 43758.547).fract())
            .collect();
        let s_ab = ssim_u8(&a, &noisy, w, h);
        let s_ba = ssim_u8(&noisy, &a, w, h);
        assert!((s_ab - s_ba).abs() < 1e-12, "symmetric");
        assert!(s_ab < prev, "noise level {k}: {s_ab} !< {prev}");
        prev = s_ab;
    }
    assert!(prev < 0.9);
}

#[test]
fn dssim_gradient_matches_finite_differences() {
    let (w, h, c) = (9, 7, 2);
    let mut x = pattern(w * h * c, 0.1);
    let y = pattern(w * h * c, 1.7);
    let (_, g) = dssim_loss(&x, &y, w, h);
    let eps = 1e-6;
    for i in 0..x.len() {
        let o = x[i];
        x[i] = o + eps;
        let lp = dssim_loss(&x, &y, w, h).0;
        x[i] = o - eps;
        let lm = dssim_loss(&x, &y, w, h).0;
        x[i] = o;
        let fd = (lp - lm) / (2.0 * eps);
        let err = (fd - g[i]).abs() / fd.abs().max(g[i].abs()).max(1e-8);
        assert!(err < 1e-3, "pixel {i}: fd {fd} analytic {}", g[i]);
    }
}

#[test]
fn l1_gradient_matches_finite_differences() {
    let r = [0.2f32, 0.9, 0.5, 0.1];
    let t = [0.3f32, 0.4, 0.5 - 0.2, 0.6];
    let (loss, g) = l1_loss(&r, &t);
    assert!((loss - (0.1 + 0.5 + 0.2 + 0.5) / 4.0).abs() < 1e-6);
    for i in 0..4 {
        let h = 1e-3f32;
        let mut p = r;
        p[i] += h;
        let mut m = r;
        m[i] -= h;
        let fd = (l1_loss(&p, &t).0 - l1_loss(&m, &t).0) / (2.0 * h as f64);
        assert!((fd - g[i] as f64).abs() < 1e-3);
    }
}

#[test]
fn ssim_map_is_the_hand_computed_pixel_and_local() {
    // 1×1 grey image: the map's one value is the hand computation of the test above.
    let k5 = 1.0
        / (0..11)
            .map(|i| (-((i as f64 - 5.0).powi(2)) / 4.5).exp())
            .sum::<f64>();
    let w1 = k5 * k5;
    let (x, y) = (204.0f64 / 255.0, 77.0f64 / 255.0);
    let (m1, m2) = (w1 * x, w1 * y);
    let want = (2.0 * m1 * m2 + 1e-4) * (2.0 * (w1 * x * y - m1 * m2) + 9e-4)
        / ((m1 * m1 + m2 * m2 + 1e-4) * ((w1 * x * x - m1 * m1) + (w1 * y * y - m2 * m2) + 9e-4));
    let map = ssim_map_u8(&[x as f32], &[y as f32], 1, 1);
    // (the 8-bit levels pass through f32: 1e-7)
    assert!((map[0] - want).abs() < 1e-7, "{} vs {want}", map[0]);
    // A change confined to one corner: the far corner keeps SSIM 1 (the window is 11
    // wide), the changed pixels drop, and the map's mean is the whole-image SSIM.
    let (w, h) = (40, 30);
    let a: Vec<f32> = pattern(3 * w * h, 0.7).iter().map(|&v| v as f32).collect();
    let mut b = a.clone();
    for c in 0..3 {
        for y in 0..5 {
            for x in 0..5 {
                b[c * w * h + y * w + x] = 1.0 - b[c * w * h + y * w + x];
            }
        }
    }
    let map = ssim_map_u8(&a, &b, w, h);
    assert!((map[(h - 1) * w + w - 1] - 1.0).abs() < 1e-12);
    assert!(map[2 * w + 2] < 0.5, "{}", map[2 * w + 2]);
    let mean = map.iter().sum::<f64>() / map.len() as f64;
    assert!((mean - ssim_u8(&a, &b, w, h)).abs() < 1e-12);
}
