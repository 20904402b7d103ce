//! The contrast-maximisation loss of a dense flow and its exact gradient (paper Eq. 6
//! and 8; the definition is in the doc of `cm`).

use super::warp::{CmEvents, at, corners, event_pixel, iwe};

/// Settings of the CM loss.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct CmConfig {
    /// Number of pyramid levels (1 = full resolution only).
    pub scales: usize,
    /// Weight of the TV regulariser on the flow.
    pub lambda_tv: f64,
    /// Finest pyramid level used (0 = full resolution; coarse-to-fine schedules raise
    /// it early in training). Clamped to `scales − 1`.
    #[serde(default)]
    pub first_level: usize,
}

impl Default for CmConfig {
    fn default() -> Self {
        CmConfig {
            scales: 3,
            lambda_tv: 0.01,
            first_level: 0,
        }
    }
}

/// Value of the CM loss and its gradient with respect to the dense flow (u then v,
/// each `width·height`, row-major, px/s).
#[derive(Clone, Debug)]
pub struct CmLoss {
    pub loss: f64,
    pub grad_u: Vec<f64>,
    pub grad_v: Vec<f64>,
    /// Mean GM of the warped IWEs (over references); larger = sharper.
    pub gm_warped: f64,
    /// GM of the unwarped IWE.
    pub gm_unwarped: f64,
}

const TV_EPS: f64 = 1e-3;

/// 2×2 average pooling (odd trailing row/column dropped).
fn pool2(img: &[f64], w: usize, h: usize) -> (Vec<f64>, usize, usize) {
    let (pw, ph) = (w / 2, h / 2);
    let mut out = vec![0.0; pw * ph];
    for y in 0..ph {
        for x in 0..pw {
            let i = 2 * y * w + 2 * x;
            out[y * pw + x] = 0.25 * (img[i] + img[i + 1] + img[i + w] + img[i + w + 1]);
        }
    }
    (out, pw, ph)
}

/// Mean squared central-difference gradient over interior pixels; writes dGM/dimg
/// into `grad` (accumulating) when given.
fn gm_single(img: &[f64], w: usize, h: usize, mut grad: Option<&mut [f64]>, scale: f64) -> f64 {
    if w < 3 || h < 3 {
        return 0.0;
    }
    let n = ((w - 2) * (h - 2)) as f64;
    let mut sum = 0.0;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let i = y * w + x;
            let gx = 0.5 * (img[i + 1] - img[i - 1]);
            let gy = 0.5 * (img[i + w] - img[i - w]);
            sum += gx * gx + gy * gy;
            if let Some(g) = grad.as_deref_mut() {
                // d(gx²)/dimg[i±1] = ±gx; scaled by 1/n and the caller's scale.
                let c = scale / n;
                g[i + 1] += c * gx;
                g[i - 1] -= c * gx;
                g[i + w] += c * gy;
                g[i - w] -= c * gy;
            }
        }
    }
    sum / n
}

/// Multi-scale GM: mean over `scales` pyramid levels. With `grad`, fills dGM/dimg.
pub fn gradient_magnitude(
    img: &[f64],
    w: usize,
    h: usize,
    scales: usize,
    grad: Option<&mut [f64]>,
) -> f64 {
    gradient_magnitude_from(img, w, h, scales, 0, grad)
}

