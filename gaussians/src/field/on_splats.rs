//! The deformation field evaluated on [`Splats`]: on every Gaussian, or only on those
//! flagged dynamic (`dynamic_only`; the others keep their canonical parameters).

use super::deltas::{Deformation, Deltas, apply_deltas};
use super::mlp::{Mlp, MlpCache};
use crate::splats::Splats;

/// Indices the field is evaluated on: all (`None`), or the dynamic ones when
/// `dynamic_only` (missing flags count as dynamic).
pub fn evaluated_indices(splats: &Splats, dynamic_only: bool) -> Option<Vec<usize>> {
    dynamic_only.then(|| {
        (0..splats.len())
            .filter(|&i| splats.is_dynamic(i))
            .collect()
    })
}

/// Field deltas for every Gaussian at time `t` (zero for static-flagged ones when
/// `dynamic_only`; the field then runs on the dynamic subset only).
pub fn splat_deltas(
    mlp: &Mlp<f32>,
    splats: &Splats,
    t: f32,
    dynamic_only: bool,
) -> (Deltas, MlpCache<f32>) {
    match evaluated_indices(splats, dynamic_only) {
        None => Deformation::forward(mlp, &splats.means, &[t]),
        Some(idx) => {
            let sub: Vec<[f32; 3]> = idx.iter().map(|&i| splats.means[i]).collect();
            let (ds, cache) = Deformation::forward(mlp, &sub, &[t]);
            let mut d = Deltas::zeros(splats.len());
            for (k, &i) in idx.iter().enumerate() {
                d.dx[i] = ds.dx[k];
                d.dq[i] = ds.dq[k];
                d.ds[i] = ds.ds[k];
            }
            (d, cache)
        }
    }
}

/// Field parameter gradients from the gradients of every Gaussian's deltas (those of
/// the Gaussians the field was not evaluated on are ignored), given the cache of the
/// [`splat_deltas`] call with the same `splats` and `dynamic_only`.
pub fn splat_deltas_backward(
    mlp: &Mlp<f32>,
    splats: &Splats,
    dynamic_only: bool,
    cache: &MlpCache<f32>,
    g: &Deltas,
) -> Vec<f32> {
    match evaluated_indices(splats, dynamic_only) {
        None => Deformation::backward(mlp, cache, g),
        Some(idx) => {
            let sub = Deltas {
                dx: idx.iter().map(|&i| g.dx[i]).collect(),
                dq: idx.iter().map(|&i| g.dq[i]).collect(),
                ds: idx.iter().map(|&i| g.ds[i]).collect(),
            };
            Deformation::backward(mlp, cache, &sub)
        }
    }
}

/// The Gaussians deformed by `deltas` (Deform-GS: after activation).
// Eq. 3: the deformation field applied to the canonical Gaussians.
pub fn deform_splats(splats: &Splats, deltas: &Deltas) -> Splats {
    let g = apply_deltas(&splats.means, &splats.log_scales, &splats.rotations, deltas);
    Splats {
        means: g.means,
        log_scales: g.log_scales,
        rotations: g.rotations,
        ..splats.clone()
    }
}
