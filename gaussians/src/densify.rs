//! Adaptive density control of 3DGS (Kerbl et al. §5.2, settings as Deform-GS):
//! accumulate the screen-space positional gradient norm per Gaussian; above the
//! threshold, clone small Gaussians (max scale ≤ percent_dense·extent) and split large
//! ones into two samples with scale / 1.6; prune transparent, huge-on-screen and
//! huge-in-world Gaussians; a hard cap bounds the count (memory stays bounded).
//!
//! The result is a [`Plan`]: for every Gaussian of the new cloud, which old Gaussian it
//! comes from and its new mean and log-scale (all other attributes are copied), and
//! whether it is fresh (its Adam moments start at zero).

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DensifySettings {
    /// Densify every this many iterations…
    pub interval: u32,
    /// …from this iteration…
    pub from_iter: u32,
    /// …until this one.
    pub until_iter: u32,
    /// Mean screen-space gradient norm above which a Gaussian is densified.
    pub grad_threshold: f32,
    /// Clone when max scale ≤ this × scene extent, split otherwise.
    pub percent_dense: f32,
    /// Split children get scale / this.
    pub split_scale_div: f32,
    /// Prune when sigmoid(opacity) < this.
    pub min_opacity: f32,
    /// After the first opacity reset also prune screen radius > this (pixels)…
    pub max_screen_radius: f32,
    /// …or max world scale > this × extent.
    pub max_world_frac: f32,
    /// Reset opacities to 0.01 every this many iterations (0 = never).
    pub opacity_reset_interval: u32,
    /// Hard cap on the number of Gaussians. 0 = automatic in a `TrainSettings` (the
    /// trainer resolves it, see `TrainSettings::gaussian_cap`); [`plan`] itself reads 0
    /// as no cap.
    pub max_gaussians: usize,
}

/// The warm-up's values, so a partial `[densify]` table in a `settings.toml` keeps them
/// for the keys it does not name. 3DGS densifies until 15k of 30k iterations, resets
/// opacity every 3k and has no cap; in a 3500-iteration warm-up a reset costs more than
/// it gains (measured: docs/benchmarks/2026-11-23-warm-up.md), so densify until 2500,
/// never reset, and cap the count automatically (`max_gaussians = 0`, see `TrainSettings::gaussian_cap`).
impl Default for DensifySettings {
    fn default() -> Self {
        DensifySettings {
            interval: 100,
            from_iter: 500,
            until_iter: 2500,
            grad_threshold: 0.0002,
            percent_dense: 0.01,
            split_scale_div: 1.6,
            min_opacity: 0.005,
            max_screen_radius: 20.0,
            max_world_frac: 0.1,
            opacity_reset_interval: 0,
            max_gaussians: 0,
        }
    }
}

impl DensifySettings {
    /// Why the values cannot be used, if they cannot (the message names the key).
    pub fn validate(&self) -> Result<(), String> {
        if self.interval == 0 {
            return Err("densify.interval = 0: must be ≥ 1 (densification runs every `interval` iterations)".into());
        }
        let positive = [
            ("densify.grad_threshold", self.grad_threshold),
            ("densify.percent_dense", self.percent_dense),
            ("densify.max_screen_radius", self.max_screen_radius),
            ("densify.max_world_frac", self.max_world_frac),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} = {v} must be finite and > 0"));
            }
        }
        if !(self.split_scale_div.is_finite() && self.split_scale_div > 1.0) {
            return Err(format!(
                "densify.split_scale_div = {} must be > 1 (split children are smaller)",
                self.split_scale_div
            ));
        }
        if !(0.0..1.0).contains(&self.min_opacity) {
            return Err(format!(
                "densify.min_opacity = {} must lie in [0, 1)",
                self.min_opacity
            ));
        }
        Ok(())
    }
}

/// Running statistics between densification steps.
#[derive(Clone, Debug, Default)]
pub struct GradStats {
    pub grad_accum: Vec<f32>,
    pub count: Vec<u32>,
    pub max_radius: Vec<f32>,
}

impl GradStats {
    pub fn new(n: usize) -> Self {
        GradStats {
            grad_accum: vec![0.0; n],
            count: vec![0; n],
            max_radius: vec![0.0; n],
        }
    }
    /// Add one view's statistics: the norm of each Gaussian's screen-space mean gradient
    /// and its screen radius (0 = not visible; invisible Gaussians are not counted).
    pub fn add(&mut self, screen_grad_norm: &[f32], radius: &[f32]) {
        for i in 0..self.grad_accum.len() {
            if radius[i] > 0.0 {
                self.grad_accum[i] += screen_grad_norm[i];
                self.count[i] += 1;
                self.max_radius[i] = self.max_radius[i].max(radius[i]);
            }
        }
    }
    fn mean_grad(&self, i: usize) -> f32 {
        if self.count[i] == 0 {
            0.0
        } else {
            self.grad_accum[i] / self.count[i] as f32
        }
    }
}

/// The Gaussians' geometry the plan needs (raw, as stored: log-scale, logit opacity).
pub struct Geometry<'a> {
    pub means: &'a [[f32; 3]],
    pub log_scales: &'a [[f32; 3]],
    pub rotations: &'a [[f32; 4]],
    pub opacity_logits: &'a [f32],
}

/// What to build: new Gaussian `k` copies old `source[k]` with `means[k]`, `log_scales[k]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Plan {
    pub source: Vec<usize>,
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    pub fresh: Vec<bool>,
    pub cloned: usize,
    pub split: usize,
    pub pruned: usize,
}

