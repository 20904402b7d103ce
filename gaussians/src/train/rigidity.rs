//! Local rigidity of the motion (after Dynamic 3D Gaussians, Luiten et al., 3DV 2024:
//! the isometry term). Each Gaussian keeps, at every time, its distance to each of its
//! `k` nearest canonical neighbours:
//!
//! `L_iso = w · (1/P) Σ_i Σ_{j∈N(i)} ((‖μ'_i − μ'_j‖ − ‖μ_i − μ_j‖) / h)²`
//!
//! with `μ'` the deformed centres, `μ` the canonical ones (held fixed: the term shapes the
//! motion, not the canonical cloud), `P` the number of pairs and `h` the mean canonical
//! neighbour distance (so `w` is free of the scene's scale). Without it every Gaussian
//! of a moving object may slide along its own viewing ray at every time without changing
//! the training image: the object smears from any other viewpoint.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use scene::real::Real;
use serde::{Deserialize, Serialize};
use std::num::NonZeroUsize;

/// The isometry term's settings (`[rigidity]` in the warm-up's and the joint
/// training's settings).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RigiditySettings {
    /// Weight `w` of the term (0 = off).
    pub weight: f64,
    /// Neighbours `k` per Gaussian.
    pub neighbours: usize,
    /// Rebuild the neighbour lists every this many iterations (and whenever the
    /// Gaussians are added or removed).
    pub refresh: u32,
    /// Let the field change Gaussians' scales (`δs`). Off, `δs` gets no gradient, so
    /// with the zero-initialised head it stays 0: a moving object has to move, not be
    /// drawn by Gaussians along its whole path that grow and shrink in turn.
    pub scale_deltas: bool,
}

impl Default for RigiditySettings {
    fn default() -> Self {
        RigiditySettings {
            weight: 0.0,
            neighbours: 8,
            refresh: 100,
            scale_deltas: true,
        }
    }
}

impl RigiditySettings {
    pub fn validate(&self) -> Result<(), String> {
        if !(self.weight.is_finite() && self.weight >= 0.0) {
            return Err(format!(
                "rigidity.weight = {} must be finite and ≥ 0",
                self.weight
            ));
        }
        if self.weight > 0.0 && !(1..=64).contains(&self.neighbours) {
            return Err(format!(
                "rigidity.neighbours = {} must lie in 1..=64",
                self.neighbours
            ));
        }
        if self.refresh == 0 {
            return Err("rigidity.refresh must be positive".into());
        }
        Ok(())
    }
}

/// Each Gaussian's `k` nearest canonical neighbours among the eligible ones (those the
/// field moves), with their canonical distances.
#[derive(Clone, Debug, Default)]
pub struct Neighbours {
    /// Gaussians the lists were built for.
    pub gaussians: usize,
    /// Pairs `(i, j)` with `i` eligible, `j` one of its neighbours (eligible or not).
    pub pairs: Vec<[u32; 2]>,
    /// Canonical distance of each pair.
    pub rest: Vec<f32>,
    /// Mean canonical distance `h` (> 0).
    pub scale: f32,
    /// The iteration they were built at.
    pub built_at: u32,
}

