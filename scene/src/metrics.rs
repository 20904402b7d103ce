//! Image metrics and losses on planar images (`channels × height × width`).
//! Evaluation (PSNR, SSIM) quantises to 8 bits first, as the baselines read PNGs back;
//! SSIM uses an 11×11 Gaussian window (σ = 1.5), C1 = 0.01², C2 = 0.03², zero padding
//! ("same" size, as the 3DGS/Deform-GS code). Training losses (L1, D-SSIM = 1 − SSIM)
//! work on floats and return exact gradients.

use crate::real::Real;
use rayon::prelude::*;

pub(crate) const SSIM_WINDOW: usize = 11;
pub(crate) const SSIM_SIGMA: f64 = 1.5;
const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

/// Round to the 8-bit value a PNG would store, back in [0, 1].
pub(crate) fn quantize_u8(v: f32) -> f32 {
    (v.clamp(0.0, 1.0) * 255.0).round() / 255.0
}

/// Interleaved `h × w × c` to planar `c × h × w`.
pub fn interleaved_to_planar(
    data: &[f32],
    width: usize,
    height: usize,
    channels: usize,
) -> Vec<f32> {
    let mut out = vec![0.0; width * height * channels];
    for p in 0..width * height {
        for c in 0..channels {
            out[c * width * height + p] = data[p * channels + c];
        }
    }
    out
}

/// PSNR (dB) of two images after 8-bit quantisation; ∞ when identical. Computed on the
/// integer levels (`10·log10(255² / MSE)`), so it is exact for 8-bit inputs.
pub fn psnr_u8(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len());
    let level = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as f64;
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (level(x) - level(y)).powi(2))
        .sum::<f64>()
        / a.len().max(1) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}

/// SSIM of two planar images after 8-bit quantisation.
pub fn ssim_u8(a: &[f32], b: &[f32], width: usize, height: usize) -> f64 {
    let qa: Vec<f64> = a.iter().map(|&v| quantize_u8(v) as f64).collect();
    let qb: Vec<f64> = b.iter().map(|&v| quantize_u8(v) as f64).collect();
    ssim_and_grad(&qa, &qb, width, height, false).0
}

/// Per-pixel SSIM of two planar images after 8-bit quantisation (each pixel's mean
/// over the planes; its mean over all pixels is [`ssim_u8`]), for scores on a mask.
pub fn ssim_map_u8(a: &[f32], b: &[f32], width: usize, height: usize) -> Vec<f64> {
    assert_eq!(a.len(), b.len());
    let plane = width * height;
    assert!(plane > 0 && a.len().is_multiple_of(plane));
    let x: Vec<f64> = a.iter().map(|&v| quantize_u8(v) as f64).collect();
    let y: Vec<f64> = b.iter().map(|&v| quantize_u8(v) as f64).collect();
    let (mu1, mu2) = (blur(&x, width, height), blur(&y, width, height));
    let prod = |u: &[f64], v: &[f64]| -> Vec<f64> { u.iter().zip(v).map(|(a, b)| a * b).collect() };
    let p = blur(&prod(&x, &x), width, height);
    let q = blur(&prod(&y, &y), width, height);
    let r = blur(&prod(&x, &y), width, height);
    let planes = a.len() / plane;
    let mut map = vec![0.0; plane];
    for i in 0..a.len() {
        let (m1, m2) = (mu1[i], mu2[i]);
        let s = (2.0 * m1 * m2 + C1) * (2.0 * (r[i] - m1 * m2) + C2)
            / ((m1 * m1 + m2 * m2 + C1) * ((p[i] - m1 * m1) + (q[i] - m2 * m2) + C2));
        map[i % plane] += s / planes as f64;
    }
    map
}

