//! Adam with per-group learning rates, shared by every trainer (the Gaussians, the
//! deformation field, the flow network's adapters, PoseNet), and the log-linear
//! learning-rate schedule of 3DGS / Deform-GS (`get_expon_lr_func`). Groups can grow and
//! shrink when Gaussians are cloned, split or pruned: moment buffers follow the items
//! via [`Adam::remap`].

use serde::{Deserialize, Serialize};

/// Log-linear decay `lr(step) = exp((1−τ) ln lr_init + τ ln lr_final)`, τ = step/max_steps
/// clamped to [0, 1], with the optional delayed warm-up of 3DGS.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExpSchedule {
    pub lr_init: f64,
    pub lr_final: f64,
    pub max_steps: u64,
    pub delay_steps: u64,
    pub delay_mult: f64,
}

impl ExpSchedule {
    pub fn new(lr_init: f64, lr_final: f64, max_steps: u64) -> Self {
        ExpSchedule {
            lr_init,
            lr_final,
            max_steps,
            delay_steps: 0,
            delay_mult: 1.0,
        }
    }
    /// A constant learning rate.
    pub fn constant(lr: f64) -> Self {
        Self::new(lr, lr, 1)
    }
    pub fn at(&self, step: u64) -> f64 {
        if self.lr_init == 0.0 && self.lr_final == 0.0 {
            return 0.0;
        }
        let delay = if self.delay_steps > 0 {
            let s = (step as f64 / self.delay_steps as f64).clamp(0.0, 1.0);
            self.delay_mult + (1.0 - self.delay_mult) * (0.5 * std::f64::consts::PI * s).sin()
        } else {
            1.0
        };
        let tau = (step as f64 / self.max_steps.max(1) as f64).clamp(0.0, 1.0);
        delay * ((1.0 - tau) * self.lr_init.ln() + tau * self.lr_final.ln()).exp()
    }
}

/// State of one parameter group.
#[derive(Clone, Debug)]
pub struct Group {
    pub name: String,
    pub lr: f64,
    pub eps: f64,
    /// Values per item (3 for means, 4 for rotations, 1 for the field's flat vector…).
    pub width: usize,
    pub m: Vec<f32>,
    pub v: Vec<f32>,
    pub step: u64,
}

/// Adam (β₁ = 0.9, β₂ = 0.999) over named groups.
#[derive(Clone, Debug)]
pub struct Adam {
    pub beta1: f64,
    pub beta2: f64,
    pub groups: Vec<Group>,
}

impl Default for Adam {
    fn default() -> Self {
        Adam {
            beta1: 0.9,
            beta2: 0.999,
            groups: Vec::new(),
        }
    }
}

impl Adam {
    /// Add a group of `len` values (`len` divisible by `width`); returns its index.
    pub fn add_group(&mut self, name: &str, lr: f64, eps: f64, width: usize, len: usize) -> usize {
        assert!(width > 0 && len.is_multiple_of(width));
        self.groups.push(Group {
            name: name.to_string(),
            lr,
            eps,
            width,
            m: vec![0.0; len],
            v: vec![0.0; len],
            step: 0,
        });
        self.groups.len() - 1
    }

    pub fn group(&self, name: &str) -> Option<usize> {
        self.groups.iter().position(|g| g.name == name)
    }

    /// One Adam step on group `g` (PyTorch's formulation):
    /// `m ← β₁m + (1−β₁)g`, `v ← β₂v + (1−β₂)g²`,
    /// `p ← p − lr · (m / (1−β₁ᵗ)) / (√(v / (1−β₂ᵗ)) + eps)`.
    pub fn step(&mut self, g: usize, params: &mut [f32], grads: &[f32]) {
        let (b1, b2) = (self.beta1, self.beta2);
        let group = &mut self.groups[g];
        assert_eq!(params.len(), group.m.len(), "group {} size", group.name);
        assert_eq!(grads.len(), params.len());
        group.step += 1;
        let bc1 = 1.0 - b1.powi(group.step as i32);
        let bc2 = 1.0 - b2.powi(group.step as i32);
        let step_size = (group.lr / bc1) as f32;
        let bc2_sqrt = bc2.sqrt() as f32;
        let eps = group.eps as f32;
        let (b1, b2) = (b1 as f32, b2 as f32);
        use rayon::prelude::*;
        params
            .par_chunks_mut(4096)
            .zip(grads.par_chunks(4096))
            .zip(
                group
                    .m
                    .par_chunks_mut(4096)
                    .zip(group.v.par_chunks_mut(4096)),
            )
            .for_each(|((p, gr), (m, v))| {
                for i in 0..p.len() {
                    let gi = if gr[i].is_finite() { gr[i] } else { 0.0 };
                    m[i] = b1 * m[i] + (1.0 - b1) * gi;
                    v[i] = b2 * v[i] + (1.0 - b2) * gi * gi;
                    p[i] -= step_size * m[i] / (v[i].sqrt() / bc2_sqrt + eps);
                }
            });
    }

