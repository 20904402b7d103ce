//! Event voxel grid (`docs/DESIGN.md` §5, paper Eq. 15) — the flow network's input.
//!
//! For a window `[t_a, t_b]` and `B` bins, each event gets the normalised time
//! `t*_i = (B−1)(t_i − t_a)/(t_b − t_a)` and is spread bilinearly in time over the two
//! nearest bins, signed by its polarity:
//!
//! `E(x, y, n) = Σ_i p_i · max(0, 1 − |n − t*_i|)`, `n = 0 … B−1`.
//!
//! The grid is then z-score normalised over its **non-zero cells only** (as in the
//! public EV-FlowNet / event_flow code): `E ← (E − mean)/std` where mean and std are
//! taken over the cells with `E ≠ 0` (population std); cells that received nothing
//! stay exactly 0. If the std is 0 (e.g. a single non-zero cell) only the mean is
//! subtracted. An empty window gives all zeros, never NaN.
//!
//! Layout of the result: `bins × height × width`, row-major (`[n][y][x]`), f32.
//! Events outside the sensor are ignored. A degenerate window (`t_b ≤ t_a`) or
//! `bins == 1` puts every event in bin 0.

use scene::EventSlice;

/// Number of bins the paper uses.
pub const DEFAULT_BINS: usize = 5;

/// The polarity-signed, time-bilinear voxel grid of Eq. 15 **before** normalisation.
pub fn voxel_grid_raw(
    events: &EventSlice,
    t_a: f64,
    t_b: f64,
    bins: usize,
    width: u32,
    height: u32,
) -> Vec<f32> {
    let (w, h) = (width as usize, height as usize);
    let mut grid = vec![0f32; bins * w * h];
    if bins == 0 || w == 0 || h == 0 {
        return grid;
    }
    let span = t_b - t_a;
    let scale = if bins > 1 && span > 0.0 && span.is_finite() {
        (bins - 1) as f64 / span
    } else {
        0.0
    };
    let plane = w * h;
    let last = (bins - 1) as f64;
    for i in 0..events.len() {
        let (x, y) = (events.x[i] as usize, events.y[i] as usize);
        if x >= w || y >= h {
            continue;
        }
        let ts = (events.t[i] - t_a) * scale;
        if !ts.is_finite() || ts <= -1.0 || ts >= last + 1.0 {
            continue;
        }
        let p = events.p[i] as f64;
        let lo = ts.floor();
        let frac = ts - lo;
        let pix = y * w + x;
        // Tent weights on the two neighbouring bins: max(0, 1 − |n − t*|).
        for (n, weight) in [(lo, 1.0 - frac), (lo + 1.0, frac)] {
            if n >= 0.0 && n <= last && weight > 0.0 {
                grid[n as usize * plane + pix] += (p * weight) as f32;
            }
        }
    }
    grid
}

/// Z-score normalise the non-zero cells in place (see the module doc).
pub fn normalize_nonzero(grid: &mut [f32]) {
    let (mut n, mut sum) = (0usize, 0f64);
    for &v in grid.iter() {
        if v != 0.0 {
            n += 1;
            sum += v as f64;
        }
    }
    if n == 0 {
        return;
    }
    let mean = sum / n as f64;
    let var = grid
        .iter()
        .filter(|&&v| v != 0.0)
        .map(|&v| (v as f64 - mean).powi(2))
        .sum::<f64>()
        / n as f64;
    let std = var.sqrt();
    let inv = if std > 0.0 { 1.0 / std } else { 1.0 };
    for v in grid.iter_mut() {
        if *v != 0.0 {
            *v = ((*v as f64 - mean) * inv) as f32;
        }
    }
}

/// Eq. 15 voxel grid with z-score normalisation of the non-zero cells:
/// `bins × height × width` f32, row-major.
pub fn voxel_grid(
    events: &EventSlice,
    t_a: f64,
    t_b: f64,
    bins: usize,
    width: u32,
    height: u32,
) -> Vec<f32> {
    let mut grid = voxel_grid_raw(events, t_a, t_b, bins, width, height);
    normalize_nonzero(&mut grid);
    grid
}
