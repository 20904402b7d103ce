//! The lanes backward against the one-at-a-time [`project_backward`] on every Gaussian of
//! a random scene (culled ones included), for every lane count this CPU has.

use super::*;
use crate::raster::project::project;
use crate::raster::project_lanes::tests::{Rng, camera, splats};

/// Outputs of one span, owned.
#[derive(Clone, Default)]
struct Grads {
    means: Vec<[f32; 3]>,
    log_scales: Vec<[f32; 3]>,
    rotations: Vec<[f32; 4]>,
    opacity_logits: Vec<f32>,
    sh_dc: Vec<[f32; 3]>,
    sh_rest: Vec<[f32; 45]>,
    screen_grad_norm: Vec<f32>,
}

impl Grads {
    fn new(n: usize) -> Self {
        // NaN: every entry must be written.
        Grads {
            means: vec![[f32::NAN; 3]; n],
            log_scales: vec![[f32::NAN; 3]; n],
            rotations: vec![[f32::NAN; 4]; n],
            opacity_logits: vec![f32::NAN; n],
            sh_dc: vec![[f32::NAN; 3]; n],
            sh_rest: vec![[f32::NAN; 45]; n],
            screen_grad_norm: vec![f32::NAN; n],
        }
    }
    fn outs(&mut self) -> Outs<'_> {
        Outs {
            means: &mut self.means,
            log_scales: &mut self.log_scales,
            rotations: &mut self.rotations,
            opacity_logits: &mut self.opacity_logits,
            sh_dc: &mut self.sh_dc,
            sh_rest: &mut self.sh_rest,
            screen_grad_norm: &mut self.screen_grad_norm,
        }
    }
    /// Gaussian `i`'s gradients in groups (mean, scale, rotation, opacity, SH, norm).
    fn groups(&self, i: usize) -> [Vec<f32>; 6] {
        let mut sh = self.sh_dc[i].to_vec();
        sh.extend(self.sh_rest[i]);
        [
            self.means[i].to_vec(),
            self.log_scales[i].to_vec(),
            self.rotations[i].to_vec(),
            vec![self.opacity_logits[i]],
            sh,
            vec![self.screen_grad_norm[i]],
        ]
    }
}

#[test]
fn lanes_backward_agrees_with_the_one_at_a_time_path() {
    let mut rng = Rng(11);
    let cam = camera();
    let n = 16 * 40 + 5;
    let s = splats(n, &mut rng);
    let mut widths = vec![false];
    if simd::wide_available() {
        widths.push(true);
    } else {
        eprintln!("no AVX-512F here: only the 4-lane backward is compared");
    }
    for degree in 0..=3 {
        // Visible Gaussians get a slot and a random screen gradient.
        let (mut slot, mut screen, mut cond) = (vec![u32::MAX; n], Vec::new(), vec![1.0f32; n]);
        for i in 0..n {
            if let Some(g) = project(&s, i, &cam, degree) {
                slot[i] = screen.len() as u32;
                let sg: ScreenGrad = std::array::from_fn(|_| rng.uf(-1.0, 1.0));
                screen.push(sg);
                let [a, b, c] = g.cov;
                cond[i] = ((a + c) * (a + c) / (a * c - b * b)).max(1.0);
            }
        }
        let shared = Shared {
            cam: &cam,
            sh_degree: degree,
            slot: &slot,
            screen: &screen,
            half: [30.5, 23.5],
        };
        // The plain path, Gaussian by Gaussian.
        let mut want = Grads::new(n);
        let (mut want_cam, mut cam_scale) = ([0.0f64; 15], [0.0f64; 15]);
        {
            let mut out = want.outs();
            for i in 0..n {
                let mut c = [0.0f64; 15];
                one_at_a_time(&s, i, i, &shared, &mut out, &mut c);
                for k in 0..15 {
                    want_cam[k] += c[k];
                    // Each Gaussian's rounding scales with its term and its condition.
                    cam_scale[k] += c[k].abs() * cond[i] as f64;
                }
            }
        }
        for &wide in &widths {
            let mut got = Grads::new(n);
            let got_cam = if wide {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: AVX-512F was detected above.
                unsafe {
                    backward_span_avx512(&s, 0, shared, got.outs())
                }
                #[cfg(not(target_arch = "x86_64"))]
                unreachable!()
            } else {
                backward_span_lanes::<F4>(&s, 0, shared, got.outs())
            };
            for i in 0..n {
                // Rounding in f32 is relative to the largest terms of the chain, not to
                // the result: a thin Gaussian's log-scale gradient is a small difference
                // of large ones. Measure it against the Gaussian's largest geometric
                // gradient (mean, scale, rotation) and the 2-D covariance's condition.
                let geo = want.groups(i)[..3]
                    .iter()
                    .flatten()
                    .fold(0.0f32, |m, v| m.max(v.abs()));
                for (k, (a, b)) in got.groups(i).iter().zip(want.groups(i)).enumerate() {
                    let own = b.iter().fold(0.0f32, |m, v| m.max(v.abs()));
                    let size = if k < 3 { own.max(geo) } else { own };
                    let tol = 2e-5 * cond[i] * size + 1e-9;
                    for (x, y) in a.iter().zip(&b) {
                        assert!(
                            (x - y).abs() <= tol,
                            "degree {degree}, wide {wide}, Gaussian {i}, group {k}: {a:?} against {b:?} (condition {})",
                            cond[i]
                        );
                    }
                }
            }
            for k in 0..15 {
                let tol = 2e-5 * cam_scale[k] + 1e-6;
                assert!(
                    (got_cam[k] - want_cam[k]).abs() <= tol,
                    "camera {k}: {} against {} (tolerance {tol})",
                    got_cam[k],
                    want_cam[k]
                );
            }
        }
    }
}
