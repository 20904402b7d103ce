//! Tests of `images.rs`: PSNR and SSIM against known values and a brute-force SSIM.

use super::*;

fn ramp(w: usize, h: usize, c: usize, k: f32) -> Vec<f32> {
    (0..w * h * c)
        .map(|i| ((i * 37 % 251) as f32 * k).round().min(255.0))
        .collect()
}

#[test]
fn psnr_known_values() {
    let a = vec![0.0f32; 100];
    let mut b = a.clone();
    assert_eq!(psnr_u8(&a, &b), f64::INFINITY);
    b.iter_mut().for_each(|x| *x = 1.0); // MSE 1 → 48.1308 dB
    assert!((psnr_u8(&a, &b) - 48.130_803_608_679_1).abs() < 1e-9);
    b.iter_mut().for_each(|x| *x = 255.0); // MSE 255² → 0 dB
    assert!(psnr_u8(&a, &b).abs() < 1e-12);
}

/// Brute-force SSIM of one channel (0–255 levels): every pixel's 11×11 Gaussian
/// window, zero outside the image, averaged over all pixels.
fn ssim_brute(a: &[f32], b: &[f32], w: usize, h: usize) -> f64 {
    let g = |d: isize| (-((d as f64).powi(2)) / 4.5).exp();
    let norm: f64 = (-5..=5).map(g).sum::<f64>().powi(2);
    let (c1, c2) = (6.5025, 58.5225);
    let mut total = 0.0;
    for cy in 0..h as isize {
        for cx in 0..w as isize {
            let mut m = [0f64; 5];
            for dy in -5..=5isize {
                for dx in -5..=5isize {
                    let (x, y) = (cx + dx, cy + dy);
                    if x < 0 || y < 0 || x >= w as isize || y >= h as isize {
                        continue;
                    }
                    let wt = g(dx) * g(dy) / norm;
                    let i = y as usize * w + x as usize;
                    let (p, q) = (a[i] as f64, b[i] as f64);
                    m[0] += wt * p;
                    m[1] += wt * q;
                    m[2] += wt * p * p;
                    m[3] += wt * q * q;
                    m[4] += wt * p * q;
                }
            }
            let (vx, vy, cxy) = (m[2] - m[0] * m[0], m[3] - m[1] * m[1], m[4] - m[0] * m[1]);
            total += ((2.0 * m[0] * m[1] + c1) * (2.0 * cxy + c2))
                / ((m[0] * m[0] + m[1] * m[1] + c1) * (vx + vy + c2));
        }
    }
    total / (w * h) as f64
}

#[test]
fn ssim_identity_and_symmetry() {
    let (w, h) = (24, 20);
    let a = ramp(w, h, 3, 1.0);
    assert!((ssim_u8(&a, &a, w, h, 3) - 1.0).abs() < 1e-9);
    let b = ramp(w, h, 3, 0.7);
    let s = ssim_u8(&a, &b, w, h, 3);
    assert!(s < 0.999 && s > -1.0);
    assert!((s - ssim_u8(&b, &a, w, h, 3)).abs() < 1e-9);
}

#[test]
fn ssim_matches_a_brute_force_window_sum() {
    // one channel, and three channels as the mean of their brute-force values
    let (w, h) = (13, 11);
    let a = ramp(w, h, 1, 1.0);
    let b = ramp(w, h, 1, 0.5);
    let want = ssim_brute(&a, &b, w, h);
    assert!((ssim_u8(&a, &b, w, h, 1) - want).abs() < 1e-6, "{want}");
    let (x, y) = (vec![100.0f32; w * h], vec![110.0f32; w * h]);
    assert!((ssim_u8(&x, &y, w, h, 1) - ssim_brute(&x, &y, w, h)).abs() < 1e-6);
    let a3 = ramp(w, h, 3, 1.0);
    let b3 = ramp(w, h, 3, 0.6);
    let chan = |v: &[f32], c: usize| -> Vec<f32> { v.iter().skip(c).step_by(3).copied().collect() };
    let want3 = (0..3)
        .map(|c| ssim_brute(&chan(&a3, c), &chan(&b3, c), w, h))
        .sum::<f64>()
        / 3.0;
    assert!((ssim_u8(&a3, &b3, w, h, 3) - want3).abs() < 1e-6, "{want3}");
}

#[test]
fn renders_pair_by_name_then_by_order() {
    let t: Vec<PathBuf> = ["a/test_0000.png", "a/test_0001.png"]
        .map(PathBuf::from)
        .into();
    let r: Vec<PathBuf> = ["r/test_0001.png", "r/test_0000.png"]
        .map(PathBuf::from)
        .into();
    let p = pair_renders(&t, &r).unwrap();
    assert_eq!(p[0].1, PathBuf::from("r/test_0000.png"));
    let r2: Vec<PathBuf> = ["r/0.png", "r/1.png"].map(PathBuf::from).into();
    assert_eq!(
        pair_renders(&t, &r2).unwrap()[1].1,
        PathBuf::from("r/1.png")
    );
    assert!(pair_renders(&t, &r2[..1]).is_err());
}
