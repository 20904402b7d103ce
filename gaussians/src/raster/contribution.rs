//! Blending weight per Gaussian: `Σ_pixels α_i·T_i`, Gaussian i's share of the colour
//! of every pixel it reaches (Eq. 1's weight), summed over one render. A separate pass
//! over a finished render (the forward pass itself does not pay for it), walking each
//! tile front to back exactly as the forward does (same lanes, same `α`, same stop), so
//! the weights are the forward's own. Pruning by contribution reads them
//! (the warm-up's sizing, `train/sizing.rs`).

use super::alpha::{T_MIN, eval_alpha};
use super::forward::{Plane, RenderState, TILE, lane_bits, row_span};
use super::simd::{self, F4, Lanes, Mask};
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

/// `out[k]` = the weight of tile entry k summed over the tile's pixels; the loop is the
/// forward's (`forward::tile_forward_lanes`) with the colour replaced by the weight.
#[inline(always)]
fn tile_weights_lanes<V: Lanes>(st: &RenderState, t: usize, out: &mut [f32]) {
    out.fill(0.0);
    let p = &st.proj;
    let list = st.tiles.of(t);
    let r = st.tiles.rect(t, st.cam.width, st.cam.height);
    let mut tt: Plane<f32> = [[1.0; TILE]; TILE];
    let n = V::N;
    let chunk_bits = lane_bits(0, n);
    let mut active = [lane_bits(0, r[1] - r[0]); TILE];
    let mut remaining = ((r[1] - r[0]) * (r[3] - r[2])) as u32;
    let s = V::splat;
    let xs: [V; 4] = std::array::from_fn(|c| V::iota((r[0] + (c * n) % TILE) as f32));
    for (k, &g) in list.iter().enumerate() {
        if remaining == 0 {
            break;
        }
        let g = g as usize;
        let b = p.bbox[g];
        let (x0, x1) = ((b[0] as usize).max(r[0]), (b[1] as usize + 1).min(r[1]));
        let (y0, y1) = ((b[2] as usize).max(r[2]), (b[3] as usize + 1).min(r[3]));
        let [u, v] = p.xy[g];
        let (conic, op, u4) = (p.conic[g], p.opacity[g], s(u));
        let mut sum = s(0.0);
        for y in y0..y1 {
            let row = y - r[2];
            let dyf = y as f32 - v;
            let (lo, hi) = if n == TILE {
                (x0 - r[0], x1 - r[0])
            } else {
                row_span(conic, p.cut[g], u, dyf, [x0, x1, r[0]])
            };
            let inb = lane_bits(lo, hi);
            let dy = s(dyf);
            for c in lo / n..hi.div_ceil(n) {
                let bits = (inb & active[row]) >> (n * c) & chunk_bits;
                if bits == 0 {
                    continue;
                }
                let l = n * c..n * c + n;
                let (a0, _) = eval_alpha(conic, op, xs[c] - u4, dy);
                let a0 = a0.and(V::M::from_bits(bits));
                let tv = V::load(&tt[row][l.clone()]);
                let test_t = tv * (s(1.0) - a0);
                let stop = a0.gt(s(0.0)).and(test_t.lt(s(T_MIN)));
                let sb = stop.bits();
                active[row] &= !(sb << (n * c));
                remaining -= sb.count_ones();
                let a = V::select(stop, s(0.0), a0);
                sum = sum + a * tv;
                V::select(a.gt(s(0.0)), test_t, tv).store(&mut tt[row][l]);
            }
        }
        out[k] = sum.sum();
    }
}
