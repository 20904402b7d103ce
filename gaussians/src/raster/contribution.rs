//! Blending weight per Gaussian: `Σ_pixels α_i·T_i`, Gaussian i's share of the colour
//! of every pixel it reaches (Eq. 1's weight), summed over one render. A separate pass
//! over a finished render (the forward pass itself does not pay for it), walking each
//! tile with the forward's own walk (`forward::walk_tile`: same lanes, same `α`, same
//! stop), so the weights are the forward's. Pruning by contribution reads them
//! (the warm-up's sizing, `train/sizing.rs`).

use super::forward::{Plane, Projected, RenderState, TILE, TileSink, walk_tile};
use super::simd::{self, F4, Lanes};
use rayon::prelude::*;

/// Add each Gaussian's blending weight in the render `st` to `acc` (one entry per
/// rendered Gaussian; culled Gaussians get nothing). For every pixel the weights of its
/// Gaussians sum to its alpha (`1 − T_final`).
pub fn add_contributions(st: &RenderState, acc: &mut [f64]) {
    assert_eq!(acc.len(), st.n, "contributions: one entry per Gaussian");
    let tiles = &st.tiles;
    let mut pairs = vec![0.0f32; tiles.list.len()];
    let ntiles = tiles.nx * tiles.ny;
    let mut slices = Vec::with_capacity(ntiles);
    let mut rest = &mut pairs[..];
    for t in 0..ntiles {
        let len = (tiles.ranges[t + 1] - tiles.ranges[t]) as usize;
        let (a, b) = rest.split_at_mut(len);
        slices.push((t, a));
        rest = b;
    }
    slices
        .into_par_iter()
        .for_each(|(t, out)| tile_weights(st, t, out));
    for (&w, &k) in pairs.iter().zip(&tiles.list) {
        acc[st.proj.id[k as usize] as usize] += w as f64;
    }
}

/// One tile with the widest lanes this CPU has (as the forward chooses).
fn tile_weights(st: &RenderState, t: usize, out: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if simd::use_wide() {
        // SAFETY: `use_wide` checked that the CPU has AVX-512F.
        return unsafe { tile_weights_avx512(st, t, out) };
    }
    tile_weights_lanes::<F4>(st, t, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn tile_weights_avx512(st: &RenderState, t: usize, out: &mut [f32]) {
    tile_weights_lanes::<simd::F16>(st, t, out)
}

/// Sums each tile entry's weight over the tile's pixels into `out[k]`.
struct Weights<'a, V> {
    out: &'a mut [f32],
    sum: V,
}

impl<V: Lanes> TileSink<V> for Weights<'_, V> {
    #[inline(always)]
    fn gaussian(&mut self, _p: &Projected, _k: usize, _g: usize) {
        self.sum = V::splat(0.0);
    }

    #[inline(always)]
    fn chunk(&mut self, _row: usize, _l: std::ops::Range<usize>, w: V, _used: V::M) {
        self.sum = self.sum + w;
    }

    #[inline(always)]
    fn done(&mut self, k: usize) {
        self.out[k] = self.sum.sum();
    }
}

/// `out[k]` = the weight of tile entry k summed over the tile's pixels: the forward's
/// walk (`forward::walk_tile`) with the colour replaced by the weight.
#[inline(always)]
fn tile_weights_lanes<V: Lanes>(st: &RenderState, t: usize, out: &mut [f32]) {
    out.fill(0.0);
    let list = st.tiles.of(t);
    let r = st.tiles.rect(t, st.cam.width, st.cam.height);
    let mut tt: Plane<f32> = [[1.0; TILE]; TILE];
    let mut sink = Weights {
        out,
        sum: V::splat(0.0),
    };
    walk_tile(&st.proj, list, r, &mut tt, &mut sink);
}