/// Multi-scale GM over the pyramid levels `first..scales` (level 0 = `img`; `first`
/// clamped to `scales − 1`): their mean. With `grad`, fills dGM/dimg.
// Eq. 6 (contrast of the IWE; the GM of Shiba et al., see the module doc)
pub fn gradient_magnitude_from(
    img: &[f64],
    w: usize,
    h: usize,
    scales: usize,
    first: usize,
    grad: Option<&mut [f64]>,
) -> f64 {
    let scales = scales.max(1);
    let first = first.min(scales - 1);
    let inv = 1.0 / (scales - first) as f64;
    let mut levels: Vec<(Vec<f64>, usize, usize)> = vec![(img.to_vec(), w, h)];
    for _ in 1..scales {
        let (l, lw, lh) = levels.last().unwrap();
        let next = pool2(l, *lw, *lh);
        levels.push(next);
    }
    let want_grad = grad.is_some();
    let mut total = 0.0;
    let mut level_grads = Vec::new();
    for (i, (l, lw, lh)) in levels.iter().enumerate() {
        let mut g = if want_grad {
            vec![0.0; lw * lh]
        } else {
            Vec::new()
        };
        if i >= first {
            total += inv * gm_single(l, *lw, *lh, want_grad.then_some(&mut g[..]), inv);
        }
        level_grads.push(g);
    }
    if let Some(out) = grad {
        // Back through the pooling, coarse to fine.
        for s in (1..levels.len()).rev() {
            let (_, lw, lh) = &levels[s];
            let fw = levels[s - 1].1;
            let (coarse, fine) = {
                let (a, b) = level_grads.split_at_mut(s);
                (&b[0], &mut a[s - 1])
            };
            for y in 0..*lh {
                for x in 0..*lw {
                    let g = 0.25 * coarse[y * lw + x];
                    let i = 2 * y * fw + 2 * x;
                    fine[i] += g;
                    fine[i + 1] += g;
                    fine[i + fw] += g;
                    fine[i + fw + 1] += g;
                }
            }
        }
        out.copy_from_slice(&level_grads[0]);
    }
    total
}

/// Reference times and weights: start, middle (×2), end (Shiba et al.).
pub fn references(t_a: f64, t_b: f64) -> [(f64, f64); 3] {
    [(t_a, 1.0), (0.5 * (t_a + t_b), 2.0), (t_b, 1.0)]
}

/// Smooth total variation (mean Charbonnier of forward differences) and its gradient.
fn tv(u: &[f64], w: usize, h: usize, grad: &mut [f64], weight: f64) -> f64 {
    let mut sum = 0.0;
    let mut count = 0usize;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            for j in [(x + 1 < w).then_some(i + 1), (y + 1 < h).then_some(i + w)]
                .into_iter()
                .flatten()
            {
                let d = u[j] - u[i];
                let r = (d * d + TV_EPS * TV_EPS).sqrt();
                sum += r;
                count += 1;
                let g = d / r;
                grad[j] += weight * g;
                grad[i] -= weight * g;
            }
        }
    }
    if count == 0 {
        return 0.0;
    }
    // The gradient was accumulated with `weight`; rescale for the mean.
    let inv = 1.0 / count as f64;
    for g in grad.iter_mut() {
        *g *= inv;
    }
    sum * inv
}

