//! The deformation field evaluated on [`Splats`]: on every Gaussian, or only on those
//! flagged dynamic (`dynamic_only`; the others keep their canonical parameters). A field
//! with a colour head runs on every Gaussian even when `dynamic_only`: the static ones
//! keep their canonical geometry and take its colour (a still floor under a moving
//! shadow changes colour without moving).

use super::deltas::{Deformation, Deltas, apply_color_deltas, apply_deltas, apply_deltas_in_place};
use super::mlp::{HEAD_OUT, Mlp, MlpCache, MlpScratch};
use crate::splats::Splats;

/// Indices the field is evaluated on: all (`None`), or the dynamic ones when
/// `dynamic_only` and the field has no colour head (missing flags count as dynamic).
pub fn evaluated_indices(
    mlp: &Mlp<f32>,
    splats: &Splats,
    dynamic_only: bool,
) -> Option<Vec<usize>> {
    subset(mlp, dynamic_only).then(|| {
        (0..splats.len())
            .filter(|&i| splats.is_dynamic(i))
            .collect()
    })
}

/// Whether the field runs on the dynamic subset only: `dynamic_only` without a colour
/// head.
fn subset(mlp: &Mlp<f32>, dynamic_only: bool) -> bool {
    dynamic_only && !mlp.settings.color
}

/// Zero the geometric deltas (or their gradients) of the static-flagged Gaussians.
fn still_geometry(splats: &Splats, d: &mut Deltas) {
    for i in (0..d.len()).filter(|&i| !splats.is_dynamic(i)) {
        d.dx[i] = [0.0; 3];
        d.dq[i] = [0.0; 4];
        d.ds[i] = [0.0; 3];
    }
}

/// The same on head rows of `width` (geometry first, as [`Deltas::set_row`]).
fn still_geometry_rows(splats: &Splats, rows: &mut [f32], width: usize) {
    for (i, r) in rows.chunks_mut(width).enumerate() {
        if !splats.is_dynamic(i) {
            r[..HEAD_OUT].fill(0.0);
        }
    }
}

/// Field deltas for every Gaussian at time `t` (zero for static-flagged ones when
/// `dynamic_only`; the field then runs on the dynamic subset only).
pub fn splat_deltas(
    mlp: &Mlp<f32>,
    splats: &Splats,
    t: f32,
    dynamic_only: bool,
) -> (Deltas, MlpCache<f32>) {
    match evaluated_indices(mlp, splats, dynamic_only) {
        None => {
            let (mut d, cache) = Deformation::forward(mlp, &splats.means, &[t]);
            if dynamic_only {
                still_geometry(splats, &mut d);
            }
            (d, cache)
        }
        Some(idx) => {
            let sub: Vec<[f32; 3]> = idx.iter().map(|&i| splats.means[i]).collect();
            let (ds, cache) = Deformation::forward(mlp, &sub, &[t]);
            let mut d = Deltas::default();
            d.set_zeros_with(splats.len(), ds.has_color());
            for (k, &i) in idx.iter().enumerate() {
                d.copy_one(i, &ds, k);
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
    match evaluated_indices(mlp, splats, dynamic_only) {
        None if dynamic_only => {
            let mut g = g.clone();
            still_geometry(splats, &mut g);
            Deformation::backward(mlp, cache, &g)
        }
        None => Deformation::backward(mlp, cache, g),
        Some(idx) => {
            let mut sub = Deltas::default();
            for &i in &idx {
                sub.push_one(g, i);
            }
            Deformation::backward(mlp, cache, &sub)
        }
    }
}

/// The Gaussians deformed by `deltas` (Deform-GS: after activation).
// Eq. 3: the deformation field applied to the canonical Gaussians.
pub fn deform_splats(splats: &Splats, deltas: &Deltas) -> Splats {
    let g = apply_deltas(&splats.means, &splats.log_scales, &splats.rotations, deltas);
    let mut out = Splats {
        means: g.means,
        log_scales: g.log_scales,
        rotations: g.rotations,
        ..splats.clone()
    };
    apply_color_deltas(&mut out.sh_dc, deltas);
    out
}

/// Reusable buffers of the field evaluated on [`Splats`] ([`splat_deltas_into`],
/// [`splat_deltas_backward_into`]); a training loop keeps one, so that once warm an
/// iteration allocates nothing for the field.
#[derive(Clone, Debug, Default)]
pub struct FieldWork {
    scratch: MlpScratch<f32>,
    rows: Vec<f32>,
    sub: Vec<[f32; 3]>,
    sub_deltas: Deltas,
}

/// [`splat_deltas`] into `deltas` and `cache` (overwritten; allocations reused).
pub fn splat_deltas_into(
    mlp: &Mlp<f32>,
    splats: &Splats,
    t: f32,
    dynamic_only: bool,
    work: &mut FieldWork,
    deltas: &mut Deltas,
    cache: &mut MlpCache<f32>,
) {
    let FieldWork {
        scratch, rows, sub, ..
    } = work;
    let width = mlp.settings.head_out();
    if !subset(mlp, dynamic_only) {
        mlp.forward_into(&splats.means, &[t], cache, scratch, rows);
        if dynamic_only {
            still_geometry_rows(splats, rows, width);
        }
        deltas.set_rows(rows, width);
        return;
    }
    sub.clear();
    sub.extend(
        (0..splats.len())
            .filter(|&i| splats.is_dynamic(i))
            .map(|i| splats.means[i]),
    );
    mlp.forward_into(sub, &[t], cache, scratch, rows);
    deltas.set_zeros_with(splats.len(), mlp.settings.color);
    let dynamic = (0..splats.len()).filter(|&i| splats.is_dynamic(i));
    for (r, i) in rows.chunks(width).zip(dynamic) {
        deltas.set_row(i, r);
    }
}

/// [`splat_deltas_backward`] into `grads` (overwritten; allocations reused).
pub fn splat_deltas_backward_into(
    mlp: &Mlp<f32>,
    splats: &Splats,
    dynamic_only: bool,
    cache: &MlpCache<f32>,
    g: &Deltas,
    work: &mut FieldWork,
    grads: &mut Vec<f32>,
) {
    let FieldWork {
        scratch,
        rows,
        sub_deltas,
        ..
    } = work;
    let width = mlp.settings.head_out();
    if subset(mlp, dynamic_only) {
        sub_deltas.set_zeros(0);
        for i in (0..splats.len()).filter(|&i| splats.is_dynamic(i)) {
            sub_deltas.push_one(g, i);
        }
        sub_deltas.rows_into(rows, width);
    } else {
        g.rows_into(rows, width);
        if dynamic_only {
            still_geometry_rows(splats, rows, width);
        }
    }
    mlp.backward_into(cache, rows, scratch, grads);
}

/// [`deform_splats`] into `out` (overwritten; allocations reused).
pub fn deform_splats_into(splats: &Splats, deltas: &Deltas, out: &mut Splats) {
    out.clone_from(splats);
    apply_deltas_in_place(
        &mut out.means,
        &mut out.log_scales,
        &mut out.rotations,
        deltas,
    );
    apply_color_deltas(&mut out.sh_dc, deltas);
}