    /// Rebuild group `g` for a new item list: new item `i` takes the moments of old item
    /// `src[i]`, or zeros when `None` (new Gaussians start with fresh moments, as 3DGS).
    pub fn remap(&mut self, g: usize, src: &[Option<usize>]) {
        let group = &mut self.groups[g];
        let w = group.width;
        let mut m = vec![0.0; src.len() * w];
        let mut v = vec![0.0; src.len() * w];
        for (i, s) in src.iter().enumerate() {
            if let Some(s) = *s {
                m[i * w..(i + 1) * w].copy_from_slice(&group.m[s * w..(s + 1) * w]);
                v[i * w..(i + 1) * w].copy_from_slice(&group.v[s * w..(s + 1) * w]);
            }
        }
        group.m = m;
        group.v = v;
    }

    /// Zero the moments of the listed items (used after an opacity reset).
    pub fn reset_items(&mut self, g: usize, items: impl Iterator<Item = usize>) {
        let group = &mut self.groups[g];
        let w = group.width;
        for i in items {
            group.m[i * w..(i + 1) * w].fill(0.0);
            group.v[i * w..(i + 1) * w].fill(0.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_is_log_linear() {
        let s = ExpSchedule::new(8e-4, 1.6e-6, 40_000);
        assert!((s.at(0) - 8e-4).abs() < 1e-15);
        assert!((s.at(40_000) - 1.6e-6).abs() < 1e-15);
        assert!((s.at(80_000) - 1.6e-6).abs() < 1e-15);
        let mid = (8e-4f64 * 1.6e-6).sqrt();
        assert!((s.at(20_000) - mid).abs() < 1e-12);
        let mut d = s;
        d.delay_steps = 100;
        d.delay_mult = 0.01;
        assert!((d.at(0) - 0.01 * 8e-4).abs() < 1e-15);
        assert!((d.at(100) - s.at(100)).abs() < 1e-15);
    }

    #[test]
    fn adam_matches_hand_computed_steps() {
        let mut a = Adam::default();
        let g = a.add_group("p", 0.1, 1e-8, 1, 2);
        let mut p = vec![1.0f32, -2.0];
        a.step(g, &mut p, &[0.5, -4.0]);
        // first step: m̂ = g, v̂ = g², update = lr·g/(|g|+eps) = ±lr
        assert!((p[0] - 0.9).abs() < 1e-6);
        assert!((p[1] + 1.9).abs() < 1e-6);
        a.step(g, &mut p, &[0.25, 0.0]);
        // by hand for item 0: m = 0.9·0.05 + 0.1·0.25 = 0.07, v = 0.999·0.00025 + 0.001·0.0625
        let m: f64 = 0.07;
        let v: f64 = 0.999 * 0.00025 + 0.001 * 0.0625;
        let mhat = m / (1.0 - 0.81);
        let vhat = v / (1.0 - 0.999f64.powi(2));
        let want = 0.9 - 0.1 * mhat / (vhat.sqrt() + 1e-8);
        assert!((p[0] as f64 - want).abs() < 5e-6, "{} vs {want}", p[0]);
    }

    #[test]
    fn remap_moves_moments_with_items_and_zeroes_new_ones() {
        let mut a = Adam::default();
        let g = a.add_group("means", 0.01, 1e-15, 3, 6);
        let mut p = vec![0.0f32; 6];
        a.step(g, &mut p, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        a.remap(g, &[Some(1), None, Some(0)]);
        let gr = &a.groups[g];
        assert_eq!(gr.m.len(), 9);
        assert!((gr.m[0] - 0.4).abs() < 1e-6 && (gr.m[2] - 0.6).abs() < 1e-6);
        assert_eq!(&gr.m[3..6], &[0.0; 3]);
        assert!((gr.m[6] - 0.1).abs() < 1e-6);
        assert!((gr.v[8] - 0.009).abs() < 1e-6);
    }

    #[test]
    fn non_finite_gradients_are_ignored() {
        let mut a = Adam::default();
        let g = a.add_group("x", 0.1, 1e-8, 1, 1);
        let mut p = vec![1.0f32];
        a.step(g, &mut p, &[f32::NAN]);
        assert_eq!(p[0], 1.0);
    }
}