impl Neighbours {
    /// The `k` nearest other Gaussians of each eligible one (`eligible = None`: all),
    /// searched among all Gaussians: a moving Gaussian next to still ones keeps its
    /// distance to them too, which is right where the field moves nothing.
    pub fn build(means: &[[f32; 3]], eligible: Option<&[bool]>, k: usize, at: u32) -> Self {
        let n = means.len();
        let ok = |i: usize| eligible.is_none_or(|e| e.get(i).copied().unwrap_or(true));
        let finite: Vec<u32> = (0..n as u32)
            .filter(|&i| means[i as usize].iter().all(|v| v.is_finite()))
            .collect();
        let empty = Neighbours {
            gaussians: n,
            scale: 1.0,
            built_at: at,
            ..Default::default()
        };
        let Some(k1) = NonZeroUsize::new(k + 1) else {
            return empty;
        };
        if finite.len() < 2 {
            return empty;
        }
        let pts: Vec<[f32; 3]> = finite.iter().map(|&i| means[i as usize]).collect();
        let tree: ImmutableKdTree<f32, 3> =
            ImmutableKdTree::new_from_slice(&pts).expect("finite points build a tree");
        let per: Vec<Vec<([u32; 2], f32)>> = finite
            .par_iter()
            .filter(|&&i| ok(i as usize))
            .map(|&i| {
                let found = tree
                    .query(&means[i as usize])
                    .nearest_n::<SquaredEuclidean<f32>>(k1)
                    .execute();
                let mut v: Vec<([u32; 2], f32)> = found
                    .into_iter()
                    .map(|q| ([i, finite[q.item as usize]], q.distance.sqrt()))
                    .filter(|(p, _)| p[0] != p[1])
                    .collect();
                v.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0[1].cmp(&b.0[1])));
                v.truncate(k);
                v
            })
            .collect();
        let (pairs, rest): (Vec<[u32; 2]>, Vec<f32>) = per.into_iter().flatten().unzip();
        let mean = rest.iter().map(|&d| d as f64).sum::<f64>() / rest.len().max(1) as f64;
        Neighbours {
            gaussians: n,
            pairs,
            rest,
            scale: if mean > 0.0 { mean as f32 } else { 1.0 },
            built_at: at,
        }
    }

    /// Rebuild `slot` when the term is on (weight > 0, field on) and the lists are
    /// missing, older than `refresh` iterations, or for another number of Gaussians
    /// (built over the field-moved ones: the dynamic ones when `dynamic_only`); empty it
    /// when the term is off.
    pub(crate) fn refresh(
        slot: &mut Option<Neighbours>,
        s: &RigiditySettings,
        field_on: bool,
        splats: &crate::Splats,
        dynamic_only: bool,
        iteration: u32,
    ) {
        if s.weight <= 0.0 || !field_on {
            *slot = None;
            return;
        }
        let means = &splats.means;
        let dynamic = (dynamic_only && splats.dynamic.len() == means.len())
            .then_some(splats.dynamic.as_slice());
        let fresh = slot
            .as_ref()
            .is_some_and(|nb| nb.gaussians == means.len() && iteration < nb.built_at + s.refresh);
        if !fresh {
            *slot = Some(Neighbours::build(means, dynamic, s.neighbours, iteration));
        }
    }

    /// The settings' share of a view's backward: `∂L_iso/∂μ'` added to the deltas'
    /// gradient `g.dx` (when there are lists and they fit the Gaussians), and `δs`'s
    /// gradient zeroed when the field may not change scales; returns `L_iso`.
    pub fn backward(
        nb: Option<&Neighbours>,
        s: &RigiditySettings,
        deformed: &[[f32; 3]],
        g: &mut crate::field::Deltas,
    ) -> f64 {
        if !s.scale_deltas {
            g.ds.iter_mut().for_each(|v| *v = [0.0; 3]);
        }
        match nb {
            Some(nb) if s.weight > 0.0 && nb.gaussians == deformed.len() => {
                nb.isometry(s.weight, deformed, &mut g.dx) as f64
            }
            _ => 0.0,
        }
    }

    /// `L_iso` at the deformed centres `deformed` (same length as the canonical cloud
    /// the lists were built for); `grad` (same length) receives `∂L_iso/∂μ'` added.
    pub fn isometry<T: Real>(&self, weight: f64, deformed: &[[T; 3]], grad: &mut [[T; 3]]) -> T {
        assert_eq!(deformed.len(), self.gaussians, "isometry: Gaussian count");
        assert_eq!(grad.len(), self.gaussians, "isometry: gradient size");
        if self.pairs.is_empty() || weight == 0.0 {
            return T::ZERO;
        }
        let h = T::from_f64(self.scale as f64);
        let c = T::from_f64(weight / self.pairs.len() as f64);
        let two = T::from_f64(2.0);
        let mut loss = T::ZERO;
        // Sequential scatter: P = N·k small sums, cheaper than the rasterizer by far.
        for (p, &r) in self.pairs.iter().zip(&self.rest) {
            let (i, j) = (p[0] as usize, p[1] as usize);
            let d: [T; 3] = std::array::from_fn(|a| deformed[i][a] - deformed[j][a]);
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let e = (len - T::from_f64(r as f64)) / h;
            loss += c * e * e;
            if len > T::from_f64(1e-12) {
                // ∂/∂μ'_i of c·e² = 2c·e/h · d/len ; μ'_j the opposite.
                let s = two * c * e / (h * len);
                for a in 0..3 {
                    grad[i][a] += s * d[a];
                    grad[j][a] -= s * d[a];
                }
            }
        }
        loss
    }
}