/// CM loss of a dense flow on a `(width, height)` grid over the window `(t_a, t_b)`
/// and its exact gradient.
///
/// Loss = Σ_ref w_ref·GM(unwarped)/GM(warped to ref) / Σ w_ref + λ·(TV(u) + TV(v)).
/// With no events (or a featureless unwarped IWE) the data term is 0 and only TV acts.
// Eq. 8 (the LoCM loss)
pub fn cm_loss(
    ev: &CmEvents,
    u: &[f64],
    v: &[f64],
    (w, h): (usize, usize),
    (t_a, t_b): (f64, f64),
    cfg: &CmConfig,
) -> CmLoss {
    assert_eq!(u.len(), w * h, "flow u has the wrong size");
    assert_eq!(v.len(), w * h, "flow v has the wrong size");
    let mut grad_u = vec![0.0; w * h];
    let mut grad_v = vec![0.0; w * h];
    if w == 0 || h == 0 {
        let (gm_warped, gm_unwarped) = (0.0, 0.0);
        return CmLoss {
            loss: 0.0,
            grad_u,
            grad_v,
            gm_warped,
            gm_unwarped,
        };
    }
    let zero = vec![0.0; w * h];
    let gm0 = gradient_magnitude_from(
        &iwe(ev, &zero, &zero, t_a, w, h),
        w,
        h,
        cfg.scales,
        cfg.first_level,
        None,
    );
    let mut data = 0.0;
    let mut gm_mean = 0.0;
    let refs = references(t_a, t_b);
    let wsum: f64 = refs.iter().map(|r| r.1).sum();
    let mut g_img = vec![0.0; w * h];
    for (t_ref, wt) in refs {
        let img = iwe(ev, u, v, t_ref, w, h);
        let gm = gradient_magnitude_from(&img, w, h, cfg.scales, cfg.first_level, Some(&mut g_img));
        gm_mean += wt * gm / wsum;
        if gm0 <= 0.0 || gm <= 0.0 {
            continue;
        }
        data += wt / wsum * gm0 / gm;
        let dl_dgm = -wt / wsum * gm0 / (gm * gm);
        // Back through the bilinear splat and the warp.
        for k in 0..ev.len() {
            let p = event_pixel(ev.x[k], ev.y[k], w, h);
            let dt = ev.t[k] - t_ref;
            let wx = ev.x[k] - dt * u[p];
            let wy = ev.y[k] - dt * v[p];
            if !wx.is_finite() || !wy.is_finite() {
                continue;
            }
            let (x0, y0, fx, fy) = corners(wx, wy);
            let g00 = at(&g_img, w, h, x0, y0);
            let g10 = at(&g_img, w, h, x0 + 1, y0);
            let g01 = at(&g_img, w, h, x0, y0 + 1);
            let g11 = at(&g_img, w, h, x0 + 1, y0 + 1);
            let d_wx = (1.0 - fy) * (g10 - g00) + fy * (g11 - g01);
            let d_wy = (1.0 - fx) * (g01 - g00) + fx * (g11 - g10);
            grad_u[p] -= dl_dgm * dt * d_wx;
            grad_v[p] -= dl_dgm * dt * d_wy;
        }
    }
    let mut tv_gu = vec![0.0; w * h];
    let mut tv_gv = vec![0.0; w * h];
    let tv_val = tv(u, w, h, &mut tv_gu, cfg.lambda_tv) + tv(v, w, h, &mut tv_gv, cfg.lambda_tv);
    for i in 0..w * h {
        grad_u[i] += tv_gu[i];
        grad_v[i] += tv_gv[i];
    }
    CmLoss {
        loss: data + cfg.lambda_tv * tv_val,
        grad_u,
        grad_v,
        gm_warped: gm_mean,
        gm_unwarped: gm0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn random_case(seed: u64, w: usize, h: usize, n: usize) -> (CmEvents, Vec<f64>, Vec<f64>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut ev = CmEvents::default();
        for _ in 0..n {
            ev.x.push(rng.random_range(1.0..(w as f64 - 2.0)));
            ev.y.push(rng.random_range(1.0..(h as f64 - 2.0)));
            ev.t.push(rng.random_range(0.0..1.0));
        }
        let u = (0..w * h).map(|_| rng.random_range(-2.0..2.0)).collect();
        let v = (0..w * h).map(|_| rng.random_range(-2.0..2.0)).collect();
        (ev, u, v)
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let cfg = CmConfig {
            scales: 2,
            lambda_tv: 0.05,
            first_level: 0,
        };
        check_gradient(12, 10, &cfg);
    }

    #[test]
    fn coarse_levels_only_gradient_matches_finite_differences() {
        // Levels 1..3 of a 3-level pyramid (the coarse-to-fine schedule's first epochs).
        let cfg = CmConfig {
            scales: 3,
            lambda_tv: 0.05,
            first_level: 1,
        };
        check_gradient(16, 12, &cfg);
        // The full-resolution level does change the value.
        let (ev, u, v) = random_case(7, 16, 12, 150);
        let all = CmConfig {
            first_level: 0,
            ..cfg.clone()
        };
        let a = cm_loss(&ev, &u, &v, (16, 12), (0.0, 1.0), &cfg).loss;
        let b = cm_loss(&ev, &u, &v, (16, 12), (0.0, 1.0), &all).loss;
        assert!((a - b).abs() > 1e-6, "{a} {b}");
        // first_level past the coarsest level is clamped to it.
        let top = |f| CmConfig {
            first_level: f,
            ..cfg.clone()
        };
        let c2 = cm_loss(&ev, &u, &v, (16, 12), (0.0, 1.0), &top(2)).loss;
        let c9 = cm_loss(&ev, &u, &v, (16, 12), (0.0, 1.0), &top(9)).loss;
        assert_eq!(c2, c9);
    }

    fn check_gradient(w: usize, h: usize, cfg: &CmConfig) {
        let cfg = cfg.clone();
        let (ev, u, v) = random_case(7, w, h, 150);
        let l = cm_loss(&ev, &u, &v, (w, h), (0.0, 1.0), &cfg);
        assert!(l.loss.is_finite() && l.loss > 0.0);
        let eps = 1e-6;
        let mut worst: f64 = 0.0;
        let mut checked = 0;
        for i in (0..w * h).step_by(7) {
            for comp in 0..2 {
                let (mut up, mut vp) = (u.clone(), v.clone());
                let (mut um, mut vm) = (u.clone(), v.clone());
                if comp == 0 {
                    up[i] += eps;
                    um[i] -= eps;
                } else {
                    vp[i] += eps;
                    vm[i] -= eps;
                }
                let fp = cm_loss(&ev, &up, &vp, (w, h), (0.0, 1.0), &cfg).loss;
                let fm = cm_loss(&ev, &um, &vm, (w, h), (0.0, 1.0), &cfg).loss;
                let fd = (fp - fm) / (2.0 * eps);
                let an = if comp == 0 { l.grad_u[i] } else { l.grad_v[i] };
                let rel = (fd - an).abs() / (fd.abs().max(an.abs()).max(1e-6));
                worst = worst.max(rel);
                checked += 1;
            }
        }
        assert!(checked > 20);
        assert!(worst < 1e-3, "worst relative error {worst}");
        assert!(
            l.grad_u.iter().any(|g| g.abs() > 1e-6),
            "gradient is all zero"
        );
    }

    #[test]
    fn correct_flow_sharpens_a_moving_edge() {
        // Events of a vertical edge moving at 20 px/s over 1 s.
        let (w, h) = (48, 24);
        let mut ev = CmEvents::default();
        for k in 0..2000 {
            let t = k as f64 / 2000.0;
            ev.x.push(10.0 + 20.0 * t);
            ev.y.push(2.0 + (k % 20) as f64);
            ev.t.push(t);
        }
        let cfg = CmConfig::default();
        let loss_with = |vx: f64| {
            let u = vec![vx; w * h];
            let v = vec![0.0; w * h];
            cm_loss(&ev, &u, &v, (w, h), (0.0, 1.0), &cfg).loss
        };
        let (good, zero, bad) = (loss_with(20.0), loss_with(0.0), loss_with(-20.0));
        assert!(good < 0.5 * zero, "good {good} zero {zero}");
        assert!(bad > zero, "bad {bad} zero {zero}");
    }

    #[test]
    fn no_events_gives_finite_tv_only() {
        let (w, h) = (8, 8);
        let ev = CmEvents::default();
        let u = vec![1.0; 64];
        let v = vec![0.0; 64];
        let l = cm_loss(&ev, &u, &v, (w, h), (0.0, 1.0), &CmConfig::default());
        assert!(l.loss.is_finite());
        assert!(l.loss.abs() < 1e-3);
        assert!(l.grad_u.iter().all(|g| g.is_finite()));
    }
}