impl Plan {
    /// Gather a per-Gaussian attribute into the new order.
    pub fn gather<T: Clone>(&self, old: &[T]) -> Vec<T> {
        self.source.iter().map(|&s| old[s].clone()).collect()
    }

    /// The new Gaussians: `sp`'s gathered, with the plan's centres and scales (flags,
    /// trajectories, lives and tracks follow their sources; a track only its first copy).
    pub fn apply(&self, sp: &crate::splats::Splats) -> crate::splats::Splats {
        crate::splats::Splats {
            means: self.means.clone(),
            log_scales: self.log_scales.clone(),
            rotations: self.gather(&sp.rotations),
            opacity_logits: self.gather(&sp.opacity_logits),
            sh_dc: self.gather(&sp.sh_dc),
            sh_rest: self.gather(&sp.sh_rest),
            dynamic: self.gather_rows(&sp.dynamic, sp.len()),
            motion: self.gather_rows(&sp.motion, sp.len()),
            track: crate::splats::first_copies(self.gather_rows(&sp.track, sp.len())),
            life: self.gather_rows(&sp.life, sp.len()),
            part: self.gather_rows(&sp.part, sp.len()),
            parts: sp.parts.clone(),
        }
    }

    /// [`Self::gather`] of an optional attribute (empty unless one row per Gaussian).
    fn gather_rows<T: Clone>(&self, old: &[T], n: usize) -> Vec<T> {
        if old.len() == n {
            self.gather(old)
        } else {
            Vec::new()
        }
    }
    /// For `optim::Adam::remap`: old index for kept Gaussians, `None` for fresh ones.
    pub fn moment_sources(&self) -> Vec<Option<usize>> {
        self.source
            .iter()
            .zip(&self.fresh)
            .map(|(&s, &f)| (!f).then_some(s))
            .collect()
    }
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Rotate a local vector by the (normalised) quaternion `q` (w, x, y, z).
fn rotate(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
    let n = q.iter().map(|a| a * a).sum::<f32>().sqrt().max(1e-12);
    let g = glam::Quat::from_xyzw(q[1] / n, q[2] / n, q[3] / n, q[0] / n);
    (g * glam::Vec3::from(v)).into()
}

/// Plan one densify + prune step. `extent` is the scene extent (Deform-GS: 1.1 × the
/// largest camera-centre distance from their mean); `size_prune` enables the screen and
/// world size tests (3DGS: after the first opacity reset).
pub fn plan(
    geo: &Geometry<'_>,
    stats: &GradStats,
    s: &DensifySettings,
    extent: f32,
    size_prune: bool,
    seed: u64,
) -> Plan {
    let n = geo.means.len();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let max_scale = |i: usize| {
        geo.log_scales[i]
            .iter()
            .fold(f32::MIN, |a, &b| a.max(b))
            .exp()
    };
    let prune_source = |i: usize| {
        sigmoid(geo.opacity_logits[i]) < s.min_opacity
            || (size_prune
                && (stats.max_radius[i] > s.max_screen_radius
                    || max_scale(i) > s.max_world_frac * extent))
    };
    // candidates by decreasing gradient, so the cap keeps the most needed ones
    let mut cand: Vec<usize> = (0..n)
        .filter(|&i| stats.mean_grad(i) >= s.grad_threshold && !prune_source(i))
        .collect();
    cand.sort_by(|&a, &b| stats.mean_grad(b).total_cmp(&stats.mean_grad(a)));
    let kept = (0..n).filter(|&i| !prune_source(i)).count();
    let cap = if s.max_gaussians == 0 {
        usize::MAX
    } else {
        s.max_gaussians
    };
    let mut budget = cap.saturating_sub(kept);
    let mut action = vec![0u8; n]; // 0 keep, 1 clone, 2 split
    for &i in &cand {
        if budget == 0 {
            break;
        }
        action[i] = if max_scale(i) <= s.percent_dense * extent {
            1
        } else {
            2
        };
        budget -= 1;
    }
    let mut p = Plan::default();
    let mut extra = Plan::default();
    let div_ln = s.split_scale_div.ln();
    for (i, &act) in action.iter().enumerate() {
        if prune_source(i) {
            p.pruned += 1;
            continue;
        }
        match act {
            0 | 1 => {
                p.source.push(i);
                p.means.push(geo.means[i]);
                p.log_scales.push(geo.log_scales[i]);
                p.fresh.push(false);
                if act == 1 {
                    p.cloned += 1;
                    extra.source.push(i);
                    extra.means.push(geo.means[i]);
                    extra.log_scales.push(geo.log_scales[i]);
                    extra.fresh.push(true);
                }
            }
            _ => {
                p.split += 1;
                for _ in 0..2 {
                    let sc = geo.log_scales[i].map(f32::exp);
                    let local: [f32; 3] = std::array::from_fn(|k| {
                        let z: f32 = StandardNormal.sample(&mut rng);
                        z * sc[k]
                    });
                    let d = rotate(geo.rotations[i], local);
                    let m = geo.means[i];
                    extra.source.push(i);
                    extra.means.push([m[0] + d[0], m[1] + d[1], m[2] + d[2]]);
                    extra.log_scales.push(geo.log_scales[i].map(|v| v - div_ln));
                    extra.fresh.push(true);
                }
            }
        }
    }
    p.source.extend(extra.source);
    p.means.extend(extra.means);
    p.log_scales.extend(extra.log_scales);
    p.fresh.extend(extra.fresh);
    p
}

/// Opacity reset of 3DGS: opacity ← min(opacity, 0.01), as logits.
pub fn reset_opacity(opacity_logits: &mut [f32]) {
    let cap = (0.01f32 / 0.99).ln();
    for o in opacity_logits {
        *o = o.min(cap);
    }
}
