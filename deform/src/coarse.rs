//! The event term at a lower resolution (`event_downsample = k`): the pseudo image
//! averaged over `k × k` blocks of pixels, in linear intensity (the render's domain:
//! `log(mean(P + ε))`, not the mean of the logs), and compared with a render by a camera
//! whose pixels are those blocks (focal lengths divided by `k`, principal point moved to
//! the blocks' centres; the last `width mod k` columns and `height mod k` rows are left
//! out). Unlike a tile ([`crate::crop`]) every Gaussian in view still gets its gradient
//! each step, at `1/k²` of the rasterizer's pixels: the warm-up's coarse-to-fine
//! (`gaussians::train::View::half`) for `L_event`.

use crate::event_image::PseudoImage;
use scene::{Camera, real::Real};

/// The camera whose pixel `(x, y)` is the block of pixels `k·x .. k·x + k − 1` (and
/// rows alike) of `camera`: the block's centre `k·x + (k − 1)/2` maps to `x`.
pub fn camera(camera: &Camera, k: usize) -> Camera {
    let mut c = *camera;
    let i = &mut c.intrinsics;
    let kf = k as f64;
    let shift = 0.5 * (kf - 1.0);
    i.width /= k as u32;
    i.height /= k as u32;
    (i.fx, i.fy) = (i.fx / kf, i.fy / kf);
    (i.cx, i.cy) = ((i.cx - shift) / kf, (i.cy - shift) / kf);
    c
}

/// `full` averaged over `k × k` blocks into `out` (its buffers reused). A block is valid
/// when any of its pixels is; its value is `log` of the mean of `exp(data)` over its valid
/// pixels (`data = log(P + ε)`), and its `∂/∂C` the mean of the pixels' `n_eff` weighted by
/// `P + ε` (the derivative of that log-mean).
pub fn pseudo<R: Real>(full: &PseudoImage<R>, k: usize, out: &mut PseudoImage<R>) {
    let (w, h) = (full.width, full.height);
    let (w2, h2) = (w / k, h / k);
    out.begin_like(full, w2, h2);
    for c in 0..full.channels {
        let plane = c * w * h;
        for y in 0..h2 {
            for x in 0..w2 {
                let (mut sum, mut weighted, mut m) = (0.0f64, 0.0f64, 0usize);
                for dy in 0..k {
                    let row = plane + (k * y + dy) * w + k * x;
                    for i in row..row + k {
                        if full.valid[i] {
                            let p = full.data[i].to_f64().exp();
                            sum += p;
                            weighted += p * full.n_eff[i].to_f64();
                            m += 1;
                        }
                    }
                }
                let ok = m > 0 && sum > 0.0;
                out.valid.push(ok);
                out.data
                    .push(R::from_f64(if ok { (sum / m as f64).ln() } else { 0.0 }));
                out.n_eff
                    .push(R::from_f64(if ok { weighted / sum } else { 0.0 }));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};
    use scene::{Intrinsics, Pose};

    /// A world point seen at pixel `p` of the full camera is seen at `(p − (k−1)/2)/k`
    /// by the coarse one (pinhole in closed form), for k = 2 and 3.
    #[test]
    fn coarse_pixels_are_block_centres() {
        let full = Camera {
            intrinsics: Intrinsics {
                cx: 30.3,
                cy: 17.9,
                ..Intrinsics::from_fov_x(61, 37, 1.1)
            },
            cam_to_world: Pose::default(),
        };
        for k in [2usize, 3] {
            let c = camera(&full, k);
            assert_eq!(
                (c.intrinsics.width, c.intrinsics.height),
                (61 / k as u32, 37 / k as u32)
            );
            for p in [DVec3::new(0.4, -0.2, -2.0), DVec3::new(-1.0, 0.7, -5.0)] {
                let (a, _) = full.project_world(p).unwrap();
                let (b, _) = c.project_world(p).unwrap();
                let want = (a - DVec2::splat(0.5 * (k as f64 - 1.0))) / k as f64;
                assert!((b - want).length() < 1e-12, "k {k}: {b} vs {want}");
            }
        }
    }

    /// Block values against a brute-force f64 log-mean, invalid pixels left out, a block
    /// with none valid invalid, and the weighted `n_eff` against a finite difference of
    /// the block's value in `C` (each pixel's `log(P + ε)` moved by `n_eff·dC`).
    #[test]
    fn blocks_average_linear_intensity() {
        let (w, h, k) = (5usize, 4usize, 2usize);
        let mut full = PseudoImage::<f64>::default();
        (full.width, full.height, full.channels) = (w, h, 1);
        for i in 0..w * h {
            full.data.push((0.05 + 0.09 * i as f64).ln());
            full.n_eff.push(i as f64 - 7.0);
            full.valid.push(i % 7 != 3);
        }
        // The block of columns 2–3, rows 0–1 all invalid.
        for i in [2, 3, 7, 8] {
            full.valid[i] = false;
        }
        let mut out = PseudoImage::default();
        pseudo(&full, k, &mut out);
        assert_eq!((out.width, out.height, out.data.len()), (2, 2, 4));
        let value = |img: &PseudoImage<f64>, dc: f64, x: usize, y: usize| -> Option<f64> {
            let idx: Vec<usize> = (0..k)
                .flat_map(|dy| (0..k).map(move |dx| (k * y + dy) * w + k * x + dx))
                .filter(|&i| img.valid[i])
                .collect();
            let mean = idx
                .iter()
                .map(|&i| (img.data[i] + img.n_eff[i] * dc).exp())
                .sum::<f64>()
                / idx.len() as f64;
            (!idx.is_empty()).then(|| mean.ln())
        };
        for y in 0..2 {
            for x in 0..2 {
                let j = y * 2 + x;
                match value(&full, 0.0, x, y) {
                    None => assert!(!out.valid[j], "block {x},{y}"),
                    Some(v) => {
                        assert!(out.valid[j]);
                        assert!((out.data[j] - v).abs() < 1e-12, "{} vs {v}", out.data[j]);
                        let e = 1e-6;
                        let fd = (value(&full, e, x, y).unwrap() - value(&full, -e, x, y).unwrap())
                            / (2.0 * e);
                        assert!((out.n_eff[j] - fd).abs() < 1e-6, "{} vs {fd}", out.n_eff[j]);
                    }
                }
            }
        }
        assert!(!out.valid[1]);
    }
}