/// Normalised 1-D Gaussian window.
fn window<T: Real>() -> [T; SSIM_WINDOW] {
    let c = (SSIM_WINDOW / 2) as f64;
    let raw: [f64; SSIM_WINDOW] =
        std::array::from_fn(|i| (-(i as f64 - c).powi(2) / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp());
    let s: f64 = raw.iter().sum();
    raw.map(|v| T::from_f64(v / s))
}

/// Separable zero-padded Gaussian blur of each `width × height` plane (self-adjoint).
fn blur<T: Real>(src: &[T], width: usize, height: usize) -> Vec<T> {
    let k = window::<T>();
    let r = SSIM_WINDOW as isize / 2;
    let plane = width * height;
    let mut tmp = vec![T::ZERO; src.len()];
    tmp.par_chunks_mut(width)
        .zip(src.par_chunks(width))
        .for_each(|(dst, row)| {
            for (x, d) in dst.iter_mut().enumerate() {
                let mut acc = T::ZERO;
                for (j, &kj) in k.iter().enumerate() {
                    let xx = x as isize + j as isize - r;
                    if xx >= 0 && (xx as usize) < width {
                        acc += kj * row[xx as usize];
                    }
                }
                *d = acc;
            }
        });
    let mut out = vec![T::ZERO; src.len()];
    out.par_chunks_mut(width)
        .enumerate()
        .for_each(|(row_i, dst)| {
            let (p, y) = (row_i / height, row_i % height);
            let base = p * plane;
            for (j, &kj) in k.iter().enumerate() {
                let yy = y as isize + j as isize - r;
                if yy >= 0 && (yy as usize) < height {
                    let srow = &tmp[base + yy as usize * width..base + (yy as usize + 1) * width];
                    for (d, &s) in dst.iter_mut().zip(srow) {
                        *d += kj * s;
                    }
                }
            }
        });
    out
}

/// Mean SSIM over all planes and pixels and, if asked, its gradient w.r.t. `x`.
pub fn ssim_and_grad<T: Real>(
    x: &[T],
    y: &[T],
    width: usize,
    height: usize,
    want_grad: bool,
) -> (f64, Vec<T>) {
    assert_eq!(x.len(), y.len());
    assert!(width * height > 0 && x.len().is_multiple_of(width * height));
    let (c1, c2) = (T::from_f64(C1), T::from_f64(C2));
    let two = T::from_f64(2.0);
    let mu1 = blur(x, width, height);
    let mu2 = blur(y, width, height);
    let xx: Vec<T> = x.iter().map(|&v| v * v).collect();
    let yy: Vec<T> = y.iter().map(|&v| v * v).collect();
    let xy: Vec<T> = x.iter().zip(y).map(|(&a, &b)| a * b).collect();
    let p = blur(&xx, width, height);
    let q = blur(&yy, width, height);
    let r = blur(&xy, width, height);
    let n = x.len();
    let inv_n = T::from_f64(1.0 / n as f64);
    let mut total = 0.0f64;
    let (mut g_mu, mut g_p, mut g_r) = if want_grad {
        (vec![T::ZERO; n], vec![T::ZERO; n], vec![T::ZERO; n])
    } else {
        (Vec::new(), Vec::new(), Vec::new())
    };
    for i in 0..n {
        let (m1, m2) = (mu1[i], mu2[i]);
        let a1 = two * m1 * m2 + c1;
        let a2 = two * (r[i] - m1 * m2) + c2;
        let b1 = m1 * m1 + m2 * m2 + c1;
        let b2 = (p[i] - m1 * m1) + (q[i] - m2 * m2) + c2;
        let s = a1 * a2 / (b1 * b2);
        total += s.to_f64();
        if want_grad {
            // ∂S/∂μ₁, ∂S/∂(G∗x²), ∂S/∂(G∗xy), each scaled by 1/N for the mean.
            let sn = s * inv_n;
            g_mu[i] = sn * (two * m2 / a1 - two * m2 / a2 - two * m1 / b1 + two * m1 / b2);
            g_p[i] = -sn / b2;
            g_r[i] = sn * two / a2;
        }
    }
    if !want_grad {
        return (total / n as f64, Vec::new());
    }
    let bm = blur(&g_mu, width, height);
    let bp = blur(&g_p, width, height);
    let br = blur(&g_r, width, height);
    let grad = (0..n)
        .map(|i| bm[i] + two * x[i] * bp[i] + y[i] * br[i])
        .collect();
    (total / n as f64, grad)
}

/// D-SSIM loss `1 − SSIM(render, target)` and its gradient w.r.t. the render.
pub fn dssim_loss<T: Real>(
    render: &[T],
    target: &[T],
    width: usize,
    height: usize,
) -> (f64, Vec<T>) {
    let (s, g) = ssim_and_grad(render, target, width, height, true);
    (1.0 - s, g.into_iter().map(|v| -v).collect())
}

/// Mean absolute error and its (sub)gradient `sign(r − t)/N` w.r.t. the render.
pub fn l1_loss(render: &[f32], target: &[f32]) -> (f64, Vec<f32>) {
    assert_eq!(render.len(), target.len());
    let inv = 1.0 / render.len().max(1) as f32;
    let mut total = 0.0f64;
    let grad = render
        .iter()
        .zip(target)
        .map(|(&r, &t)| {
            let d = r - t;
            total += d.abs() as f64;
            if d > 0.0 {
                inv
            } else if d < 0.0 {
                -inv
            } else {
                0.0
            }
        })
        .collect();
    (total / render.len().max(1) as f64, grad)
}
